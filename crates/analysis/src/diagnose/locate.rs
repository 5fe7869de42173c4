//! Locate: where in time a simulation departs from the recording by more than the noise.
//!
//! The noise floor is the measurement noise of V_P, estimated robustly from its second
//! differences ([`stats::noise_sd`]: a smooth movement has almost none), so steps and jumps do
//! not inflate it. A mismatch window is a stretch where the residual's mean square over one
//! second stays above four times the noise variance; each window is tied to what O_P and V_P
//! were doing there. This module measures; it does not decide what is missing (that is
//! [`super::judge`]).

use serde::Serialize;

use vb_core::metrics::stats::{self, Differences};
use vb_core::recording::RecordingView;

/// One stretch of recording where the model misses by more than the noise.
#[derive(Debug, Clone, Serialize)]
pub struct Window {
    pub start_s: f64,
    pub end_s: f64,
    /// Sum over the window of (residual² - noise variance), %².
    pub excess_sse: f64,
    /// What O_P and V_P were doing there.
    pub kind: Context,
    /// Mean V_P over the window, %.
    pub opening_pct: f64,
}

/// What the valve was doing in a window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Context {
    /// O_P reversed its direction shortly before or inside the window.
    Reversal,
    /// O_P stepped by more than 5 % in the same direction as before.
    LargeStep,
    /// O_P moved by a small step or a ramp in the same direction.
    Move,
    /// O_P held still: the valve should have been at rest.
    Rest,
    /// O_P or V_P near a travel limit.
    NearLimit,
}

/// Measurement noise (standard deviation, %) of V_P, from its second differences.
pub fn noise_floor(vp: &[f64]) -> f64 {
    stats::noise_sd(vp, Differences::Second)
}

/// Finds the mismatch windows of `residual` (measured - simulated) in `rec` given the noise
/// `sigma`. Rows without a measured V_P (NaN) are left out of the means.
pub fn windows(rec: &RecordingView, residual: &[f64], sigma: f64) -> Vec<Window> {
    let dt = rec.dt;
    let n = residual.len();
    let w = ((1.0 / dt).round() as usize).clamp(1, n.max(1));
    let var = sigma * sigma;
    // Floor the threshold at 0.05 %² so noiseless recordings do not flag rounding noise.
    let threshold = (4.0 * var).max(2.5e-3);
    let mut out = Vec::new();
    // Squared residual and whether it was measured.
    let sq = |k: usize| {
        let r = residual[k];
        if r.is_finite() {
            (r * r, 1.0)
        } else {
            (0.0, 0.0)
        }
    };
    let (mut acc, mut count) = (0..w.min(n))
        .map(sq)
        .fold((0.0, 0.0), |(a, c), (x, m)| (a + x, c + m));
    let mut start: Option<usize> = None;
    let mut last_hot = 0;
    let gap = w / 2;
    for i in 0..n.saturating_sub(w) {
        let hot = count > 0.0 && acc / count > threshold;
        if hot {
            if start.is_none() {
                start = Some(i);
            }
            last_hot = i + w;
        } else if let Some(s) = start {
            if i > last_hot + gap {
                out.push(make(rec, residual, var, s..last_hot.min(n)));
                start = None;
            }
        }
        let ((add, m_add), (drop, m_drop)) = (sq(i + w), sq(i));
        acc += add - drop;
        count += m_add - m_drop;
    }
    if let Some(s) = start {
        out.push(make(rec, residual, var, s..last_hot.min(n)));
    }
    out
}

