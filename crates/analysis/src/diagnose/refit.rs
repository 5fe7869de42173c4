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
/// Share of the fit error within which a lower stop wind-up fits as well ([`least_windup`]):
/// far below the differences a refit keeps (a thousandth), above the rounding of sums.
const WINDUP_FLAT_SHARE: f64 = 1e-6;
/// Halvings of [`least_windup`]'s search: its box (400 %) to a tenth of a per cent.
const WINDUP_HALVINGS: usize = 12;

/// A knob to fit: its box and scale, and where the search starts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Free {
    pub knob: Knob,
    pub def: ParamDef,
    pub init: f64,
    /// The least value the knob is given wherever the search goes (the box's lower edge
    /// unless [`Free::at_least`] raised it): below it the fit error is flat, and the search
    /// over the box is the same as without it wherever it stays above.
    pub floor: f64,
}

impl Free {
    /// `knob` searched in `lo..=hi` from `init`.
    pub(super) fn new(knob: Knob, lo: f64, hi: f64, init: f64) -> Self {
        Free {
            knob,
            def: ParamDef::new(knob.label(), knob.unit(), lo, hi),
            init,
            floor: lo,
        }
    }

    /// The same knob and box, starting at `init`.
    pub(super) fn from(self, init: f64) -> Self {
        Free { init, ..self }
    }

    /// The same knob and box, never given less than `floor` (nor started below it).
    pub(super) fn at_least(self, floor: f64) -> Self {
        let floor = floor.max(self.def.lo);
        Free {
            floor,
            init: self.init.max(floor),
            ..self
        }
    }

    /// Whether `other` frees the same knob in the same box, with the same floor.
    pub(super) fn same_box(&self, other: &Free) -> bool {
        self.knob == other.knob
            && self.def.lo == other.def.lo
            && self.def.hi == other.def.hi
            && self.floor == other.floor
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
        composed::set(&mut s, f.knob, f.def.from_unit(v).max(f.floor));
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
    let (fitted, fitted_errors) = if refined_errors.fit <= errors.fit {
        (refined, refined_errors)
    } else {
        (best, errors)
    };
    if free.iter().any(|f| f.knob == Knob::Windup) {
        least_windup(scorer, fitted, fitted_errors)
    } else {
        (fitted, fitted_errors)
    }
}

/// `spec` with its stop wind-up lowered to the least that fits the fit blocks as well (within
/// [`WINDUP_FLAT_SHARE`] of their error `errors.fit`), found by halving. The drive winds up
/// only while V_P is held at the stop, so a wind-up beyond what the fit blocks' stays at the
/// stop reach changes none of their simulations: the search leaves it wherever it drifted, up
/// to its box, and a longer stay in a held-out block would then keep the model at the stop long
/// after the valve left it. The least wind-up the fit blocks allow is the most they measure.
/// Where they measure none (a wind-up of zero fits them as well), the search's value stays: no
/// lower value is any better founded.
fn least_windup(scorer: &Scorer, spec: ModelSpec, errors: Errors) -> (ModelSpec, Errors) {
    let target = errors.fit * (1.0 + WINDUP_FLAT_SHARE);
    let with = |w: f64| {
        let mut s = spec.clone();
        composed::set(&mut s, Knob::Windup, w);
        s
    };
    let fits = |w: f64| scorer.fit_error(&with(w)) <= target;
    let (mut lo, mut hi) = (0.0, composed::get(&spec, Knob::Windup));
    if hi <= 0.0 || fits(lo) {
        return (spec, errors);
    }
    for _ in 0..WINDUP_HALVINGS {
        let mid = 0.5 * (lo + hi);
        if fits(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let least = with(hi);
    let least_errors = scorer.errors(&least);
    (least, least_errors)
}

/// The knobs of `free`, each starting at its value in `spec`.
pub(crate) fn starting_at(free: &[Free], spec: &ModelSpec) -> Vec<Free> {
    free.iter()
        .map(|f| f.from(composed::get(spec, f.knob)))
        .collect()
}

/// The time constant a positioner's fit starts from, s: a healthy positioner's.
pub(crate) const START_TIME_CONSTANT_S: f64 = 0.3;

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
                time_constant_s: START_TIME_CONSTANT_S,
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

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::bundled;
    use vb_core::testkit::{answer, Columns};

    #[test]
    fn a_wind_up_beyond_what_the_fit_blocks_reach_is_lowered_to_that_reach() {
        // 600 s at 100 Hz (blocks of 30 s, fit and held out in turn): O_P at 50 %, and in each
        // block at 0 %, below the valve's 20 % stop, for 20 s in the fit blocks and for 1 s in
        // the held-out ones. The valve's drive may wind up 100 % past the stop; the long stays
        // wind it up to most of that, and any wind-up from there up fits the fit blocks alike.
        let dt = 0.01;
        let op: Vec<f64> = (0..60_000)
            .map(|k| {
                let stay = if (k / 3000) % 2 == 0 { 2000 } else { 100 };
                if (500..500 + stay).contains(&(k % 3000)) {
                    0.0
                } else {
                    50.0
                }
            })
            .collect();
        let mut truth = composed::compose(&bundled(ModelKind::Fopdt), dt);
        composed::set(&mut truth, Knob::TravelMin, 20.0);
        composed::set(&mut truth, Knob::Slew, 20.0);
        composed::set(&mut truth, Knob::Windup, 100.0);
        let rec = Columns::new(op.clone(), answer(&truth, &op, dt), dt);
        let scorer = Scorer::new(&rec.view());
        // A search that drifted the wind-up to 390 %: the fit blocks cannot tell, the short
        // stays of the held-out blocks can.
        let mut drifted = truth.clone();
        composed::set(&mut drifted, Knob::Windup, 390.0);
        let before = scorer.errors(&drifted);
        assert!(before.fit < 1e-9 && before.held > 1e6, "{before:?}");
        let (least, after) = least_windup(&scorer, drifted, before);
        let w = composed::get(&least, Knob::Windup);
        let fit_at = |w: f64| {
            let mut s = least.clone();
            composed::set(&mut s, Knob::Windup, w);
            scorer.fit_error(&s)
        };
        assert!(w > 50.0 && w <= 100.0, "{w}");
        assert!(
            fit_at(w - 0.2) > before.fit * (1.0 + WINDUP_FLAT_SHARE),
            "{w}"
        );
        assert!(
            after.fit <= before.fit * (1.0 + WINDUP_FLAT_SHARE),
            "{after:?}"
        );
        assert!(after.held < 0.01 * before.held, "{after:?}");
        // Below that reach the fit blocks see the wind-up: it stays (within what changes their
        // error by less than the flat share).
        let mut short = truth.clone();
        composed::set(&mut short, Knob::Windup, 50.0);
        let (kept, _) = least_windup(&scorer, short.clone(), scorer.errors(&short));
        let kept = composed::get(&kept, Knob::Windup);
        assert!((kept - 50.0).abs() < 0.5, "{kept}");
        // Fit blocks that never reach the stop measure no wind-up: the search's value stays.
        let blind: Vec<f64> = (op.iter().enumerate())
            .map(|(k, &u)| if (k / 3000) % 2 == 0 { 50.0 } else { u })
            .collect();
        let rec = Columns::new(blind.clone(), answer(&truth, &blind, dt), dt);
        let scorer = Scorer::new(&rec.view());
        let mut guessed = truth.clone();
        composed::set(&mut guessed, Knob::Windup, 47.0);
        let (kept, _) = least_windup(&scorer, guessed.clone(), scorer.errors(&guessed));
        assert_eq!(composed::get(&kept, Knob::Windup), 47.0);
    }
}
