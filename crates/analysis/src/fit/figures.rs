//! Valve-maintenance figures that positioner diagnostics report, measured on a fitted model by
//! running standard test signals through it: dead time, T63 / T86 of small and large steps,
//! dead band, stick-slip size and the largest travel speed opening and closing.
//!
//! Measuring on the simulated valve (rather than reading parameters) gives every model the
//! same figures in the same units, whatever its structure: a pin-cart II has no "dead band"
//! parameter, but a slow reversal through it shows one.
//!
//! Tests, all around 50 % opening (`AROUND_PCT`):
//! - steps: approach from below, hold, then step up by 1 % (small) or 10 % (large); T63 / T86
//!   are the times from the step until V_P covered 63 / 86 % of its final change.
//! - dead band: a slow ramp up (0.05 %/s), then down; the O_P travel after the reversal
//!   until V_P has come down by 0.02 %, less what the ramp covers in the dead time.
//! - stick-slip: the largest jump of V_P in one sample during the slow ramp down, less the ramp's own
//!   movement per sample.
//! - speeds: 10 → 90 % and back; the largest change of V_P over 0.1 s, per second.
//!
//! Not here: fitting.

use serde::Serialize;

use vb_core::model::{ModelSpec, Valve};

/// Opening the tests run around, %.
pub const AROUND_PCT: f64 = 50.0;

/// The maintenance figures of one model.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Figures {
    /// Dead time T_d, s.
    pub dead_time_s: f64,
    /// T63 / T86 of a 1 % step, s (None: never got there in 30 s).
    pub t63_small_s: Option<f64>,
    pub t86_small_s: Option<f64>,
    /// T63 / T86 of a 10 % step, s.
    pub t63_large_s: Option<f64>,
    pub t86_large_s: Option<f64>,
    /// O_P travel needed to reverse V_P in the slow ramp test, % (what a positioner's
    /// dead-band test shows; pin-cart backlash is crossed by an integrating pin, so it shows
    /// mostly as time, see `backlash_pct`).
    pub dead_band_pct: f64,
    /// The model's own backlash / band parameter, % of travel: B_L for pin-cart I and II, the
    /// stickband S for stiction; 0 for models without one.
    pub backlash_pct: f64,
    /// Largest slip jump of V_P, %.
    pub stick_slip_pct: f64,
    /// Largest travel speed opening and closing, %/s.
    pub max_speed_open_pct_per_s: f64,
    pub max_speed_close_pct_per_s: f64,
}

/// Samples in `secs` at `dt`, at least three, so every test has a before, a during and an after
/// even on data sampled once a minute.
fn samples(secs: f64, dt: f64) -> usize {
    ((secs / dt) as usize).max(3)
}

fn run(spec: &ModelSpec, dt: f64, op: &[f64]) -> Option<Vec<f64>> {
    let mut v = Valve::new(spec, dt).ok()?;
    Some(v.simulate(op, op[0]))
}

/// T63 and T86 of a step of `size` % at 50 %, approached from below.
fn step_times(spec: &ModelSpec, dt: f64, size: f64) -> (Option<f64>, Option<f64>) {
    let n_hold = samples(20.0, dt);
    let n_after = samples(30.0, dt);
    let op: Vec<f64> = std::iter::repeat_n(AROUND_PCT - 2.0, n_hold)
        .chain(std::iter::repeat_n(AROUND_PCT, n_hold))
        .chain(std::iter::repeat_n(AROUND_PCT + size, n_after))
        .collect();
    let Some(vp) = run(spec, dt, &op) else {
        return (None, None);
    };
    let a = 2 * n_hold;
    let (v0, v1) = (vp[a - 1], vp[vp.len() - 1]);
    let change = v1 - v0;
    if change.abs() < 1e-9 {
        return (None, None);
    }
    let at = |share: f64| {
        (a..vp.len())
            .find(|&k| (vp[k] - v0) / change >= share)
            .map(|k| (k - a + 1) as f64 * dt)
    };
    (at(0.63), at(0.86))
}

