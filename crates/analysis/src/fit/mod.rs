//! Identification: fit the paper's valve models to a recording by minimising the free-run
//! simulation error, and score them as the paper's Table 1, with held-out scores and AIC/BIC.
//!
//! The pieces are reusable on their own:
//! - [`params`]: each model kind as a parameter vector (names, units, bounds, scale) ↔ spec.
//! - [`cost`]: the simulation-error cost over masked samples ([`cost::Problem`]).
//! - [`search`]: Latin hypercube + argmin Nelder-Mead in the unit cube, in parallel (rayon).
//! - [`seeds`]: warm starts from physical estimates (cross-correlation dead time, step T63).
//! - [`vb_core::metrics::steps`] (below, shared with diagnosis and the daemon): the step-delay
//!   analysis of Section 4.1 and pin-cart II's polynomial.
//! - [`windows`]: windows to score (given or unsaturated) and the blocked held-out split.
//! - [`figures`]: maintenance figures (T63/T86, dead band, speeds) measured on a fitted model.
//! - [`determined`]: which fitted parameters the recording does not pin down (at a bound of
//!   their box, or the error flat along them).
//!
//! [`identify`] runs them all: for each model (in parallel) it surveys the box on a decimated
//! copy of the fit blocks, polishes the best distinct points with Nelder-Mead, sweeps each axis
//! of the best ones and polishes again (decimated), then polishes on the full-rate fit blocks, scores the winner on the held-out blocks it never saw,
//! and finally refines the candidates (and the physical seeds) on all scored samples for the
//! Table 1 row and the model file.
//! Every simulation runs freely from the first sample of the recording; only scoring is
//! restricted to the windows.
//!
//! Not here: printing, files and plots (`cli::identify`, `vb_report`).

pub mod cost;
pub mod determined;
pub mod figures;
pub mod params;
pub mod search;
pub mod seeds;
pub mod windows;

use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;
use serde::Serialize;

use cost::Problem;
use params::{Layout, Limits};
use seeds::Physical;
use vb_core::metrics::steps::{self, StepAnalysis, StepOptions, StepsError};
use vb_core::metrics::{self, Scores};
use vb_core::model::{ModelKind, ModelSpec};
use vb_core::recording::RecordingView;
use windows::{Split, Window};

/// Why identification could not run.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// A `--windows` list that cannot be read.
    #[error("--windows {text}: {detail}")]
    Windows { text: String, detail: String },
    /// Step-analysis options that make no sense, or no measured V_P.
    #[error(transparent)]
    Steps(#[from] StepsError),
    /// A model that is not one of the paper's (the physical simulator).
    #[error("{0} is a simulator with {count} parameters, not one of the paper's identifiable models: choose from fopdt, stiction, pincart1, pincart2 (modelless and delayed are always added)", count = vb_core::model::PhysicalParams::COUNT)]
    NotIdentifiable(ModelKind),
    /// Too little data in the windows.
    #[error(
        "only {scored} samples to score {where_}: identification needs at least {need}; {fix}"
    )]
    TooFew {
        scored: usize,
        need: usize,
        where_: String,
        fix: String,
    },
}

/// How hard to search, per model. The defaults fit all six models of Table 1 on 41,300
/// samples in about a second on two cores.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Effort {
    /// Survey points per free parameter (Latin hypercube on the decimated problem).
    pub survey_per_param: usize,
    /// Distinct survey points polished.
    pub starts: usize,
    /// Nelder-Mead iterations per free parameter on the decimated problem.
    pub coarse_iters_per_param: u64,
    /// Polished points carried on to an axis sweep, a second coarse simplex and the
    /// full-rate problem.
    pub fine_starts: usize,
    /// Values tried per axis in the sweep.
    pub sweep_points: usize,
    /// Nelder-Mead iterations per free parameter at full rate (fit blocks).
    pub fine_iters_per_param: u64,
    /// Nelder-Mead iterations per free parameter of each final refine on all scored samples
    /// (from every full-rate candidate and every physical seed).
    pub refine_iters_per_param: u64,
    /// Sample period the global stage is decimated to, s (no decimation when the data are
    /// already this slow).
    pub coarse_period_s: f64,
}

