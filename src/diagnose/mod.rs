//! Diagnose: find where a model and a recording differ, name the physics the model left out,
//! add it, and show on held-out data that the fit improved.
//!
//! 1. **Baseline**: the user's model, or an FOPDT with unity gain fitted here. The fitted FOPDT
//!    may use what every healthy positioner has: a dead time up to 0.2 s and a stroke-speed
//!    limit no slower than 40 %/s (full stroke in 2.5 s); anything beyond is a finding.
//! 2. **Locate** ([`locate`]): noise floor of V_P, and the windows where the residual stands
//!    above it, each tied to what O_P and V_P were doing.
//! 3. **Explain and extend**: every effect of the vocabulary ([`Effect`]) is a few numbers of a
//!    composed pin-cart II valve ([`composed`]). Each candidate is added, refitted from a warm
//!    start (with the base gain and dead time), and kept only if, on **held-out** blocks that
//!    were never fitted, it lowers the error by more than chance (paired test over blocks), by
//!    a real share of the error above the noise floor, and BIC agrees. The best candidate wins
//!    a round; rounds repeat until nothing passes, so several effects can be found.
//!    Stick-slip that hunts is a limit cycle whose phase O_P does not set, which free-run
//!    error cannot judge: when nothing passes, it is judged by the slips of V_P instead
//!    (`stickslip`), and a finding there ends the search.
//! 4. **Report**: evidence a person can follow, before/after Table 1 rows on held-out data,
//!    the windows before and after, the final model, and a verdict that says so when nothing is
//!    missing, or which experiment would separate two effects the data cannot tell apart.
//!
//! The split alternates blocks (fit, held out, fit, ...) so both halves cover every operating
//! region. Judging simulates the whole recording and scores the held-out blocks; refits
//! simulate only the fit blocks, each from the measured position a few seconds before it.
//!
//! Time goes into refits, so they are spent where they matter: every start of a candidate
//! gets a short search and only the best start a long one (successive halving), an effect that
//! helped next to nothing is not tried again, and after each kept effect everything kept so
//! far is refitted together, so a later effect can take back what an earlier one was stretched
//! to cover. Effects stay apart: an opening-dependent slowdown may not bring the stroke speed
//! at half travel below a healthy one until `slew_rate` has been found on its own.

pub mod composed;
pub mod evidence;
pub mod locate;
mod stickslip;

use rayon::prelude::*;
use serde::Serialize;

use crate::fit;
use crate::metrics::{self, Scores};
use crate::model::{FopdtParams, ModelKind, ModelSpec, Valve};
pub use composed::Effect;
use composed::{Knob, FASTEST_PCT_PER_S};
use evidence::Facts;
use locate::{Context, Window};

/// Largest dead time a healthy positioner is allowed in the fitted baseline, s.
pub const NOMINAL_DEAD_TIME_S: f64 = 0.2;
/// Slowest stroke speed the fitted baseline may use, %/s (full stroke in 2.5 s).
pub const NOMINAL_MIN_SLEW_PCT_PER_S: f64 = 40.0;
/// Most effects one diagnosis adds.
const ROUNDS: usize = 4;
/// Edge of a refit's initial simplex, as a share of each knob's (possibly logarithmic) range.
const REFIT_STEP: f64 = 0.2;
/// An effect whose best refit removed less held-out error than this share of what remains
/// after the round's winner is not tried again: to be kept next round it would have to remove
/// twenty times as much (a tenth of the excess), and each round refits every candidate on the
/// whole recording.
const RETRY_SHARE: f64 = 0.005;
/// Simulated time before each fit block when refits simulate the fit blocks alone, s: longer
/// than the longest dead time a diagnosis fits (3 s).
const WARM_UP_S: f64 = 10.0;
/// Simplex iterations every start of a candidate gets, and then the best start.
const SURVEY_ITERS: u64 = 40;
const REFINE_ITERS: u64 = 120;

/// The starting point, scored.
#[derive(Debug, Clone, Serialize)]
pub struct Baseline {
    pub model: String,
    pub heldout_sse: f64,
    pub sse: f64,
    #[serde(skip)]
    pub spec: ModelSpec,
}

/// One effect found and kept.
#[derive(Debug, Clone, Serialize)]
pub struct Finding {
    pub effect: Effect,
    pub evidence: String,
    pub params: serde_json::Map<String, serde_json::Value>,
    pub heldout_sse_before: f64,
    pub heldout_sse_after: f64,
    pub delta_bic: f64,
}

/// The model diagnosis ends with.
#[derive(Debug, Clone, Serialize)]
pub struct Final {
    pub model: String,
    pub heldout_sse: f64,
    pub params: serde_json::Value,
    #[serde(skip)]
    pub spec: ModelSpec,
}

/// Table 1 rows on the held-out blocks, before and after.
#[derive(Debug, Clone)]
pub struct Comparison {
    pub before: Scores,
    pub after: Scores,
}

/// Everything a diagnosis found, in the shape of `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnosis {
    pub baseline: Baseline,
    pub noise_floor_pct: f64,
    pub mismatch_windows: Vec<Window>,
    pub findings: Vec<Finding>,
    #[serde(rename = "final")]
    pub final_model: Final,
    pub verdict: String,
    /// Windows left after the final model.
    #[serde(skip)]
    pub windows_after: Vec<Window>,
    #[serde(skip)]
    pub heldout: Option<Comparison>,
    /// Simulated V_P of the baseline and the final model, for plots.
    #[serde(skip)]
    pub sim_before: Vec<f64>,
    #[serde(skip)]
    pub sim_after: Vec<f64>,
    /// Notes on what the data could not tell apart, and what experiment would.
    pub notes: Vec<String>,
    /// The step responses measured in the recording (evidence for delays).
    #[serde(skip)]
    pub steps: Vec<evidence::StepResponse>,
}

/// Errors that stop a diagnosis.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("the recording has {0} samples: diagnosis needs at least 20 s of data")]
    TooShort(usize),
    #[error(
        "the recording has no measured V_P column: diagnosis compares a model to measurements"
    )]
    NoPosition,
    #[error("the starting model cannot run: {0}")]
    Model(#[from] crate::model::ModelError),
}

/// The data a refit scores against: O_P, V_P and the alternating fit / held-out blocks.
struct Scorer<'a> {
    op: &'a [f64],
    vp: &'a [f64],
    dt: f64,
    /// Block index of each sample; even blocks are fitted, odd ones held out.
    block_len: usize,
    /// Samples at the start left out of all scoring (initial transient).
    skip: usize,
    n_blocks: usize,
}

/// Fit and held-out error of one simulation.
struct Errors {
    fit: f64,
    held: f64,
}

