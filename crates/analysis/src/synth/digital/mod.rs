//! A digital positioner on a spring-diaphragm valve, written from physics apart from the
//! project's models (nothing here steps [`vb_core::model`]): a second family of valves to check
//! diagnosis against, as an independent simulator would record them. All positions are in %
//! of travel, forces in % of travel too (the position the spring alone would balance them
//! at), pressures in bar, times in s.
//!
//! - **Positioner** (sampled, pulse-width modulated, Bürkert-style). Every `sample_s` it reads
//!   its travel sensor, the potentiometer on the linkage below (noise and lattice of its own,
//!   no lever error: the positioner is calibrated to it), and takes the set-point, O_P
//!   `input_delay_s` ago. With `e` = set-point - reading: inside the tolerance band
//!   `|e| <= tolerance_pct` nothing fires; outside it the PD law
//!   `d = duty_per_pct * (e + derivative_s * de/dt)` (de/dt over the last sample) opens the fill
//!   solenoid (`e > 0`) or the vent solenoid (`e < 0`) for `|d| * sample_s` from the sample on,
//!   never shorter than `min_pulse_s` and never longer than the sample; when `d` points against
//!   `e` (braking) no pulse fires. A pulse reaches the chamber `line_delay_s` later.
//! - **Chamber** (isothermal). Absolute pressure `p`, volume `V0 (1 + g x/100)` (the diaphragm
//!   sweeps it): `d(p V)/dt = p_n (Q_fill - Q_vent)`, each flow through an orifice by
//!   ISO 6358, `Q = C p_up phi(p_down/p_up)`, `phi = 1` when choked (ratio <= `critical_ratio`),
//!   else `sqrt(1 - ((r - b)/(1 - b))^2)`; filling from the supply, venting to the atmosphere.
//!   `fill_per_s` and `vent_per_s` are `p_n C / V0`.
//! - **Stem** (spring, diaphragm, mass): `x'' = w^2 (P(p) - x - F)`, `P(p) = 100 (p - p_atm -
//!   spring_start_bar) / (spring_end_bar - spring_start_bar)` (air to open), `F` LuGre friction
//!   with bristle deflection `z`: `z' = x' - s0 |x'| z / g(x')`, `g(v) = F_c + (F_s - F_c)
//!   exp(-(v/v_s)^2)`, `F = s0 z + s1 exp(-(x'/v_s)^2) z' + s2 x'` (the bristles damp while
//!   they stick; a constant `s1` would damp a sliding stem many times over). Static above
//!   Coulomb makes the stem stick, then slip. Travel stops at `stop_low_pct` and
//!   `stop_high_pct` stop it dead.
//! - **Linkage and position feedback**: the potentiometer's arm is driven from the stem through
//!   a linkage with play `play_pct` (the arm stays put until the stem takes the play up: lost
//!   motion on every reversal). The positioner closes its loop on the arm, so the play is
//!   inside the loop: the arm comes to rest at the set-point and the stem half the play beyond
//!   it, and a reversal waits while the stem crosses the play unseen (as an independent
//!   positioner's linkage does). The transmitted V_P is the arm through the transmitter's
//!   error (`gain`, `offset_pct`), an ADC on a lattice `lattice_pct` and Gaussian noise
//!   `noise_pct`; the positioner does not use those four, so they shape V_P and not the valve.
//!
//! Each sample is integrated in whole internal steps of at most `internal_step_s`: chamber
//! explicitly, stem semi-implicitly (viscous and bristle damping implicit, the bristle
//! deflection by implicit Euler, position from the new speed). Not here: which values are
//! healthy, and what counts as a fault (a benchmark states its own thresholds).

mod sim;
#[cfg(test)]
mod tests;

use serde::Serialize;

pub use sim::DigitalValve;

/// Atmospheric pressure, bar absolute.
pub const ATMOSPHERE_BAR: f64 = 1.013;

/// A parameter of a digital valve outside what the simulator takes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("digital valve: {name} = {value} is outside {range}")]
pub struct DigitalError {
    pub name: &'static str,
    pub value: f64,
    pub range: &'static str,
}

