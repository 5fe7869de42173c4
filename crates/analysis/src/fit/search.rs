//! Derivative-free search in a box: a Latin hypercube for the global stage, argmin's
//! Nelder-Mead for the local one, both in the unit cube of a [`Layout`].
//!
//! Backlash, stick-slip and dead time make the simulation error piecewise smooth at best, with
//! plateaus and kinks, so no gradients are used. The scheme is the classic multistart: sample
//! the physically bounded box (plus the physical seeds) on a cheap, decimated problem, keep
//! the best few distinct points, and polish each with a simplex on the full problem, in
//! parallel. The hypercube is written here (a dozen lines) because it needs nothing more than
//! a shuffled stratum per axis; argmin's particle swarm was the alternative, but its budget is
//! spent in sequential generations and it starts from random points only, while this scheme
//! spends evaluations where the seeds and the coarse survey point, and parallelises every
//! stage with rayon.
//!
//! argmin's Nelder-Mead knows no bounds: the cost clamps each trial point into the cube and
//! adds a penalty for the distance outside, which keeps the simplex inside without moving the
//! optimum.
//!
//! Not here: what is minimised (any `Fn(&[f64]) -> f64` over the unit cube).

use std::cell::{Cell, RefCell};

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::neldermead::NelderMead;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A point of the unit cube and its cost.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// Unit-cube coordinates.
    pub u: Vec<f64>,
    /// Cost there.
    pub cost: f64,
}

/// `n` points of a Latin hypercube in `[0, 1]^d`: each axis cut into `n` strata, one point in
/// each, strata paired at random. Deterministic for a given `seed`.
pub fn latin_hypercube(n: usize, d: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut pts = vec![vec![0.0; d]; n];
    for j in 0..d {
        let mut strata: Vec<usize> = (0..n).collect();
        strata.shuffle(&mut rng);
        for (p, s) in pts.iter_mut().zip(strata) {
            p[j] = (s as f64 + rng.gen::<f64>()) / n as f64;
        }
    }
    pts
}

/// Evaluates `f` at every point in parallel and returns them sorted, best first (non-finite
/// costs last).
pub fn survey<F: Fn(&[f64]) -> f64 + Sync>(f: &F, points: Vec<Vec<f64>>) -> Vec<Scored> {
    let mut out: Vec<Scored> = points
        .into_par_iter()
        .map(|u| {
            let cost = f(&u);
            Scored { u, cost }
        })
        .collect();
    out.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    out
}

/// The best `k` points of a sorted survey that lie at least `min_dist` (max-norm in the unit
/// cube) from every point already picked, so the local searches start in different basins.
pub fn distinct_best(sorted: &[Scored], k: usize, min_dist: f64) -> Vec<Scored> {
    let mut picked: Vec<Scored> = Vec::with_capacity(k);
    for s in sorted {
        if picked.len() == k {
            break;
        }
        if !s.cost.is_finite() {
            continue;
        }
        let far = picked.iter().all(|p| {
            p.u.iter()
                .zip(&s.u)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
                >= min_dist
        });
        if far {
            picked.push(s.clone());
        }
    }
    picked
}

/// The cost on the unit cube, clamped, with a penalty for leaving it; counts evaluations.
/// Remembers the cost of every point of the cube it was evaluated at: the simplex starts at a
/// point already evaluated, trial points outside the cube can clamp to the same point, and the
/// best point is evaluated once more at the end. A cost is a whole simulation, a look-up a few
/// comparisons.
struct Boxed<'a, F> {
    f: &'a F,
    evals: Cell<usize>,
    seen: RefCell<Vec<Scored>>,
}

impl<F: Fn(&[f64]) -> f64> Boxed<'_, F> {
    /// `f` at the point `u` of the cube, evaluated once per point.
    fn at(&self, u: Vec<f64>) -> Scored {
        // The same bits: a point is the same point (-0 and 0 are two).
        let same = |s: &&Scored| {
            s.u.iter()
                .map(|x| x.to_bits())
                .eq(u.iter().map(|x| x.to_bits()))
        };
        if let Some(s) = self.seen.borrow().iter().find(same) {
            return s.clone();
        }
        let s = Scored {
            cost: (self.f)(&u),
            u,
        };
        self.seen.borrow_mut().push(s.clone());
        s
    }
}