impl Scorer<'_> {
    fn held(&self, k: usize) -> bool {
        k >= self.skip && (k / self.block_len) % 2 == 1
    }

    /// Fit error alone, what refits minimise: each fit block is simulated on its own, from
    /// rest at the measured V_P [`WARM_UP_S`] before the block, so the held-out blocks between
    /// them are never simulated (half the work). The warm-up fills the dead-time line and lets
    /// the start from rest die out; hysteresis that outlives it (a pin left off-centre) costs
    /// the fit a little, never the judgement, which simulates the whole recording.
    fn fit_error(&self, spec: &ModelSpec) -> f64 {
        let Ok(mut valve) = Valve::new(spec, self.dt) else {
            return f64::INFINITY;
        };
        let warm = (WARM_UP_S / self.dt) as usize;
        let mut sum = 0.0;
        for b in (0..self.n_blocks).step_by(2) {
            let start = b * self.block_len;
            let end = (start + self.block_len).min(self.op.len());
            let from = start.saturating_sub(warm);
            valve.reset(self.op[from], self.vp[from]);
            for k in from..start {
                valve.step(self.op[k]);
            }
            let first = start.max(self.skip);
            for k in start..end {
                let y = valve.step(self.op[k]);
                if k >= first {
                    sum += (self.vp[k] - y) * (self.vp[k] - y);
                }
            }
        }
        sum
    }

    /// Fit and held-out error of `spec` simulated over the whole recording.
    fn errors(&self, spec: &ModelSpec) -> Errors {
        let Ok(mut valve) = Valve::new(spec, self.dt) else {
            return Errors {
                fit: f64::INFINITY,
                held: f64::INFINITY,
            };
        };
        valve.reset(self.op[0], self.vp[0]);
        self.errors_of(self.op.iter().map(|&u| valve.step(u)))
    }

    /// Fit and held-out error of a simulated V_P, sample by sample from the first.
    fn errors_of(&self, sim: impl Iterator<Item = f64>) -> Errors {
        let mut sums = [0.0, 0.0];
        for (k, (&m, y)) in self.vp.iter().zip(sim).enumerate() {
            if k >= self.skip {
                sums[(k / self.block_len) % 2] += (m - y) * (m - y);
            }
        }
        Errors {
            fit: sums[0],
            held: sums[1],
        }
    }

    /// Per held-out block: the drop in squared error from `a` to `b`, and the sum of squared
    /// differences between the two simulations (what sets the noise of that drop).
    fn paired(&self, a: &ModelSpec, b: &ModelSpec) -> Vec<(f64, f64)> {
        let mut out = vec![(0.0, 0.0); self.n_blocks.div_ceil(2)];
        let (Ok(mut va), Ok(mut vb)) = (Valve::new(a, self.dt), Valve::new(b, self.dt)) else {
            return out;
        };
        va.reset(self.op[0], self.vp[0]);
        vb.reset(self.op[0], self.vp[0]);
        for (k, (&u, &m)) in self.op.iter().zip(self.vp).enumerate() {
            let (ya, yb) = (va.step(u), vb.step(u));
            if self.held(k) {
                let o = &mut out[k / self.block_len / 2];
                o.0 += (m - ya).powi(2) - (m - yb).powi(2);
                o.1 += (ya - yb).powi(2);
            }
        }
        out
    }

    fn simulate(&self, spec: &ModelSpec) -> Vec<f64> {
        match Valve::new(spec, self.dt) {
            Ok(mut v) => v.simulate(self.op, self.vp[0]),
            Err(_) => self.op.to_vec(),
        }
    }

    fn n_fit(&self) -> usize {
        (self.skip..self.op.len())
            .filter(|&k| !self.held(k))
            .count()
    }
}

/// A knob to fit with its box and starting value.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Free {
    knob: Knob,
    lo: f64,
    hi: f64,
    init: f64,
}

/// Refits `free` knobs of `spec` to the fit blocks; returns the refitted spec and its errors.
///
/// Knobs whose box spans more than a factor of 20 on the positive axis (gains, times, speeds)
/// are searched on a log scale, so the simplex moves in proportions rather than in steps that
/// are coarse for small values.
fn refit(
    scorer: &Scorer,
    spec: &ModelSpec,
    free: &[Free],
    step: f64,
    iters: u64,
) -> (ModelSpec, Errors) {
    // Each knob maps to a unit interval of the search cube, linearly or on a log scale.
    let log: Vec<bool> = free
        .iter()
        .map(|f| f.lo > 0.0 && f.hi / f.lo > 20.0)
        .collect();
    let to = |i: usize, v: f64| if log[i] { v.ln() } else { v };
    let span = |i: usize| (to(i, free[i].lo), to(i, free[i].hi));
    let from_unit = |i: usize, u: f64| {
        let (lo, hi) = span(i);
        let v = lo + u * (hi - lo);
        if log[i] {
            v.exp()
        } else {
            v
        }
    };
    let u0: Vec<f64> = free
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let (lo, hi) = span(i);
            (to(i, f.init.clamp(f.lo, f.hi)) - lo) / (hi - lo).max(f64::MIN_POSITIVE)
        })
        .collect();
    let build = |u: &[f64]| {
        let mut s = spec.clone();
        for (i, (f, &v)) in free.iter().zip(u).enumerate() {
            composed::set(&mut s, f.knob, from_unit(i, v).clamp(f.lo, f.hi));
        }
        s
    };
    let cost = |u: &[f64]| scorer.fit_error(&build(u));
    let local = fit::search::nelder_mead(&cost, &u0, step, iters);
    let best = build(&local.best.u);
    let errors = scorer.errors(&best);
    (best, errors)
}

/// Refits a candidate from several starts by successive halving: every start gets a short
/// search, and only the best one is searched further, from where it ended with a smaller
/// simplex. Most starts of a multi-modal candidate are plainly worse after a few dozen
/// iterations, and refits are where diagnosis spends its time.
fn refit_from(scorer: &Scorer, spec: &ModelSpec, starts: &[Vec<Free>]) -> (ModelSpec, Errors) {
    let surveyed = starts
        .par_iter()
        .map(|free| (free, refit(scorer, spec, free, REFIT_STEP, SURVEY_ITERS)))
        .min_by(|a, b| a.1 .1.fit.total_cmp(&b.1 .1.fit));
    let Some((free, (best, errors))) = surveyed else {
        return (spec.clone(), scorer.errors(spec));
    };
    let (refined, refined_errors) = refit(
        scorer,
        &best,
        &starting_at(free, &best),
        REFIT_STEP / 2.0,
        REFINE_ITERS,
    );
    if refined_errors.fit <= errors.fit {
        (refined, refined_errors)
    } else {
        (best, errors)
    }
}