/// Everything a digital valve is (module doc for the physics).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct DigitalParams {
    /// Positioner's sampling period, s.
    pub sample_s: f64,
    /// Tolerance band: no pulse while |e| <= this, % (the band is twice as wide).
    pub tolerance_pct: f64,
    /// Share of the sample a pulse lasts per % of error.
    pub duty_per_pct: f64,
    /// Derivative time of the PD law, s.
    pub derivative_s: f64,
    /// Shortest pulse the solenoids open for, s.
    pub min_pulse_s: f64,
    /// Transport delay of the set-point before the positioner sees it, s.
    pub input_delay_s: f64,
    /// Transport delay of the pneumatic line from the solenoids to the chamber, s.
    pub line_delay_s: f64,
    /// Noise of the positioner's travel sensor (standard deviation), %.
    pub travel_noise_pct: f64,
    /// Lattice of the positioner's travel sensor, % (0: continuous).
    pub travel_lattice_pct: f64,
    /// Supply pressure, bar gauge.
    pub supply_bar: f64,
    /// Chamber pressure that balances the spring closed and fully open, bar gauge.
    pub spring_start_bar: f64,
    pub spring_end_bar: f64,
    /// Fill and vent orifices as `p_n C / V0`, 1/(s bar) times bar: 1/s.
    pub fill_per_s: f64,
    pub vent_per_s: f64,
    /// Critical pressure ratio of both orifices (ISO 6358 b).
    pub critical_ratio: f64,
    /// Chamber volume growth over the stroke g: `V = V0 (1 + g x/100)`.
    pub volume_growth: f64,
    /// Natural frequency of spring and stem, Hz.
    pub natural_freq_hz: f64,
    /// LuGre levels: Coulomb and static friction, % of travel (force over spring rate).
    pub coulomb_pct: f64,
    pub static_pct: f64,
    /// Stribeck speed, %/s.
    pub stribeck_pct_per_s: f64,
    /// Viscous friction s2, s (force % per %/s).
    pub viscous_s: f64,
    /// Bristle stiffness s0 (force % per % of deflection) and damping s1, s.
    pub bristle_stiffness: f64,
    pub bristle_damping_s: f64,
    /// Travel stops of the stem, %.
    pub stop_low_pct: f64,
    pub stop_high_pct: f64,
    /// Play of the linkage from the stem to the potentiometer, % (the stem's lost motion on a
    /// reversal, inside the positioner's loop).
    pub play_pct: f64,
    /// The feedback transmitter's error: V_P = gain * arm + offset.
    pub gain: f64,
    pub offset_pct: f64,
    /// Noise (standard deviation) and lattice of the feedback's ADC, %.
    pub noise_pct: f64,
    pub lattice_pct: f64,
    /// Seed of both sensors' noise.
    pub noise_seed: u64,
    /// Longest internal integration step, s.
    pub internal_step_s: f64,
}

impl Default for DigitalParams {
    /// A valve in good order: a 10 ms positioner of gain 20 /s with a 0.08 % tolerance band and
    /// a 0.5 ms minimum pulse (0.03 % of travel), an actuator of 1.2-2.8 bar on a 6 bar supply
    /// stroking at about 60 %/s, light friction (a 0.1 % band), 0.03 % of linkage play, a
    /// calibrated feedback with 0.02 % noise.
    fn default() -> Self {
        let mut p = DigitalParams {
            sample_s: 0.01,
            tolerance_pct: 0.08,
            duty_per_pct: 0.33,
            derivative_s: 0.01,
            min_pulse_s: 0.0005,
            input_delay_s: 0.03,
            line_delay_s: 0.005,
            travel_noise_pct: 0.01,
            travel_lattice_pct: 0.01,
            supply_bar: 6.0,
            spring_start_bar: 1.2,
            spring_end_bar: 2.8,
            fill_per_s: 1.0,
            vent_per_s: 1.0,
            critical_ratio: 0.45,
            volume_growth: 0.15,
            natural_freq_hz: 15.0,
            coulomb_pct: 0.05,
            static_pct: 0.06,
            stribeck_pct_per_s: 1.0,
            viscous_s: 0.0,
            bristle_stiffness: 150.0,
            bristle_damping_s: 0.0,
            stop_low_pct: 0.0,
            stop_high_pct: 100.0,
            play_pct: 0.03,
            gain: 1.0,
            offset_pct: 0.0,
            noise_pct: 0.02,
            lattice_pct: 0.0,
            noise_seed: 1,
            internal_step_s: 1e-4,
        };
        p.damp(0.7, 0.6);
        p.set_stroke_speeds(60.0, 60.0);
        p
    }
}