impl Default for Effort {
    fn default() -> Self {
        Effort {
            survey_per_param: 24,
            starts: 4,
            coarse_iters_per_param: 40,
            fine_starts: 2,
            sweep_points: 16,
            fine_iters_per_param: 25,
            refine_iters_per_param: 25,
            coarse_period_s: 0.05,
        }
    }
}

/// What to identify and where to score.
#[derive(Debug, Clone)]
pub struct Options {
    /// Models to fit (modelless and delayed are cheap references; add them for Table 1).
    pub models: Vec<ModelKind>,
    /// Windows to fit and score; `None` leaves out saturation automatically.
    pub windows: Option<Vec<Window>>,
    /// The held-out split.
    pub split: Split,
    /// Search effort.
    pub effort: Effort,
    /// What counts as a step for the step analysis.
    pub steps: StepOptions,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            models: ModelKind::ALL.to_vec(),
            windows: None,
            split: Split::default(),
            effort: Effort::default(),
            steps: StepOptions::default(),
        }
    }
}

impl Options {
    /// The default options for `models`, after the two references Table 1 always lists
    /// (modelless and delayed modelless); each model once.
    pub fn for_models(models: &[ModelKind]) -> Self {
        let mut all = vec![ModelKind::Modelless, ModelKind::Delayed];
        for m in models {
            if !all.contains(m) {
                all.push(*m);
            }
        }
        Options {
            models: all,
            ..Options::default()
        }
    }
}

/// One fitted model: its Table 1 and Table 2 rows and more.
#[derive(Debug, Clone, Serialize)]
pub struct ModelFit {
    /// Which model.
    #[serde(rename = "model")]
    pub kind: ModelKind,
    /// The fitted model (refined on all scored samples); its Table 2 parameters in `--json`.
    #[serde(rename = "params", serialize_with = "params::serialize_table2")]
    pub spec: ModelSpec,
    /// Number of free parameters (Table 2's count).
    pub n_params: usize,
    /// Table 1 metrics over all scored samples.
    #[serde(flatten)]
    pub scores: Scores,
    /// Table 1 metrics of the fit-blocks model on the held-out blocks only.
    pub heldout: Scores,
    /// AIC and BIC over all scored samples.
    pub aic: f64,
    pub bic: f64,
    /// Simulations spent on this model.
    #[serde(rename = "simulations")]
    pub evals: usize,
    /// Free-run V_P of the fitted model over the whole recording.
    #[serde(skip)]
    pub sim: Vec<f64>,
    /// Maintenance figures of the fitted model.
    pub figures: figures::Figures,
    /// Fitted parameters the recording does not pin down.
    pub undetermined: Vec<determined::Undetermined>,
}

impl ModelFit {
    /// Table 2: the fitted parameters in physical units, `(name, value, unit)`.
    pub fn params(&self) -> Vec<(&'static str, f64, &'static str)> {
        params::table2(&self.spec)
    }
}

/// Everything identification found, in the shape of `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct Identification {
    /// Number of samples in the recording.
    pub n_samples: usize,
    /// Sample period, s.
    pub sample_period_s: f64,
    /// Windows fitted and scored.
    pub windows: Vec<Window>,
    /// True when the windows were found by leaving out saturation (no `--windows`).
    pub windows_auto: bool,
    /// Samples scored, and how many of them were held out.
    pub n_scored: usize,
    pub n_heldout: usize,
    /// The held-out split used.
    pub split: Split,
    /// One row per model, in the order asked for.
    pub rows: Vec<ModelFit>,
    /// The step-delay analysis (seeds pin-cart II when the recording has steps).
    pub steps: StepAnalysis,
    /// The physical estimates the search started from.
    pub physical: Physical,
    /// Scored and held-out masks over the recording.
    #[serde(skip)]
    pub scored_mask: Vec<bool>,
    #[serde(skip)]
    pub heldout_mask: Vec<bool>,
    /// Time the identification took, s.
    pub elapsed_s: f64,
}

