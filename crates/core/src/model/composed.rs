//! The composed valve that diagnosis grows: pin-cart II plus effects, and the effect vocabulary.
//! It lives with the models so that the emulator side (compensation, synthesis) and diagnosis
//! share it without either importing the other.
//!
//! Every model diagnosis starts from is first written as an equivalent pin-cart II spec with all
//! effects off (an FOPDT is pin-cart II without a cart, without speed limits and with
//! `P_k = (1 - e^(-dt/tau)) / dt`, which steps exactly the same recursion). Adding an effect
//! then means freeing a few numbers of that spec ("knobs"), never writing a new model.
//!
//! Not here: which effect a recording shows, and how its knobs are fitted (`vb_analysis::diagnose`).

use serde::Serialize;

use super::{Effects, ModelKind, ModelSpec, PinCart2Params};

/// An effect's size, with its interval and its weight against what is worth maintenance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Size {
    /// What the number is (`friction_band_pct`, `dead_time_s`, ...).
    pub name: &'static str,
    pub unit: &'static str,
    pub value: f64,
    /// 90 % interval (block bootstrap over the held-out blocks, widened by diagnosis to at
    /// least the model's error the blind bench measured); the value itself when none was
    /// computed. `high` is infinite (`null` in JSON) when the recording bounds the size from
    /// below only (a speed ratio whose faster side no move asked for).
    pub low: f64,
    pub high: f64,
    /// How the size compares with what is worth maintenance: 1 at the threshold, above 1
    /// beyond it (for a stroke speed, the threshold over the speed).
    pub worth: f64,
    /// `worth` at the less material end of the held-out blocks' evidence (its 5 % quantile
    /// over the same resamples, before the interval is widened by the model's spread): at
    /// least 1 when the recording is sure the effect is worth maintenance. `worth` itself when
    /// no interval was computed.
    pub worth_low: f64,
}

impl Size {
    /// The size with its interval, in words: `friction band 1.40 % (1.10-1.80)`.
    pub fn words(&self) -> String {
        crate::human::size_text(self.name, self.value, self.low, self.high)
    }
}

/// The physics diagnosis can name; the JSON names are the vocabulary of the issue tracker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Effect {
    DeadTime,
    Backlash,
    StateDependentDelay,
    SlewRate,
    Asymmetry,
    MinSpeed,
    Stiction,
    Deadband,
    Saturation,
    Quantization,
    Calibration,
}

impl Effect {
    /// Every effect, in the order candidates are tried.
    pub const ALL: [Effect; 11] = [
        Effect::DeadTime,
        Effect::Backlash,
        Effect::StateDependentDelay,
        Effect::SlewRate,
        Effect::Asymmetry,
        Effect::MinSpeed,
        Effect::Stiction,
        Effect::Deadband,
        Effect::Saturation,
        Effect::Quantization,
        Effect::Calibration,
    ];

    /// The vocabulary name (`dead_time`, `backlash`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Effect::DeadTime => "dead_time",
            Effect::Backlash => "backlash",
            Effect::StateDependentDelay => "state_dependent_delay",
            Effect::SlewRate => "slew_rate",
            Effect::Asymmetry => "asymmetry",
            Effect::MinSpeed => "min_speed",
            Effect::Stiction => "stiction",
            Effect::Deadband => "deadband",
            Effect::Saturation => "saturation",
            Effect::Quantization => "quantization",
            Effect::Calibration => "calibration",
        }
    }

    /// Effects that leave similar traces, so a win of one over the other needs a margin.
    pub fn look_alikes(self) -> &'static [Effect] {
        match self {
            Effect::Backlash => &[Effect::Deadband, Effect::StateDependentDelay],
            Effect::Deadband => &[Effect::Backlash, Effect::Calibration, Effect::Stiction],
            Effect::Quantization => &[],
            Effect::Stiction => &[Effect::Deadband],
            Effect::SlewRate => &[Effect::Asymmetry, Effect::MinSpeed],
            Effect::Asymmetry => &[Effect::SlewRate],
            Effect::Calibration => &[Effect::Deadband, Effect::Saturation],
            Effect::Saturation => &[Effect::Calibration],
            Effect::StateDependentDelay => &[Effect::Backlash],
            Effect::MinSpeed => &[Effect::SlewRate],
            Effect::DeadTime => &[],
        }
    }
}

