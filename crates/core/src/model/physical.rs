//! A first-principles pneumatic valve with its positioner: `model = "physical"`.
//!
//! This is not the composed pin-cart valve that diagnosis fits: its backlash, stick-slip,
//! slowdowns and speed limits come out of a positioner, a pneumatic chamber, a spring-loaded
//! stem with friction, travel stops and a position sensor, so it can check diagnosis (and test
//! controllers) against physics they do not share. All quantities are in % of travel and
//! seconds; `u` is O_P after the spec's transport delay `dead_time_s` (the valve's delay line).
//!
//! - Positioner (proportional, with a deadband and two flow limits): with `e = u - x`,
//!   `q = 0` while `|e| < deadband/2`, else `q = sgn(e) max(K |e|, q_min)`, limited to
//!   `q_fill` while filling (`e > 0`, opening) and `q_vent` while venting (`e < 0`, closing).
//! - Chamber: pressure `p` in % of travel (the position the spring alone would balance it at),
//!   `dp/dt = q / (1 + g x/100)`: the volume grows with travel, so an open valve answers,
//!   strokes and crosses its friction band more slowly. `p` stays within -20..120 % (atmosphere
//!   and supply); it keeps winding past a travel stop, as a real one does.
//! - Stem (mass, spring, viscous damping and friction):
//!   `x'' = w²(p - x) - 2 z w x' - w² F`, `w = 2 pi f_n`. Friction is Karnopp's: a stem at rest
//!   stays put while `|p - x| <= S/2` (`S` the static band); a sliding stem feels
//!   `F = sgn(x') C/2` (`C` the Coulomb band) and sticks when its speed would change sign within
//!   an internal step, or falls below the stick-velocity window (0.05 %/s) while static friction
//!   can hold it (`|p - x| <= S/2`). A reversal
//!   therefore costs the chamber a crossing of the band `C` before the stem moves (lost motion,
//!   backlash-like), and `S > C` makes the stem stick, then slip by about `S - C` (stick-slip).
//! - Travel stops: `x` stays in `[travel.min_pct, travel.max_pct]`; hitting one stops the stem.
//! - Sensor: `V_P = round_r(a x + b + n)`, `n` Gaussian (seeded ChaCha8, re-seeded on reset),
//!   `round_r` the resolution lattice (`r = 0`: continuous). The positioner controls the true
//!   position, so a calibration error shows between O_P and V_P. The reading is not clamped.
//!
//! Each sample is integrated in whole internal steps of at most `internal_step_s`:
//! positioner and chamber explicitly, the stem semi-implicitly (damping implicit, position
//! from the new speed), which is stable over the documented ranges. Stepping allocates nothing.
//! Nothing here knows about effects of the composed valve (`[effects]` is refused).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::Travel;

/// Lowest chamber pressure, % of travel: atmosphere, below the spring's closed point.
pub(super) const PRESSURE_MIN_PCT: f64 = -20.0;
/// Highest chamber pressure, % of travel: the supply, above the spring's open point.
pub(super) const PRESSURE_MAX_PCT: f64 = 120.0;
/// Karnopp's stick-velocity window, %/s: a stem slower than this sticks if static friction
/// can hold it (a thousandth of a healthy stroke speed).
pub(super) const STICK_SPEED_PCT_PER_S: f64 = 0.05;

