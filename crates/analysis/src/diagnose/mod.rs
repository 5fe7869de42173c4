//! Diagnose: find where a model and a recording differ, name the physics the model left out,
//! add it, and show on held-out data that the fit improved.
//!
//! 1. **Baseline** ([`refit::fit_baseline`]): the user's model, or an FOPDT with unity gain
//!    fitted here. The fitted FOPDT may use what every healthy positioner has: a dead time up
//!    to 0.2 s and a stroke-speed limit no slower than 40 %/s (full stroke in 2.5 s); anything
//!    beyond is a finding.
//! 2. **Locate** ([`locate`]): noise floor of V_P, and the windows where the residual stands
//!    above it, each tied to what O_P and V_P were doing. [`facts`] measures what the
//!    recording shows without a model (step delays, speeds, holds, the sensor lattice, slips).
//! 3. **Explain and extend** ([`rounds`]): every effect of the vocabulary ([`Effect`]) is a few
//!    numbers of a composed pin-cart II valve ([`vb_core::model::composed`]). Each candidate
//!    ([`candidates`]) is added and refitted ([`refit`]) on the fit blocks ([`scorer`]), and
//!    kept only if, on **held-out** blocks that were never fitted, it lowers the error by more
//!    than chance, by a real share of the error above the noise floor, BIC agrees, and it is
//!    material: its size in engineering units ([`size`]) is worth maintenance and it removes a
//!    real share of the held-out error ([`judge`], thresholds in one [`Tuning`]). The best
//!    candidate wins a round; rounds repeat until nothing passes, so several effects can be
//!    found. One that is real but immaterial is a [`Trace`]. Stick-slip that hunts is a limit
//!    cycle whose phase O_P does not set, which free-run error cannot judge: when nothing
//!    passes, it is judged by the slips of V_P instead ([`stickslip`]), in the distance
//!    between slip-size histograms.
//! 4. **Conclude**: typed evidence per finding ([`evidence`]), each finding's size in the final
//!    model with its interval and the [`Measure`] it improved, the [`Figures`] of the final
//!    model every output quotes, Table 1 rows before and after on the held-out blocks, the
//!    windows before and after, the final model, an [`Outcome`] and [`Note`]s (look-alikes the
//!    data cannot separate). The sentences are written by `report::diagnose`.
//!
//! Diagnosis is a client of identification ([`crate::fit`]): its parameters are
//! [`crate::fit::params::ParamDef`]s, its cost is [`crate::fit::cost::Problem`], its search
//! [`crate::fit::search::nelder_mead`].

mod candidates;
mod delay;
mod diagnosis;
pub mod evidence;
pub mod facts;
mod floor;
mod judge;
pub mod locate;
mod measure;
mod refit;
mod rests;
mod rounds;
mod scorer;
mod sensor;
mod settled;
pub mod size;
mod slow;
mod speeds;
mod stickslip;
pub mod tuning;

pub use diagnosis::{
    Baseline, Comparison, Diagnosis, Figures, Final, Finding, Note, Outcome, Support, Trace,
};
use locate::Window;
pub use measure::Measure;
pub use refit::{NOMINAL_DEAD_TIME_S, NOMINAL_MIN_SLEW_PCT_PER_S};
use rounds::{Data, Search};
use scorer::{Errors, Scorer};
pub use size::Size;
pub use tuning::{Tuning, Worth};
use vb_core::metrics::{self, stats};
pub use vb_core::model::composed::Effect;
use vb_core::model::{composed, ModelSpec, Valve};
use vb_core::recording::RecordingView;

/// Slowest sampling diagnosis accepts, s.
pub const MAX_SAMPLE_PERIOD_S: f64 = 2.0;