/// The knobs of `free`, each starting at its value in `spec`.
fn starting_at(free: &[Free], spec: &ModelSpec) -> Vec<Free> {
    free.iter()
        .map(|f| Free {
            init: composed::get(spec, f.knob),
            ..*f
        })
        .collect()
}

/// The nominal FOPDT baseline: unity gain, dead time <= 0.2 s, stroke speed >= 40 %/s.
fn fit_baseline(scorer: &Scorer, facts: &Facts) -> ModelSpec {
    let dt = scorer.dt;
    let same: Vec<f64> = facts
        .steps
        .iter()
        .filter(|s| !s.reversal)
        .map(|s| s.delay_s)
        .collect();
    let td0 = median(&same).unwrap_or(0.1).min(NOMINAL_DEAD_TIME_S) * 0.5;
    let start = composed::compose(
        &ModelSpec {
            fopdt: Some(FopdtParams {
                time_constant_s: 0.3,
            }),
            ..ModelSpec::bare(ModelKind::Fopdt, td0)
        },
        dt,
    );
    let free = [
        Free {
            knob: Knob::Gain,
            lo: 0.05,
            hi: 1.0 / dt,
            init: composed::get(&start, Knob::Gain),
        },
        Free {
            knob: Knob::DeadTime,
            lo: 0.0,
            hi: NOMINAL_DEAD_TIME_S,
            init: td0,
        },
        Free {
            knob: Knob::Slew,
            lo: NOMINAL_MIN_SLEW_PCT_PER_S,
            hi: FASTEST_PCT_PER_S,
            init: facts
                .open_speed
                .max(facts.close_speed)
                .max(NOMINAL_MIN_SLEW_PCT_PER_S)
                * 1.2,
        },
    ];
    // Two starts: the slew limit near the observed speed, and as fast as allowed.
    let starts = [
        free,
        [
            free[0],
            free[1],
            Free {
                init: FASTEST_PCT_PER_S,
                ..free[2]
            },
        ],
    ];
    starts
        .par_iter()
        .map(|f| refit(scorer, &start, f, REFIT_STEP, 150))
        .min_by(|a, b| a.1.fit.total_cmp(&b.1.fit))
        .map(|(s, _)| s)
        .unwrap_or(start)
}

fn median(x: &[f64]) -> Option<f64> {
    if x.is_empty() {
        return None;
    }
    let mut v = x.to_vec();
    Some(evidence::percentile(&mut v, 0.5))
}

/// The variants to try for `effect` on top of `spec`, or none when it is already there or the
/// data cannot identify it.
fn candidates(
    effect: Effect,
    spec: &ModelSpec,
    facts: &Facts,
    op: &[f64],
    vp: &[f64],
    td_max: f64,
) -> Vec<Vec<Free>> {
    let get = |k| composed::get(spec, k);
    let f = |knob, lo: f64, hi: f64, init: f64| Free { knob, lo, hi, init };
    let slew = get(Knob::Slew);
    let half_open_slew = get(Knob::HalfOpenSlew);
    let speed = facts.open_speed.max(facts.close_speed).max(0.5);
    match effect {
        Effect::DeadTime if td_max < 3.0 => vec![vec![f(
            Knob::DeadTime,
            0.0,
            3.0,
            get(Knob::DeadTime).max(0.3),
        )]],
        Effect::Backlash if get(Knob::Crossing) == 0.0 => {
            vec![
                vec![f(Knob::Crossing, 0.02, 5.0, 0.2)],
                vec![f(Knob::Crossing, 0.02, 5.0, 0.8)],
            ]
        }
        Effect::StateDependentDelay
            if get(Knob::Slowdown) == 0.0 && get(Knob::CrossingSlope) == 0.0 =>
        {
            // The slowdown lowers the stroke speed with opening too, so the speed limit is
            // refitted with it (it may be faster near closed than the baseline's average).
            // Until a speed limit has been found, it stays a healthy one at half travel: a
            // valve slower than that is `slew_rate`, judged on its own.
            let limit = if half_open_slew >= NOMINAL_MIN_SLEW_PCT_PER_S {
                f(
                    Knob::HalfOpenSlew,
                    NOMINAL_MIN_SLEW_PCT_PER_S,
                    FASTEST_PCT_PER_S,
                    half_open_slew.min(FASTEST_PCT_PER_S),
                )
            } else {
                f(
                    Knob::Slew,
                    0.5,
                    FASTEST_PCT_PER_S,
                    (1.5 * slew).min(FASTEST_PCT_PER_S),
                )
            };
            let mut v = vec![vec![f(Knob::Slowdown, 0.0, 20.0, 1.0), limit]];
            let c = get(Knob::Crossing);
            if c > 0.0 {
                v.push(vec![
                    f(Knob::Crossing, 0.0, 5.0, c * 0.5),
                    f(Knob::CrossingSlope, -c / 100.0, 0.05, c / 100.0),
                ]);
            }
            v
        }
        Effect::SlewRate
            if half_open_slew >= NOMINAL_MIN_SLEW_PCT_PER_S
                && spec.effects.closing_slew_pct_per_s == 0.0 =>
        {
            vec![vec![f(
                Knob::Slew,
                0.5,
                slew.min(FASTEST_PCT_PER_S),
                speed.min(slew),
            )]]
        }
        Effect::Asymmetry if spec.effects.closing_slew_pct_per_s == 0.0 => vec![vec![
            f(
                Knob::Slew,
                0.5,
                FASTEST_PCT_PER_S,
                facts.open_speed.max(0.5),
            ),
            f(
                Knob::ClosingSlew,
                0.5,
                FASTEST_PCT_PER_S,
                facts.close_speed.max(0.5),
            ),
        ]],
        Effect::MinSpeed if get(Knob::MinSpeed) == 0.0 => {
            vec![vec![f(Knob::MinSpeed, 0.01, 2.0, 0.2)]]
        }
        // Stick-slip either on the valve's input (Choudhury) or inside the positioner loop
        // (breakaway: sticks when slow, slips past the target, hunts).
        Effect::Stiction if get(Knob::Stickband) == 0.0 && get(Knob::Breakaway) == 0.0 => vec![
            vec![
                f(Knob::Stickband, 0.05, 10.0, 0.5),
                f(Knob::JumpFraction, 0.0, 1.0, 0.5),
            ],
            vec![
                f(Knob::Stickband, 0.05, 10.0, 2.0),
                f(Knob::JumpFraction, 0.0, 1.0, 0.5),
            ],
            vec![f(Knob::Breakaway, 0.05, 10.0, 0.5)],
        ],
        Effect::Deadband if get(Knob::Deadband) == 0.0 => {
            vec![vec![f(Knob::Deadband, 0.02, 10.0, 0.5)]]
        }
        Effect::Saturation if spec.travel.min_pct == 0.0 && spec.travel.max_pct == 100.0 => {
            let (vmin, vmax) = vp
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            let (omin, omax) = op
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                    (a.min(x), b.max(x))
                });
            let mut free = Vec::new();
            if omax > vmax + 0.5 && vmax < 99.5 {
                free.push(f(Knob::TravelMax, (vmax - 2.0).max(50.0), 100.0, vmax));
            }
            if omin < vmin - 0.5 && vmin > 0.5 {
                free.push(f(Knob::TravelMin, 0.0, (vmin + 2.0).min(50.0), vmin));
            }
            if free.is_empty() {
                vec![]
            } else {
                vec![free]
            }
        }
        Effect::Quantization if get(Knob::Quantum) == 0.0 && facts.lattice_pct > 0.0 => {
            let q = facts.lattice_pct;
            vec![vec![f(Knob::Quantum, q * 0.999, q * 1.001, q)]]
        }
        Effect::Calibration if get(Knob::CalGain) == 1.0 && get(Knob::CalOffset) == 0.0 => {
            let (g, o) = steady_gain_offset(facts);
            vec![vec![
                f(Knob::CalGain, 0.7, 1.3, g),
                f(Knob::CalOffset, -15.0, 15.0, o),
            ]]
        }
        _ => vec![],
    }
}

