//! How fast V_P moves: its fastest opening and closing speeds, with the noise of the sensor
//! taken out, for the facts diagnosis checks its speed limits against.
//!
//! Also whether a log shows a model's stroke speed at all ([`stroke_speed_shown`]). Not here:
//! how fast V_P closes in on where it settles (`facts::approach`), the speed a model is given
//! (`candidates`).

use vb_core::metrics::stats::quantile;
use vb_core::model::composed::{self, Knob};
use vb_core::model::{ModelKind, ModelSpec};

/// The window lengths the fastest speeds of a recording are measured over, s: the shortest,
/// then those of the speeds V_P holds (0.3 s or more).
pub(super) const WINDOWS_S: [f64; 4] = [0.1, 0.3, 1.0, 3.0];

/// The fastest opening and closing speeds of V_P over windows of `windows_s`, %/s, noise
/// taken out: for a window of h samples, the speed is the mean of the h/2 differences of V_P
/// over h samples that end in the window's second half (pairs with a reading missing left
/// out; a window with fewer than half its pairs measured too), each window starting where the
/// last ended. Every pair spans the same time, so a speed limit bounds the mean as it bounds
/// each pair, while the noise of the mean is that of one difference over the square root of
/// the pairs (a sensor of 0.25 % hides a 2 %/s stroke from one difference over 0.3 s, not
/// from fifteen). Per window length, the 99.9th percentile in each direction of the speeds
/// less what noise alone reaches in their window (2.8 sigmas of the mean of the pairs it
/// measured, so a window with rows missing gets its wider allowance); the largest over the
/// window lengths. Short windows see fast strokes, long ones the slow moves that noise hides
/// in short ones.
pub(super) fn speeds(vp: &[f64], dt: f64, sigma: f64, windows_s: &[f64]) -> (f64, f64) {
    let mut best = (0.0f64, 0.0f64);
    for &window_s in windows_s {
        let h = ((window_s / dt).round() as usize).max(1);
        let pairs = (h / 2).max(1);
        let w = h as f64 * dt;
        let noise = |n: usize| 2.8 * sigma * std::f64::consts::SQRT_2 / (w * (n as f64).sqrt());
        let mut up: Vec<f64> = Vec::new();
        let mut down: Vec<f64> = Vec::new();
        for end in (h + pairs..=vp.len()).step_by(h + pairs) {
            let (sum, n) = (end - pairs..end)
                .map(|k| vp[k] - vp[k - h])
                .filter(|d| d.is_finite())
                .fold((0.0, 0usize), |(s, n), d| (s + d, n + 1));
            if 2 * n < pairs {
                continue;
            }
            let s = sum / (n as f64 * w);
            if s > 0.0 {
                up.push(s - noise(n));
            } else {
                down.push(-s - noise(n));
            }
        }
        best.0 = best.0.max(quantile(&mut up, 0.999));
        best.1 = best.1.max(quantile(&mut down, 0.999));
    }
    best
}

/// The fastest opening and closing speeds V_P holds for 1 s or more ([`speeds`] over the
/// windows of 1 and 3 s), %/s, within each stretch between `restarts` (a time gap's jump is
/// no move): a speed limit is never slower, and the jump of a stem that sticks and slips adds
/// little over a second.
pub(super) fn sustained_speeds(vp: &[f64], restarts: &[usize], dt: f64, sigma: f64) -> (f64, f64) {
    let cuts = (restarts.iter().copied()).filter(|&r| r > 0 && r < vp.len());
    let ends: Vec<usize> = cuts.chain(std::iter::once(vp.len())).collect();
    let mut from = 0;
    let mut best = (0.0f64, 0.0f64);
    for end in ends {
        let (open, close) = speeds(&vp[from..end.max(from)], dt, sigma, &WINDOWS_S[2..]);
        best = (best.0.max(open), best.1.max(close));
        from = end.max(from);
    }
    best
}

/// The opening and closing speeds of V_P as its speed limits show in them, %/s, from its
/// fastest moves each way (`fastest`) and the speeds it holds for 0.3 s or more (`held`), and
/// whether they are the held ones: those when the fastest are alike ([`differ`]) and the held
/// are not. A stem that sticks and jumps jumps as fast one way as the other, whatever its air
/// flows; what the flows allow shows once it has landed.
pub(super) fn limit_speeds(fastest: (f64, f64), held: (f64, f64)) -> ((f64, f64), bool) {
    if !differ(fastest) && differ(held) {
        (held, true)
    } else {
        (fastest, false)
    }
}

/// Whether two speeds differ by a fifth or more.
pub(super) fn differ((a, b): (f64, f64)) -> bool {
    a.max(b) / a.min(b).max(1e-9) >= 1.2
}

