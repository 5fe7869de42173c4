//! Step and speed measurements, shared by identification, diagnosis and the daemon's live
//! health check: the stroke speed of V_P ([`travel_speed`]) and the step-delay analysis.
//!
//! Step-delay analysis (the paper's Section 4.1, Figs. 5-7): find the steps of O_P, measure how
//! long V_P takes to answer each, split them into same-direction steps and reversals, fit the
//! second-order polynomial of the reversal delay against the initial opening, and derive
//! pin-cart II's eq. (7) coefficients from it.
//!
//! A step is a jump of O_P of at least [`StepOptions::min_size_pct`] in one sample, followed by
//! a hold (O_P within a noise tolerance of its new level) of at least
//! [`StepOptions::min_hold_s`]. Its delay is the time until V_P has moved
//! [`StepOptions::fraction`] of the step towards the new level (and at least four noise
//! standard deviations). It is a *reversal* when it goes against the previous movement of O_P.
//!
//! Reading of eq. (7) (see `model::pincart`): a reversal costs T_d + the cart-crossing time +
//! the first rise, a same-direction step T_d + the first rise; so the crossing time at opening
//! V is the reversal polynomial minus the mean same-direction delay.
//!
//! Not here: anything that needs a model. The analysis only reads O_P and V_P.

use serde::Serialize;

use super::stats::{mean_sd, noise_sd, quantile, Differences};
use crate::model::crossing_poly;
use crate::recording::RecordingView;

/// Why a step analysis cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StepsError {
    /// Step-analysis options that make no sense.
    #[error("step analysis: {0}")]
    Options(String),
    /// No measured V_P to measure against.
    #[error("the recording has no measured V_P column: identification and step delays need it (map it with --columns vp=NAME)")]
    NoPosition,
}

/// What counts as a step and when it has answered.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepOptions {
    /// Smallest O_P jump that counts as a step, %.
    pub min_size_pct: f64,
    /// Share of the step V_P must have covered for the delay to end (0-1).
    pub fraction: f64,
    /// Shortest hold of O_P after the jump, s (at least three samples).
    pub min_hold_s: f64,
}

impl StepOptions {
    /// Options checked for sense: `fraction` strictly between 0 and 1, a positive size and
    /// hold.
    pub fn new(min_size_pct: f64, fraction: f64, min_hold_s: f64) -> Result<Self, StepsError> {
        let bad = |detail: String| Err(StepsError::Options(detail));
        if !(fraction > 0.0 && fraction < 1.0) {
            return bad(format!(
                "fraction {fraction}: must be between 0 and 1 (e.g. 0.1 for a tenth of the step)"
            ));
        }
        if !(min_size_pct > 0.0 && min_size_pct.is_finite()) {
            return bad(format!(
                "smallest step {min_size_pct} %: must be a positive size in % (e.g. 0.5)"
            ));
        }
        if !(min_hold_s > 0.0 && min_hold_s.is_finite()) {
            return bad(format!(
                "shortest hold {min_hold_s} s: must be a positive time in s (e.g. 1)"
            ));
        }
        Ok(StepOptions {
            min_size_pct,
            fraction,
            min_hold_s,
        })
    }
}

impl Default for StepOptions {
    fn default() -> Self {
        StepOptions {
            min_size_pct: 0.5,
            fraction: 0.1,
            min_hold_s: 1.0,
        }
    }
}

/// One step of O_P and how V_P answered it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Step {
    /// Sample index of the jump.
    pub index: usize,
    /// One past the last sample of the hold after it.
    pub hold_end: usize,
    /// Time of the jump, s from the start of the recording.
    pub t_s: f64,
    /// V_P just before the jump: the initial opening, %.
    pub from_pct: f64,
    /// O_P jump, % (signed).
    pub size_pct: f64,
    /// Against the previous movement of O_P; `None` for the first movement.
    pub reversal: Option<bool>,
    /// Time until V_P moved the set fraction of the step, s; `None` if it never did in the hold.
    pub delay_s: Option<f64>,
    /// Time until V_P covered 63 % of the step, s (when it did within the hold).
    pub t63_s: Option<f64>,
}

/// Mean, spread and count of a group of delays.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Population {
    pub mean_s: f64,
    /// Sample standard deviation (0 for fewer than two).
    pub sd_s: f64,
    pub count: usize,
}