/// The variant from its own start and from two more starts spread over the knobs' boxes
/// (a tenth and two fifths of the way, on a log scale for scale-type knobs): stick-slip,
/// backlash and dead time make the error surface multi-modal.
fn spread_starts(variant: Vec<Free>) -> Vec<Vec<Free>> {
    let at = |f: &Free, share: f64| {
        if f.lo > 0.0 && f.hi / f.lo > 20.0 {
            f.lo * (f.hi / f.lo).powf(share)
        } else {
            f.lo + share * (f.hi - f.lo)
        }
    };
    let moved = |share: f64| {
        variant
            .iter()
            .map(|f| Free {
                init: at(f, share),
                ..*f
            })
            .collect::<Vec<_>>()
    };
    vec![moved(0.1), moved(0.4), variant]
}

/// Least-squares line through the settled holds: V_P = g O_P + o (1, 0 with too few holds).
fn steady_gain_offset(facts: &Facts) -> (f64, f64) {
    let h = &facts.holds;
    if h.len() < 3 {
        return (1.0, 0.0);
    }
    let n = h.len() as f64;
    let mx = h.iter().map(|x| x.op_pct).sum::<f64>() / n;
    let my = h.iter().map(|x| x.vp_pct).sum::<f64>() / n;
    let sxx: f64 = h.iter().map(|x| (x.op_pct - mx).powi(2)).sum();
    if sxx < 1.0 {
        return (1.0, my - mx);
    }
    let g = h
        .iter()
        .map(|x| (x.op_pct - mx) * (x.vp_pct - my))
        .sum::<f64>()
        / sxx;
    (g.clamp(0.7, 1.3), my - g.clamp(0.7, 1.3) * mx)
}

/// A refitted candidate and how it did on the held-out blocks.
struct Trial {
    effect: Effect,
    spec: ModelSpec,
    errors: Errors,
    free: Vec<Free>,
    /// Held-out blocks helped beyond noise (z > 2); 0 when the blocks hurt lose over a quarter
    /// of what those gain.
    t_stat: f64,
    excess_share: f64,
    delta_bic: f64,
    material: bool,
}

impl Trial {
    fn passes(&self) -> bool {
        self.material && self.t_stat >= 2.0 && self.excess_share >= 0.1 && self.delta_bic < -10.0
    }
}

