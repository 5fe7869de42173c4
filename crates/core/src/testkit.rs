//! Fixtures the unit tests share: O_P that steps through levels, sample times, columns of a
//! recording to view, a valve's answer to an O_P, and repeatable noise. Built with the tests
//! only: this crate's, and those of the crates above through the `testkit` feature.

use crate::model::{ModelSpec, Valve};
use crate::recording::RecordingView;

/// `n` samples of O_P that hold each of `levels` for `hold` samples, in turn, over and over.
pub fn steps(n: usize, hold: usize, levels: &[f64]) -> Vec<f64> {
    (0..n).map(|k| levels[(k / hold) % levels.len()]).collect()
}

/// `n` samples at `first`, then at each `(from, level)` of `changes` (in order) from sample
/// `from` on.
pub fn changes(n: usize, first: f64, changes: &[(usize, f64)]) -> Vec<f64> {
    (0..n)
        .map(|k| {
            (changes.iter().rev())
                .find(|&&(from, _)| k >= from)
                .map_or(first, |&(_, level)| level)
        })
        .collect()
}

/// The times of `n` samples `dt` apart, from 0 s.
pub fn times(n: usize, dt: f64) -> Vec<f64> {
    (0..n).map(|k| k as f64 * dt).collect()
}

/// What valve `spec` answers to `op`, sampled every `dt`, from rest at `op[0]`.
pub fn answer(spec: &ModelSpec, op: &[f64], dt: f64) -> Vec<f64> {
    (Valve::new(spec, dt).expect("a bundled model builds"))
        .simulate(op, op.first().copied().unwrap_or(0.0))
}

/// A small ripple of amplitude `amp` at sample `k`, the same on every run: `amp` times a saw of
/// period 13 between -1 and 1.
pub fn ripple(k: usize, amp: f64) -> f64 {
    amp * ((k * 7919 % 13) as f64 / 6.0 - 1.0)
}

/// `n` samples of Gaussian noise of standard deviation `sd`, the same on every run (seeded).
pub fn noise(n: usize, sd: f64) -> Vec<f64> {
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(987654321);
    let normal = Normal::new(0.0, sd).expect("a finite, positive deviation");
    (0..n).map(|_| normal.sample(&mut rng)).collect()
}

/// The columns of a recording sampled every `dt` from 0 s, with no restarts, for a
/// [`RecordingView`] of them.
#[derive(Debug)]
pub struct Columns {
    pub t: Vec<f64>,
    pub op: Vec<f64>,
    pub vp: Vec<f64>,
    pub dt: f64,
}

impl Columns {
    /// O_P and V_P, sampled every `dt`.
    pub fn new(op: Vec<f64>, vp: Vec<f64>, dt: f64) -> Columns {
        Columns {
            t: times(op.len(), dt),
            op,
            vp,
            dt,
        }
    }

    /// The recording, borrowed, as analysis reads it.
    pub fn view(&self) -> RecordingView<'_> {
        RecordingView {
            t: &self.t,
            op: &self.op,
            vp: &self.vp,
            restarts: &[],
            dt: self.dt,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_and_changes_hold_their_levels() {
        assert_eq!(
            steps(7, 2, &[1.0, 2.0, 3.0]),
            [1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 1.0]
        );
        assert_eq!(
            changes(6, 4.0, &[(2, 5.0), (4, 4.5)]),
            [4.0, 4.0, 5.0, 5.0, 4.5, 4.5]
        );
        assert_eq!(times(3, 0.5), [0.0, 0.5, 1.0]);
        assert!((0..26).all(|k| ripple(k, 0.05).abs() <= 0.05));
    }
}