/// Parameters of the physical valve (`[physical]`); every key may be left out for its default,
/// which is a healthy Bürkert-like valve (`config/models/physical.toml`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PhysicalParams {
    /// K: positioner gain, chamber flow per % of error, 1/s (0-100, and at most z * 2 pi f_n,
    /// or the positioner oscillates with the stem). Default 8.
    pub positioner_gain_per_s: f64,
    /// Positioner deadband, % (0-10): no action while |O_P - x| < deadband/2. Default 0.05.
    pub deadband_pct: f64,
    /// q_fill: largest flow while filling (opening), %/s of pressure at the closed volume
    /// (0.1-1000). Default 60.
    pub fill_rate_pct_per_s: f64,
    /// q_vent: largest flow while venting (closing), %/s (0.1-1000). Default 60.
    pub vent_rate_pct_per_s: f64,
    /// q_min: smallest flow outside the deadband, %/s (0 to the smaller flow limit; 0 = none).
    /// Small errors are then closed at a constant rate. Default 0.
    pub min_rate_pct_per_s: f64,
    /// g: chamber volume growth over the stroke (0-20): the volume is `1 + g x/100` times the
    /// closed one, so fully open is `1 + g` times slower. Default 0.
    pub volume_growth: f64,
    /// f_n: natural frequency of the spring and stem, Hz (1-100). Default 10.
    pub natural_freq_hz: f64,
    /// z: damping ratio of the stem (0.3-5). Default 0.8.
    pub damping_ratio: f64,
    /// C: Coulomb (sliding) friction band, % of travel (0-20): the chamber must cross this
    /// band on a reversal before the stem moves. Default 0.1.
    pub coulomb_band_pct: f64,
    /// S: static friction band, % of travel (C-20): a stem at rest breaks loose once |p - x|
    /// exceeds S/2; S > C gives stick-slip. Default 0.1.
    pub static_band_pct: f64,
    /// a: sensor gain (0.5-1.5; 1 = calibrated). Default 1.
    pub sensor_gain: f64,
    /// b: sensor offset, % (-10 to 10; 0 = calibrated). Default 0.
    pub sensor_offset_pct: f64,
    /// Standard deviation of the sensor's Gaussian noise, % (0-5). Default 0.02.
    pub sensor_noise_pct: f64,
    /// r: sensor resolution, % (0-10; 0 = continuous): V_P is rounded to multiples of it.
    /// Default 0.
    pub sensor_resolution_pct: f64,
    /// Seed of the sensor noise (the same seed gives the same run). Default 1.
    pub noise_seed: u64,
    /// Longest internal integration step, s (1e-5 to 0.01, and at most 0.08 / f_n); each
    /// sample is split into whole steps. Default 0.001.
    pub internal_step_s: f64,
}

impl PhysicalParams {
    /// How many parameters `[physical]` has (for messages).
    pub const COUNT: usize = 16;
}

impl Default for PhysicalParams {
    fn default() -> Self {
        PhysicalParams {
            positioner_gain_per_s: 8.0,
            deadband_pct: 0.05,
            fill_rate_pct_per_s: 60.0,
            vent_rate_pct_per_s: 60.0,
            min_rate_pct_per_s: 0.0,
            volume_growth: 0.0,
            natural_freq_hz: 10.0,
            damping_ratio: 0.8,
            coulomb_band_pct: 0.1,
            static_band_pct: 0.1,
            sensor_gain: 1.0,
            sensor_offset_pct: 0.0,
            sensor_noise_pct: 0.02,
            sensor_resolution_pct: 0.0,
            noise_seed: 1,
            internal_step_s: 0.001,
        }
    }
}

/// Running state of the physical valve.
#[derive(Debug, Clone)]
pub(crate) struct Physical {
    k: f64,
    half_deadband: f64,
    fill: f64,
    vent: f64,
    floor: f64,
    growth: f64,
    /// w², 1/s².
    w2: f64,
    /// 2 z w, 1/s.
    two_zw: f64,
    c_half: f64,
    s_half: f64,
    gain: f64,
    offset: f64,
    noise: f64,
    quantum: f64,
    seed: u64,
    lo: f64,
    hi: f64,
    substeps: u32,
    h: f64,
    /// True stem position, %.
    x: f64,
    /// Stem speed, %/s (exactly 0 while stuck).
    v: f64,
    /// Chamber pressure, % of travel.
    p: f64,
    rng: ChaCha8Rng,
}