/// Whether the log shows the stroke speed of the pin-cart II `spec`, simulated as `sim` on the
/// log's `op` at `dt`: some sample asks the model's positioner, opening or closing, for at least
/// its speed limit (its gain times the error between the delayed, calibrated O_P, less half an
/// input deadband, and the simulated position). A log whose moves never ask for it (small
/// steps on a healthy valve) fits any limit above what they ask alike, so the fitted limit says
/// nothing about the valve. True for a spec without a pin-cart II core (nothing to show).
pub(super) fn stroke_speed_shown(spec: &ModelSpec, op: &[f64], sim: &[f64], dt: f64) -> bool {
    if spec.model != ModelKind::Pincart2 || spec.pincart2.is_none() {
        return true;
    }
    let get = |k: Knob| composed::get(spec, k);
    let e = &spec.effects;
    let delay = (spec.dead_time_s / dt).round() as usize;
    let (mut open, mut close) = (0.0f64, 0.0f64);
    for (k, &x) in sim.iter().enumerate().skip(delay) {
        let u = e.calibration_gain * op[k - delay] + e.calibration_offset_pct;
        let err = u - x;
        let asked = (err.abs() - e.deadband_pct / 2.0).max(0.0);
        if err > 0.0 {
            open = open.max(asked);
        } else {
            close = close.max(asked);
        }
    }
    let gain = get(Knob::Gain);
    gain * open >= get(Knob::Slew) || gain * close >= get(Knob::ClosingSlew)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_with_rows_missing_gets_the_allowance_of_the_pairs_it_measured() {
        // V_P opens at 2 %/s, read every 10 ms with every other reading missing: each 1 s
        // window measures 25 of its 50 pairs, so the noise of its mean is that of one
        // difference over the square root of 25, not of 50.
        let (dt, sigma, w) = (0.01, 0.25, 1.0);
        let allowance = |n: f64| 2.8 * sigma * std::f64::consts::SQRT_2 / (w * n.sqrt());
        let ramp: Vec<f64> = (0..3000).map(|k| 2.0 * k as f64 * dt).collect();
        let holed: Vec<f64> = (ramp.iter().enumerate())
            .map(|(k, &v)| if k % 2 == 1 { f64::NAN } else { v })
            .collect();
        for (vp, measured) in [(ramp, 50.0), (holed, 25.0)] {
            let (open, close) = speeds(&vp, dt, sigma, &[w]);
            assert!((open - (2.0 - allowance(measured))).abs() < 1e-9, "{open}");
            assert_eq!(close, 0.0);
        }
    }

    #[test]
    fn a_held_speed_is_measured_within_each_stretch_between_restarts() {
        // V_P opens at 2 %/s for 30 s, then, after a time gap, at 1 %/s from 20 % lower: the
        // gap's jump is no move, and the faster stretch gives the speed.
        let (dt, sigma) = (0.01, 0.0);
        let vp: Vec<f64> = (0..6000)
            .map(|k| match k < 3000 {
                true => 2.0 * k as f64 * dt,
                false => 40.0 + (k - 3000) as f64 * dt,
            })
            .collect();
        let (open, close) = sustained_speeds(&vp, &[3000], dt, sigma);
        assert!((open - 2.0).abs() < 1e-9, "{open}");
        assert_eq!(close, 0.0);
        // Read as one stretch, the jump is a closing move of 20 % within a 3 s window.
        assert!(sustained_speeds(&vp, &[], dt, sigma).1 > 1.0);
    }

    #[test]
    fn small_steps_do_not_show_a_stroke_speed_and_a_large_one_does() {
        // Pin-cart II at 10 /s up to 60 %/s: steps of 2 % ask for 20 %/s at most, one of 10 %
        // for 100 %/s.
        let spec = vb_core::model::bundled(ModelKind::Pincart2);
        let spec = ModelSpec {
            pincart2: spec.pincart2.map(|p| vb_core::model::PinCart2Params {
                p_gain_per_s: 10.0,
                dy_max_pct_per_s: 60.0,
                ..p
            }),
            ..spec
        };
        let dt = 0.01;
        let shown = |size: f64| {
            let op: Vec<f64> = (0..3000)
                .map(|k| 50.0 + if (k / 500) % 2 == 1 { size } else { 0.0 })
                .collect();
            let sim = vb_core::model::Valve::new(&spec, dt)
                .unwrap()
                .simulate(&op, 50.0);
            stroke_speed_shown(&spec, &op, &sim, dt)
        };
        assert!(!shown(2.0));
        assert!(shown(10.0));
    }
}
