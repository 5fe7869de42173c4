//! Refits: move a few knobs of the composed valve to fit the fit blocks, with identification's
//! parameter mapping ([`ParamDef`]) and Nelder-Mead ([`search::nelder_mead`]).
//!
//! A refit starts from the knobs' values (or from spread starts) and searches the unit cube of
//! their boxes, on a log scale for knobs whose box spans more than a factor of 20 (gains, times,
//! speeds). Refits are where diagnosis spends its time, so a candidate with several starts is
//! refitted by successive halving: every start gets a short search, and only the best start a
//! long one. The fitted baseline (an FOPDT with what a healthy positioner has) is a refit too.
//!
//! Not here: which knobs an effect frees ([`super::candidates`]) or whether a refit is kept
//! ([`super::judge`]).

use rayon::prelude::*;

use super::facts::Facts;
use super::scorer::{Errors, Scorer};
use crate::fit::params::ParamDef;
use crate::fit::search;
use vb_core::metrics::stats;
use vb_core::model::composed::{self, Knob, FASTEST_PCT_PER_S};
use vb_core::model::{FopdtParams, ModelKind, ModelSpec};

/// Largest dead time a healthy positioner is allowed in the fitted baseline, s.
pub const NOMINAL_DEAD_TIME_S: f64 = 0.2;
/// Slowest stroke speed the fitted baseline may use, %/s (full stroke in 2.5 s).
pub const NOMINAL_MIN_SLEW_PCT_PER_S: f64 = 40.0;
/// Edge of a refit's initial simplex, as a share of each knob's (possibly logarithmic) range.
const REFIT_STEP: f64 = 0.2;
/// Simplex iterations every start of a candidate gets, and then the best start.
const SURVEY_ITERS: u64 = 40;
const REFINE_ITERS: u64 = 120;
/// Simplex iterations of each start of the baseline fit.
const BASELINE_ITERS: u64 = 150;

/// A knob to fit: its box and scale, and where the search starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Free {
    pub knob: Knob,
    pub def: ParamDef,
    pub init: f64,
}

impl Free {
    /// `knob` searched in `lo..=hi` from `init`.
    pub(super) fn new(knob: Knob, lo: f64, hi: f64, init: f64) -> Self {
        Free {
            knob,
            def: ParamDef::new(knob.label(), knob.unit(), lo, hi),
            init,
        }
    }

    /// The same knob and box, starting at `init`.
    pub(super) fn from(self, init: f64) -> Self {
        Free { init, ..self }
    }

    /// Whether `other` frees the same knob in the same box.
    pub(super) fn same_box(&self, other: &Free) -> bool {
        self.knob == other.knob && self.def.lo == other.def.lo && self.def.hi == other.def.hi
    }
}

/// The positioner gain P_k of `spec`, free between a very slow positioner and one that closes
/// the error in one sample.
pub(crate) fn free_gain(spec: &ModelSpec, dt: f64) -> Free {
    Free::new(Knob::Gain, 0.05, 1.0 / dt, composed::get(spec, Knob::Gain))
}

/// `spec` with the `free` knobs set to the unit-cube point `u`.
fn build(spec: &ModelSpec, free: &[Free], u: &[f64]) -> ModelSpec {
    let mut s = spec.clone();
    for (f, &v) in free.iter().zip(u) {
        composed::set(&mut s, f.knob, f.def.from_unit(v));
    }
    s
}

/// Which fit error a refit minimises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Stage {
    /// Every other fit block: the short survey of a candidate's starts.
    Survey,
    /// Every fit block.
    Fit,
}

/// Refits the `free` knobs of `spec` to the fit blocks (of `stage`) from their `init` values
/// with a simplex of edge `step` for at most `iters` iterations; returns the refitted spec and
/// its errors over the whole recording.
pub(crate) fn refit(
    scorer: &Scorer,
    spec: &ModelSpec,
    free: &[Free],
    (step, iters): (f64, u64),
    stage: Stage,
) -> (ModelSpec, Errors) {
    let u0: Vec<f64> = free.iter().map(|f| f.def.to_unit(f.init)).collect();
    let cost = |u: &[f64]| {
        let s = build(spec, free, u);
        match stage {
            Stage::Survey => scorer.survey_error(&s),
            Stage::Fit => scorer.fit_error(&s),
        }
    };
    let local = search::nelder_mead(&cost, &u0, step, iters);
    let best = build(spec, free, &local.best.u);
    let errors = scorer.errors(&best);
    (best, errors)
}

