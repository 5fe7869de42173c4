//! How diagnosis scores a model: alternating fit and held-out blocks over the recording, on
//! identification's cost ([`crate::fit::cost::Problem`]).
//!
//! The recording is cut into blocks from its first sample, alternately fitted and held out
//! ([`crate::fit::windows::alternating`]), so both halves cover every operating region; the
//! first second (the start from rest) is scored in neither. Refits minimise the error on the
//! fit blocks of a *restarted* problem: each fit block simulated on its own from the measured
//! position [`WARM_UP_S`] before it, so the held-out blocks between them are never simulated
//! while fitting (half the work). Judging simulates the whole recording once and splits its
//! error by block. On a long recording refits see at most [`MAX_FIT_SAMPLES`] (the start of
//! every fit block), and the short survey of each start every other fit block: the cost of a
//! refit stops growing with the length of the recording, while judging still sees all of it.
//!
//! Not here: what is refitted or how it is judged ([`super::refit`], [`super::judge`]).

use crate::fit::cost::{self, Problem};
use crate::fit::windows;
use vb_core::model::ModelSpec;
use vb_core::recording::RecordingView;

/// Simulated time before each fit block when refits simulate the fit blocks alone, s: longer
/// than the longest dead time a diagnosis fits (3 s). Hysteresis that outlives it (a pin left
/// off-centre) costs the fit a little, never the judgement, which simulates the whole recording.
pub(super) const WARM_UP_S: f64 = 10.0;
/// Most samples a refit is scored on (the first part of each fit block): fifteen minutes at
/// 100 Hz give as many; a longer recording adds to what is judged, not to what each refit
/// simulates.
pub(super) const MAX_FIT_SAMPLES: usize = 45_000;

/// The data a refit scores against: O_P, V_P and the alternating fit / held-out blocks.
pub(crate) struct Scorer<'a> {
    pub op: &'a [f64],
    /// NaN where not measured (never in a mask).
    pub vp: &'a [f64],
    /// Where simulations start again (after long gaps).
    pub restarts: &'a [usize],
    pub dt: f64,
    /// Samples per block; even blocks are fitted, odd ones held out.
    pub block_len: usize,
    /// Samples at the start left out of all scoring (initial transient).
    pub skip: usize,
    pub n_blocks: usize,
    fit_mask: Vec<bool>,
    held_mask: Vec<bool>,
    /// The fit blocks (at most [`MAX_FIT_SAMPLES`]), each simulated from the measurement
    /// [`WARM_UP_S`] before it.
    fit: Problem,
    /// Every other one of them, for the short survey of a refit's starts.
    survey: Problem,
}

/// Fit and held-out error of one simulation, %².
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Errors {
    pub fit: f64,
    pub held: f64,
}

impl<'a> Scorer<'a> {
    /// Blocks of a twentieth of the recording (10-120 s, so about ten held-out blocks), the
    /// first second left out.
    pub(crate) fn new(rec: &RecordingView<'a>) -> Self {
        let (n, dt) = (rec.len(), rec.dt);
        let block_len = (((n as f64 * dt / 20.0).clamp(10.0, 120.0) / dt) as usize).max(1);
        let skip = (1.0 / dt) as usize;
        let (mut fit_mask, mut held_mask) = windows::alternating(n, block_len, skip);
        for (k, (f, h)) in fit_mask.iter_mut().zip(&mut held_mask).enumerate() {
            let measured = rec.has_vp(k);
            *f &= measured;
            *h &= measured;
        }
        let warm = (WARM_UP_S / dt) as usize;
        let n_fit_blocks = n.div_ceil(block_len).div_ceil(2).max(1);
        let per_block = (MAX_FIT_SAMPLES / n_fit_blocks).max(1);
        let capped: Vec<bool> = (fit_mask.iter().enumerate())
            .map(|(k, &f)| f && k % block_len < per_block)
            .collect();
        let every_other: Vec<bool> = (capped.iter().enumerate())
            .map(|(k, &f)| f && (k / block_len).is_multiple_of(4))
            .collect();
        let problem = |mask: &[bool]| {
            Problem::restarted(rec.op, rec.vp, mask, dt, warm).restarting_at(rec.restarts)
        };
        Scorer {
            op: rec.op,
            vp: rec.vp,
            restarts: rec.restarts,
            dt,
            block_len,
            skip,
            n_blocks: n.div_ceil(block_len),
            fit: problem(&capped),
            survey: problem(&every_other),
            fit_mask,
            held_mask,
        }
    }

    /// Whether sample `k` is scored as held out.
    pub(crate) fn held(&self, k: usize) -> bool {
        self.held_mask[k]
    }

    /// The held-out samples.
    pub(crate) fn held_mask(&self) -> &[bool] {
        &self.held_mask
    }