/// Runs the whole diagnosis of a recording (`op`, `vp` every `dt` seconds), starting from the
/// user's model `base` or, without one, a fitted FOPDT. `progress(done, total)` is called as
/// the refits finish.
pub fn diagnose(
    t: &[f64],
    op: &[f64],
    vp: &[f64],
    dt: f64,
    base: Option<&ModelSpec>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    if vp.len() != op.len() || vp.is_empty() {
        return Err(DiagnoseError::NoPosition);
    }
    let n = op.len();
    if (n as f64) * dt < 20.0 {
        return Err(DiagnoseError::TooShort(n));
    }
    let sigma = locate::noise_floor(vp);
    let facts = evidence::measure(op, vp, dt, sigma);
    // Blocks of a twentieth of the recording (10-120 s) give ten held-out blocks.
    let block_len = (((n as f64 * dt / 20.0).clamp(10.0, 120.0) / dt) as usize).max(1);
    let scorer = Scorer {
        op,
        vp,
        dt,
        block_len,
        skip: (1.0 / dt) as usize,
        n_blocks: n.div_ceil(block_len),
    };

    let (base_spec, base_label, mut td_max) = match base {
        Some(b) => {
            Valve::new(b, dt)?;
            (b.clone(), format!("{} (given)", b.model), b.dead_time_s)
        }
        None => (
            fit_baseline(&scorer, &facts),
            "fopdt".to_string(),
            NOMINAL_DEAD_TIME_S,
        ),
    };
    let base_errors = scorer.errors(&base_spec);
    let sim_before = scorer.simulate(&base_spec);
    let residual: Vec<f64> = vp.iter().zip(&sim_before).map(|(m, s)| m - s).collect();
    let mismatch_windows = locate::windows(t, op, vp, &residual, sigma, dt);
    // Residual correlation length: BIC counts independent samples, not raw samples. It is
    // measured again after each kept effect, whose residual is closer to white.
    let mut corr_len = correlation_length(&residual);
    let n_fit = scorer.n_fit();
    let n_held_noise = (n - scorer.skip - n_fit) as f64 * sigma * sigma;

    let mut current = composed::compose(&base_spec, dt);
    let mut cur_errors = scorer.errors(&current);
    let mut findings: Vec<Finding> = Vec::new();
    // The knobs the kept effects freed, with their boxes.
    let mut freed: Vec<Free> = Vec::new();
    let mut notes = Vec::new();
    // Set when stiction was kept by the slips of V_P rather than by the free-run error.
    let mut by_slips = false;
    let total = Effect::ALL.len() * ROUNDS;
    let mut done = 0;
    // Effects worth trying this round: all at first, then those that helped enough before.
    let mut worth: Vec<Effect> = Effect::ALL.to_vec();
    for round in 0..ROUNDS {
        // Per candidate, its starts: variants that differ only in their own start share the
        // spread starts.
        let mut jobs: Vec<(Effect, Vec<Vec<Free>>)> = Vec::new();
        for effect in Effect::ALL {
            if findings.iter().any(|f| f.effect == effect) || !worth.contains(&effect) {
                continue;
            }
            for variant in candidates(effect, &current, &facts, op, vp, td_max) {
                for mut free in spread_starts(variant) {
                    free.push(Free {
                        knob: Knob::Gain,
                        lo: 0.05,
                        hi: 1.0 / dt,
                        init: composed::get(&current, Knob::Gain),
                    });
                    let td = composed::get(&current, Knob::DeadTime);
                    let hi = if effect == Effect::DeadTime {
                        3.0
                    } else {
                        td_max.max(td)
                    };
                    if !free.iter().any(|f| f.knob == Knob::DeadTime) {
                        free.push(Free {
                            knob: Knob::DeadTime,
                            lo: 0.0,
                            hi,
                            init: td,
                        });
                    }
                    let same_box = |starts: &Vec<Vec<Free>>| {
                        starts[0].len() == free.len()
                            && starts[0]
                                .iter()
                                .zip(&free)
                                .all(|(a, b)| a.knob == b.knob && a.lo == b.lo && a.hi == b.hi)
                    };
                    match jobs
                        .iter_mut()
                        .find(|(e, starts)| *e == effect && same_box(starts))
                    {
                        Some((_, starts)) if starts.contains(&free) => {}
                        Some((_, starts)) => starts.push(free),
                        None => jobs.push((effect, vec![free])),
                    }
                }
            }
        }
        tracing::debug!(
            round,
            candidates = jobs.len(),
            starts = jobs.iter().map(|j| j.1.len()).sum::<usize>(),
            "trying effects"
        );
        let trials: Vec<Trial> = jobs
            .par_iter()
            .map(|(effect, starts)| {
                let (spec, errors) = refit_from(&scorer, &current, starts);
                judge(
                    &scorer,
                    &current,
                    sigma,
                    *effect,
                    spec,
                    errors,
                    starts[0].clone(),
                    &cur_errors,
                    n_held_noise,
                    n_fit,
                    corr_len,
                    &facts,
                )
            })
            .collect();
        done += Effect::ALL.len();
        progress(done.min(total), total);
        // Keep the best variant per effect, then the best effect.
        let mut best: Vec<&Trial> = Vec::new();
        for trial in &trials {
            match best.iter_mut().find(|b| b.effect == trial.effect) {
                Some(b) if b.errors.held > trial.errors.held => *b = trial,
                Some(_) => {}
                None => best.push(trial),
            }
        }
        best.sort_by(|a, b| a.errors.held.total_cmp(&b.errors.held));
        for t in &best {
            tracing::debug!(
                effect = t.effect.name(),
                held_before = cur_errors.held,
                held_after = t.errors.held,
                t_stat = t.t_stat,
                excess_share = t.excess_share,
                delta_bic = t.delta_bic,
                material = t.material,
                params = %serde_json::Value::Object(params_of(t)),
                "candidate"
            );
        }
        let Some(winner) = best.iter().find(|t| t.passes()) else {
            // Nothing lowers the free-run error; stick-slip may still be there, judged by its
            // character (see `stickslip`). A model with a limit cycle of its own phase leaves
            // free-run SSE unable to judge anything after it, so this ends the search.
            let stuck = [Knob::Stickband, Knob::Breakaway]
                .iter()
                .any(|&k| composed::get(&current, k) > 0.0);
            let fitted = if stuck {
                None
            } else {
                stickslip::fit(&scorer, &current, &facts)
            };
            if let Some(c) = fitted.filter(|c| c.passes()) {
                let errors = scorer.errors(&c.spec);
                let k_new = c.knobs.iter().filter(|&&k| k != Knob::Gain).count();
                findings.push(Finding {
                    effect: Effect::Stiction,
                    evidence: stickslip_evidence(&c, &facts, &cur_errors, &errors, dt),
                    params: c
                        .knobs
                        .iter()
                        .map(|&k| {
                            (
                                k.label().to_string(),
                                serde_json::json!(round4(composed::get(&c.spec, k))),
                            )
                        })
                        .collect(),
                    heldout_sse_before: cur_errors.held,
                    heldout_sse_after: errors.held,
                    delta_bic: bic_change(&cur_errors, &errors, k_new, n_fit, corr_len),
                });
                notes.push(format!(
                    "stiction was judged by the slips of V_P (slip-size histograms of 10 s pieces of the held-out blocks, signed-rank test), \
                     not by the free-run error: a stick-slip limit cycle's phase is not set by O_P, so a simulated one \
                     slips at other moments than the valve, and the held-out SSE cannot show that it slips like the \
                     valve ({:.1} -> {:.1} %²); to confirm it, run {}",
                    cur_errors.held,
                    errors.held,
                    Effect::Stiction.experiment()
                ));
                current = c.spec;
                by_slips = true;
            }
            break;
        };
        worth = best
            .iter()
            .filter(|t| cur_errors.held - t.errors.held >= RETRY_SHARE * winner.errors.held)
            .map(|t| t.effect)
            .collect();
        let gain = cur_errors.held - winner.errors.held;
        for other in best
            .iter()
            .filter(|o| o.effect != winner.effect && o.passes())
        {
            let g = cur_errors.held - other.errors.held;
            if winner.effect.look_alikes().contains(&other.effect) && g >= 0.8 * gain {
                notes.push(format!(
                    "{} and {} explain the mismatch almost equally well ({:.0} % vs {:.0} % of the held-out error removed): \
                     this recording cannot tell them apart; {} would",
                    winner.effect.name(),
                    other.effect.name(),
                    100.0 * gain / cur_errors.held,
                    100.0 * g / cur_errors.held,
                    winner.effect.experiment()
                ));
            }
        }
        if winner.effect == Effect::DeadTime {
            td_max = 3.0;
        }
        findings.push(Finding {
            effect: winner.effect,
            evidence: explain(winner, &current, &facts, &mismatch_windows, sigma),
            params: params_of(winner),
            heldout_sse_before: cur_errors.held,
            heldout_sse_after: winner.errors.held,
            delta_bic: winner.delta_bic,
        });
        // Every knob freed so far is refitted together, from where the rounds left it (an
        // effect found later may explain what an earlier one was stretched to cover) ...
        for f in &winner.free {
            match freed.iter_mut().find(|g| g.knob.same_number(f.knob)) {
                Some(g) => *g = *f,
                None => freed.push(*f),
            }
        }
        current = winner.spec.clone();
        cur_errors = scorer.errors(&current);
        if round > 0 {
            let from_here = starting_at(&freed, &current);
            // ... and afresh from the starts the rounds began with: effects fitted one at a
            // time can leave the joint fit in a valley it only finds its way out of from outside.
            let mut starts = spread_starts(freed.clone());
            starts.push(from_here);
            let (polished, errors) = refit_from(&scorer, &current, &starts);
            tracing::debug!(
                held_before = cur_errors.held,
                held_after = errors.held,
                "polish"
            );
            if errors.fit < cur_errors.fit && errors.held <= cur_errors.held {
                current = polished;
                cur_errors = errors;
            }
        }
        let sim = scorer.simulate(&current);
        let residual: Vec<f64> = vp.iter().zip(&sim).map(|(m, s)| m - s).collect();
        corr_len = correlation_length(&residual);
        tracing::debug!(corr_len, "residual after the round");
    }
    if findings.is_empty() && facts.reversals < 10 {
        notes.push(format!(
            "only {} reversals of O_P: backlash, deadband and state-dependent delay show at reversals; {} would test for them",
            facts.reversals,
            Effect::Backlash.experiment()
        ));
    }

    let final_spec = if findings.is_empty() {
        base_spec.clone()
    } else {
        current.clone()
    };
    let sim_after = scorer.simulate(&final_spec);
    let residual_after: Vec<f64> = vp.iter().zip(&sim_after).map(|(m, s)| m - s).collect();
    let windows_after = locate::windows(t, op, vp, &residual_after, sigma, dt);
    let held_mask: Vec<bool> = (0..n).map(|k| scorer.held(k)).collect();
    let heldout = Some(Comparison {
        before: metrics::scores_masked(vp, &sim_before, op, dt, &held_mask),
        after: metrics::scores_masked(vp, &sim_after, op, dt, &held_mask),
    });
    let final_errors = scorer.errors(&final_spec);
    let verdict = verdict(
        &findings,
        &base_errors,
        &final_errors,
        n_held_noise,
        &mismatch_windows,
        by_slips,
    );
    Ok(Diagnosis {
        baseline: Baseline {
            model: base_label,
            heldout_sse: base_errors.held,
            sse: base_errors.fit + base_errors.held,
            spec: base_spec,
        },
        noise_floor_pct: sigma,
        mismatch_windows,
        final_model: Final {
            model: if findings.is_empty() {
                final_spec.model.tag().to_string()
            } else {
                format!(
                    "pincart2 + {}",
                    findings
                        .iter()
                        .map(|f| f.effect.name())
                        .collect::<Vec<_>>()
                        .join(" + ")
                )
            },
            heldout_sse: final_errors.held,
            params: serde_json::to_value(&final_spec).unwrap_or_default(),
            spec: final_spec,
        },
        findings,
        verdict,
        windows_after,
        heldout,
        sim_before,
        sim_after,
        notes,
        steps: facts.steps,
    })
}