impl std::str::FromStr for Effect {
    type Err = String;

    /// An effect by its vocabulary name (`backlash`, `dead_time`, ...).
    fn from_str(s: &str) -> Result<Self, String> {
        Effect::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| {
                let all: Vec<&str> = Effect::ALL.iter().map(|e| e.name()).collect();
                format!("unknown effect `{s}`: expected one of {}", all.join(", "))
            })
    }
}

/// One number of the composed spec that a fit may move.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Knob {
    /// P_k, 1/s.
    Gain,
    /// T_d, s.
    DeadTime,
    /// Cart-crossing time at V = 0 (c_p), s.
    Crossing,
    /// Change of the crossing time per % of opening (b_p), s/%.
    CrossingSlope,
    /// Opening-dependent slowdown r.
    Slowdown,
    /// dy_max, %/s.
    Slew,
    /// Closing slew rate, %/s.
    ClosingSlew,
    /// dy_min, %/s.
    MinSpeed,
    /// Stickband S, %.
    Stickband,
    /// Slip jump as a fraction of S.
    JumpFraction,
    /// Breakaway distance of stick-slip inside the positioner loop, %.
    Breakaway,
    /// Friction band crossed at the positioner's speed, %.
    FrictionBand,
    /// Wind-up of the drive past a travel stop, %.
    Windup,
    /// Deadband width, %.
    Deadband,
    /// Width of the positioner's deadband, %.
    PositionerDeadband,
    /// Lowest travel, %.
    TravelMin,
    /// Highest travel, %.
    TravelMax,
    /// Sensor resolution, %.
    Quantum,
    /// Calibration gain.
    CalGain,
    /// Calibration offset, %.
    CalOffset,
}

impl Knob {
    /// The unit of the knob's value as printed.
    pub fn unit(self) -> &'static str {
        match self {
            Knob::Gain => "1/s",
            Knob::DeadTime | Knob::Crossing => "s",
            Knob::CrossingSlope => "s/%",
            Knob::Slowdown | Knob::JumpFraction | Knob::CalGain => "",
            Knob::Slew | Knob::ClosingSlew | Knob::MinSpeed => "%/s",
            Knob::Stickband
            | Knob::Breakaway
            | Knob::FrictionBand
            | Knob::Windup
            | Knob::Deadband
            | Knob::PositionerDeadband
            | Knob::TravelMin
            | Knob::TravelMax
            | Knob::Quantum
            | Knob::CalOffset => "%",
        }
    }

    /// Parameter name (with its unit) for reports and JSON.
    pub fn label(self) -> &'static str {
        match self {
            Knob::Gain => "p_gain_per_s",
            Knob::DeadTime => "dead_time_s",
            Knob::Crossing => "crossing_time_s",
            Knob::CrossingSlope => "crossing_slope_s_per_pct",
            Knob::Slowdown => "open_slowdown",
            Knob::Slew => "slew_pct_per_s",
            Knob::ClosingSlew => "closing_slew_pct_per_s",
            Knob::MinSpeed => "min_speed_pct_per_s",
            Knob::Stickband => "stickband_pct",
            Knob::JumpFraction => "jump_fraction",
            Knob::Breakaway => "breakaway_pct",
            Knob::FrictionBand => "friction_band_pct",
            Knob::Windup => "stop_windup_pct",
            Knob::Deadband => "deadband_pct",
            Knob::PositionerDeadband => "positioner_deadband_pct",
            Knob::TravelMin => "travel_min_pct",
            Knob::TravelMax => "travel_max_pct",
            Knob::Quantum => "quantization_pct",
            Knob::CalGain => "calibration_gain",
            Knob::CalOffset => "calibration_offset_pct",
        }
    }
}

/// "Off" value of a speed limit: 1000 % a sample at 100 Hz, so it never binds, not even for
/// a pass-through (modelless) core.
pub const NO_LIMIT_PCT_PER_S: f64 = 1e5;
/// The fastest speed limit a fit considers, %/s: a full stroke in 0.1 s.
pub const FASTEST_PCT_PER_S: f64 = 1000.0;