/// Fewest samples identification accepts in the windows.
pub const MIN_SCORED: usize = 100;

/// Fits one model to `fit` (decimated copy `coarse`), returning the physical vectors of its
/// polished candidates on the fit blocks (best first, never empty) and the simulations spent
/// (a decimated simulation counted as its share of a full one). Exposed for reuse (e.g. refits
/// in diagnosis).
pub fn fit_vector(
    layout: &Layout,
    fit: &Problem,
    coarse: &Problem,
    seeds: &[Vec<f64>],
    effort: &Effort,
    seed: u64,
) -> (Vec<Vec<f64>>, usize) {
    let d = layout.len();
    if d == 0 {
        return (vec![vec![]], 0);
    }
    let coarse_cost = |u: &[f64]| coarse.sse(&layout.spec(&layout.from_unit(u)));
    let fine_cost = |u: &[f64]| fit.sse(&layout.spec(&layout.from_unit(u)));
    let mut points = search::latin_hypercube(effort.survey_per_param * d, d, seed);
    points.extend(seeds.iter().map(|x| layout.to_unit(x)));
    let n_survey = points.len();
    let surveyed = search::survey(&coarse_cost, points);
    let starts: Vec<Vec<f64>> = search::distinct_best(&surveyed, effort.starts, 0.08)
        .into_iter()
        .map(|s| s.u)
        .collect();
    let coarse_runs = search::polish(
        &coarse_cost,
        &starts,
        0.1,
        effort.coarse_iters_per_param * d as u64,
    );
    // Axis sweeps around the best coarse points, then a second simplex: escapes plateaus.
    let mut swept_evals = 0;
    let swept: Vec<Vec<f64>> = coarse_runs
        .iter()
        .take(effort.fine_starts)
        .map(|l| {
            let (s, e) = search::axis_sweep(&coarse_cost, &l.best, effort.sweep_points);
            swept_evals += e;
            s.u
        })
        .collect();
    let coarse_again = search::polish(
        &coarse_cost,
        &swept,
        0.05,
        effort.coarse_iters_per_param * d as u64 / 2,
    );
    let fine_starts: Vec<Vec<f64>> = coarse_again.iter().map(|l| l.best.u.clone()).collect();
    let fine_runs = search::polish(
        &fine_cost,
        &fine_starts,
        0.02,
        effort.fine_iters_per_param * d as u64,
    );
    let evals_coarse: usize = coarse_runs
        .iter()
        .chain(&coarse_again)
        .map(|l| l.evals)
        .sum::<usize>()
        + n_survey
        + swept_evals;
    let evals_fine: usize = fine_runs.iter().map(|l| l.evals).sum();
    let m = (fit.dt() / coarse.dt()).max(1e-9);
    // Coarse simulations cost a fraction of a full one; count them as such.
    let evals = (evals_coarse as f64 * m).ceil() as usize + evals_fine;
    let mut found: Vec<Vec<f64>> = fine_runs
        .iter()
        .map(|l| layout.from_unit(&l.best.u))
        .collect();
    if found.is_empty() {
        found.push(layout.vector(&layout.spec(&[])));
    }
    (found, evals)
}

/// What every model's fit shares: the recording, the masks and problems, the bounds and the
/// physical estimates.
struct Shared<'a> {
    rec: &'a RecordingView<'a>,
    opts: &'a Options,
    scored: &'a [bool],
    held_mask: &'a [bool],
    limits: Limits,
    physical: &'a Physical,
    /// The fit blocks at full rate and decimated, and all scored samples.
    fit: Problem,
    coarse: Problem,
    all: Problem,
}

