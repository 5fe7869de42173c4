//! The simulation-error cost: run a model freely over the whole O_P of a recording and add up
//! the squared error of V_P on the samples a mask selects.
//!
//! Free run (not one-step prediction) is what the paper scores and what matters when the model
//! stands in for the valve: every sample is simulated from the first one on, and only the
//! scoring is restricted (to windows, or to the fit / held-out blocks of a split). The cost
//! never allocates beyond building the [`Valve`] (its small delay line): the squared errors
//! are summed while stepping, so no buffer is needed at all.
//!
//! A problem can also be **restarted**: each run of consecutive scored samples (a fit block) is
//! simulated on its own, from rest at the measured V_P a warm-up before it, so the samples
//! between runs (held-out blocks) are never simulated. Diagnosis refits that way (half the
//! work, and the held-out blocks stay unseen); the warm-up fills the dead-time line and lets the
//! start from rest die out.
//!
//! Rows without a measured V_P (NaN) are simulated through and never scored: the mask drops
//! them. A recording's restarts (after long gaps) end one run and start the next from the
//! measured V_P there: nothing is known of what the valve did in the gap.
//!
//! Not here: choosing the mask ([`super::windows`]) or minimising ([`super::search`]).

use vb_core::model::{ModelSpec, Valve};
use vb_core::recording::RecordingView;

/// O_P, measured V_P and a scoring mask, sampled every `dt`.
#[derive(Debug, Clone)]
pub struct Problem {
    op: Vec<f64>,
    vp: Vec<f64>,
    mask: Vec<bool>,
    dt: f64,
    /// Where each simulation starts (from rest at the measured V_P) and ends: one run from the
    /// first sample to one past the last masked sample, or one per masked run when restarted.
    runs: Vec<(usize, usize)>,
    /// Samples simulated before each masked run when restarted (`None`: one run from the start).
    warm_up: Option<usize>,
    n_scored: usize,
    /// Where simulations start again (see [`Problem::restarting_at`]).
    restarts: Vec<usize>,
}

impl Problem {
    /// A problem scoring the samples where `mask` is true and V_P was measured.
    ///
    /// # Panics
    /// If the three slices differ in length (a caller bug).
    pub fn new(op: &[f64], vp: &[f64], mask: &[bool], dt: f64) -> Self {
        assert!(
            op.len() == vp.len() && vp.len() == mask.len(),
            "O_P, V_P and mask lengths differ"
        );
        let mask: Vec<bool> = mask
            .iter()
            .zip(vp)
            .map(|(&m, v)| m && v.is_finite())
            .collect();
        let end = mask.iter().rposition(|&m| m).map_or(0, |k| k + 1);
        Problem {
            op: op.to_vec(),
            vp: vp.to_vec(),
            n_scored: mask.iter().filter(|&&m| m).count(),
            mask,
            dt,
            runs: vec![(0, end)],
            warm_up: None,
            restarts: Vec::new(),
        }
    }

    /// The same problem with simulations starting again at `restarts` (increasing sample
    /// indices, a recording's long gaps): a run that spans one is cut there, and the pieces
    /// with nothing scored (a warm-up reaching back across one) are dropped.
    pub fn restarting_at(mut self, restarts: &[usize]) -> Self {
        self.restarts = restarts.to_vec();
        let mut runs = Vec::with_capacity(self.runs.len() + restarts.len());
        for &(from, end) in &self.runs {
            let mut a = from;
            for &r in restarts.iter().filter(|&&r| r > from && r < end) {
                runs.push((a, r));
                a = r;
            }
            runs.push((a, end));
        }
        // A piece with nothing scored (a warm-up cut off by a restart) is not simulated.
        runs.retain(|&(a, b)| self.mask[a..b].iter().any(|&m| m));
        self.runs = runs;
        self
    }

    /// A problem scoring the samples where `mask` is true, each run of them simulated on its
    /// own from rest at the measured V_P `warm_up` samples before the run (or from the first
    /// sample). Runs closer together than the warm-up are simulated as one, through what lies
    /// between them: cheaper than a warm-up, and the state carries over. So rows without V_P
    /// inside a block (a reply lost now and then) cost nothing extra.
    pub fn restarted(op: &[f64], vp: &[f64], mask: &[bool], dt: f64, warm_up: usize) -> Self {
        let mut p = Problem::new(op, vp, mask, dt);
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for (a, b) in masked_runs(&p.mask) {
            match runs.last_mut() {
                Some(last) if a <= last.1 + warm_up => last.1 = b,
                _ => runs.push((a.saturating_sub(warm_up), b)),
            }
        }
        p.runs = runs;
        p.warm_up = Some(warm_up);
        p
    }