impl Physical {
    /// The valve of `p` within `travel`, stepped every `dt` seconds, at rest at 0 %.
    pub(crate) fn new(p: &PhysicalParams, travel: &Travel, dt: f64) -> Self {
        let w = std::f64::consts::TAU * p.natural_freq_hz;
        let substeps = (dt / p.internal_step_s - 1e-9).ceil().clamp(1.0, 1e6) as u32;
        Physical {
            k: p.positioner_gain_per_s,
            half_deadband: p.deadband_pct / 2.0,
            fill: p.fill_rate_pct_per_s,
            vent: p.vent_rate_pct_per_s,
            floor: p.min_rate_pct_per_s,
            growth: p.volume_growth,
            w2: w * w,
            two_zw: 2.0 * p.damping_ratio * w,
            c_half: p.coulomb_band_pct / 2.0,
            s_half: p.static_band_pct.max(p.coulomb_band_pct) / 2.0,
            gain: p.sensor_gain,
            offset: p.sensor_offset_pct,
            noise: p.sensor_noise_pct,
            quantum: p.sensor_resolution_pct,
            seed: p.noise_seed,
            lo: travel.min_pct,
            hi: travel.max_pct,
            substeps,
            h: dt / f64::from(substeps),
            x: 0.0,
            v: 0.0,
            p: 0.0,
            rng: ChaCha8Rng::seed_from_u64(p.noise_seed),
        }
    }

    /// At rest where the sensor would read `vp0` (noise aside), with the chamber balancing the
    /// spring there; the noise starts again from its seed.
    pub(crate) fn reset(&mut self, vp0: f64) {
        self.x = ((vp0 - self.offset) / self.gain).clamp(self.lo, self.hi);
        self.v = 0.0;
        self.p = self.x;
        self.rng = ChaCha8Rng::seed_from_u64(self.seed);
    }

    /// Advances one sample with the (delayed) O_P `u` and returns the sensor's reading.
    #[inline]
    pub(crate) fn step(&mut self, u: f64) -> f64 {
        for _ in 0..self.substeps {
            self.chamber(u);
            self.stem();
        }
        self.sensor()
    }

    /// The positioner's flow for error `e`, %/s at the closed volume.
    #[inline]
    fn flow(&self, e: f64) -> f64 {
        if e == 0.0 || e.abs() < self.half_deadband {
            return 0.0;
        }
        let rate = (self.k * e.abs()).max(self.floor);
        if e > 0.0 {
            rate.min(self.fill)
        } else {
            -rate.min(self.vent)
        }
    }

    /// One internal step of the positioner and the chamber.
    #[inline]
    fn chamber(&mut self, u: f64) {
        let q = self.flow(u - self.x);
        if q != 0.0 {
            let volume = 1.0 + self.growth * (self.x / 100.0).clamp(0.0, 1.0);
            self.p = (self.p + self.h * q / volume).clamp(PRESSURE_MIN_PCT, PRESSURE_MAX_PCT);
        }
    }

    /// One internal step of the stem: Karnopp friction, semi-implicit, then the stops.
    #[inline]
    fn stem(&mut self) {
        let h = self.h;
        let drive = self.p - self.x;
        let dir = if self.v != 0.0 {
            self.v.signum()
        } else if drive.abs() > self.s_half {
            drive.signum()
        } else {
            return; // static friction holds the stem
        };
        let v = (self.v + h * self.w2 * (drive - dir * self.c_half)) / (1.0 + h * self.two_zw);
        // Friction can stop the stem, never push it back: a speed that would change sign sticks,
        // and so does a crawl that static friction can hold.
        let holds = v.abs() < STICK_SPEED_PCT_PER_S && drive.abs() <= self.s_half;
        self.v = if v * dir > 0.0 && !holds { v } else { 0.0 };
        self.x += h * self.v;
        if self.x >= self.hi {
            self.x = self.hi;
            self.v = self.v.min(0.0);
        } else if self.x <= self.lo {
            self.x = self.lo;
            self.v = self.v.max(0.0);
        }
    }

    /// The position sensor's reading of the true position.
    #[inline]
    fn sensor(&mut self) -> f64 {
        let mut y = self.gain * self.x + self.offset;
        if self.noise > 0.0 {
            let n: f64 = StandardNormal.sample(&mut self.rng);
            y += self.noise * n;
        }
        if self.quantum > 0.0 {
            y = (y / self.quantum).round() * self.quantum;
        }
        y
    }

    /// True stem position, % (for tests).
    #[cfg(test)]
    pub(crate) fn position(&self) -> f64 {
        self.x
    }

    /// Chamber pressure, % of travel (for tests).
    #[cfg(test)]
    pub(crate) fn pressure(&self) -> f64 {
        self.p
    }
}

#[cfg(test)]
#[path = "physical_tests.rs"]
mod tests;