impl<F: Fn(&[f64]) -> f64> CostFunction for Boxed<'_, F> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Self::Param) -> Result<f64, Error> {
        self.evals.set(self.evals.get() + 1);
        let mut outside = 0.0;
        let clamped: Vec<f64> = x
            .iter()
            .map(|&v| {
                let c = v.clamp(0.0, 1.0);
                outside += (v - c).abs();
                c
            })
            .collect();
        let y = self.at(clamped).cost;
        Ok(if y.is_finite() {
            y * (1.0 + outside) + outside
        } else {
            f64::MAX
        })
    }
}

/// Result of a local search.
#[derive(Debug, Clone, PartialEq)]
pub struct Local {
    /// Best point found (inside the cube) and its cost.
    pub best: Scored,
    /// Cost evaluations the search asked for (a point asked for again is looked up, not
    /// simulated again, and still counts).
    pub evals: usize,
}

/// Nelder-Mead from `start` in the unit cube with an initial simplex of edge `step` along each
/// axis (towards the interior), at most `max_iters` iterations. Never returns a point worse
/// than the start.
pub fn nelder_mead<F: Fn(&[f64]) -> f64>(f: &F, start: &[f64], step: f64, max_iters: u64) -> Local {
    let start: Vec<f64> = start.iter().map(|v| v.clamp(0.0, 1.0)).collect();
    let problem = Boxed {
        f,
        evals: Cell::new(1),
        seen: RefCell::new(Vec::new()),
    };
    let fallback = problem.at(start.clone());
    if start.is_empty() || max_iters == 0 {
        return Local {
            best: fallback,
            evals: 1,
        };
    }
    let mut simplex = vec![start.clone()];
    for i in 0..start.len() {
        let mut p = start.clone();
        p[i] = if p[i] + step <= 1.0 {
            p[i] + step
        } else {
            p[i] - step
        };
        simplex.push(p);
    }
    let solver = match NelderMead::new(simplex).with_sd_tolerance(1e-12) {
        Ok(s) => s,
        Err(_) => {
            return Local {
                best: fallback,
                evals: 1,
            }
        }
    };
    let result = Executor::new(problem, solver)
        .configure(|state| state.max_iters(max_iters))
        .run();
    let Ok(res) = result else {
        return Local {
            best: fallback,
            evals: 1,
        };
    };
    let problem = res.problem.problem.as_ref();
    let evals = problem.map_or(0, |p| p.evals.get());
    let best = res.state().get_best_param().map(|p| {
        let u: Vec<f64> = p.iter().map(|v| v.clamp(0.0, 1.0)).collect();
        match problem {
            Some(problem) => problem.at(u),
            None => Scored { cost: f(&u), u },
        }
    });
    match best {
        Some(b) if b.cost <= fallback.cost => Local {
            best: b,
            evals: evals + 1,
        },
        _ => Local {
            best: fallback,
            evals: evals + 1,
        },
    }
}

/// One sweep over the axes: for each coordinate in turn, try `points` evenly spaced values over
/// the whole unit interval (in parallel) with the other coordinates held, and keep the best.
/// Finds the valleys a simplex misses when it sits on a plateau of one parameter (a gain so
/// large that the valve is rate-limited everywhere, say). Returns the point and evaluations.
pub fn axis_sweep<F: Fn(&[f64]) -> f64 + Sync>(
    f: &F,
    start: &Scored,
    points: usize,
) -> (Scored, usize) {
    let mut best = start.clone();
    let mut evals = 0;
    for i in 0..best.u.len() {
        let trials: Vec<Vec<f64>> = (0..points)
            .map(|j| {
                let mut u = best.u.clone();
                u[i] = (j as f64 + 0.5) / points as f64;
                u
            })
            .collect();
        evals += trials.len();
        if let Some(s) = survey(f, trials).into_iter().next() {
            if s.cost < best.cost {
                best = s;
            }
        }
    }
    (best, evals)
}

