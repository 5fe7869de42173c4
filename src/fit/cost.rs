//! The simulation-error cost: run a model freely over the whole O_P of a recording and add up
//! the squared error of V_P on the samples a mask selects.
//!
//! Free run (not one-step prediction) is what the paper scores and what matters when the model
//! stands in for the valve: every sample is simulated from the first one on, and only the
//! scoring is restricted (to windows, or to the fit / held-out blocks of a split). The cost
//! never allocates beyond building the [`Valve`] (its small delay line): the squared errors
//! are summed while stepping, so no buffer is needed at all.
//!
//! Not here: choosing the mask ([`super::windows`]) or minimising ([`super::search`]).

use crate::model::{ModelSpec, Valve};

/// O_P, measured V_P and a scoring mask, sampled every `dt`.
#[derive(Debug, Clone)]
pub struct Problem {
    op: Vec<f64>,
    vp: Vec<f64>,
    mask: Vec<bool>,
    dt: f64,
    /// One past the last masked sample: the simulation stops there.
    end: usize,
    n_scored: usize,
}

impl Problem {
    /// A problem scoring the samples where `mask` is true.
    ///
    /// # Panics
    /// If the three slices differ in length (a caller bug).
    pub fn new(op: &[f64], vp: &[f64], mask: &[bool], dt: f64) -> Self {
        assert!(
            op.len() == vp.len() && vp.len() == mask.len(),
            "O_P, V_P and mask lengths differ"
        );
        let end = mask.iter().rposition(|&m| m).map_or(0, |k| k + 1);
        Problem {
            op: op.to_vec(),
            vp: vp.to_vec(),
            mask: mask.to_vec(),
            dt,
            end,
            n_scored: mask.iter().filter(|&&m| m).count(),
        }
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
        Problem::new(&pick(&self.op), &pick(&self.vp), &mask, self.dt * m as f64)
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

    /// Like [`Problem::sse`] for a valve already built (it is reset first).
    pub fn sse_of(&self, valve: &mut Valve) -> f64 {
        let (Some(&op0), Some(&vp0)) = (self.op.first(), self.vp.first()) else {
            return 0.0;
        };
        valve.reset(op0, vp0);
        let mut sum = 0.0;
        for ((&u, &m), &keep) in self.op[..self.end]
            .iter()
            .zip(&self.vp[..self.end])
            .zip(&self.mask[..self.end])
        {
            let r = m - valve.step(u);
            if keep {
                sum += r * r;
            }
        }
        if sum.is_finite() {
            sum
        } else {
            f64::INFINITY
        }
    }
}

/// The free-run V_P of `spec` over `op` from rest at (`op[0]`, `vp0`); O_P itself when the
/// spec cannot run.
pub fn simulate(spec: &ModelSpec, op: &[f64], vp0: f64, dt: f64) -> Vec<f64> {
    match Valve::new(spec, dt) {
        Ok(mut v) => v.simulate(op, vp0),
        Err(_) => op.to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{bundled, ModelKind};

    #[test]
    fn the_true_model_has_zero_cost_and_masking_counts() {
        let spec = bundled(ModelKind::Pincart2);
        let op: Vec<f64> = (0..3000)
            .map(|k| if (k / 500) % 2 == 0 { 40.0 } else { 55.0 })
            .collect();
        let vp = simulate(&spec, &op, 40.0, 0.01);
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
}