/// How a quasi-static stroke goes: `(numerator, denominator)` of its speed at `x` (see
/// [`DigitalParams::stroke_speed_pct_per_s`]).
fn stroke_terms(p: &DigitalParams, x: f64, opening: bool) -> (f64, f64) {
    let span = p.spring_end_bar - p.spring_start_bar;
    // The pressure that holds the stem at x while it slides that way.
    let force = if opening {
        x + p.coulomb_pct
    } else {
        x - p.coulomb_pct
    };
    let pressure = ATMOSPHERE_BAR + p.spring_start_bar + span * force / 100.0;
    let volume = 1.0 + p.volume_growth * x.clamp(0.0, 100.0) / 100.0;
    let flow = if opening {
        let supply = ATMOSPHERE_BAR + p.supply_bar;
        supply * flow_factor(pressure / supply, p.critical_ratio)
    } else {
        pressure * flow_factor(ATMOSPHERE_BAR / pressure, p.critical_ratio)
    };
    (100.0 * flow, volume * span + pressure * p.volume_growth)
}

/// ISO 6358's flow factor at the pressure ratio `r` (downstream over upstream) for a critical
/// ratio `b`: 1 when choked, falling to 0 as the pressures meet.
pub(crate) fn flow_factor(r: f64, b: f64) -> f64 {
    if r <= b {
        1.0
    } else if r >= 1.0 {
        0.0
    } else {
        let s = (r - b) / (1.0 - b);
        (1.0 - s * s).sqrt()
    }
}

impl DigitalParams {
    /// The stroke speed at `x` with one solenoid held open (`opening`: the fill one), %/s: the
    /// stem following the pressure quasi-statically, sliding against Coulomb friction, the
    /// chamber growing with it: `x' = 100 Q / (V/V0 span + p g)` from the mass balance.
    pub fn stroke_speed_pct_per_s(&self, x: f64, opening: bool) -> f64 {
        let (num, den) = stroke_terms(self, x, opening);
        let k = if opening {
            self.fill_per_s
        } else {
            self.vent_per_s
        };
        k * num / den
    }

    /// Sets the orifices so that the valve strokes at `opening` and `closing` %/s at half
    /// travel.
    pub fn set_stroke_speeds(&mut self, opening: f64, closing: f64) {
        let (num, den) = stroke_terms(self, 50.0, true);
        self.fill_per_s = opening * den / num;
        let (num, den) = stroke_terms(self, 50.0, false);
        self.vent_per_s = closing * den / num;
    }

    /// Sets the viscous friction for a sliding stem of damping ratio `stem` and the bristle
    /// damping for bristles of damping ratio `bristles` (on the bristle stiffness).
    pub fn damp(&mut self, stem: f64, bristles: f64) {
        let w = std::f64::consts::TAU * self.natural_freq_hz;
        self.viscous_s = 2.0 * stem / w;
        self.bristle_damping_s = 2.0 * bristles * self.bristle_stiffness.sqrt() / w;
    }

    /// The error below which the minimum pulse takes over from the proportional width, %:
    /// small moves then go at the constant [`Self::floor_speed_pct_per_s`].
    pub fn min_pulse_band_pct(&self) -> f64 {
        self.min_pulse_s / (self.duty_per_pct * self.sample_s)
    }

    /// The mean speed of one minimum pulse every sample at half travel (both ways'
    /// average), %/s.
    pub fn floor_speed_pct_per_s(&self) -> f64 {
        let v = 0.5
            * (self.stroke_speed_pct_per_s(50.0, true) + self.stroke_speed_pct_per_s(50.0, false));
        v * self.min_pulse_s / self.sample_s
    }

    /// The positioner's gain at half travel, 1/s: the mean speed per % of error where the
    /// pulse width is proportional.
    pub fn gain_per_s(&self) -> f64 {
        0.5 * (self.stroke_speed_pct_per_s(50.0, true) + self.stroke_speed_pct_per_s(50.0, false))
            * self.duty_per_pct
    }

