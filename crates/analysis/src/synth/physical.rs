//! Physical valves with an effect of the diagnosis vocabulary built in: each [`Effect`] is
//! made by the physics of `model = "physical"` that causes it in a real valve, on top of a
//! healthy valve, so diagnosis (which fits a composed pin-cart valve) can be checked against
//! physics it does not share.
//!
//! | effect | physics | size |
//! |---|---|---|
//! | `dead_time` | transport delay | `dead_time_s`, s |
//! | `backlash` | Coulomb friction band (static band as much above it as before) | band, % |
//! | `stiction` | static band above the Coulomb band | excess, % |
//! | `state_dependent_delay` | chamber volume growth over the stroke | g |
//! | `slew_rate` | both flow limits | limit, %/s |
//! | `asymmetry` | vent limit against fill limit | fill/vent ratio (> 1: slow venting, < 1: slow filling) |
//! | `min_speed` | the positioner's minimum flow | floor, %/s |
//! | `deadband` | positioner deadband | band, % |
//! | `saturation` | upper travel stop below 100 % | 100 - stop, % |
//! | `quantization` | sensor resolution lattice | resolution, % |
//! | `calibration` | sensor offset | offset, % |
//!
//! This module only builds specs; it does not decide what counts as healthy or detectable
//! (a benchmark states its own thresholds) and does not run anything.

use vb_core::model::composed::Effect;
use vb_core::model::{bundled, ModelKind, ModelSpec, PhysicalParams};

/// The healthy physical valve: `config/models/physical.toml` (fast positioner, 0.05 s
/// transport delay, 0.1 % friction band, 0.05 % deadband, 60 %/s flow limits, 0.02 % noise).
pub fn healthy() -> ModelSpec {
    bundled(ModelKind::Physical)
}

/// The healthy physical valve with `effect` at `size` (units in the module's table).
pub fn with_effect(effect: Effect, size: f64) -> ModelSpec {
    let mut spec = healthy();
    apply(&mut spec, effect, size);
    spec
}

/// Builds `effect` at `size` into a physical spec (other physics unchanged); a spec of
/// another kind is left alone. Sizes are taken as given: the spec's own checks judge them.
pub fn apply(spec: &mut ModelSpec, effect: Effect, size: f64) {
    if spec.model != ModelKind::Physical {
        return;
    }
    if effect == Effect::DeadTime {
        spec.dead_time_s = size;
        return;
    }
    if effect == Effect::Saturation {
        spec.travel.max_pct = 100.0 - size;
        return;
    }
    let Some(p) = spec.physical.as_mut() else {
        return;
    };
    apply_params(p, effect, size);
}

fn apply_params(p: &mut PhysicalParams, effect: Effect, size: f64) {
    match effect {
        Effect::Backlash => {
            let excess = p.static_band_pct - p.coulomb_band_pct;
            p.coulomb_band_pct = size;
            p.static_band_pct = size + excess;
        }
        Effect::Stiction => p.static_band_pct = p.coulomb_band_pct + size,
        Effect::StateDependentDelay => p.volume_growth = size,
        Effect::SlewRate => {
            p.fill_rate_pct_per_s = size;
            p.vent_rate_pct_per_s = size;
            p.min_rate_pct_per_s = p.min_rate_pct_per_s.min(size);
        }
        Effect::Asymmetry => {
            if size >= 1.0 {
                p.vent_rate_pct_per_s = p.fill_rate_pct_per_s / size;
            } else {
                p.fill_rate_pct_per_s = p.vent_rate_pct_per_s * size;
            }
            let slowest = p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s);
            p.min_rate_pct_per_s = p.min_rate_pct_per_s.min(slowest);
        }
        Effect::MinSpeed => p.min_rate_pct_per_s = size,
        Effect::Deadband => p.deadband_pct = size,
        Effect::Quantization => p.sensor_resolution_pct = size,
        Effect::Calibration => p.sensor_offset_pct = size,
        Effect::DeadTime | Effect::Saturation => {}
    }
}