    /// Fit error alone, what refits minimise (the fit blocks simulated one by one).
    pub(crate) fn fit_error(&self, spec: &ModelSpec) -> f64 {
        self.fit.sse(spec)
    }

    /// The fit error on every other fit block, what the short survey of a refit's starts
    /// minimises.
    pub(crate) fn survey_error(&self, spec: &ModelSpec) -> f64 {
        self.survey.sse(spec)
    }

    /// Fit and held-out error of `spec` simulated over the whole recording (infinite when it
    /// cannot run).
    pub(crate) fn errors(&self, spec: &ModelSpec) -> Errors {
        if spec.validate().is_err() {
            return Errors {
                fit: f64::INFINITY,
                held: f64::INFINITY,
            };
        }
        self.errors_of(&self.simulate(spec))
    }

    /// Fit and held-out error of a simulated V_P of the whole recording.
    pub(crate) fn errors_of(&self, sim: &[f64]) -> Errors {
        let mut sums = [0.0, 0.0];
        for (k, (&m, y)) in self.vp.iter().zip(sim).enumerate() {
            if self.fit_mask[k] {
                sums[0] += (m - y) * (m - y);
            } else if self.held_mask[k] {
                sums[1] += (m - y) * (m - y);
            }
        }
        Errors {
            fit: sums[0],
            held: sums[1],
        }
    }

    /// Per held-out block: the drop in squared error from simulation `ya` to `yb` (each from
    /// [`Scorer::simulate`]), and the sum of squared differences between the two (what sets
    /// the noise of that drop).
    pub(crate) fn paired(&self, ya: &[f64], yb: &[f64]) -> Vec<(f64, f64)> {
        let mut out = vec![(0.0, 0.0); self.n_blocks.div_ceil(2)];
        for (k, &m) in self.vp.iter().enumerate() {
            if self.held_mask[k] {
                let o = &mut out[k / self.block_len / 2];
                o.0 += (m - ya[k]).powi(2) - (m - yb[k]).powi(2);
                o.1 += (ya[k] - yb[k]).powi(2);
            }
        }
        out
    }

    /// The squared error of a simulated V_P `sim` in each held-out block, %².
    pub(crate) fn held_blocks(&self, sim: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.n_blocks.div_ceil(2)];
        for (k, (&m, y)) in self.vp.iter().zip(sim).enumerate() {
            if self.held_mask[k] {
                out[k / self.block_len / 2] += (m - y) * (m - y);
            }
        }
        out
    }

    /// The free-run V_P of `spec` over the whole recording, from rest at the first measured
    /// sample (and again at each restart).
    pub(crate) fn simulate(&self, spec: &ModelSpec) -> Vec<f64> {
        cost::simulate(spec, &self.view())
    }

    /// The recording this scorer scores.
    pub(crate) fn view(&self) -> RecordingView<'a> {
        RecordingView {
            t: &[],
            op: self.op,
            vp: self.vp,
            restarts: self.restarts,
            dt: self.dt,
        }
    }

    /// Number of samples in the fit blocks (what [`Scorer::errors`] sums as `fit`).
    pub(crate) fn n_fit(&self) -> usize {
        self.fit_mask.iter().filter(|&&f| f).count()
    }

    /// Number of held-out samples.
    pub(crate) fn n_held(&self) -> usize {
        self.held_mask.iter().filter(|&&h| h).count()
    }

    /// Number of samples scored, fitted or held out.
    pub(crate) fn n_scored(&self) -> usize {
        self.n_fit() + self.n_held()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, ModelKind};
    use vb_core::testkit::{answer, steps, Columns};

    #[test]
    fn blocks_alternate_and_errors_split_by_block() {
        let dt = 0.01;
        let op = steps(60000, 700, &[30.0, 40.0, 50.0, 60.0]);
        let truth = bundled(ModelKind::Fopdt);
        let vp = answer(&truth, &op, dt);
        let rec = Columns::new(op, vp, dt);
        let s = Scorer::new(&rec.view());
        // 600 s: blocks of 30 s, twenty of them, ten held out.
        assert_eq!((s.block_len, s.n_blocks, s.skip), (3000, 20, 100));
        assert!(!s.held(2999) && s.held(3000) && !s.held(6000));
        assert_eq!(s.n_fit() + s.n_held(), rec.op.len() - 100);
        assert_eq!(
            s.errors(&truth),
            Errors {
                fit: 0.0,
                held: 0.0
            }
        );
        let other = bundled(ModelKind::Delayed);
        let e = s.errors(&other);
        assert!(e.fit > 0.0 && e.held > 0.0);
        let blocks = s.paired(&s.simulate(&other), &s.simulate(&truth));
        assert_eq!(blocks.len(), 10);
        let total: f64 = blocks.iter().map(|b| b.0).sum();
        assert!((total - e.held).abs() < 1e-6 * e.held);
    }
}