/// Errors that stop a diagnosis.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("the recording has {0} samples: diagnosis needs at least 20 s of data")]
    TooShort(usize),
    #[error(
        "the recording has no measured V_P column: diagnosis compares a model to measurements"
    )]
    NoPosition,
    #[error("the recording is sampled every {0} s: a valve's dead time, stroke and lost motion last seconds, so diagnosis needs a sample at least every {MAX_SAMPLE_PERIOD_S} s (identify fits the delayed and FOPDT models to slower data)")]
    TooSlow(f64),
    #[error("model = \"physical\" is a simulator, not a starting model diagnosis can extend: give one of the paper's models (e.g. config/models/pincart2.toml) or none")]
    NotExtendable,
    #[error("the starting model cannot run: {0}")]
    Model(#[from] vb_core::model::ModelError),
}

/// Noise, in steps of the sensor lattice, below which V_P's median second difference is too
/// coarse a measure of it (a multiple of the step: noise of 0.1 % read in steps of 0.1 % comes
/// out 0.12 %), and a trimmed mean square is taken instead ([`stats::noise_sd_trimmed`]).
const COARSE_MEDIAN_STEPS: f64 = 2.0;

/// Runs the whole diagnosis of a recording, starting from the user's model `base` or, without
/// one, a fitted FOPDT, with the default [`Tuning`]. `progress(done, total)` is called as the
/// rounds finish.
///
/// ```no_run
/// use vb_analysis::diagnose::diagnose;
/// use vb_core::recording::{read, ReadOptions};
///
/// let rec = read("recording.csv".as_ref(), &ReadOptions::default())?;
/// let d = diagnose(&rec.view(), None, &|_, _| {})?;
/// for f in &d.findings {
///     println!("{}: {:?}", f.effect.name(), f.size);
/// }
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub fn diagnose(
    rec: &RecordingView,
    base: Option<&ModelSpec>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with(rec, base, &Tuning::default(), progress)
}

