//! Wear over hours: a dead time and a friction band that grow with time around any valve
//! model, for the live health check to notice. The daemon's emulated valve and sim-device step
//! their model through the same [`Drift`].
//!
//! - Dead time: O_P is delayed before the model by a time that grows by `dead_time_drift_s_per_h`
//!   per hour, up to `dead_time_drift_max_s`, by whole samples (a blended O_P changing every sample
//!   would look like a new step to pin-cart II).
//! - Friction band: the pin-cart cart, which is the valve's friction band, widens by
//!   `friction_band_drift_pct_per_h` % of travel per hour, up to `friction_band_drift_max_pct` more
//!   ([`Valve::widen_band`]): packing that tightens, a stem that corrodes. The positioner
//!   swings the actuator's pressure no faster, so a reversal takes longer to cross the wider
//!   band: the reversal delay grows, a step that keeps its direction does not change. Only the
//!   pin-cart models have a friction band; another model with this drift is refused.
//!
//! Time is the sample index `k` times the sample period: loop slots for the daemon, model steps
//! for sim-device. Stepping never allocates.

use serde::{Deserialize, Serialize};

use super::{DelayLine, ModelError, ModelKind, Valve};

/// How fast the valve wears (all 0: no drift).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriftSpec {
    /// Dead time added per hour, s/h.
    pub dead_time_drift_s_per_h: f64,
    /// The most dead time the drift adds, s.
    pub dead_time_drift_max_s: f64,
    /// Friction band widening per hour, % of travel per hour.
    pub friction_band_drift_pct_per_h: f64,
    /// The most the friction band widens, % of travel.
    pub friction_band_drift_max_pct: f64,
}

impl Default for DriftSpec {
    fn default() -> Self {
        DriftSpec {
            dead_time_drift_s_per_h: 0.0,
            dead_time_drift_max_s: 2.0,
            friction_band_drift_pct_per_h: 0.0,
            friction_band_drift_max_pct: 5.0,
        }
    }
}

/// A key of [`DriftSpec`] that is out of range, or asks for what the model lacks.
#[derive(Debug, Clone, PartialEq)]
pub struct DriftViolation {
    /// The key, as named in [`DriftSpec`].
    pub key: &'static str,
    /// Its value.
    pub value: f64,
    /// What is allowed.
    pub allowed: String,
}

impl DriftSpec {
    /// True when nothing drifts.
    pub fn is_none(&self) -> bool {
        self.dead_time_drift_s_per_h == 0.0 && self.friction_band_drift_pct_per_h == 0.0
    }

    /// The first setting out of range, or a friction band drift of a `model` without a band.
    pub fn violation(&self, model: ModelKind) -> Option<DriftViolation> {
        let ranges = [
            (
                "dead_time_drift_s_per_h",
                self.dead_time_drift_s_per_h,
                3600.0,
                "a growth of the dead time in s per hour",
            ),
            (
                "dead_time_drift_max_s",
                self.dead_time_drift_max_s,
                60.0,
                "the most dead time the drift adds, s",
            ),
            (
                "friction_band_drift_pct_per_h",
                self.friction_band_drift_pct_per_h,
                100.0,
                "a widening of the friction band in % per hour",
            ),
            (
                "friction_band_drift_max_pct",
                self.friction_band_drift_max_pct,
                100.0,
                "the most the friction band widens, %",
            ),
        ];
        for (key, value, hi, what) in ranges {
            if !(value.is_finite() && (0.0..=hi).contains(&value)) {
                return Some(DriftViolation {
                    key,
                    value,
                    allowed: format!("{what}, 0 to {hi}"),
                });
            }
        }
        let banded = matches!(model, ModelKind::Pincart1 | ModelKind::Pincart2);
        (self.friction_band_drift_pct_per_h > 0.0 && !banded).then(|| DriftViolation {
            key: "friction_band_drift_pct_per_h",
            value: self.friction_band_drift_pct_per_h,
            allowed: format!(
                "only a pin-cart model (pincart1, pincart2) has a friction band to widen, not `{model}`"
            ),
        })
    }
}

/// A valve's wear, applied each step (see the module documentation).
#[derive(Debug, Clone)]
pub struct Drift {
    /// The growing dead time (None: no dead-time drift).
    line: Option<DelayLine>,
    /// Dead-time growth per sample, in samples.
    dead_samples_per_step: f64,
    /// Band growth per sample, %, and its most.
    band_per_step_pct: f64,
    band_max_pct: f64,
}