    /// The same problem on every `m`-th sample (sample period `m * dt`): a cheap stand-in for
    /// a global search, about `m` times faster. `m <= 1` gives a copy.
    pub fn decimated(&self, m: usize) -> Self {
        if m <= 1 {
            return self.clone();
        }
        let pick = |x: &[f64]| x.iter().step_by(m).copied().collect::<Vec<f64>>();
        // A decimated sample is scored when any sample it stands for is.
        let mask: Vec<bool> = self.mask.chunks(m).map(|c| c.iter().any(|&b| b)).collect();
        // A decimated V_P sample stands for the first of its chunk: the first measured one.
        let vp: Vec<f64> = self
            .vp
            .chunks(m)
            .map(|c| {
                c.iter()
                    .copied()
                    .find(|v| v.is_finite())
                    .unwrap_or(f64::NAN)
            })
            .collect();
        let (op, dt) = (pick(&self.op), self.dt * m as f64);
        let restarts: Vec<usize> = self.restarts.iter().map(|r| r.div_ceil(m)).collect();
        match self.warm_up {
            None => Problem::new(&op, &vp, &mask, dt),
            Some(w) => Problem::restarted(&op, &vp, &mask, dt, w / m),
        }
        .restarting_at(&restarts)
    }

    /// Sample period, s.
    pub fn dt(&self) -> f64 {
        self.dt
    }

    /// Number of samples scored.
    pub fn n_scored(&self) -> usize {
        self.n_scored
    }

    /// Squared error of `spec`'s free run on the masked samples, %²; infinite when the spec
    /// cannot run (a parameter out of range).
    pub fn sse(&self, spec: &ModelSpec) -> f64 {
        let Ok(mut valve) = Valve::new(spec, self.dt) else {
            return f64::INFINITY;
        };
        self.sse_of(&mut valve)
    }

    /// Like [`Problem::sse`] for a valve already built (it is reset at the start of each run).
    pub fn sse_of(&self, valve: &mut Valve) -> f64 {
        let mut sum = 0.0;
        for &(from, end) in &self.runs {
            if from >= end {
                continue;
            }
            valve.reset(self.op[from], first_measured(&self.vp, &self.op, from, end));
            let mut measured = self.vp[from..end].iter().zip(&self.mask[from..end]);
            valve.run(&self.op[from..end], |v| {
                if let Some((&m, &keep)) = measured.next() {
                    let r = m - v;
                    if keep {
                        sum += r * r;
                    }
                }
            });
        }
        if sum.is_finite() {
            sum
        } else {
            f64::INFINITY
        }
    }
}

/// The maximal runs `a..b` of true values in `mask`.
fn masked_runs(mask: &[bool]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut k = 0;
    std::iter::from_fn(move || {
        let a = k + mask.get(k..)?.iter().position(|&m| m)?;
        let b = mask[a..]
            .iter()
            .position(|&m| !m)
            .map_or(mask.len(), |l| a + l);
        k = b;
        Some((a, b))
    })
}

/// The first measured V_P in `from..end`, or O_P at `from` when none was measured: where a run
/// starts from rest.
fn first_measured(vp: &[f64], op: &[f64], from: usize, end: usize) -> f64 {
    vp.get(from..end)
        .and_then(|v| v.iter().copied().find(|v| v.is_finite()))
        .unwrap_or(op[from])
}