/// Identifies `opts.models` on a recording. `progress(done, total)` is called as models finish
/// (from worker threads).
///
/// ```
/// use vb_analysis::fit::{identify, Options};
/// use vb_core::model::{bundled, ModelKind, Valve};
/// use vb_core::recording::RecordingView;
///
/// // 60 s at 10 Hz of an FOPDT valve answering steps of O_P every 5 s.
/// let dt = 0.1;
/// let t: Vec<f64> = (0..600).map(|k| k as f64 * dt).collect();
/// let op: Vec<f64> = (t.iter())
///     .map(|t| if (t / 5.0) as usize % 2 == 0 { 40.0 } else { 60.0 })
///     .collect();
/// let vp = Valve::new(&bundled(ModelKind::Fopdt), dt)?.simulate(&op, op[0]);
/// let rec = RecordingView { t: &t, op: &op, vp: &vp, restarts: &[], dt };
/// let id = identify(&rec, &Options::for_models(&[ModelKind::Fopdt]), &|_, _| {})?;
/// let fopdt = id.rows.iter().find(|r| r.kind == ModelKind::Fopdt).expect("fitted");
/// assert!(fopdt.scores.r2 > 0.99, "R² {}", fopdt.scores.r2);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn identify(
    rec: &RecordingView,
    opts: &Options,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Identification, FitError> {
    let started = std::time::Instant::now();
    let (op, vp, dt) = (rec.op, rec.vp, rec.dt);
    if let Some(&kind) = opts.models.iter().find(|k| !k.is_identifiable()) {
        return Err(FitError::NotIdentifiable(kind));
    }
    if vp.len() != op.len() || vp.is_empty() {
        return Err(StepsError::NoPosition.into());
    }
    let (wins, auto) = match &opts.windows {
        Some(w) => (w.clone(), false),
        None => (windows::unsaturated(rec.t, vp, dt, 0.0, 100.0), true),
    };
    let scored: Vec<bool> = windows::mask(rec.t, &wins)
        .into_iter()
        .enumerate()
        .map(|(k, m)| m && rec.has_vp(k))
        .collect();
    let n_scored = scored.iter().filter(|&&m| m).count();
    if n_scored < MIN_SCORED {
        return Err(too_few(rec, n_scored, auto));
    }
    let (fit_mask, held_mask) = opts.split.masks(&scored);
    let steps = steps::analyse(rec, &opts.steps);
    let physical = seeds::estimate(op, vp, dt, &steps);
    let fit = Problem::new(op, vp, &fit_mask, dt).restarting_at(rec.restarts);
    let m = ((opts.effort.coarse_period_s / dt).round() as usize).max(1);
    let shared = Shared {
        rec,
        opts,
        scored: &scored,
        held_mask: &held_mask,
        limits: Limits::for_recording(
            dt,
            physical
                .dead_time_s
                .max(physical.same_delay_s.unwrap_or(0.0)),
        ),
        physical: &physical,
        coarse: fit.decimated(m),
        fit,
        all: Problem::new(op, vp, &scored, dt).restarting_at(rec.restarts),
    };
    let done = AtomicUsize::new(0);
    let total = opts.models.len();
    let rows: Vec<ModelFit> = opts
        .models
        .par_iter()
        .enumerate()
        .map(|(i, &kind)| {
            let row = fit_model(&shared, kind, 0x5eed + i as u64);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
            row
        })
        .collect();
    Ok(Identification {
        n_samples: op.len(),
        sample_period_s: dt,
        windows: wins,
        windows_auto: auto,
        n_scored,
        n_heldout: held_mask.iter().filter(|&&m| m).count(),
        split: opts.split,
        rows,
        steps,
        physical,
        scored_mask: scored,
        heldout_mask: held_mask,
        elapsed_s: started.elapsed().as_secs_f64(),
    })
}