    /// Checks every parameter is one the simulator takes.
    pub fn validate(&self) -> Result<(), DigitalError> {
        let within = |name, value: f64, lo: f64, hi: f64, range| {
            if value.is_finite() && (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(DigitalError { name, value, range })
            }
        };
        within("sample_s", self.sample_s, 1e-3, 0.1, "1 ms - 0.1 s")?;
        within("tolerance_pct", self.tolerance_pct, 0.0, 10.0, "0-10 %")?;
        within("duty_per_pct", self.duty_per_pct, 1e-4, 100.0, "1e-4 - 100")?;
        within("derivative_s", self.derivative_s, 0.0, 1.0, "0-1 s")?;
        within(
            "min_pulse_s",
            self.min_pulse_s,
            0.0,
            self.sample_s,
            "0 to sample_s",
        )?;
        within("input_delay_s", self.input_delay_s, 0.0, 60.0, "0-60 s")?;
        within("line_delay_s", self.line_delay_s, 0.0, 1.0, "0-1 s")?;
        within("travel_noise_pct", self.travel_noise_pct, 0.0, 5.0, "0-5 %")?;
        within(
            "travel_lattice_pct",
            self.travel_lattice_pct,
            0.0,
            10.0,
            "0-10 %",
        )?;
        within(
            "spring_start_bar",
            self.spring_start_bar,
            0.0,
            10.0,
            "0-10 bar",
        )?;
        let start = self.spring_start_bar;
        within(
            "spring_end_bar",
            self.spring_end_bar,
            start + 0.1,
            20.0,
            "above the start",
        )?;
        let end = self.spring_end_bar;
        within(
            "supply_bar",
            self.supply_bar,
            end + 0.2,
            20.0,
            "0.2 bar above the spring's end",
        )?;
        within("fill_per_s", self.fill_per_s, 1e-4, 1e3, "1e-4 - 1e3 /s")?;
        within("vent_per_s", self.vent_per_s, 1e-4, 1e3, "1e-4 - 1e3 /s")?;
        within("critical_ratio", self.critical_ratio, 0.05, 0.6, "0.05-0.6")?;
        within("volume_growth", self.volume_growth, 0.0, 20.0, "0-20")?;
        within(
            "natural_freq_hz",
            self.natural_freq_hz,
            1.0,
            100.0,
            "1-100 Hz",
        )?;
        within("coulomb_pct", self.coulomb_pct, 1e-3, 20.0, "0.001-20 %")?;
        within(
            "static_pct",
            self.static_pct,
            self.coulomb_pct,
            40.0,
            "coulomb_pct - 40 %",
        )?;
        within(
            "stribeck_pct_per_s",
            self.stribeck_pct_per_s,
            1e-3,
            100.0,
            "0.001-100 %/s",
        )?;
        within("viscous_s", self.viscous_s, 0.0, 10.0, "0-10 s")?;
        within(
            "bristle_stiffness",
            self.bristle_stiffness,
            1.0,
            1e4,
            "1-1e4",
        )?;
        within(
            "bristle_damping_s",
            self.bristle_damping_s,
            0.0,
            10.0,
            "0-10 s",
        )?;
        within("stop_low_pct", self.stop_low_pct, 0.0, 99.0, "0-99 %")?;
        let low = self.stop_low_pct;
        within(
            "stop_high_pct",
            self.stop_high_pct,
            low + 1.0,
            100.0,
            "above the low stop",
        )?;
        within("play_pct", self.play_pct, 0.0, 20.0, "0-20 %")?;
        within("gain", self.gain, 0.5, 1.5, "0.5-1.5")?;
        within("offset_pct", self.offset_pct, -10.0, 10.0, "-10 to 10 %")?;
        within("noise_pct", self.noise_pct, 0.0, 5.0, "0-5 %")?;
        within("lattice_pct", self.lattice_pct, 0.0, 10.0, "0-10 %")?;
        let w =
            std::f64::consts::TAU * self.natural_freq_hz * (1.0 + self.bristle_stiffness).sqrt();
        within(
            "internal_step_s",
            self.internal_step_s,
            1e-6,
            0.5 / w,
            "1e-6 s to 0.5 / the bristles' angular frequency",
        )
    }
}