/// The window of samples `range` of the residual `r`, trimmed to the samples that are
/// themselves above the threshold, with its context.
fn make(rec: &RecordingView, r: &[f64], var: f64, range: std::ops::Range<usize>) -> Window {
    let (a, b) = (range.start, range.end);
    let hot = |k: &usize| r[*k] * r[*k] > 4.0 * var;
    let a = (a..b).find(hot).unwrap_or(a);
    let b = (a..b).rev().find(hot).map_or(b, |k| k + 1);
    let excess_sse = (r[a..b].iter())
        .filter(|x| x.is_finite())
        .map(|x| x * x - var)
        .sum::<f64>()
        .max(0.0);
    let measured: Vec<f64> = (rec.vp[a..b].iter())
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    Window {
        start_s: rec.t[a],
        end_s: rec.t[b.saturating_sub(1)],
        excess_sse,
        kind: classify(rec.op, rec.vp, a, b, rec.dt),
        opening_pct: measured.iter().sum::<f64>() / measured.len().max(1) as f64,
    }
}

/// What O_P was doing from two seconds before the window to its end.
pub fn classify(op: &[f64], vp: &[f64], a: usize, b: usize, dt: f64) -> Context {
    let back = (2.0 / dt) as usize;
    let lo = a.saturating_sub(back);
    // A row without V_P (NaN) is near nothing.
    let near = |x: f64| x.is_finite() && !(2.0..=98.0).contains(&x);
    if op[lo..b].iter().chain(&vp[a..b]).any(|&x| near(x)) {
        return Context::NearLimit;
    }
    let span = op[lo..b].iter().fold(f64::NEG_INFINITY, |m, &x| m.max(x))
        - op[lo..b].iter().fold(f64::INFINITY, |m, &x| m.min(x));
    if span < 0.05 {
        return Context::Rest;
    }
    // Direction of the last clear movement before `lo`, and of the movement inside.
    let inside = direction_changes(op, lo, b);
    let before = last_direction(op, lo, dt);
    match (before, inside.first()) {
        (Some(d0), Some(&d1)) if d0 != d1 => Context::Reversal,
        _ if inside.windows(2).any(|w| w[0] != w[1]) => Context::Reversal,
        _ if span > 5.0 => Context::LargeStep,
        _ => Context::Move,
    }
}

/// Signs of the successive clear movements of `op` in `a..b` (moves over 0.02 % a sample).
fn direction_changes(op: &[f64], a: usize, b: usize) -> Vec<i8> {
    let mut dirs = Vec::new();
    for k in a.max(1)..b {
        let d = op[k] - op[k - 1];
        if d.abs() > 0.02 {
            let s = if d > 0.0 { 1 } else { -1 };
            if dirs.last() != Some(&s) {
                dirs.push(s);
            }
        }
    }
    dirs
}

/// The sign of the last clear movement of `op` before `a`, looking back at most 60 s.
fn last_direction(op: &[f64], a: usize, dt: f64) -> Option<i8> {
    let stop = a.saturating_sub((60.0 / dt) as usize).max(1);
    (stop..a).rev().find_map(|k| {
        let d = op[k] - op[k - 1];
        (d.abs() > 0.02).then_some(if d > 0.0 { 1 } else { -1 })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::testkit::{changes, ripple, Columns};

    #[test]
    fn windows_find_the_bad_stretch_and_its_context() {
        let n = 6000;
        // O_P goes up at 10 s and reverses at 30 s; the residual is bad for 1 s after 30 s.
        let op = changes(n, 40.0, &[(1000, 50.0), (3000, 45.0)]);
        let r = changes(n, 0.0, &[(3000, 1.0), (3100, 0.0)]);
        let rec = Columns::new(op.clone(), op, 0.01);
        let w = windows(&rec.view(), &r, 0.05);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].start_s > 28.5 && w[0].end_s < 31.5, "{w:?}");
        assert_eq!(w[0].kind, Context::Reversal);
        assert!((w[0].excess_sse - 100.0 * (1.0 - 0.0025)).abs() < 1.0);
    }

    #[test]
    fn clean_residual_gives_no_window() {
        let x = vec![50.0; 1000];
        let r: Vec<f64> = (0..1000).map(|k| ripple(k, 0.05)).collect();
        let rec = Columns::new(x.clone(), x, 0.01);
        assert!(windows(&rec.view(), &r, 0.05).is_empty());
    }
}