/// The error for too few samples to score, with what to do about it.
fn too_few(rec: &RecordingView, scored: usize, auto: bool) -> FitError {
    FitError::TooFew {
        scored,
        need: MIN_SCORED,
        where_: if auto {
            "outside saturation".into()
        } else {
            "in the windows given".into()
        },
        fix: if auto {
            "the valve sits on a stop almost all the time; choose windows with --windows START-END"
                .into()
        } else {
            format!(
                "the recording spans {:.2}-{:.2} s; choose windows inside it",
                rec.t.first().copied().unwrap_or(0.0),
                rec.t.last().copied().unwrap_or(0.0)
            )
        },
    }
}

/// Fits one model: the search on the fit blocks, its held-out score, then the refinement on all
/// scored samples for the Table 1 row and the model file.
fn fit_model(sh: &Shared, kind: ModelKind, seed: u64) -> ModelFit {
    let (op, vp, dt) = (sh.rec.op, sh.rec.vp, sh.rec.dt);
    let rec = sh.rec;
    let layout = Layout::new(kind, sh.limits);
    let seeds = seeds::starts(&layout, sh.physical);
    let (found, evals) = fit_vector(&layout, &sh.fit, &sh.coarse, &seeds, &sh.opts.effort, seed);
    let fit_spec = layout.spec(&found[0]);
    // Held-out: the fit-blocks model, scored where it was not fitted.
    let sim_fit = cost::simulate(&fit_spec, rec);
    let heldout = metrics::scores_masked(vp, &sim_fit, op, dt, sh.held_mask);
    let (spec, refine_evals) = refine(sh, &layout, &found, &seeds).unwrap_or((fit_spec, 0));
    let sim = cost::simulate(&spec, rec);
    let scores = metrics::scores_masked(vp, &sim, op, dt, sh.scored);
    let d = layout.len();
    let residual: Vec<f64> = (0..vp.len())
        .map(|k| {
            if sh.scored[k] {
                vp[k] - sim[k]
            } else {
                f64::NAN
            }
        })
        .collect();
    let n_eff = scores.n as f64 / vb_core::metrics::stats::correlation_length(&residual);
    let undetermined =
        determined::undetermined(&layout, &layout.vector(&spec), &sh.all, scores.sse, n_eff);
    ModelFit {
        kind,
        n_params: d,
        aic: metrics::aic(scores.sse, scores.n, d),
        bic: metrics::bic(scores.sse, scores.n, d),
        figures: figures::measure(&spec, dt),
        spec,
        scores,
        heldout,
        evals: evals + refine_evals,
        sim,
        undetermined,
    }
}

/// Refines the fitted candidates, and the physical seeds, on all scored samples (the model
/// file and Table 1): the best wins. `None` when there is nothing to refine.
fn refine(
    sh: &Shared,
    layout: &Layout,
    found: &[Vec<f64>],
    seeds: &[Vec<f64>],
) -> Option<(ModelSpec, usize)> {
    let iters = sh.opts.effort.refine_iters_per_param * layout.len() as u64;
    if layout.is_empty() || iters == 0 {
        return None;
    }
    let cost = |u: &[f64]| sh.all.sse(&layout.spec(&layout.from_unit(u)));
    let starts: Vec<Vec<f64>> = found
        .iter()
        .chain(seeds)
        .map(|x| layout.to_unit(x))
        .collect();
    let runs = search::polish(&cost, &starts, 0.02, iters);
    let mut evals = runs.iter().map(|r| r.evals).sum::<usize>();
    let best = runs.first()?;
    // A simplex shrunk onto a ridge stops short; one restart with a fresh, small simplex from
    // its best point (the usual Nelder-Mead remedy) goes on.
    let again = search::nelder_mead(&cost, &best.best.u, 0.005, iters);
    evals += again.evals;
    Some((layout.spec(&layout.from_unit(&again.best.u)), evals))
}
