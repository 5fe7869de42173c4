//! The transport delay as the increments of O_P and V_P show it, without a model: the lag at
//! which V_P's increments follow O_P's most closely.
//!
//! A dead time is read off steps where O_P steps ([`super::facts::StepResponse`]); a
//! controller in closed loop never steps, and a noisy process measurement makes its output
//! move a little every sample. A valve behind a long dead time then repeats that chatter late,
//! and the free-run error has a valley only a few samples wide at the true delay: a lag (a
//! slow positioner) fits the slow part of the motion as well as any delay a few samples off,
//! and a simplex started from the baseline's lag does not find the valley. The
//! cross-correlation of the increments peaks where V_P's answer starts (at the delay for a
//! positioner that answers at once, a little after it for a slow one), and is where the
//! dead time's refit starts too.
//!
//! Not here: the refit ([`super::candidates`] starts it) or the judging of a dead time.

use vb_core::metrics::stats::mean_sd;
use vb_core::recording::RecordingView;

/// Longest dead time a diagnosis fits, s.
pub(super) const MAX_DEAD_TIME_S: f64 = 3.0;
/// Standard deviations of the cross-correlation of white noise the peak must stand out by:
/// the largest of 300 lags of noise alone reaches about three.
const DELAY_SIGMAS: f64 = 5.0;

/// The lag, s, at which the cross-correlation of O_P's and V_P's increments peaks, up to
/// [`MAX_DEAD_TIME_S`], when the peak stands out of what V_P's own increments would give by
/// chance; `None` otherwise (O_P never moves, or V_P does not answer it beyond its noise).
/// Increments across a restart or next to a row without V_P are left out.
pub(super) fn answer_delay(rec: &RecordingView) -> Option<f64> {
    let increments = |x: &[f64]| -> Vec<f64> {
        let mut d: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
        for &r in rec.restarts {
            if let Some(v) = r.checked_sub(1).and_then(|k| d.get_mut(k)) {
                *v = f64::NAN;
            }
        }
        d.iter_mut()
            .filter(|v| !v.is_finite())
            .for_each(|v| *v = 0.0);
        d
    };
    let (dop, dvp) = (increments(rec.op), increments(rec.vp));
    let n = dop.len().min(dvp.len());
    let lags = ((MAX_DEAD_TIME_S / rec.dt).round() as usize).min(n.saturating_sub(1));
    let (lag, peak) = (0..=lags)
        .map(|l| {
            let c: f64 = dop[..n - l]
                .iter()
                .zip(&dvp[l..n])
                .map(|(a, b)| a * b)
                .sum();
            (l, c)
        })
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    let energy: f64 = dop[..n].iter().map(|a| a * a).sum();
    let (_, spread, _) = mean_sd(dvp[..n].iter().copied());
    (peak > DELAY_SIGMAS * energy.sqrt() * spread).then_some(lag as f64 * rec.dt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::testkit::Columns;

    /// A controller's output that chatters every sample around a slow swing, and V_P that
    /// repeats it `delay` samples late through a first-order lag of `tau` samples, read with
    /// white noise of `noise` %.
    fn loop_like(delay: usize, tau: f64, noise: f64) -> Columns {
        let n: usize = 30_000;
        let mut state = 12_345_u64;
        let mut white = || {
            // A 64-bit linear congruential generator: the test needs noise, not quality.
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let op: Vec<f64> = (0..n)
            .map(|k| 40.0 + 3.0 * (k as f64 * 0.001).sin() + white())
            .collect();
        let mut x = op[0];
        let vp: Vec<f64> = (0..n)
            .map(|k| {
                x += (op[k.saturating_sub(delay)] - x) / tau;
                x + noise * white()
            })
            .collect();
        Columns::new(op, vp, 0.01)
    }

    #[test]
    fn a_long_delay_shows_in_a_chattering_loop() {
        let d = answer_delay(&loop_like(185, 2.0, 0.5).view());
        assert_eq!(d.map(|d| (d * 100.0).round()), Some(185.0), "{d:?}");
        let d = answer_delay(&loop_like(40, 8.0, 0.5).view());
        assert!(d.is_some_and(|d| (0.40..=0.45).contains(&d)), "{d:?}");
    }

    #[test]
    fn a_valve_that_does_not_answer_shows_no_delay() {
        // O_P played backwards: V_P's increments do not follow it.
        let c = loop_like(185, 2.0, 0.5);
        let c = Columns::new(c.op.iter().rev().copied().collect(), c.vp, 0.01);
        assert_eq!(answer_delay(&c.view()), None);
        let still = Columns::new(vec![40.0; 1000], vec![40.0; 1000], 0.01);
        assert_eq!(answer_delay(&still.view()), None);
    }
}