fn pc2(spec: &ModelSpec) -> PinCart2Params {
    spec.pincart2.unwrap_or(PinCart2Params {
        p_gain_per_s: 10.0,
        dy_max_pct_per_s: NO_LIMIT_PCT_PER_S,
        dy_min_pct_per_s: 0.0,
        a_p: 0.0,
        b_p: 0.0,
        c_p: 0.0,
        backlash_pct: 0.0,
    })
}

/// How many times slower than closed the opening-dependent slowdown makes the valve at half
/// travel (its speed limit and its crossing of the cart alike).
pub fn half_open(spec: &ModelSpec) -> f64 {
    1.0 + spec.effects.open_slowdown / 2.0
}

/// The reading's calibration: (gain, offset %), V_P as read = gain × stem + offset.
pub fn calibration(spec: &ModelSpec) -> (f64, f64) {
    (
        spec.effects.calibration_gain,
        spec.effects.calibration_offset_pct,
    )
}

/// Reads a knob's value from a composed spec.
pub fn get(spec: &ModelSpec, knob: Knob) -> f64 {
    let p = pc2(spec);
    let e = &spec.effects;
    match knob {
        Knob::Gain => p.p_gain_per_s,
        Knob::DeadTime => spec.dead_time_s,
        Knob::Crossing => p.c_p,
        Knob::CrossingSlope => p.b_p,
        Knob::Slowdown => e.open_slowdown,
        Knob::Slew => p.dy_max_pct_per_s,
        Knob::ClosingSlew => {
            if e.closing_slew_pct_per_s > 0.0 {
                e.closing_slew_pct_per_s
            } else {
                p.dy_max_pct_per_s
            }
        }
        Knob::MinSpeed => p.dy_min_pct_per_s,
        Knob::Stickband => e.stickband_pct,
        Knob::JumpFraction => {
            if e.stickband_pct > 0.0 {
                e.jumpband_pct / e.stickband_pct
            } else {
                0.0
            }
        }
        Knob::Breakaway => e.breakaway_pct,
        Knob::FrictionBand => e.friction_band_pct,
        Knob::Windup => e.stop_windup_pct,
        Knob::Deadband => e.deadband_pct,
        Knob::PositionerDeadband => e.positioner_deadband_pct,
        Knob::TravelMin => spec.travel.min_pct,
        Knob::TravelMax => spec.travel.max_pct,
        Knob::Quantum => e.quantization_pct,
        Knob::CalGain => e.calibration_gain,
        Knob::CalOffset => e.calibration_offset_pct,
    }
}

/// Sets a knob on a composed spec (the caller keeps values inside their bounds).
pub fn set(spec: &mut ModelSpec, knob: Knob, v: f64) {
    let mut p = pc2(spec);
    let e = &mut spec.effects;
    match knob {
        Knob::Gain => p.p_gain_per_s = v,
        Knob::DeadTime => spec.dead_time_s = v,
        Knob::Crossing => {
            p.c_p = v;
            p.backlash_pct = 1.0;
        }
        Knob::CrossingSlope => p.b_p = v,
        Knob::Slowdown => e.open_slowdown = v,
        Knob::Slew => {
            p.dy_max_pct_per_s = v;
            p.dy_min_pct_per_s = p.dy_min_pct_per_s.min(v);
        }
        Knob::ClosingSlew => e.closing_slew_pct_per_s = v,
        Knob::MinSpeed => p.dy_min_pct_per_s = v.min(p.dy_max_pct_per_s),
        Knob::Stickband => {
            let frac = if e.stickband_pct > 0.0 {
                e.jumpband_pct / e.stickband_pct
            } else {
                0.5
            };
            e.stickband_pct = v;
            e.jumpband_pct = frac * v;
        }
        Knob::JumpFraction => e.jumpband_pct = v.clamp(0.0, 1.0) * e.stickband_pct,
        Knob::Breakaway => e.breakaway_pct = v,
        Knob::FrictionBand => e.friction_band_pct = v,
        Knob::Windup => e.stop_windup_pct = v,
        Knob::Deadband => e.deadband_pct = v,
        Knob::PositionerDeadband => e.positioner_deadband_pct = v,
        Knob::TravelMin => spec.travel.min_pct = v,
        Knob::TravelMax => spec.travel.max_pct = v,
        Knob::Quantum => e.quantization_pct = v,
        Knob::CalGain => e.calibration_gain = v,
        Knob::CalOffset => e.calibration_offset_pct = v,
    }
    spec.pincart2 = Some(p);
}