impl std::fmt::Display for Population {
    /// `0.452 ± 0.031 s (n = 40)`, or `none`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.count == 0 {
            f.write_str("none")
        } else {
            write!(
                f,
                "{:.3} ± {:.3} s (n = {})",
                self.mean_s, self.sd_s, self.count
            )
        }
    }
}

impl Population {
    /// Mean, sample standard deviation and count of `x` (mean NaN when empty).
    pub fn of(x: &[f64]) -> Self {
        let (mean_s, sd_s, count) = mean_sd(x.iter().copied());
        Population {
            mean_s: if count == 0 { f64::NAN } else { mean_s },
            sd_s,
            count,
        }
    }
}

/// A second-order polynomial `a V² + b V + c` of the opening V in %.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Poly {
    pub a: f64,
    pub b: f64,
    pub c: f64,
}

impl Poly {
    /// Value at opening `v` (%).
    pub fn at(&self, v: f64) -> f64 {
        (self.a * v + self.b) * v + self.c
    }
}

/// Pin-cart II's eq. (7) coefficients derived from the step delays.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CrossingSeed {
    pub a_p: f64,
    pub b_p: f64,
    pub c_p: f64,
    /// Crossing times at 0, 50 and 100 % opening, s (never negative).
    pub at_0_50_100_s: [f64; 3],
}

/// Everything the step analysis found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepAnalysis {
    pub options_fraction: f64,
    pub steps: Vec<Step>,
    /// Delays of steps in the same direction as the previous movement.
    pub same: Population,
    /// Delays of reversals.
    pub reversal: Population,
    /// Least-squares fit of the reversal delay against the initial opening (needs five
    /// reversals spread over at least 10 % of travel).
    pub reversal_poly: Option<Poly>,
    /// Pin-cart II's a_p, b_p, c_p: the reversal polynomial minus the mean same-direction
    /// delay (needs the polynomial and a same-direction delay).
    pub pincart2: Option<CrossingSeed>,
    /// Noise standard deviation of V_P used for the thresholds, %.
    pub noise_pct: f64,
}

/// The 99.5th percentile of the speed of V_P over 0.1 s, %/s: of every move (`direction`
/// None), or only of the opening (`Some(1.0)`) or closing (`Some(-1.0)`) moves (0 when there
/// are none).
pub fn travel_speed(vp: &[f64], dt: f64, direction: Option<f64>) -> f64 {
    let h = ((0.1 / dt).round() as usize).max(1);
    let mut speeds: Vec<f64> = (h..vp.len())
        .step_by(h)
        .map(|k| (vp[k] - vp[k - h]) / (h as f64 * dt))
        .filter(|v| v.is_finite())
        .filter_map(|v| match direction {
            None => Some(v.abs()),
            Some(d) => (v * d > 0.0).then_some(v.abs()),
        })
        .collect();
    quantile(&mut speeds, 0.995)
}

/// Analyses the steps of a recording; it must have a measured V_P.
pub fn analyse_recording(
    rec: &RecordingView,
    opts: &StepOptions,
) -> Result<StepAnalysis, StepsError> {
    if rec.vp.len() != rec.op.len() || rec.vp.is_empty() {
        return Err(StepsError::NoPosition);
    }
    Ok(analyse(rec, opts))
}

/// Longest run of rows without V_P a step's answer may contain: a lost reply now and then
/// (one to three rows) moves a measured delay by at most that much; a longer gap could hide
/// when V_P moved.
pub const MAX_MISSING_ROWS: usize = 3;