/// Scores a refitted candidate against the current model.
#[allow(clippy::too_many_arguments)]
fn judge(
    scorer: &Scorer,
    current: &ModelSpec,
    sigma: f64,
    effect: Effect,
    spec: ModelSpec,
    errors: Errors,
    free: Vec<Free>,
    cur: &Errors,
    held_noise: f64,
    n_fit: usize,
    corr_len: f64,
    facts: &Facts,
) -> Trial {
    // Per held-out block, the drop in squared error is tested against measurement noise: with
    // noise sigma, the drop has a standard deviation of 2 sigma sqrt(sum (y_before - y_after)^2)
    // when nothing real changed. An effect that exists helps significantly (z > 2) wherever the
    // recording excites it, and what it costs elsewhere is small next to what it gains; one
    // fitted to chance helps some blocks about as much as it hurts others. `t_stat` is the
    // number of blocks helped, or 0 when the blocks hurt lose more than a quarter of what the
    // blocks helped gain.
    let blocks = scorer.paired(current, &spec);
    let z = |(drop, diff2): (f64, f64)| drop / (2.0 * sigma.max(1e-6) * diff2.sqrt() + 1e-12);
    let (mut better, mut helped, mut hurt) = (0usize, 0.0, 0.0);
    for &p in &blocks {
        if z(p) > 2.0 {
            better += 1;
            helped += p.0;
        } else if z(p) < -2.0 {
            hurt -= p.0;
        }
    }
    let t_stat = if hurt * 4.0 <= helped {
        better as f64
    } else {
        0.0
    };
    let excess = (cur.held - held_noise).max(1e-12);
    let excess_share = (cur.held - errors.held) / excess.max(0.05 * cur.held);
    let k_new = free
        .iter()
        .filter(|f| f.knob != Knob::Gain && f.knob != Knob::DeadTime)
        .count()
        .max(1);
    let delta_bic = bic_change(cur, &errors, k_new, n_fit, corr_len);
    // A fitted value pinned at the edge of its search range is the effect standing in for
    // something else, not a measurement of it.
    let pinned = free.iter().any(|f| {
        let v = composed::get(&spec, f.knob);
        let scale = f.lo > 0.0 && f.hi / f.lo > 20.0;
        (scale || f.knob == Knob::Slowdown)
            && f.knob != Knob::Gain
            && f.knob != Knob::DeadTime
            && (v >= f.hi * 0.98 || v <= f.lo * 1.02)
    });
    let material = !pinned && material(effect, &spec, facts);
    Trial {
        effect,
        spec,
        errors,
        free,
        t_stat,
        excess_share,
        delta_bic,
        material,
    }
}

/// BIC change from `cur` to `new` on the fit blocks with `k_new` more parameters, counting
/// independent samples (`n_fit` over the residual's correlation length), not raw ones.
fn bic_change(cur: &Errors, new: &Errors, k_new: usize, n_fit: usize, corr_len: f64) -> f64 {
    let n_eff = (n_fit as f64 / corr_len).max(10.0);
    n_eff * (new.fit / cur.fit).ln() + k_new as f64 * n_eff.ln()
}

/// Whether a fitted effect is large enough to matter to a valve engineer, and agrees with what
/// the recording shows directly (a speed limit must be reached by the measured V_P; opening and
/// closing speeds must differ the same way as the fit says).
fn material(effect: Effect, spec: &ModelSpec, facts: &Facts) -> bool {
    let g = |k| composed::get(spec, k);
    match effect {
        Effect::DeadTime => g(Knob::DeadTime) > NOMINAL_DEAD_TIME_S + 0.02,
        Effect::Backlash => g(Knob::Crossing) * composed::half_open(spec) >= 0.03,
        Effect::StateDependentDelay => {
            g(Knob::Slowdown) >= 0.3 || g(Knob::CrossingSlope).abs() * 100.0 >= 0.1
        }
        Effect::SlewRate => {
            let top = facts.open_speed.max(facts.close_speed);
            let half = g(Knob::HalfOpenSlew);
            half < NOMINAL_MIN_SLEW_PCT_PER_S && top >= 0.7 * half
        }
        Effect::Asymmetry => {
            let (a, b) = (g(Knob::Slew), g(Knob::ClosingSlew));
            let (oa, ob) = (facts.open_speed, facts.close_speed);
            let seen = oa.max(ob) / oa.min(ob).max(1e-9) >= 1.2 && (a > b) == (oa > ob);
            seen && a.max(b) / a.min(b) >= 1.3
                && a.min(b) < 0.8 * FASTEST_PCT_PER_S
                && oa.min(ob) >= 0.7 * a.min(b)
        }
        Effect::MinSpeed => g(Knob::MinSpeed) >= 0.02,
        // Stick-slip needs the slip: a stickband without a jump is a deadband on the input.
        Effect::Stiction => {
            (g(Knob::Stickband) >= 0.1 && g(Knob::Stickband) * g(Knob::JumpFraction) >= 0.1)
                || g(Knob::Breakaway) >= 0.1
        }
        Effect::Deadband => g(Knob::Deadband) >= 0.05,
        Effect::Saturation => spec.travel.max_pct < 99.5 || spec.travel.min_pct > 0.5,
        Effect::Quantization => g(Knob::Quantum) > 0.0,
        Effect::Calibration => {
            (g(Knob::CalGain) - 1.0).abs() >= 0.01 || g(Knob::CalOffset).abs() >= 0.2
        }
    }
}