/// The free-run V_P of `spec` over a recording's O_P, from rest at its first measured V_P, and
/// again from the measured V_P at each restart; O_P itself when the spec cannot run.
pub fn simulate(spec: &ModelSpec, rec: &RecordingView) -> Vec<f64> {
    let Ok(mut valve) = Valve::new(spec, rec.dt) else {
        return rec.op.to_vec();
    };
    let n = rec.op.len();
    let mut out = vec![0.0; n];
    let bounds: Vec<usize> = std::iter::once(0)
        .chain(rec.restarts.iter().copied().filter(|&r| r > 0 && r < n))
        .chain(std::iter::once(n))
        .collect();
    for w in bounds.windows(2) {
        let (a, b) = (w[0], w[1]);
        let vp0 = first_measured(rec.vp, rec.op, a, b);
        valve.simulate_into(&rec.op[a..b], vp0, &mut out[a..b]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, ModelKind};

    #[test]
    fn the_true_model_has_zero_cost_and_masking_counts() {
        let spec = bundled(ModelKind::Pincart2);
        let op: Vec<f64> = (0..3000)
            .map(|k| if (k / 500) % 2 == 0 { 40.0 } else { 55.0 })
            .collect();
        let vp = Valve::new(&spec, 0.01).unwrap().simulate(&op, 40.0);
        let all = vec![true; op.len()];
        let p = Problem::new(&op, &vp, &all, 0.01);
        assert_eq!(p.sse(&spec), 0.0);
        let other = bundled(ModelKind::Fopdt);
        let full = p.sse(&other);
        assert!(full > 1.0);
        let half: Vec<bool> = (0..op.len()).map(|k| k < 1500).collect();
        let ph = Problem::new(&op, &vp, &half, 0.01);
        let part = ph.sse(&other);
        assert!(part > 0.0 && part < full);
        assert_eq!(ph.n_scored(), 1500);
        let d = p.decimated(10);
        assert_eq!(d.n_scored(), 300);
        assert!((d.dt() - 0.1).abs() < 1e-12);
    }

    #[test]
    fn a_restarted_problem_simulates_each_block_from_the_measurement_before_it() {
        // A pure delay has no state beyond its delay line, which the warm-up refills: the
        // true model costs nothing.
        let spec = bundled(ModelKind::Delayed);
        let op: Vec<f64> = (0..6000)
            .map(|k| 30.0 + 10.0 * ((k / 400) % 4) as f64)
            .collect();
        let vp = Valve::new(&spec, 0.01).unwrap().simulate(&op, 30.0);
        let blocks: Vec<bool> = (0..op.len()).map(|k| (k / 1000) % 2 == 0).collect();
        let p = Problem::restarted(&op, &vp, &blocks, 0.01, 300);
        assert_eq!(p.runs, vec![(0, 1000), (1700, 3000), (3700, 5000)]);
        assert_eq!(p.sse(&spec), 0.0);
        // Another model's error is what a whole simulation gives on those blocks, up to the
        // restarts: close, but not equal.
        let other = bundled(ModelKind::Pincart2);
        let whole = Problem::new(&op, &vp, &blocks, 0.01).sse(&other);
        let restarted = p.sse(&other);
        assert!(
            restarted > 0.5 * whole && restarted < 1.5 * whole,
            "{restarted} {whole}"
        );
        assert_eq!(p.decimated(10).runs, vec![(0, 100), (170, 300), (370, 500)]);
        let runs: Vec<_> = masked_runs(&[false, true, true, false, true]).collect();
        assert_eq!(runs, vec![(1, 3), (4, 5)]);
        // Rows without V_P inside the blocks (every tenth) do not cut them into runs, each
        // with its own warm-up: the runs and the error are those of the intact recording.
        let mut holed = vp.clone();
        holed
            .iter_mut()
            .skip(5)
            .step_by(10)
            .for_each(|v| *v = f64::NAN);
        let h = Problem::restarted(&op, &holed, &blocks, 0.01, 300);
        assert_eq!(h.runs, vec![(0, 1000), (1700, 3000), (3700, 5000)]);
        assert_eq!(h.sse(&spec), 0.0);
    }

    #[test]
    fn missing_samples_are_not_scored_and_restarts_start_from_the_measurement() {
        let spec = bundled(ModelKind::Fopdt);
        let op: Vec<f64> = (0..4000)
            .map(|k| if (k / 500) % 2 == 0 { 40.0 } else { 60.0 })
            .collect();
        let mut vp = Valve::new(&spec, 0.01).unwrap().simulate(&op, 40.0);
        let all = vec![true; op.len()];
        // The true model costs nothing whatever is missing: no NaN reaches the sum.
        vp[100..300].iter_mut().for_each(|v| *v = f64::NAN);
        vp[0] = f64::NAN;
        let p = Problem::new(&op, &vp, &all, 0.01);
        assert_eq!(p.n_scored(), 4000 - 201);
        assert!(p.sse(&spec) < 1e-9, "{}", p.sse(&spec));
        // After a long gap the valve is found elsewhere (at 90 %, O_P 40 %): the true model
        // restarted from the measurement costs nothing, run through it costs much.
        let second = Valve::new(&spec, 0.01).unwrap().simulate(&op[2000..], 90.0);
        vp[2000..].copy_from_slice(&second);
        let from_start = Problem::new(&op, &vp, &all, 0.01).sse(&spec);
        let restarted = Problem::new(&op, &vp, &all, 0.01).restarting_at(&[2000]);
        assert_eq!(restarted.runs, vec![(0, 2000), (2000, 4000)]);
        assert!(
            restarted.sse(&spec) < 1e-2 * from_start,
            "{} {from_start}",
            restarted.sse(&spec)
        );
        let view = RecordingView {
            t: &[],
            op: &op,
            vp: &vp,
            restarts: &[2000],
            dt: 0.01,
        };
        let sim = simulate(&spec, &view);
        let through = simulate(
            &spec,
            &RecordingView {
                restarts: &[],
                ..view
            },
        );
        let after = |s: &[f64]| vb_core::metrics::sse(&s[2000..], &vp[2000..]);
        assert!(sim.iter().all(|v| v.is_finite()));
        assert!(
            after(&sim) < 1e-2 * after(&through),
            "{} {}",
            after(&sim),
            after(&through)
        );
        // A warm-up never reaches back across a restart.
        let blocks: Vec<bool> = (0..4000).map(|k| k >= 2100).collect();
        let w = Problem::restarted(&op, &vp, &blocks, 0.01, 300).restarting_at(&[2000]);
        assert_eq!(w.runs, vec![(2000, 4000)]);
    }
}