/// The composed pin-cart II spec that steps like `base` (or as close as the family allows).
///
/// FOPDT, delayed modelless, modelless, stiction and pin-cart II convert exactly. Pin-cart I's
/// crossing time depends on the error size, which pin-cart II cannot express: it converts to a
/// constant crossing time of `B_L / (P_k * 1 %)`, the time for a 1 % reversal.
pub fn compose(base: &ModelSpec, dt: f64) -> ModelSpec {
    let mut spec = ModelSpec {
        model: ModelKind::Pincart2,
        pincart2: None,
        fopdt: None,
        stiction: None,
        pincart1: None,
        physical: None,
        ..base.clone()
    };
    let pass_through = 1.0 / dt;
    let mut p = pc2(&spec);
    match base.model {
        ModelKind::Modelless | ModelKind::Delayed => p.p_gain_per_s = pass_through,
        ModelKind::Fopdt => {
            let tau = base.fopdt.map(|f| f.time_constant_s).unwrap_or(dt);
            p.p_gain_per_s = (1.0 - (-dt / tau).exp()) / dt;
        }
        ModelKind::Stiction => {
            p.p_gain_per_s = pass_through;
            if let Some(s) = base.stiction {
                spec.effects = Effects {
                    stickband_pct: s.stickband_pct,
                    jumpband_pct: s.jumpband_pct,
                    ..spec.effects
                };
            }
        }
        ModelKind::Pincart1 => {
            if let Some(q) = base.pincart1 {
                p.p_gain_per_s = q.p_gain_per_s;
                p.backlash_pct = 1.0;
                p.c_p = q.backlash_pct / q.p_gain_per_s;
            }
        }
        ModelKind::Pincart2 => p = base.pincart2.unwrap_or(p),
        // A physical valve is a simulator, not a starting model (`diagnose --model` refuses it).
        ModelKind::Physical => {}
    }
    spec.pincart2 = Some(p);
    spec
}

#[cfg(test)]
mod tests {

    #[test]
    fn sizes_read_with_their_intervals() {
        let s = Size {
            name: "friction_band_pct",
            unit: "%",
            value: 1.4,
            low: 1.1,
            high: 1.8,
            worth: 4.7,
            worth_low: 3.6,
        };
        assert_eq!(s.words(), "friction band 1.40 % (1.10-1.80)");
        let exact = Size {
            low: 1.4,
            high: 1.4,
            ..s
        };
        assert_eq!(exact.words(), "friction band 1.40 %");
    }
    use super::*;
    use crate::model::{bundled, Valve};

    #[test]
    fn composed_fopdt_steps_exactly_like_fopdt() {
        let op: Vec<f64> = (0..3000)
            .map(|k| if (k / 400) % 2 == 0 { 30.0 } else { 70.0 })
            .collect();
        for kind in [
            ModelKind::Fopdt,
            ModelKind::Delayed,
            ModelKind::Modelless,
            ModelKind::Stiction,
            ModelKind::Pincart2,
        ] {
            let base = bundled(kind);
            let a = Valve::new(&base, 0.01).unwrap().simulate(&op, 30.0);
            let b = Valve::new(&compose(&base, 0.01), 0.01)
                .unwrap()
                .simulate(&op, 30.0);
            let worst = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-9, "{kind}: {worst}");
        }
    }

    #[test]
    fn knobs_round_trip() {
        let mut spec = compose(&bundled(ModelKind::Fopdt), 0.01);
        for (knob, v) in [
            (Knob::Crossing, 0.4),
            (Knob::Slew, 12.0),
            (Knob::ClosingSlew, 6.0),
            (Knob::Stickband, 1.5),
            (Knob::Deadband, 0.3),
            (Knob::CalOffset, -1.0),
            (Knob::Slowdown, 2.0),
        ] {
            set(&mut spec, knob, v);
            assert_eq!(get(&spec, knob), v, "{knob:?}");
        }
        assert_eq!(get(&spec, Knob::Slew), 12.0);
        spec.validate().unwrap();
    }
}
