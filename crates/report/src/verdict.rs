//! A diagnosis's conclusion in words: the verdict a maintenance planner acts on (each finding
//! in the words of [`vb_core::vocabulary`]: what is wrong with its size, how sure, how bad for
//! control, what to do), the modeller's verdict (what the model was missing and the measure in
//! which adding it improved the fit), the sizes of findings and traces, and the figures of the
//! final model.
//!
//! Not here: the evidence of each finding or the notes (`report::diagnose`).

use vb_analysis::diagnose::{Diagnosis, Figures, Measure, Note, Outcome, Trace};
pub use vb_core::human::{sig3 as num, size_label as label, size_text};
use vb_core::vocabulary::{self, capitalised, Advice};

/// The measure a finding improved, in words.
pub fn measure(m: &Measure) -> String {
    match *m {
        Measure::HeldoutSse { before, after } => format!(
            "held-out SSE {} -> {} %² ({:.0} % less)",
            num(before),
            num(after),
            100.0 * (1.0 - after / before.max(1e-12))
        ),
        Measure::SlipDistance {
            heldout,
            before,
            after,
        } => format!(
            "distance between the model's and the recording's slip-size histograms ({}) {} -> {} slips",
            if heldout {
                "held-out pieces"
            } else {
                "whole recording"
            },
            num(before),
            num(after)
        ),
    }
}

/// A trace in words: its effect, size and share of the held-out error.
pub fn trace(t: &Trace) -> String {
    format!(
        "{} ({}, {:.0} % of the held-out error)",
        t.effect.name(),
        t.size.words(),
        100.0 * t.heldout_share
    )
}

/// The figures of the final model in words.
pub fn figures(f: &Figures) -> String {
    let band = if f.friction_band_pct.is_finite() {
        format!("{} %", num(f.friction_band_pct))
    } else {
        "not told by these steps (see the crossing time)".into()
    };
    let speed = if f.opening_speed_pct_per_s.is_finite() {
        format!(
            "stroke speed at half travel {} %/s opening and {} %/s closing",
            num(f.opening_speed_pct_per_s),
            num(f.closing_speed_pct_per_s)
        )
    } else {
        "stroke speed not determined (no move of the recording asked for it)".into()
    };
    format!(
        "dead time {} s, friction band {band}, {speed}",
        num(f.dead_time_s)
    )
}

/// Every finding of `d` in the words of the vocabulary, highest priority first.
pub fn advice(d: &Diagnosis) -> Vec<Advice> {
    vocabulary::advice(d.findings.iter().map(|f| (f.effect, &f.size)))
}

/// The traces of `d` in plain words, each `lost motion (backlash) loses 0.12 % of travel on
/// every reversal`.
pub fn plain_traces(d: &Diagnosis) -> Vec<String> {
    (d.traces.iter())
        .map(|t| {
            let e = vocabulary::words(t.effect);
            format!("{} {}", e.plain, vocabulary::does(&t.size))
        })
        .collect()
}

/// The verdict a maintenance planner acts on: each finding, highest priority first, in the
/// vocabulary's words (severity, what is wrong with its size and unit, how sure, what it does
/// to control, what to do), or that nothing worth maintenance was found; then what was too small
/// to act on. No modeller's figures: those are in [`model_verdict`].
pub fn verdict(d: &Diagnosis) -> String {
    let traces = plain_traces(d);
    let traces = if traces.is_empty() {
        String::new()
    } else {
        format!(" Too small to act on: {}.", traces.join("; "))
    };
    let list = advice(d);
    // A slow valve is said whether or not the model needed a speed limit.
    let slow = d.notes.iter().find_map(|n| match *n {
        Note::SlowStrokes {
            opening_pct_per_s,
            closing_pct_per_s,
            largest_step_pct,
            asked_pct_per_s,
            worth_pct_per_s,
        } => Some(capitalised(&slow_strokes(
            (opening_pct_per_s, closing_pct_per_s),
            largest_step_pct,
            asked_pct_per_s,
            worth_pct_per_s,
        ))),
        _ => None,
    });
    if !list.is_empty() {
        let sentences: Vec<String> = list.iter().map(Advice::sentence).chain(slow).collect();
        return sentences.join(" ") + &traces;
    }
    let (slow, nothing) = match slow {
        Some(s) => (s + ". ", "Nothing else worth maintenance"),
        None => (String::new(), "Nothing worth maintenance"),
    };
    slow + &match &d.outcome {
        Outcome::NotSignificant { windows } if *windows > 0 => {
            let (stretches, differ, them) = if *windows == 1 {
                ("1 stretch".to_string(), "differs", "it")
            } else {
                (format!("{windows} stretches"), "differ", "them")
            };
            format!(
                "{nothing}: {stretches} of the recording {differ} from the model by \
                 more than the noise, but nothing the vocabulary names explains {them} beyond \
                 chance and by a size worth maintenance.{traces}"
            )
        }
        _ => format!(
            "{nothing}: the valve does what its model does, within the noise of \
             its reading.{traces}"
        ),
    }
}