/// [`diagnose`] with the thresholds of `tuning`.
pub fn diagnose_with(
    rec: &RecordingView,
    base: Option<&ModelSpec>,
    tuning: &Tuning,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Diagnosis, DiagnoseError> {
    if rec.vp.len() != rec.op.len() || rec.vp.is_empty() {
        return Err(DiagnoseError::NoPosition);
    }
    let (n, dt) = (rec.len(), rec.dt);
    if dt > MAX_SAMPLE_PERIOD_S {
        return Err(DiagnoseError::TooSlow(dt));
    }
    if (n as f64) * dt < 20.0 {
        return Err(DiagnoseError::TooShort(n));
    }
    // On a sensor lattice, the reading errs by up to half a step: a quiet sensor's noise is
    // at least the rounding's (q / sqrt 12), which the differences of V_P do not show, and
    // their median is a multiple of the step, too coarse where the noise is within
    // [`COARSE_MEDIAN_STEPS`] steps (a trimmed mean square is not).
    let lattice = facts::lattice(rec.vp);
    let median = locate::noise_floor(rec.vp);
    let noise = if lattice > 0.0 && median < COARSE_MEDIAN_STEPS * lattice {
        stats::noise_sd_trimmed(rec.vp)
    } else {
        median
    };
    let sigma = noise.max(lattice / 12f64.sqrt());
    let facts = facts::measure(rec, sigma, lattice);
    let scorer = Scorer::new(rec);
    let (base_spec, base_label, td_max) = match base {
        Some(b) if !b.model.is_identifiable() => return Err(DiagnoseError::NotExtendable),
        Some(b) => {
            Valve::new(b, dt)?;
            (b.clone(), format!("{} (given)", b.model), b.dead_time_s)
        }
        None => (
            refit::fit_baseline(&scorer, &facts),
            "fopdt".to_string(),
            NOMINAL_DEAD_TIME_S,
        ),
    };
    let sim_before = scorer.simulate(&base_spec);
    let residual: Vec<f64> = rec.vp.iter().zip(&sim_before).map(|(m, s)| m - s).collect();
    let mismatch_windows = locate::windows(rec, &residual, sigma);
    // BIC counts independent samples, not raw samples (measured again after each kept effect).
    let corr_len = stats::correlation_length(&residual);
    let data = Data {
        rec,
        scorer: &scorer,
        facts: &facts,
        sigma,
        windows: &mismatch_windows,
        tuning,
    };
    let start = composed::compose(&base_spec, dt);
    let mut search = Search::new(data, start, corr_len, td_max);
    search.run(progress);
    let baseline = Baseline {
        model: base_label,
        heldout_sse: 0.0,
        sse: 0.0,
        spec: base_spec,
    };
    Ok(conclude(data, search, baseline, sim_before))
}

/// The diagnosis of a finished search: the final model against the baseline.
fn conclude(data: Data, search: Search, mut baseline: Baseline, sim_before: Vec<f64>) -> Diagnosis {
    let (rec, scorer) = (data.rec, data.scorer);
    let base_errors = scorer.errors_of(&sim_before);
    baseline.heldout_sse = base_errors.held;
    baseline.sse = base_errors.fit + base_errors.held;
    let (held_noise, corr_len) = (search.held_noise(), search.corr_len());
    let Search {
        current,
        mut findings,
        mut traces,
        mut notes,
        by_slips,
        ..
    } = search;
    let sized = (data.facts, rec.op, data.tuning);
    for f in findings.iter_mut() {
        // A stick-slip finding judged by its slips is sized by the measured slips.
        if matches!(f.measure, Measure::HeldoutSse { .. }) {
            let now = size::size(f.effect, &current, data.facts, rec.op, data.tuning);
            let now = size::interval(now, f.effect, &current, scorer, sized);
            f.size = size::open_ended(f.effect, now, &current, scorer, data.tuning);
            f.params = diagnosis::params(&current, f.knobs.iter().copied());
            f.facts.in_final(f.effect, &current, data.facts, data.sigma);
        }
    }
    slow::slow_findings(
        (&mut findings, &traces),
        &current,
        data,
        (held_noise, corr_len),
    );
    // The traces stay in the model only beside a finding.
    let final_spec = if findings.is_empty() {
        baseline.spec.clone()
    } else {
        current
    };
    for t in traces.iter_mut() {
        t.size = size::interval(t.size, t.effect, &t.spec, scorer, sized);
    }
    let (mut findings, shrunk) = worth_maintenance(findings, &final_spec, data.tuning.materiality);
    traces.extend(shrunk);
    for s in
        (findings.iter_mut().map(|f| &mut f.size)).chain(traces.iter_mut().map(|t| &mut t.size))
    {
        *s = size::with_model_spread(*s, data.facts.vp_span_pct);
    }
    let final_spec = if findings.is_empty() {
        baseline.spec.clone()
    } else {
        final_spec
    };
    // A valve found slow already has its speed limit among the findings.
    let speed_found =
        (findings.iter()).any(|f| matches!(f.effect, Effect::SlewRate | Effect::Asymmetry));
    let worth_speed = data.tuning.worth_speed();
    slow::slowdown_first(&mut findings, &final_spec, worth_speed);
    if let Some(slow) = slow::slow_strokes(data.facts, rec.op, worth_speed).filter(|_| !speed_found)
    {
        notes.push(slow);
    }
    let sim_after = scorer.simulate(&final_spec);
    let mut final_spec = final_spec;
    final_spec.stroke_speed_undetermined =
        !speeds::stroke_speed_shown(&final_spec, rec.op, &sim_after, rec.dt);
    let figures = figures(&final_spec, data.facts, rec.op);
    let residual_after: Vec<f64> = rec.vp.iter().zip(&sim_after).map(|(m, s)| m - s).collect();
    let windows_after = locate::windows(rec, &residual_after, data.sigma);
    let held = scorer.held_mask();
    let heldout = Some(Comparison {
        before: metrics::scores_masked(rec.vp, &sim_before, rec.op, rec.dt, held),
        after: metrics::scores_masked(rec.vp, &sim_after, rec.op, rec.dt, held),
    });
    let final_errors = scorer.errors(&final_spec);
    let effects: Vec<Effect> = findings.iter().map(|f| f.effect).collect();
    // The held-out SSE the effects judged by it brought the model to.
    let smooth_held = match findings.last() {
        Some(stiction) if by_slips => stiction.heldout_sse_before,
        _ => final_errors.held,
    };
    let outcome = outcome(
        &effects,
        &base_errors,
        smooth_held,
        held_noise,
        data.windows,
        by_slips,
    );
    let model = if effects.is_empty() {
        final_spec.model.tag().to_string()
    } else {
        let names: Vec<&str> = effects.iter().map(|e| e.name()).collect();
        format!("pincart2 + {}", names.join(" + "))
    };
    Diagnosis {
        baseline,
        noise_floor_pct: data.sigma,
        mismatch_windows: data.windows.to_vec(),
        final_model: Final {
            model,
            heldout_sse: final_errors.held,
            params: serde_json::to_value(&final_spec).unwrap_or_default(),
            spec: final_spec,
        },
        findings,
        traces,
        figures,
        outcome,
        notes,
        windows_after,
        heldout,
        sim_before,
        sim_after,
        steps: data.facts.steps.clone(),
    }
}

/// The findings still worth maintenance in the final model `spec`, all through their interval
/// (its less material end at least `materiality`), and those the joint refit of the others
/// shrank below that or whose interval reaches below it, as traces (they stay in the model):
/// a size the recording cannot tell from one not worth maintenance is no maintenance ticket.
/// Stick-slip judged by its slips was judged on its slips' interval and stays.
fn worth_maintenance(
    findings: Vec<Finding>,
    spec: &ModelSpec,
    materiality: f64,
) -> (Vec<Finding>, Vec<Trace>) {
    let (kept, shrunk): (Vec<Finding>, Vec<Finding>) = findings.into_iter().partition(|f| {
        f.size.worth_low >= materiality || !matches!(f.measure, Measure::HeldoutSse { .. })
    });
    let traces = shrunk
        .into_iter()
        .map(|f| Trace {
            effect: f.effect,
            size: f.size,
            heldout_share: (f.heldout_sse_before - f.heldout_sse_after)
                / f.heldout_sse_before.max(1e-12),
            params: f.params,
            spec: spec.clone(),
        })
        .collect();
    (kept, traces)
}

/// The figures of the final model `spec` (see [`Figures`]).
fn figures(spec: &ModelSpec, facts: &facts::Facts, op: &[f64]) -> Figures {
    use composed::Knob;
    let speed = |k: Knob| {
        if spec.stroke_speed_undetermined {
            f64::NAN
        } else {
            composed::get(spec, k) / composed::half_open(spec)
        }
    };
    Figures {
        dead_time_s: composed::get(spec, Knob::DeadTime),
        friction_band_pct: size::friction_band(spec, facts, op),
        opening_speed_pct_per_s: speed(Knob::Slew),
        closing_speed_pct_per_s: speed(Knob::ClosingSlew),
    }
}

/// The outcome: what was missing, or whether the residual is noise. `smooth_held` is the
/// held-out SSE after the effects judged by it.
fn outcome(
    effects: &[Effect],
    base: &Errors,
    smooth_held: f64,
    held_noise: f64,
    windows: &[Window],
    by_slips: bool,
) -> Outcome {
    if !effects.is_empty() {
        return Outcome::Missing {
            effects: effects.to_vec(),
            heldout_sse_before: base.held,
            heldout_sse_after: smooth_held,
            by_slips,
        };
    }
    if base.held <= 1.5 * held_noise || windows.is_empty() {
        Outcome::Noise
    } else {
        Outcome::NotSignificant {
            windows: windows.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::composed::Knob;
    use vb_core::model::{bundled, ModelKind};
    use vb_core::testkit::Columns;

    /// A finding of `effect` on `spec` worth `worth` (at its value) and `worth_low` (at its
    /// interval's low end), judged by `measure`.
    fn finding(
        effect: Effect,
        spec: &ModelSpec,
        (worth, worth_low): (f64, f64),
        measure: Measure,
    ) -> Finding {
        let rec = Columns::new(vec![40.0; 200], vec![40.0; 200], 0.01);
        let facts = facts::measure(&rec.view(), 0.05, 0.0);
        Finding {
            effect,
            facts: evidence::Evidence::of(effect, spec, spec, &facts, &[], 0.05),
            params: serde_json::Map::new(),
            alternatives: vec![],
            heldout_sse_before: 100.0,
            heldout_sse_after: 80.0,
            delta_bic: -10.0,
            support: None,
            size: Size {
                name: "slip_pct",
                unit: "%",
                value: 0.1 * worth,
                low: 0.1 * worth,
                high: 0.1 * worth,
                worth,
                worth_low,
            },
            measure,
            knobs: vec![],
        }
    }

    #[test]
    fn a_finding_shrunk_below_worth_or_unsure_of_it_is_a_trace() {
        let spec = composed::compose(&bundled(ModelKind::Fopdt), 0.01);
        let finding = |effect, worth, measure| finding(effect, &spec, worth, measure);
        let sse = Measure::HeldoutSse {
            before: 100.0,
            after: 80.0,
        };
        let (kept, traces) = worth_maintenance(
            vec![
                finding(Effect::Backlash, (2.0, 1.5), sse),
                finding(Effect::Stiction, (0.6, 0.5), sse),
                // Material at its value, not at its interval's low end.
                finding(Effect::Deadband, (1.5, 0.7), sse),
            ],
            &spec,
            1.0,
        );
        assert_eq!(
            kept.iter().map(|f| f.effect).collect::<Vec<_>>(),
            [Effect::Backlash]
        );
        let traced: Vec<(Effect, f64)> = traces.iter().map(|t| (t.effect, t.size.worth)).collect();
        assert_eq!(traced, [(Effect::Stiction, 0.6), (Effect::Deadband, 1.5)]);
        assert!((traces[0].heldout_share - 0.2).abs() < 1e-12);
    }

    #[test]
    fn a_valve_slow_at_half_travel_only_through_its_slowdown_has_the_slowdown_first() {
        let sse = Measure::HeldoutSse {
            before: 100.0,
            after: 80.0,
        };
        let order = |slew: f64, slowdown: f64| {
            let mut spec = composed::compose(&bundled(ModelKind::Fopdt), 0.01);
            composed::set(&mut spec, Knob::Slew, slew);
            composed::set(&mut spec, Knob::Slowdown, slowdown);
            let mut found: Vec<Finding> = [
                Effect::SlewRate,
                Effect::DeadTime,
                Effect::StateDependentDelay,
            ]
            .map(|e| finding(e, &spec, (2.0, 2.0), sse))
            .into();
            slow::slowdown_first(&mut found, &spec, 40.0);
            found.iter().map(|f| f.effect).collect::<Vec<_>>()
        };
        // Fast closed (60 %/s), three times slower fully open: the slowdown makes it slow.
        assert_eq!(
            order(60.0, 2.0),
            [
                Effect::DeadTime,
                Effect::StateDependentDelay,
                Effect::SlewRate
            ]
        );
        // Slow even closed (20 %/s), or no slowdown in the model: the order stays.
        for (slew, slowdown) in [(20.0, 2.0), (60.0, 0.0)] {
            assert_eq!(
                order(slew, slowdown),
                [
                    Effect::SlewRate,
                    Effect::DeadTime,
                    Effect::StateDependentDelay
                ]
            );
        }
    }
}