/// Polishes every start with [`nelder_mead`] in parallel; returns all results, best first.
pub fn polish<F: Fn(&[f64]) -> f64 + Sync>(
    f: &F,
    starts: &[Vec<f64>],
    step: f64,
    max_iters: u64,
) -> Vec<Local> {
    let mut out: Vec<Local> = starts
        .par_iter()
        .map(|s| nelder_mead(f, s, step, max_iters))
        .collect();
    out.sort_by(|a, b| a.best.cost.total_cmp(&b.best.cost));
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hypercube_has_one_point_per_stratum() {
        let pts = latin_hypercube(20, 3, 7);
        for j in 0..3 {
            let mut s: Vec<usize> = pts.iter().map(|p| (p[j] * 20.0) as usize).collect();
            s.sort();
            assert_eq!(s, (0..20).collect::<Vec<_>>());
        }
    }

    #[test]
    fn multistart_finds_the_global_minimum_of_a_two_basin_function() {
        // Shallow basin at 0.2, deep one at 0.8 (per axis).
        let f = |u: &[f64]| {
            let a: f64 = u.iter().map(|v| (v - 0.2).powi(2)).sum::<f64>();
            let b: f64 = u.iter().map(|v| (v - 0.8).powi(2)).sum::<f64>();
            (a + 0.05).min(b)
        };
        let s = survey(&f, latin_hypercube(30, 2, 1));
        let starts: Vec<Vec<f64>> = distinct_best(&s, 3, 0.1).into_iter().map(|s| s.u).collect();
        let best = &polish(&f, &starts, 0.1, 200)[0];
        assert!(best.best.cost < 1e-8, "{best:?}");
        assert!(best.best.u.iter().all(|v| (v - 0.8).abs() < 1e-3));
        assert!(best.evals > 10);
    }

    #[test]
    fn axis_sweep_leaves_a_plateau() {
        // Flat for u[0] > 0.3, a narrow valley at 0.1.
        let f = |u: &[f64]| {
            if u[0] > 0.3 {
                1.0
            } else {
                (u[0] - 0.1).abs() + (u[1] - 0.5).powi(2)
            }
        };
        let start = Scored {
            u: vec![0.8, 0.2],
            cost: 1.0,
        };
        let (b, evals) = axis_sweep(&f, &start, 20);
        assert!(b.cost < 0.2 && (b.u[0] - 0.1).abs() < 0.03, "{b:?}");
        assert_eq!(evals, 40);
    }

    #[test]
    fn local_search_stays_in_the_cube_and_never_worsens() {
        let f = |u: &[f64]| (u[0] - 3.0).powi(2);
        let r = nelder_mead(&f, &[0.5], 0.2, 100);
        assert!((r.best.u[0] - 1.0).abs() < 1e-6);
        let flat = |u: &[f64]| if u[0] == 0.3 { 0.0 } else { 1.0 };
        let r = nelder_mead(&flat, &[0.3], 0.2, 20);
        assert_eq!(r.best.cost, 0.0);
    }

    #[test]
    fn a_point_asked_for_again_is_not_evaluated_again() {
        // The start (first vertex of the simplex) and the best point at the end are asked for
        // twice, and trial points beyond the cube's edge clamp onto the same point.
        let calls = Cell::new(0);
        let f = |u: &[f64]| {
            calls.set(calls.get() + 1);
            (u[0] - 3.0).powi(2) + (u[1] - 0.5).powi(2)
        };
        let r = nelder_mead(&f, &[0.5, 0.2], 0.2, 60);
        assert!((r.best.u[0] - 1.0).abs() < 1e-6, "{r:?}");
        assert!(calls.get() + 2 <= r.evals, "{} of {}", calls.get(), r.evals);
    }
}