/// Refits a candidate from several starts by successive halving: every start gets a short
/// search on every other fit block, and only the best one (by the fit error of the whole
/// simulation) is searched further on all of them, from where it ended with a smaller simplex.
/// Most starts of a multi-modal candidate are plainly worse after a few dozen iterations.
pub(crate) fn refit_from(
    scorer: &Scorer,
    spec: &ModelSpec,
    starts: &[Vec<Free>],
) -> (ModelSpec, Errors) {
    let surveyed = starts
        .par_iter()
        .map(|free| {
            let surveyed = refit(
                scorer,
                spec,
                free,
                (REFIT_STEP, SURVEY_ITERS),
                Stage::Survey,
            );
            (free, surveyed)
        })
        .min_by(|a, b| a.1 .1.fit.total_cmp(&b.1 .1.fit));
    let Some((free, (best, errors))) = surveyed else {
        return (spec.clone(), scorer.errors(spec));
    };
    let (refined, refined_errors) = refit(
        scorer,
        &best,
        &starting_at(free, &best),
        (REFIT_STEP / 2.0, REFINE_ITERS),
        Stage::Fit,
    );
    if refined_errors.fit <= errors.fit {
        (refined, refined_errors)
    } else {
        (best, errors)
    }
}

/// The knobs of `free`, each starting at its value in `spec`.
pub(crate) fn starting_at(free: &[Free], spec: &ModelSpec) -> Vec<Free> {
    free.iter()
        .map(|f| f.from(composed::get(spec, f.knob)))
        .collect()
}

/// The knobs from their own starts and from two more spread over their boxes (a tenth and two
/// fifths of the way, on each knob's scale): stick-slip, backlash and dead time make the error
/// surface multi-modal.
pub(crate) fn spread_starts(variant: Vec<Free>) -> Vec<Vec<Free>> {
    let moved = |share: f64| {
        variant
            .iter()
            .map(|f| f.from(f.def.from_unit(share)))
            .collect::<Vec<_>>()
    };
    vec![moved(0.1), moved(0.4), variant]
}

/// The nominal FOPDT baseline: unity gain, a dead time up to [`NOMINAL_DEAD_TIME_S`], a stroke
/// speed of at least [`NOMINAL_MIN_SLEW_PCT_PER_S`], fitted from two starts (the slew limit
/// near the observed speed, and as fast as allowed).
pub(crate) fn fit_baseline(scorer: &Scorer, facts: &Facts) -> ModelSpec {
    let dt = scorer.dt;
    let same: Vec<f64> = facts
        .steps
        .iter()
        .filter(|s| !s.reversal)
        .map(|s| s.delay_s)
        .collect();
    let td0 = stats::median(&same).unwrap_or(0.1).min(NOMINAL_DEAD_TIME_S) * 0.5;
    let start = composed::compose(
        &ModelSpec {
            fopdt: Some(FopdtParams {
                time_constant_s: 0.3,
            }),
            ..ModelSpec::bare(ModelKind::Fopdt, td0)
        },
        dt,
    );
    let slew = Free::new(
        Knob::Slew,
        NOMINAL_MIN_SLEW_PCT_PER_S,
        FASTEST_PCT_PER_S,
        facts
            .open_speed
            .max(facts.close_speed)
            .max(NOMINAL_MIN_SLEW_PCT_PER_S)
            * 1.2,
    );
    let free = [
        free_gain(&start, dt),
        Free::new(Knob::DeadTime, 0.0, NOMINAL_DEAD_TIME_S, td0),
        slew,
    ];
    let starts = [free, [free[0], free[1], slew.from(FASTEST_PCT_PER_S)]];
    starts
        .par_iter()
        .map(|f| refit(scorer, &start, f, (REFIT_STEP, BASELINE_ITERS), Stage::Fit))
        .min_by(|a, b| a.1.fit.total_cmp(&b.1.fit))
        .map(|(s, _)| s)
        .unwrap_or(start)
}