/// Analyses the steps of a recording's O_P and the answers in its V_P. A step counts only when
/// V_P was measured on the sample before the jump, no more than [`MAX_MISSING_ROWS`] in a row
/// are missing from then to the end of the hold, and neither the jump nor the hold spans a
/// restart (a long gap).
pub fn analyse(rec: &RecordingView, opts: &StepOptions) -> StepAnalysis {
    let (op, vp, dt) = (rec.op, rec.vp, rec.dt);
    let n = op.len().min(vp.len());
    let sigma = noise_sd(&vp[..n], Differences::First);
    let op_tol = (4.0 * noise_sd(&op[..n], Differences::First)).max(1e-6);
    let min_hold = ((opts.min_hold_s / dt).ceil() as usize).max(3);
    let mut steps = Vec::new();
    let mut last_dir = 0.0;
    let mut k = 1;
    while k < n {
        let size = op[k] - op[k - 1];
        if size.abs() <= op_tol || rec.restarts.contains(&k) {
            k += 1;
            continue;
        }
        let dir = size.signum();
        let a = k;
        let segment_end = rec
            .restarts
            .iter()
            .copied()
            .find(|&r| r > a)
            .unwrap_or(n)
            .min(n);
        let mut end = a + 1;
        while end < segment_end && (op[end] - op[a]).abs() <= op_tol {
            end += 1;
        }
        let measured = vp[a - 1].is_finite() && longest_missing(&vp[a..end]) <= MAX_MISSING_ROWS;
        if size.abs() >= opts.min_size_pct && end - a >= min_hold && measured {
            let v0 = vp[a - 1];
            let moved = |share: f64| {
                let need = (share * size.abs()).max(4.0 * sigma);
                time_to_move(vp, a..end, (v0, dir), need, dt)
            };
            steps.push(Step {
                index: a,
                hold_end: end,
                t_s: rec
                    .t
                    .get(a)
                    .zip(rec.t.first())
                    .map_or(a as f64 * dt, |(t, t0)| t - t0),
                from_pct: v0,
                size_pct: size,
                reversal: (last_dir != 0.0).then_some(dir != last_dir),
                delay_s: moved(opts.fraction),
                t63_s: moved(0.63),
            });
        }
        last_dir = dir;
        k = end;
    }
    let delays = |rev: bool| -> Vec<(f64, f64)> {
        steps
            .iter()
            .filter(|s| s.reversal == Some(rev))
            .filter_map(|s| s.delay_s.map(|d| (s.from_pct, d)))
            .collect()
    };
    let same_d: Vec<f64> = delays(false).into_iter().map(|p| p.1).collect();
    let rev_pts = delays(true);
    let rev_d: Vec<f64> = rev_pts.iter().map(|p| p.1).collect();
    let same = Population::of(&same_d);
    let reversal = Population::of(&rev_d);
    let reversal_poly = fit_quadratic(&rev_pts);
    let pincart2 = match (reversal_poly, same.count > 0) {
        (Some(p), true) => {
            let t = [0.0, 50.0, 100.0].map(|v| (p.at(v) - same.mean_s).max(0.0));
            let (a_p, b_p, c_p) = crossing_poly(t[0], t[1], t[2]);
            Some(CrossingSeed {
                a_p,
                b_p,
                c_p,
                at_0_50_100_s: t,
            })
        }
        _ => None,
    };
    StepAnalysis {
        options_fraction: opts.fraction,
        steps,
        same,
        reversal,
        reversal_poly,
        pincart2,
        noise_pct: sigma,
    }
}

/// The time from sample `span.start` until V_P has moved `need` from `v0` in the direction
/// `dir` (+1 opening, -1 closing), s: the first sample of `span` that has; `None` when none has.
/// Rows without V_P (NaN) are passed over, never taken for a move.
pub fn time_to_move(
    vp: &[f64],
    span: std::ops::Range<usize>,
    (v0, dir): (f64, f64),
    need: f64,
    dt: f64,
) -> Option<f64> {
    let a = span.start;
    span.into_iter()
        .find(|&j| {
            vp.get(j)
                .is_some_and(|v| v.is_finite() && (v - v0) * dir >= need)
        })
        .map(|j| (j - a) as f64 * dt)
}

/// The longest run of rows without a measured value (NaN) in `x`.
pub fn longest_missing(x: &[f64]) -> usize {
    let (mut run, mut longest) = (0, 0);
    for v in x {
        run = if v.is_finite() { 0 } else { run + 1 };
        longest = longest.max(run);
    }
    longest
}