/// `valve` (a physical one; another kind is returned as it is) with physics the composed
/// model diagnosis fits does not have, as a plant's valve has: static friction 10 % above its
/// Coulomb band and 0.05 % more (it sticks and slips a little), a chamber 1.2 times larger
/// fully open, venting at 50 %/s against filling at 60, and a sensor of 0.05 % noise read in
/// steps of `resolution_pct` (0: continuous, as a register's steps then come on top).
pub fn foreign(mut valve: ModelSpec, resolution_pct: f64) -> ModelSpec {
    if let Some(p) = valve.physical.as_mut() {
        p.static_band_pct = 1.1 * p.coulomb_band_pct + 0.05;
        p.volume_growth = 0.2;
        p.vent_rate_pct_per_s = 50.0;
        p.sensor_noise_pct = 0.05;
        p.sensor_resolution_pct = resolution_pct;
    }
    valve
}

/// `effect` at `size` in words, with its unit (`1.5 % Coulomb friction band`).
pub fn describe(effect: Effect, size: f64) -> String {
    match effect {
        Effect::DeadTime => format!("{size} s transport delay"),
        Effect::Backlash => format!("{size} % Coulomb friction band"),
        Effect::Stiction => format!("static friction band {size} % above the Coulomb band"),
        Effect::StateDependentDelay => {
            format!("chamber {} times larger fully open than closed", 1.0 + size)
        }
        Effect::SlewRate => format!("flow limits of {size} %/s"),
        Effect::Asymmetry => format!("fill/vent flow limit ratio {size}"),
        Effect::MinSpeed => format!("minimum flow of {size} %/s"),
        Effect::Deadband => format!("{size} % positioner deadband"),
        Effect::Saturation => format!("upper travel stop at {} %", 100.0 - size),
        Effect::Quantization => format!("{size} % sensor resolution"),
        Effect::Calibration => format!("{size} % sensor offset"),
    }
}

/// A size of `effect` that is plain to see but not extreme (what `demo concealed` hides).
pub fn moderate_size(effect: Effect) -> f64 {
    match effect {
        Effect::DeadTime => 0.6,
        Effect::Backlash => 1.5,
        Effect::Stiction => 1.0,
        Effect::StateDependentDelay => 3.0,
        Effect::SlewRate => 4.0,
        Effect::Asymmetry => 4.0,
        Effect::MinSpeed => 3.0,
        Effect::Deadband => 0.6,
        Effect::Saturation => 55.0,
        Effect::Quantization => 0.3,
        Effect::Calibration => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_effect_at_its_moderate_size_is_a_valid_valve() {
        for effect in Effect::ALL {
            let spec = with_effect(effect, moderate_size(effect));
            spec.validate().unwrap();
            assert_ne!(spec, healthy(), "{}", effect.name());
        }
    }

    #[test]
    fn effects_stack_and_leave_other_models_alone() {
        let mut spec = with_effect(Effect::Stiction, 1.0);
        apply(&mut spec, Effect::Backlash, 2.0);
        let p = spec.physical.unwrap();
        assert_eq!((p.coulomb_band_pct, p.static_band_pct), (2.0, 3.0));
        let mut spec = with_effect(Effect::Asymmetry, 0.5);
        let p = spec.physical.unwrap();
        assert_eq!((p.fill_rate_pct_per_s, p.vent_rate_pct_per_s), (30.0, 60.0));
        apply(&mut spec, Effect::SlewRate, 10.0);
        let p = spec.physical.unwrap();
        assert_eq!((p.fill_rate_pct_per_s, p.vent_rate_pct_per_s), (10.0, 10.0));
        let pc2 = bundled(ModelKind::Pincart2);
        let mut other = pc2.clone();
        apply(&mut other, Effect::DeadTime, 2.0);
        assert_eq!(other, pc2);
    }
}