/// Number of samples over which the residual stays correlated, from its lag-1 autocorrelation.
fn correlation_length(r: &[f64]) -> f64 {
    let m = r.iter().sum::<f64>() / r.len().max(1) as f64;
    let var: f64 = r.iter().map(|x| (x - m).powi(2)).sum();
    if var <= 0.0 {
        return 1.0;
    }
    let c1: f64 = r.windows(2).map(|w| (w[0] - m) * (w[1] - m)).sum();
    let rho = (c1 / var).clamp(0.0, 0.999);
    (1.0 + rho) / (1.0 - rho)
}

/// The fitted values of the knobs a finding freed, in physical units.
fn params_of(trial: &Trial) -> serde_json::Map<String, serde_json::Value> {
    trial
        .free
        .iter()
        .map(|f| {
            (
                f.knob.label().to_string(),
                serde_json::json!(round4(composed::get(&trial.spec, f.knob))),
            )
        })
        .collect()
}

/// A parameter as reported: four decimals.
fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

/// The evidence for stick-slip judged by slips: the measured slips, what the models do, and
/// what the free-run error says.
fn stickslip_evidence(
    c: &stickslip::Candidate,
    facts: &Facts,
    cur: &Errors,
    new: &Errors,
    dt: f64,
) -> String {
    let s = &facts.slips;
    let (size_m, size_s, n) = evidence::mean_sd(s.iter().map(|x| x.size_pct.abs()));
    let reversing = s
        .windows(2)
        .filter(|w| w[0].size_pct * w[1].size_pct < 0.0)
        .count();
    let mut gaps: Vec<f64> = s
        .windows(2)
        .map(|w| (w[1].k - w[0].k) as f64 * dt)
        .collect();
    let (sim_m, _, sim_n) = evidence::mean_sd(c.slips_after.iter().map(|x| x.size_pct.abs()));
    let scale = &facts.slip_scale;
    let span = scale.span as f64 * dt;
    let g = |k| composed::get(&c.spec, k);
    let model = if g(Knob::Breakaway) > 0.0 {
        format!(
            "Stick-slip inside the positioner loop (breakaway {:.2} %, positioner gain {:.2} /s)",
            g(Knob::Breakaway),
            g(Knob::Gain)
        )
    } else {
        format!(
            "Stick-slip on the valve's input (stickband {:.2} %, jump {:.2} %, positioner gain {:.2} /s)",
            g(Knob::Stickband),
            g(Knob::Stickband) * g(Knob::JumpFraction),
            g(Knob::Gain)
        )
    };
    format!(
        "V_P slips by {size_m:.2} ± {size_s:.2} % within {span:.2} s {n} times while O_P moves less than half of that \
         (a slip is at least {:.2} %: five noise sigmas of {span:.2} s means, 1.5 sensor steps, 0.1 %), every {:.1} s on median, {reversing} of {} successive slips \
         reversing (hunting); the model before slips {} times. {model} slips {sim_n} times by {sim_m:.2} %. Judged by \
         the slip-size histograms of 10 s pieces of the held-out blocks: closer to the measured ones in {} of {} pieces (signed-rank test \
         p = {:.3}), distance {:.0} -> {:.0} slips; the held-out SSE goes {:.1} -> {:.1} %², which cannot judge a \
         limit cycle whose phase O_P does not set",
        scale.threshold_pct,
        evidence::percentile(&mut gaps, 0.5),
        n.saturating_sub(1),
        c.slips_before.len(),
        c.held.better,
        c.held.better + c.held.worse,
        c.held.p_value,
        c.held.distance_before,
        c.held.distance_after,
        cur.held,
        new.held,
    )
}

/// Where the baseline's excess error lies: "84 % of the excess error lies in 12 windows after
/// direction reversals; " or nothing when no window stands above the noise.
fn share_in(windows: &[Window], kinds: &[Context], what: &str) -> String {
    let total: f64 = windows.iter().map(|w| w.excess_sse).sum();
    let hits: Vec<&Window> = windows.iter().filter(|w| kinds.contains(&w.kind)).collect();
    let part: f64 = hits.iter().map(|w| w.excess_sse).sum();
    // Under half a percent is not where the error lies: say nothing rather than "0 %".
    if total <= 0.0 || hits.is_empty() || part < 0.005 * total {
        return String::new();
    }
    format!(
        "{:.0} % of the excess error lies in {} windows {what}; ",
        100.0 * part / total,
        hits.len()
    )
}

