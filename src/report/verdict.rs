//! A diagnosis's conclusion in words: the verdict (what was missing, its size with its
//! interval, and the measure in which adding it improved the fit), the sizes of findings and
//! traces, and the figures of the final model.
//!
//! Not here: the evidence of each finding or the notes (`report::diagnose`).

use crate::diagnose::{Diagnosis, Figures, Measure, Outcome, Trace};
pub use crate::human::{sig3 as num, size_label as label, size_text};

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

/// `s` with its first letter in upper case.
fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next()
        .map_or(String::new(), |f| f.to_uppercase().chain(c).collect())
}

/// The verdict: what was missing, how large, and what adding it improved (never a model made
/// worse: stick-slip is judged in the slip distance), or that nothing worth maintenance was
/// missing, with the traces below it.
pub fn verdict(d: &Diagnosis) -> String {
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
}