/// Runs the standard tests on `spec` sampled every `dt` seconds.
pub fn measure(spec: &ModelSpec, dt: f64) -> Figures {
    let (t63_small_s, t86_small_s) = step_times(spec, dt, 1.0);
    let (t63_large_s, t86_large_s) = step_times(spec, dt, 10.0);
    // Slow ramp up 45 -> 55 %, hold, down to 45 %.
    let rate = 0.05;
    let n_ramp = samples(10.0 / rate, dt);
    let n_hold = samples(10.0, dt);
    let mut op: Vec<f64> = vec![45.0; n_hold];
    op.extend((0..n_ramp).map(|k| 45.0 + rate * dt * k as f64));
    op.extend(std::iter::repeat_n(55.0, n_hold));
    let down = op.len();
    op.extend((0..n_ramp).map(|k| 55.0 - rate * dt * k as f64));
    let (mut dead_band_pct, mut stick_slip_pct) = (f64::NAN, f64::NAN);
    if let Some(vp) = run(spec, dt, &op) {
        let top = vp[down - 1];
        if let Some(k) = (down..vp.len()).find(|&k| vp[k] < top - 0.02) {
            let travel = 55.0 - op[k];
            dead_band_pct = (travel - rate * spec.dead_time_s - 0.02).max(0.0);
        }
        // On the way down only: the first breakaway from rest is not a stick-slip cycle.
        stick_slip_pct = vp[down..]
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max)
            - rate * dt;
        stick_slip_pct = stick_slip_pct.max(0.0);
    }
    let n_big = samples(30.0, dt);
    let op: Vec<f64> = std::iter::repeat_n(10.0, n_big)
        .chain(std::iter::repeat_n(90.0, n_big))
        .chain(std::iter::repeat_n(10.0, n_big))
        .collect();
    let (mut open, mut close) = (f64::NAN, f64::NAN);
    if let Some(vp) = run(spec, dt, &op) {
        let h = ((0.1 / dt).round() as usize).max(1);
        let speed = |range: std::ops::Range<usize>, sign: f64| {
            range
                .filter(|&k| k >= h)
                .map(|k| sign * (vp[k] - vp[k - h]) / (h as f64 * dt))
                .fold(0.0, f64::max)
        };
        open = speed(n_big..2 * n_big, 1.0);
        close = speed(2 * n_big..3 * n_big, -1.0);
    }
    Figures {
        dead_time_s: spec.dead_time_s,
        t63_small_s,
        t86_small_s,
        t63_large_s,
        t86_large_s,
        dead_band_pct,
        backlash_pct: spec
            .pincart1
            .map(|p| p.backlash_pct)
            .or(spec.pincart2.map(|p| p.backlash_pct))
            .or(spec.stiction.map(|p| p.stickband_pct))
            .unwrap_or(0.0),
        stick_slip_pct,
        max_speed_open_pct_per_s: open,
        max_speed_close_pct_per_s: close,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use vb_core::model::{bundled, FopdtParams, ModelKind, PinCart1Params, StictionParams};

    #[test]
    fn figures_of_data_sampled_once_a_minute_are_measured_without_panicking() {
        for kind in ModelKind::ALL {
            let f = measure(&bundled(kind), 60.0);
            assert!(f.dead_time_s >= 0.0, "{kind}: {f:?}");
        }
    }

    #[test]
    fn fopdt_figures_follow_from_its_time_constant() {
        let spec = ModelSpec {
            fopdt: Some(FopdtParams {
                time_constant_s: 1.0,
            }),
            ..ModelSpec::bare(ModelKind::Fopdt, 0.5)
        };
        let f = measure(&spec, 0.01);
        // T63 = T_d + tau, T86 = T_d + 2 tau.
        assert!((f.t63_small_s.unwrap() - 1.5).abs() < 0.03, "{f:?}");
        assert!((f.t86_large_s.unwrap() - 2.5).abs() < 0.03, "{f:?}");
        assert!(f.dead_band_pct < 0.1, "{f:?}");
        assert!(f.stick_slip_pct < 0.01, "{f:?}");
    }

    #[test]
    fn backlash_and_stick_slip_show() {
        let pc = ModelSpec {
            pincart1: Some(PinCart1Params {
                backlash_pct: 2.0,
                p_gain_per_s: 3.0,
            }),
            ..ModelSpec::bare(ModelKind::Pincart1, 0.2)
        };
        let f = measure(&pc, 0.01);
        // The pin integrates the error: the 2 % cart is crossed while O_P moves about
        // sqrt(4 B_L rate / P_k) ≈ 0.26 %.
        assert!((f.dead_band_pct - 0.26).abs() < 0.05, "{f:?}");
        assert_eq!(f.backlash_pct, 2.0);
        let st = ModelSpec {
            stiction: Some(StictionParams {
                stickband_pct: 1.0,
                jumpband_pct: 0.4,
            }),
            ..ModelSpec::bare(ModelKind::Stiction, 0.2)
        };
        let f = measure(&st, 0.01);
        assert!((f.stick_slip_pct - 0.4).abs() < 0.05, "{f:?}");
        assert!(f.dead_band_pct > 0.5, "{f:?}");
    }
}