/// A sentence of evidence for a finding, from the located windows, the data and the fit.
fn explain(
    trial: &Trial,
    before: &ModelSpec,
    facts: &Facts,
    windows: &[Window],
    sigma: f64,
) -> String {
    let g = |k| composed::get(&trial.spec, k);
    let (rev_m, rev_s, rev_n) =
        evidence::mean_sd(facts.steps.iter().filter(|s| s.reversal).map(|s| s.delay_s));
    let (same_m, same_s, same_n) = evidence::mean_sd(
        facts
            .steps
            .iter()
            .filter(|s| !s.reversal)
            .map(|s| s.delay_s),
    );
    let steps_text = if rev_n > 0 && same_n > 0 {
        format!(
            "steps against the previous movement start after {rev_m:.2} ± {rev_s:.2} s ({rev_n} steps), same-direction steps after {same_m:.2} ± {same_s:.2} s ({same_n})"
        )
    } else {
        format!("{} reversals of O_P in the recording", facts.reversals)
    };
    let rev = share_in(windows, &[Context::Reversal], "after direction reversals");
    let moves = share_in(
        windows,
        &[Context::LargeStep, Context::Move],
        "during moves of O_P",
    );
    let rest = share_in(windows, &[Context::Rest], "at rest");
    let limit = share_in(windows, &[Context::NearLimit], "near a travel limit");
    let offset = {
        let (m, _, _) = evidence::mean_sd(facts.holds.iter().map(|h| h.vp_pct - h.op_pct));
        m
    };
    match trial.effect {
        Effect::DeadTime => format!(
            "{moves}{steps_text}; the valve answers every move late: a pure delay of {:.2} s (was {:.2} s)",
            g(Knob::DeadTime),
            composed::get(before, Knob::DeadTime)
        ),
        Effect::Backlash => {
            // With an opening-dependent slowdown the crossing is slower when open too.
            let at_half = g(Knob::Crossing) * composed::half_open(&trial.spec);
            let range = if g(Knob::Slowdown) > 0.0 {
                format!(
                    " at half travel ({:.2} s closed, {:.2} s open)",
                    g(Knob::Crossing),
                    g(Knob::Crossing) * (1.0 + g(Knob::Slowdown))
                )
            } else {
                String::new()
            };
            format!(
                "{rev}{steps_text}; V_P stays flat for about {at_half:.2} s more after a reversal{range}: lost motion (backlash)"
            )
        }
        Effect::StateDependentDelay => {
            let by_opening = facts.steps.iter().filter(|s| s.reversal).fold((0.0, 0usize, 0.0, 0usize), |acc, s| {
                if s.from_pct < 50.0 { (acc.0 + s.delay_s, acc.1 + 1, acc.2, acc.3) } else { (acc.0, acc.1, acc.2 + s.delay_s, acc.3 + 1) }
            });
            let split = if by_opening.1 > 0 && by_opening.3 > 0 {
                format!(
                    "reversal delays average {:.2} s below 50 % opening and {:.2} s above",
                    by_opening.0 / by_opening.1 as f64,
                    by_opening.2 / by_opening.3 as f64
                )
            } else {
                steps_text.clone()
            };
            if g(Knob::Slowdown) > 0.0 {
                format!(
                    "the response slows with opening: {split}; the fit gives a valve {:.1} times slower fully open than closed",
                    1.0 + g(Knob::Slowdown)
                )
            } else {
                format!(
                    "{split}; the cart-crossing time grows from {:.2} s closed to {:.2} s open (pin-cart II, eq. 7)",
                    g(Knob::Crossing),
                    g(Knob::Crossing) + 100.0 * g(Knob::CrossingSlope)
                )
            }
        }
        Effect::SlewRate => format!(
            "{moves}V_P never moves faster than {:.1} %/s opening and {:.1} %/s closing (99.5th percentile): a slew-rate limit of {:.1} %/s",
            facts.open_speed,
            facts.close_speed,
            g(Knob::Slew)
        ),
        Effect::Asymmetry => format!(
            "V_P opens at up to {:.1} %/s but closes at up to {:.1} %/s (99.5th percentile); the fit gives \
             {:.1} %/s opening and {:.1} %/s closing",
            facts.open_speed,
            facts.close_speed,
            g(Knob::Slew),
            g(Knob::ClosingSlew)
        ),
        Effect::MinSpeed => format!(
            "small errors close at a constant rate of about {:.2} %/s instead of exponentially",
            g(Knob::MinSpeed)
        ),
        Effect::Stiction => {
            let jumps = facts.holds.iter().filter(|h| h.max_jump_pct > 5.0 * sigma.max(0.01)).count();
            format!(
                "{rest}{rev}{jumps} of {} holds show a sudden jump of V_P after it had settled: {}",
                facts.holds.len(),
                if g(Knob::Breakaway) > 0.0 {
                    format!(
                        "stick-slip inside the positioner loop: the valve sticks when it slows and breaks away {:.2} % later, overshooting and hunting",
                        g(Knob::Breakaway)
                    )
                } else {
                    format!(
                        "stick-slip with a stickband of {:.2} % and jumps of {:.2} %",
                        g(Knob::Stickband),
                        g(Knob::Stickband) * g(Knob::JumpFraction)
                    )
                }
            )
        }
        Effect::Deadband => {
            let (up, _, nu) = evidence::mean_sd(facts.holds.iter().filter(|h| h.approach > 0.0).map(|h| h.vp_pct - h.op_pct));
            let (down, _, nd) = evidence::mean_sd(facts.holds.iter().filter(|h| h.approach < 0.0).map(|h| h.vp_pct - h.op_pct));
            format!(
                "settled V_P sits {up:+.2} % from O_P after opening ({nu} holds) and {down:+.2} % after closing ({nd}): \
                 the positioner stops inside a deadband of {:.2} %",
                g(Knob::Deadband)
            )
        }
        Effect::Saturation => format!(
            "{limit}V_P stays within {:.1}-{:.1} % while O_P goes beyond: travel limited",
            trial.spec.travel.min_pct,
            trial.spec.travel.max_pct
        ),
        Effect::Quantization => format!(
            "every V_P value lies on a lattice of {:.3} %: the position sensor's resolution",
            g(Knob::Quantum)
        ),
        Effect::Calibration => format!(
            "{rest}settled V_P sits {offset:+.2} % from O_P on average over {} holds; the fit gives V_P = {:.3} × O_P {:+.2} %: \
             a gain or offset between command and position",
            facts.holds.len(),
            g(Knob::CalGain),
            g(Knob::CalOffset)
        ),
    }
}

fn verdict(
    findings: &[Finding],
    base: &Errors,
    fin: &Errors,
    held_noise: f64,
    windows: &[Window],
    by_slips: bool,
) -> String {
    if findings.is_empty() {
        return if base.held <= 1.5 * held_noise || windows.is_empty() {
            "Nothing significant is missing: the residual is consistent with measurement noise."
                .into()
        } else {
            format!(
                "Nothing significant is missing from the vocabulary: {} windows stand above the noise floor, but no effect \
                 improves the held-out fit by more than chance.",
                windows.len()
            )
        };
    }
    let names: Vec<&str> = findings.iter().map(|f| f.effect.name()).collect();
    let (change, share) = if fin.held < base.held {
        (
            "lowers",
            format!("{:.0} % less", 100.0 * (1.0 - fin.held / base.held)),
        )
    } else {
        (
            "raises",
            format!("{:.0} % more", 100.0 * (fin.held / base.held - 1.0)),
        )
    };
    format!(
        "The model was missing {}. Adding {} {change} the held-out SSE from {:.1} to {:.1} %² ({share}).{}",
        names.join(", "),
        if names.len() == 1 { "it" } else { "them" },
        base.held,
        fin.held,
        if by_slips {
            " Stiction was judged by the slips of V_P on the held-out blocks: free-run SSE cannot judge a \
             stick-slip limit cycle, whose phase O_P does not set."
        } else {
            ""
        }
    )
}