/// That the valve strokes slowly ([`Note::SlowStrokes`]), with the speeds measured each way
/// it was asked to go fast (`speeds`: opening, closing), what asked it, and what to check.
pub fn slow_strokes(
    (opening_pct_per_s, closing_pct_per_s): (Option<f64>, Option<f64>),
    largest_step_pct: f64,
    asked_pct_per_s: f64,
    worth_pct_per_s: f64,
) -> String {
    let each = |what: &str, v: Option<f64>| v.map(|v| format!("{} %/s {what}", num(v)));
    let speeds: Vec<String> = [
        each("opening", opening_pct_per_s),
        each("closing", closing_pct_per_s),
    ]
    .into_iter()
    .flatten()
    .collect();
    let asked = if asked_pct_per_s < worth_pct_per_s {
        format!(
            ", where a valve in good order would have moved at {} %/s on the same O_P",
            num(asked_pct_per_s)
        )
    } else {
        format!(
            " on steps of up to {} %, where a valve in good order strokes at {} %/s or faster",
            num(largest_step_pct),
            num(worth_pct_per_s)
        )
    };
    format!(
        "the valve strokes slowly: at most {}{asked}; check the supply pressure, the pilot or \
         booster and the air path (tubing, filters, exhaust), and the actuator size",
        speeds.join(" and "),
    )
}

/// The modeller's verdict: what was missing, how large, and what adding it improved (never a
/// model made worse: stick-slip is judged in the slip distance), or that nothing worth
/// maintenance was missing, with the traces below it.
pub fn model_verdict(d: &Diagnosis) -> String {
    let traces = if d.traces.is_empty() {
        String::new()
    } else {
        let list: Vec<String> = d.traces.iter().map(trace).collect();
        format!(
            " Below what is worth maintenance (traces): {}.",
            list.join("; ")
        )
    };
    match &d.outcome {
        Outcome::Noise => format!(
            "Nothing significant is missing: the residual is consistent with measurement noise.{traces}"
        ),
        Outcome::NotSignificant { windows } => format!(
            "Nothing worth maintenance is missing from the vocabulary: {} above the noise floor, but no \
             effect improves the held-out fit by more than chance and by a size worth maintenance.{traces}",
            if *windows == 1 {
                "1 window stands".to_string()
            } else {
                format!("{windows} windows stand")
            }
        ),
        Outcome::Missing {
            heldout_sse_before: before,
            heldout_sse_after: after,
            ..
        } => {
            let named: Vec<String> = (d.findings.iter())
                .map(|f| format!("{} ({})", f.effect.name(), f.size.words()))
                .collect();
            let by_sse: Vec<&str> = (d.findings.iter())
                .filter(|f| matches!(f.measure, Measure::HeldoutSse { .. }))
                .map(|f| f.effect.name())
                .collect();
            let mut out = format!("The model was missing {}.", named.join(", "));
            if !by_sse.is_empty() && after < before {
                out += &format!(
                    " Adding {} lowers the held-out SSE from {} to {} %² ({:.0} % less).",
                    by_sse.join(", "),
                    num(*before),
                    num(*after),
                    100.0 * (1.0 - after / before)
                );
            }
            for f in &d.findings {
                if let m @ Measure::SlipDistance { .. } = &f.measure {
                    out += &format!(
                        " {} was judged by the slips of V_P: adding it lowers the {} (free-run SSE cannot judge a \
                         stick-slip limit cycle, whose phase O_P does not set).",
                        capitalised(f.effect.name()),
                        measure(m)
                    );
                }
            }
            out + &traces
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measures_read_with_their_change() {
        assert_eq!(
            measure(&Measure::HeldoutSse {
                before: 200.0,
                after: 50.0
            }),
            "held-out SSE 200 -> 50.0 %² (75 % less)"
        );
    }

    #[test]
    fn a_slow_valve_the_baseline_fits_is_still_called_slow() {
        // A sluggish first-order valve (1.2 s time constant, no speed limit) on 30 % steps:
        // the fitted FOPDT baseline is the valve, no effect is missing, and it opens and
        // closes at 25 %/s at most.
        let dt = 0.01;
        let op = vb_core::testkit::steps(6000, 1000, &[30.0, 60.0]);
        let e = vb_core::testkit::noise(op.len(), 0.05);
        let mut x = op[0];
        let vp: Vec<f64> = (op.iter().zip(e))
            .map(|(&u, e)| {
                x += (u - x) / 1.2 * dt;
                x + e
            })
            .collect();
        let rec = vb_core::testkit::Columns::new(op, vp, dt);
        let d =
            vb_analysis::diagnose::diagnose(&rec.view(), None, &|_, _| {}).expect("diagnosis runs");
        assert!(d.findings.is_empty(), "{:?}", d.findings);
        let slow = d.notes.iter().find_map(|n| match *n {
            vb_analysis::diagnose::Note::SlowStrokes {
                opening_pct_per_s: Some(open),
                closing_pct_per_s: Some(close),
                ..
            } => Some((open, close)),
            _ => None,
        });
        let (open, close) = slow.expect("the valve is called slow");
        assert!((20.0..=26.0).contains(&open), "{open}");
        assert!((20.0..=26.0).contains(&close), "{close}");
        // The planner hears it first, though nothing was missing from the model.
        let words = verdict(&d);
        assert!(
            words.starts_with("The valve strokes slowly: at most ")
                && words.contains(" %/s opening and ")
                && words.contains("Nothing else worth maintenance: "),
            "{words}"
        );
    }
}
