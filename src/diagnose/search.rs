//! Bounded derivative-free minimisation for refits: argmin's Nelder-Mead inside a box.
//!
//! Simulation error of valve models with backlash, stick-slip and dead time is not smooth, so
//! refits use a simplex method. argmin's Nelder-Mead knows no bounds: the cost clamps each
//! trial point into the box and adds a penalty for the distance outside, which keeps the
//! simplex inside without changing the optimum.

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;

/// A box-bounded problem: `f` evaluated at clamped points, plus an outside penalty.
struct Boxed<'a, F> {
    f: &'a F,
    lo: &'a [f64],
    hi: &'a [f64],
}

impl<F: Fn(&[f64]) -> f64> CostFunction for Boxed<'_, F> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> Result<f64, Error> {
        let mut outside = 0.0;
        let clamped: Vec<f64> = x
            .iter()
            .zip(self.lo.iter().zip(self.hi))
            .map(|(&v, (&l, &h))| {
                let c = v.clamp(l, h);
                outside += ((v - c) / (h - l).max(1e-12)).abs();
                c
            })
            .collect();
        let y = (self.f)(&clamped);
        Ok(if y.is_finite() {
            y * (1.0 + outside) + outside
        } else {
            f64::MAX
        })
    }
}

/// Minimises `f` over the box `[lo, hi]` from `x0` with at most `max_iters` simplex steps.
/// Returns the best point (inside the box) and its cost. Dimensions with `lo == hi` are fixed.
pub fn minimize<F: Fn(&[f64]) -> f64>(
    f: &F,
    x0: &[f64],
    lo: &[f64],
    hi: &[f64],
    max_iters: u64,
) -> (Vec<f64>, f64) {
    let start: Vec<f64> = x0
        .iter()
        .zip(lo.iter().zip(hi))
        .map(|(&v, (&l, &h))| v.clamp(l, h))
        .collect();
    let fallback = (start.clone(), f(&start));
    if x0.is_empty() {
        return fallback;
    }
    // Initial simplex: a step of a fifth of the range along each axis, towards the interior.
    let mut simplex = vec![start.clone()];
    for i in 0..start.len() {
        let mut p = start.clone();
        let step = 0.2 * (hi[i] - lo[i]);
        p[i] = if p[i] + step <= hi[i] {
            p[i] + step
        } else {
            p[i] - step
        };
        simplex.push(p);
    }
    let problem = Boxed { f, lo, hi };
    let solver = match NelderMead::new(simplex).with_sd_tolerance(1e-10) {
        Ok(s) => s,
        Err(_) => return fallback,
    };
    let result = Executor::new(problem, solver)
        .configure(|state| state.max_iters(max_iters))
        .run();
    match result {
        Ok(res) => {
            let state = res.state();
            let best: Vec<f64> = state
                .get_best_param()
                .map(|p| {
                    p.iter()
                        .zip(lo.iter().zip(hi))
                        .map(|(&v, (&l, &h))| v.clamp(l, h))
                        .collect()
                })
                .unwrap_or_else(|| start.clone());
            let cost = f(&best);
            if cost <= fallback.1 {
                (best, cost)
            } else {
                fallback
            }
        }
        Err(_) => fallback,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_minimum_of_a_bowl() {
        let f = |x: &[f64]| (x[0] - 1.5).powi(2) + 3.0 * (x[1] + 0.5).powi(2);
        let (x, y) = minimize(&f, &[0.0, 0.0], &[-5.0, -5.0], &[5.0, 5.0], 400);
        assert!(
            (x[0] - 1.5).abs() < 1e-3 && (x[1] + 0.5).abs() < 1e-3,
            "{x:?}"
        );
        assert!(y < 1e-5);
    }

    #[test]
    fn stays_inside_the_box() {
        let f = |x: &[f64]| (x[0] - 10.0).powi(2);
        let (x, _) = minimize(&f, &[0.0], &[-1.0], &[2.0], 200);
        assert!((x[0] - 2.0).abs() < 1e-3, "{x:?}");
    }

    #[test]
    fn never_returns_worse_than_the_start() {
        let f = |x: &[f64]| if x[0] == 0.3 { 0.0 } else { 1.0 };
        let (x, y) = minimize(&f, &[0.3], &[0.0], &[1.0], 50);
        assert_eq!((x[0], y), (0.3, 0.0));
    }
}