impl Drift {
    /// The drift `spec` describes for `valve` (None when nothing drifts); refused as
    /// [`ModelError::Param`] when a setting is out of range or the model has no friction band.
    pub fn new(spec: &DriftSpec, valve: &Valve) -> Result<Option<Drift>, ModelError> {
        let model = valve.spec().model;
        if let Some(v) = spec.violation(model) {
            return Err(ModelError::Param {
                model,
                key: v.key.into(),
                value: v.value,
                allowed: v.allowed,
            });
        }
        if spec.is_none() {
            return Ok(None);
        }
        let dt = valve.sample_period_s();
        let per_step = dt / 3600.0;
        Ok(Some(Drift {
            line: (spec.dead_time_drift_s_per_h > 0.0)
                .then(|| DelayLine::with_capacity(spec.dead_time_drift_max_s, dt)),
            dead_samples_per_step: spec.dead_time_drift_s_per_h * per_step / dt,
            band_per_step_pct: spec.friction_band_drift_pct_per_h * per_step,
            band_max_pct: spec.friction_band_drift_max_pct,
        }))
    }

    /// Starts the drift's delay at rest at `op` (call with the valve's reset).
    pub fn reset(&mut self, op: f64) {
        if let Some(line) = &mut self.line {
            line.reset(op);
        }
    }

    /// Steps `valve` with `op` as sample `k`, worn by `k` samples of drift; returns V_P.
    #[inline]
    pub fn step(&mut self, valve: &mut Valve, op: f64, k: u64) -> f64 {
        let op = match &mut self.line {
            Some(line) => {
                line.set_samples((self.dead_samples_per_step * k as f64) as usize);
                line.push(op)
            }
            None => op,
        };
        if self.band_per_step_pct > 0.0 {
            valve.widen_band((self.band_per_step_pct * k as f64).min(self.band_max_pct));
        }
        valve.step(op)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::bundled;

    fn valve(kind: ModelKind) -> Valve {
        Valve::new(&bundled(kind), 0.01).unwrap()
    }

    /// Samples from a reversal at sample `at` (after holding `from` then `to` from `mid`) until
    /// V_P has moved 0.1 % back.
    fn reversal_delay(drift: &mut Drift, v: &mut Valve, at: u64) -> u64 {
        v.reset(40.0, 40.0);
        drift.reset(40.0);
        for k in 0..at {
            drift.step(v, if k < at - 1000 { 40.0 } else { 60.0 }, k);
        }
        let top = drift.step(v, 40.0, at);
        (1..2000)
            .find(|&j| drift.step(v, 40.0, at + j) < top - 0.1)
            .unwrap()
    }

    #[test]
    fn a_wider_friction_band_delays_reversals() {
        let spec = DriftSpec {
            friction_band_drift_pct_per_h: 3.6,
            friction_band_drift_max_pct: 1.0,
            ..DriftSpec::default()
        };
        let mut v = valve(ModelKind::Pincart2);
        let mut d = Drift::new(&spec, &v).unwrap().unwrap();
        // At the start the band is B_L; 3.6 %/h at 10 ms is 1e-5 % a sample: +1 % (twice the
        // width, twice eq. 7's crossing time) from sample 100,000 on.
        let early = reversal_delay(&mut d, &mut v, 2000);
        let late = reversal_delay(&mut d, &mut v, 200_000);
        let spec2 = bundled(ModelKind::Pincart2);
        let crossing = spec2.pincart2.unwrap().crossing_time_s(60.0);
        assert!(
            (early as f64 * 0.01 - spec2.dead_time_s - crossing).abs() < 0.1,
            "a reversal at 60 % costs T_d and eq. 7's crossing time: {early}"
        );
        let grown = (late - early) as f64 * 0.01;
        assert!(
            (grown - crossing).abs() < 0.1,
            "the crossing time doubles: +{grown} s against {crossing} s"
        );
    }

    #[test]
    fn settings_out_of_range_or_without_a_band_are_refused() {
        let band = DriftSpec {
            friction_band_drift_pct_per_h: 1.0,
            ..DriftSpec::default()
        };
        let e = Drift::new(&band, &valve(ModelKind::Fopdt)).unwrap_err();
        assert!(e.to_string().contains("only a pin-cart model"), "{e}");
        assert!(Drift::new(&band, &valve(ModelKind::Pincart1)).is_ok());
        let bad = DriftSpec {
            dead_time_drift_s_per_h: -1.0,
            ..DriftSpec::default()
        };
        assert_eq!(
            bad.violation(ModelKind::Pincart2).unwrap().key,
            "dead_time_drift_s_per_h"
        );
        assert!(Drift::new(&DriftSpec::default(), &valve(ModelKind::Fopdt))
            .unwrap()
            .is_none());
    }
}