/// Least-squares `a x² + b x + c` through `(x, y)` points; `None` with fewer than five points
/// or less than 10 % spread of x. Solved on x / 100 by Gaussian elimination of the 3×3 normal
/// equations with partial pivoting: small enough that a linear-algebra crate would only add a
/// dependency.
pub fn fit_quadratic(pts: &[(f64, f64)]) -> Option<Poly> {
    if pts.len() < 5 {
        return None;
    }
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
            (l.min(p.0), h.max(p.0))
        });
    if hi - lo < 10.0 {
        return None;
    }
    // Normal equations of [x², x, 1] with x scaled to 0-1.
    let mut m = [[0.0f64; 4]; 3];
    for &(x, y) in pts {
        let s = x / 100.0;
        let row = [s * s, s, 1.0];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += row[i] * row[j];
            }
            m[i][3] += row[i] * y;
        }
    }
    for col in 0..3 {
        let piv = (col..3).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        m.swap(col, piv);
        if m[col][col].abs() < 1e-12 {
            return None;
        }
        let pivot = m[col];
        for (r, row) in m.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / pivot[col];
                for (x, p) in row.iter_mut().zip(pivot).skip(col) {
                    *x -= f * p;
                }
            }
        }
    }
    let sol = [m[0][3] / m[0][0], m[1][3] / m[1][1], m[2][3] / m[2][2]];
    Some(Poly {
        a: sol[0] / 1e4,
        b: sol[1] / 100.0,
        c: sol[2],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{bundled, ModelKind, Valve};

    #[test]
    fn quadratic_is_recovered() {
        let pts: Vec<(f64, f64)> = (0..20)
            .map(|k| {
                let v = 20.0 + 4.0 * k as f64;
                (v, 2e-5 * v * v + 3e-3 * v + 0.7)
            })
            .collect();
        let p = fit_quadratic(&pts).unwrap();
        assert!(
            (p.a - 2e-5).abs() < 1e-10 && (p.b - 3e-3).abs() < 1e-8 && (p.c - 0.7).abs() < 1e-6
        );
        assert!(fit_quadratic(&pts[..4]).is_none());
    }

    #[test]
    fn reversals_take_longer_and_give_the_crossing_polynomial() {
        // Pin-cart II with the bundled crossing times 0.3-0.8 s, driven by alternating and
        // repeated steps over the whole range.
        let spec = bundled(ModelKind::Pincart2);
        let dt = 0.01;
        let mut levels = Vec::new();
        for i in 0..40 {
            let base = 15.0 + 2.0 * i as f64;
            levels.extend([base, base + 3.0, base + 6.0, base + 2.0]);
        }
        let op: Vec<f64> = levels
            .iter()
            .flat_map(|&l| std::iter::repeat_n(l, 400))
            .collect();
        let mut valve = Valve::new(&spec, dt).unwrap();
        let vp = valve.simulate(&op, op[0]);
        let a = analyse(
            &RecordingView {
                t: &[],
                op: &op,
                vp: &vp,
                restarts: &[],
                dt,
            },
            &StepOptions::default(),
        );
        assert!(
            a.same.count >= 40 && a.reversal.count >= 40,
            "{:?} {:?}",
            a.same,
            a.reversal
        );
        assert!(
            a.reversal.mean_s > a.same.mean_s + 0.3,
            "{:?} {:?}",
            a.same,
            a.reversal
        );
        let c = a.pincart2.expect("crossing polynomial");
        let truth = spec.pincart2.unwrap();
        for (v, got) in [0.0, 50.0, 100.0].into_iter().zip(c.at_0_50_100_s) {
            let want = truth.crossing_time_s(v);
            assert!((got - want).abs() < 0.15, "at {v} %: {got} vs {want}");
        }
        // The first movement has no direction to compare with.
        assert_eq!(a.steps[0].reversal, None);
        // Lost replies (one row in every 50, three in a row every 700) keep every step, each
        // delay within the three rows a burst can hide; a gap of five rows drops its step.
        let lost = |k: usize| k % 50 == 11 || (350..353).contains(&(k % 700));
        let mut holed: Vec<f64> = (vp.iter().enumerate())
            .map(|(k, &v)| if lost(k) { f64::NAN } else { v })
            .collect();
        holed[4005..4010].fill(f64::NAN);
        let view = |vp| RecordingView {
            t: &[],
            op: &op,
            vp,
            restarts: &[],
            dt,
        };
        let h = analyse(&view(&holed), &StepOptions::default());
        assert_eq!(h.steps.len(), a.steps.len() - 1);
        for (x, y) in a.steps.iter().filter(|s| s.index != 4000).zip(&h.steps) {
            assert_eq!(x.index, y.index);
            let (dx, dy) = (x.delay_s.unwrap(), y.delay_s.unwrap());
            assert!((0.0..=0.03 + 1e-9).contains(&(dy - dx)), "{dx} {dy}");
        }
    }
}
