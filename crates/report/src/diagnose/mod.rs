//! A diagnosis for people: the sentences of its evidence, outcome and notes, the text printed
//! by `valve-bridge diagnose`, its `--json` document and its HTML page.
//!
//! The diagnosis itself ([`Diagnosis`]) is typed numbers; everything worded lives here. The
//! JSON document is the diagnosis as serde derives it, plus the rendered sentences
//! (`evidence` of each finding, `verdict`, `text` of each note, `context` of each window), so
//! a script can read either.

use std::fmt::Write;

use serde_json::Value;

mod page;

use super::esc;
use super::identify::fmt_param;
pub use super::verdict::{advice, model_verdict, verdict};
use super::verdict::{figures, measure, slow_strokes, trace};
pub use page::html;
use vb_analysis::diagnose::evidence::{
    Detail, Evidence, Rests, Share, Slips, StickSlipModel, Uneven,
};
use vb_analysis::diagnose::locate::{Context, Window};
use vb_analysis::diagnose::{Diagnosis, Effect, Finding, Note};
use vb_core::metrics;
use vb_core::recording::RecordingView;

/// What experiment separates `effect` from its look-alike `other` (or from its look-alikes):
/// where the response test does, its command and plan.
pub fn experiment(effect: Effect, other: Option<Effect>) -> &'static str {
    let pair = |a, b| (effect == a && other == Some(b)) || (effect == b && other == Some(a));
    if pair(Effect::SlewRate, Effect::MinSpeed) {
        return "the response test's steps of 0.25 to 10 % (`valve-bridge response-test --plan quick`): a slew limit lengthens only the large steps' T86, a minimum speed the small ones'";
    }
    if pair(Effect::Stiction, Effect::Deadband) {
        return "the response test's slow ramp out and back (`valve-bridge response-test --plan quick`, its signature): stiction moves in jumps larger than the sensor step, a valve in a deadband follows the ramp smoothly once past the band";
    }
    match effect {
        Effect::Backlash | Effect::Deadband | Effect::StateDependentDelay => {
            "the standard response test (`valve-bridge response-test --plan standard`): reversals of every size at 25, 50 and 75 %, where lost motion delays the small reversals, a deadband stops short of every step (its final error) and a state-dependent delay grows with the opening, and the signature's dead band"
        }
        Effect::Quantization | Effect::Stiction => {
            "the response test's slow ramp out and back (`valve-bridge response-test --plan quick`, its signature): stiction moves in jumps larger than the sensor step"
        }
        Effect::SlewRate | Effect::Asymmetry => {
            "the response test's 10 % steps both ways (`valve-bridge response-test --plan quick`): T86 opening against closing"
        }
        Effect::Calibration | Effect::Saturation => {
            "steps held to steady state across the whole travel, up to 0 and 100 % (`[source] kind = \"steps\"`)"
        }
        Effect::DeadTime => {
            "the response test's small steps held until the valve settles (`valve-bridge response-test --plan quick`)"
        }
        Effect::MinSpeed => {
            "the response test's steps of 0.25 to 10 % (`valve-bridge response-test --plan quick`): a minimum speed shows in the small ones"
        }
    }
}

/// What the valve was doing in a window of a kind.
pub fn describe(kind: Context) -> &'static str {
    match kind {
        Context::Reversal => "after a direction reversal of O_P",
        Context::LargeStep => "during a large step",
        Context::Move => "while O_P moves on in the same direction",
        Context::Rest => "at rest (O_P steady)",
        Context::NearLimit => "near a travel limit",
    }
}

/// A window's context: "after a direction reversal of O_P at 63 % opening".
pub fn context(w: &Window) -> String {
    format!("{} at {:.0} % opening", describe(w.kind), w.opening_pct)
}

/// "84 % of the excess error lies in 12 windows after direction reversals; ", or nothing
/// under half a percent (that is not where the error lies).
fn share(s: &Share, what: &str) -> String {
    if s.windows == 0 || s.share < 0.005 {
        return String::new();
    }
    format!(
        "{:.0} % of the excess error lies in {} windows {what}; ",
        100.0 * s.share,
        s.windows
    )
}

/// The step delays by direction, or the number of reversals when there are none to compare.
fn steps_text(e: &Evidence) -> String {
    let (r, s) = (&e.delays.reversal, &e.delays.same_direction);
    if r.count > 0 && s.count > 0 {
        format!(
            "steps against the previous movement start after {:.2} ± {:.2} s ({} steps), same-direction steps after {:.2} ± {:.2} s ({})",
            r.mean_s, r.sd_s, r.count, s.mean_s, s.sd_s, s.count
        )
    } else {
        format!(
            "{} reversals of O_P in the recording",
            e.delays.reversals_of_op
        )
    }
}

fn stick_slip_model(m: &StickSlipModel, capital: bool) -> String {
    match *m {
        StickSlipModel::Breakaway {
            breakaway_pct,
            gain_per_s,
            tolerance_band_pct,
        } => {
            let band = |text: &str| {
                if tolerance_band_pct > 0.0 {
                    format!("{text} {tolerance_band_pct:.2} %")
                } else {
                    String::new()
                }
            };
            if capital {
                format!(
                    "Stick-slip inside the positioner loop (breakaway {breakaway_pct:.2} %, positioner gain {gain_per_s:.2} /s{})",
                    band(", tolerance band")
                )
            } else {
                format!(
                    "stick-slip inside the positioner loop: the valve sticks when it slows and breaks away {breakaway_pct:.2} % later, overshooting and hunting{}",
                    band(" until a slip lands inside the positioner's tolerance band of")
                )
            }
        }
        StickSlipModel::Input {
            stickband_pct,
            jump_pct,
            gain_per_s,
        } if capital => format!(
            "Stick-slip on the valve's input (stickband {stickband_pct:.2} %, jump {jump_pct:.2} %, positioner gain {gain_per_s:.2} /s)"
        ),
        StickSlipModel::Input {
            stickband_pct,
            jump_pct,
            ..
        } => format!("stick-slip with a stickband of {stickband_pct:.2} % and jumps of {jump_pct:.2} %"),
    }
}

fn slips_text(s: &Slips, f: &Finding) -> String {
    format!(
        "V_P slips by {:.2} ± {:.2} % within {span:.2} s {} times while O_P moves less than half of that \
         (a slip is at least {:.2} %: five noise sigmas of {span:.2} s means, 1.5 sensor steps, 0.1 %), every {:.1} s on median, {} of {} successive slips \
         reversing (hunting); the model before slips {} times. {} slips {} times by {:.2} %. Judged by \
         the slip-size histograms of 10 s pieces of the held-out blocks: closer to the measured ones in {} of {} pieces (signed-rank test \
         p = {:.3}), distance {:.0} -> {:.0} slips{}; the held-out SSE goes {:.1} -> {:.1} %², which cannot judge a \
         limit cycle whose phase O_P does not set",
        s.size_pct,
        s.size_sd_pct,
        s.count,
        s.threshold_pct,
        s.median_interval_s,
        s.reversing,
        s.successive,
        s.slips_before,
        stick_slip_model(&s.model, true),
        s.slips_after,
        s.size_after_pct,
        s.pieces_closer,
        s.pieces_compared,
        s.p_value,
        s.distance_before,
        s.distance_after,
        if s.by_count {
            " (this model matches the slips only in part; stick-slip is named for their number, \
             which no smooth valve makes)"
        } else {
            ""
        },
        f.heldout_sse_before,
        f.heldout_sse_after,
        span = s.within_s,
    )
}

/// The evidence of a finding, as a sentence a person can follow against the plots.
pub fn evidence(f: &Finding) -> String {
    let (e, l) = (&f.facts, &f.facts.located);
    let rev = share(&l.after_reversals, "after direction reversals");
    let moves = share(&l.during_moves, "during moves of O_P");
    let rest = share(&l.at_rest, "at rest");
    let limit = share(&l.near_limits, "near a travel limit");
    let steps = steps_text(e);
    match &e.detail {
        Detail::DeadTime { dead_time_s, was_s } => format!(
            "{moves}{steps}; the valve answers every move late: a pure delay of {dead_time_s:.2} s (was {was_s:.2} s)"
        ),
        Detail::Backlash {
            friction_band_pct: Some(band),
            crossing_half_open_s,
            ..
        } => format!(
            "{rev}{steps}; after a reversal the positioner must cross a friction band of {band:.2} % before V_P moves \
             (about {crossing_half_open_s:.2} s after a 5 % reversal at half travel, longer after smaller ones): lost motion (backlash)"
        ),
        Detail::Backlash {
            crossing_half_open_s,
            crossing_closed_s,
            crossing_open_s,
            ..
        } => {
            let range = match (crossing_closed_s, crossing_open_s) {
                (Some(c), Some(o)) => format!(" at half travel ({c:.2} s closed, {o:.2} s open)"),
                _ => String::new(),
            };
            format!(
                "{rev}{steps}; V_P stays flat for about {crossing_half_open_s:.2} s more after a reversal{range}: lost motion (backlash)"
            )
        }
        Detail::StateDependentDelay {
            reversal_below_half_s,
            reversal_above_half_s,
            open_vs_closed,
            crossing_closed_s,
            crossing_open_s,
        } => {
            let split = match (reversal_below_half_s, reversal_above_half_s) {
                (Some(b), Some(a)) => format!(
                    "reversal delays average {b:.2} s below 50 % opening and {a:.2} s above"
                ),
                _ => steps,
            };
            match (open_vs_closed, crossing_closed_s, crossing_open_s) {
                (Some(r), _, _) => format!(
                    "the response slows with opening: {split}; the fit gives a valve {r:.1} times slower fully open than closed"
                ),
                (None, Some(c), Some(o)) => format!(
                    "{split}; the cart-crossing time grows from {c:.2} s closed to {o:.2} s open (pin-cart II, eq. 7)"
                ),
                _ => split,
            }
        }
        Detail::SlewRate {
            open_speed,
            close_speed,
            slew_pct_per_s,
            closing_slew_pct_per_s,
            gain_per_s,
        } => format!(
            "{moves}V_P never moves faster than {open_speed:.1} %/s opening and {close_speed:.1} %/s closing (99.9th percentile): {}",
            match gain_per_s {
                Some(g) => format!(
                    "it moves at its positioner's gain of {g:.2} /s times the error and reaches no speed limit"
                ),
                None => slew_limits(*slew_pct_per_s, *closing_slew_pct_per_s),
            }
        ),
        Detail::Asymmetry(u) => uneven_text(u),
        Detail::MinSpeed {
            min_speed_pct_per_s,
        } => format!(
            "small errors close at a constant rate of about {min_speed_pct_per_s:.2} %/s instead of exponentially"
        ),
        Detail::Stiction {
            holds_with_jumps,
            holds,
            model,
        } => format!(
            "{rest}{rev}{holds_with_jumps} of {holds} holds show a sudden jump of V_P after it had settled: {}",
            stick_slip_model(model, false)
        ),
        Detail::Slips(s) => slips_text(s, f),
        Detail::Deadband(r) => deadband_text(r),
        Detail::Saturation {
            travel_min_pct,
            travel_max_pct,
            windup_pct,
        } => format!(
            "{limit}V_P stays within {travel_min_pct:.1}-{travel_max_pct:.1} % while O_P goes beyond: travel limited \
             (the positioner's drive winds up {windup_pct:.1} % past the stop and must come back before the valve leaves it)"
        ),
        Detail::Quantization { lattice_pct } => format!(
            "every V_P value lies on a lattice of {lattice_pct:.3} %: the position sensor's resolution"
        ),
        Detail::Calibration {
            mean_offset_pct,
            holds,
            gain,
            offset_pct,
        } => format!(
            "{rest}settled V_P sits {mean_offset_pct:+.2} % from O_P on average over {holds} holds; the fit gives V_P = {gain:.3} × O_P {offset_pct:+.2} %: \
             a gain or offset between command and position"
        ),
    }
}

/// The evidence of a deadband: where settled V_P sits from O_P after opening and after closing
/// or, in a loop that never holds O_P for 3 s (no holds), how far from it V_P rests.
fn deadband_text(r: &Rests) -> String {
    let cause = format!(
        "the positioner stops inside a deadband of {:.2} %",
        r.deadband_pct
    );
    if r.holds_opening + r.holds_closing == 0 {
        return format!(
            "O_P is never held for 3 s or more; V_P rests up to {:.2} % from it (95 % of the samples it stays still): {cause}",
            r.rest_distance_pct
        );
    }
    format!(
        "settled V_P sits {:+.2} % from O_P after opening ({} holds) and {:+.2} % after closing ({}): {cause}",
        r.offset_after_opening_pct, r.holds_opening, r.offset_after_closing_pct, r.holds_closing
    )
}

/// The evidence of uneven stroke speeds: V_P's speeds each way against the fit's limits.
fn uneven_text(u: &Uneven) -> String {
    let of = if u.held {
        "99.9th percentile of the speeds held for 0.3 s or more; its fastest moves are alike both ways"
    } else {
        "99.9th percentile"
    };
    format!(
        "V_P opens at up to {:.1} %/s but closes at up to {:.1} %/s ({of}); the fit gives {:.1} %/s opening and {:.1} %/s closing",
        u.open_speed, u.close_speed, u.fitted_open_pct_per_s, u.fitted_close_pct_per_s
    )
}

/// The slew-rate limit a finding's model has: one, or one each way (a valve slow both ways).
fn slew_limits(opening: f64, closing: Option<f64>) -> String {
    match closing {
        Some(close) => format!(
            "slew-rate limits of {opening:.1} %/s opening and {close:.1} %/s closing, both slow"
        ),
        None => format!("a slew-rate limit of {opening:.1} %/s"),
    }
}

/// A note as a sentence.
pub fn note(n: &Note) -> String {
    match *n {
        Note::LookAlike {
            effect,
            other,
            removed_share,
            other_removed_share,
        } => format!(
            "{} and {} explain the mismatch almost equally well ({:.0} % vs {:.0} % of the held-out error removed): \
             this recording cannot tell them apart; {} would",
            effect.name(),
            other.name(),
            100.0 * removed_share,
            100.0 * other_removed_share,
            experiment(effect, Some(other))
        ),
        Note::JudgedBySlips {
            heldout_sse_before,
            heldout_sse_after,
        } => format!(
            "stiction was judged by the slips of V_P (slip-size histograms of 10 s pieces of the held-out blocks, signed-rank test), \
             not by the free-run error: a stick-slip limit cycle's phase is not set by O_P, so a simulated one \
             slips at other moments than the valve, and the held-out SSE cannot show that it slips like the \
             valve ({heldout_sse_before:.1} -> {heldout_sse_after:.1} %²); to confirm it, run {}",
            experiment(Effect::Stiction, None)
        ),
        Note::SensorCalibration {
            gain,
            offset_pct,
            heldout_sse_before,
            heldout_sse_after,
        } => format!(
            "the reading's calibration (V_P = {gain:.4} x {offset_pct:+.3} %, within what a healthy sensor reads) \
             was put in the model before the effects were judged, not named: it explained more of the held-out \
             error than any effect ({heldout_sse_before:.1} -> {heldout_sse_after:.1} %²), and an effect fitted \
             without it would stand in for it"
        ),
        Note::BelowWorth {
            effect,
            size,
            heldout_sse_before,
            heldout_sse_after,
        } => format!(
            "{} ({}) is real but below what is worth maintenance; it was put in the model before the effects were \
             judged, not named: it explained more of the held-out error than any effect worth maintenance \
             ({heldout_sse_before:.1} -> {heldout_sse_after:.1} %²), and one judged without it could stand in for it",
            effect.name(),
            size.words()
        ),
        Note::SlowStrokes {
            opening_pct_per_s,
            closing_pct_per_s,
            largest_step_pct,
            asked_pct_per_s,
            worth_pct_per_s,
        } => slow_strokes(
            (opening_pct_per_s, closing_pct_per_s),
            largest_step_pct,
            asked_pct_per_s,
            worth_pct_per_s,
        ),
        Note::StepsInBand {
            step_pct,
            band_pct,
        } => format!(
            "V_P steps by {step_pct:.2} % at a time inside the deadband of {band_pct:.2} %, a quarter of it or less: \
             a pulsing positioner's steps back into its tolerance band, not judged stick-slip; a stem that sticks \
             and jumps by that little inside the band looks the same, and narrowing the band tells them apart \
             (stick-slip keeps its jumps, the positioner's steps shrink with the band)"
        ),
        Note::FewReversals { reversals } => format!(
            "only {reversals} reversals of O_P: backlash, deadband and state-dependent delay show at reversals; {} would test for them",
            experiment(Effect::Backlash, None)
        ),
    }
}

/// The fitted parameters a finding freed, as `(name, value, unit)`: the names and values of
/// `params` in the `--json` document.
fn finding_params(f: &Finding) -> Vec<(&'static str, String, &'static str)> {
    (f.knobs.iter())
        .map(|k| {
            let value = f.params.get(k.label()).and_then(Value::as_f64);
            (k.label(), value.map_or("-".into(), fmt_param), k.unit())
        })
        .collect()
}

/// A finding's fitted parameters as an HTML table.
fn params_html(f: &Finding) -> String {
    let mut h =
        String::from("<table><tr><th>fitted parameter</th><th>value</th><th>unit</th></tr>");
    for (name, value, unit) in finding_params(f) {
        let _ = write!(
            h,
            "<tr><td><code>{name}</code></td><td>{value}</td><td class=\"l\">{}</td></tr>",
            esc(unit)
        );
    }
    h.push_str("</table>");
    h
}

/// The `--json` document: the diagnosis as derived, plus the rendered sentences.
pub fn json(d: &Diagnosis) -> Value {
    let mut v = serde_json::to_value(d).unwrap_or(Value::Null);
    if let Some(list) = v["findings"].as_array_mut() {
        for (j, f) in list.iter_mut().zip(&d.findings) {
            j["evidence"] = Value::String(evidence(f));
        }
    }
    if let Some(list) = v["notes"].as_array_mut() {
        for (j, n) in list.iter_mut().zip(&d.notes) {
            j["text"] = Value::String(note(n));
        }
    }
    if let Some(list) = v["mismatch_windows"].as_array_mut() {
        for (j, w) in list.iter_mut().zip(&d.mismatch_windows) {
            j["context"] = Value::String(context(w));
        }
    }
    v["verdict"] = Value::String(verdict(d));
    v["model_verdict"] = Value::String(model_verdict(d));
    v["advice"] = serde_json::to_value(advice(d)).unwrap_or(Value::Null);
    v
}

/// The files `diagnose --out` writes: `report.html` (titled `title`), `model.toml` (the final
/// model) and `diagnosis.json` (the `--json` document).
pub fn files(title: &str, rec: &RecordingView, d: &Diagnosis) -> [(&'static str, String); 3] {
    let doc = serde_json::to_string_pretty(&json(d)).unwrap_or_else(|_| "null".into());
    [
        ("report.html", html(title, rec, d)),
        ("model.toml", d.final_model.spec.to_toml()),
        ("diagnosis.json", doc),
    ]
}

/// The text `valve-bridge diagnose` prints.
pub fn text(d: &Diagnosis) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "baseline: {} (held-out SSE {:.2} %², whole SSE {:.2} %²)",
        d.baseline.model, d.baseline.heldout_sse, d.baseline.sse
    );
    let _ = writeln!(
        o,
        "noise floor of V_P: {:.3} % (standard deviation)",
        d.noise_floor_pct
    );
    let mut worst = d.mismatch_windows.clone();
    worst.sort_by(|a, b| b.excess_sse.total_cmp(&a.excess_sse));
    let _ = writeln!(
        o,
        "\n{} windows where the baseline misses by more than the noise (largest first):",
        worst.len()
    );
    for w in worst.iter().take(10) {
        let _ = writeln!(
            o,
            "  {:>8.2}-{:<8.2} s  excess {:>8.2} %²  {}",
            w.start_s,
            w.end_s,
            w.excess_sse,
            context(w)
        );
    }
    if d.findings.is_empty() {
        let _ = writeln!(o, "\nfindings: none");
    }
    for f in &d.findings {
        let _ = writeln!(o, "\nfinding: {}", f.effect.name());
        if !f.alternatives.is_empty() {
            let names: Vec<&str> = f.alternatives.iter().map(|e| e.name()).collect();
            let _ = writeln!(o, "  or, as well: {} (see the notes)", names.join(", "));
        }
        let _ = writeln!(o, "  size: {} (90 % interval)", f.size.words());
        let _ = writeln!(o, "  evidence: {}", evidence(f));
        let _ = writeln!(o, "  parameters:");
        for (name, value, unit) in finding_params(f) {
            let _ = writeln!(o, "    {name:<26} {value:>12} {unit}");
        }
        let _ = writeln!(
            o,
            "  improved: {}, delta BIC {:.0}",
            measure(&f.measure),
            f.delta_bic
        );
    }
    for t in &d.traces {
        let _ = writeln!(o, "\ntrace (not worth maintenance): {}", trace(t));
    }
    let _ = writeln!(o, "\nfinal model: {}", figures(&d.figures));
    if let Some(h) = &d.heldout {
        let _ = writeln!(o, "\nTable 1 on the held-out blocks:");
        let _ = writeln!(o, "{}", metrics::table1_header());
        let _ = writeln!(o, "{}", metrics::table1_row("before (baseline)", &h.before));
        let _ = writeln!(o, "{}", metrics::table1_row("after (final)", &h.after));
        o.push_str(&metrics::table1_notes([&h.before, &h.after]));
    }
    let _ = writeln!(
        o,
        "\nmismatch windows: {} before, {} after; excess {:.1} -> {:.1} %²",
        d.mismatch_windows.len(),
        d.windows_after.len(),
        d.mismatch_windows.iter().map(|w| w.excess_sse).sum::<f64>(),
        d.windows_after.iter().map(|w| w.excess_sse).sum::<f64>()
    );
    for n in &d.notes {
        let _ = writeln!(o, "note: {}", note(n));
    }
    let _ = writeln!(o, "\nmodel: {}", model_verdict(d));
    let list = advice(d);
    if list.is_empty() {
        let _ = writeln!(o, "\nverdict: {}", verdict(d));
    } else {
        let _ = writeln!(o, "\nverdict, highest priority first:");
        for a in &list {
            let _ = writeln!(o, "  {}", a.sentence());
        }
        let traces = super::verdict::plain_traces(d);
        if !traces.is_empty() {
            let _ = writeln!(o, "  Too small to act on: {}.", traces.join("; "));
        }
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::response_plan::Plan;

    #[test]
    fn the_experiments_name_a_response_test_plan_that_exists() {
        let mut named = 0;
        for effect in Effect::ALL {
            for other in std::iter::once(None).chain(Effect::ALL.map(Some)) {
                let text = experiment(effect, other);
                let Some((_, rest)) = text.split_once("valve-bridge response-test --plan ") else {
                    continue;
                };
                let plan: String = rest
                    .chars()
                    .take_while(char::is_ascii_alphanumeric)
                    .collect();
                assert!(
                    Plan::load(&plan, (0.0, 100.0)).is_ok(),
                    "{effect:?}: {plan}"
                );
                named += 1;
            }
        }
        assert!(named > 0);
        let look_alike = note(&Note::LookAlike {
            effect: Effect::Backlash,
            other: Effect::StateDependentDelay,
            removed_share: 0.5,
            other_removed_share: 0.48,
        });
        assert!(
            look_alike.contains("`valve-bridge response-test --plan standard`"),
            "{look_alike}"
        );
        let few = note(&Note::FewReversals { reversals: 2 });
        assert!(few.contains("valve-bridge response-test"), "{few}");
        let steps = note(&Note::StepsInBand {
            step_pct: 0.306,
            band_pct: 2.42,
        });
        assert!(
            steps.contains("0.31 %") && steps.contains("2.42 %"),
            "{steps}"
        );
    }

    #[test]
    fn a_deadband_in_a_loop_without_holds_shows_where_the_valve_rests_instead() {
        let rests = |holds, rest_distance_pct, deadband_pct| Rests {
            offset_after_opening_pct: -0.41,
            holds_opening: holds,
            offset_after_closing_pct: 0.38,
            holds_closing: holds,
            rest_distance_pct,
            deadband_pct,
        };
        let held = deadband_text(&rests(6, 0.9, 0.8));
        assert!(
            held.contains("-0.41 %") && held.contains("(6 holds)"),
            "{held}"
        );
        let loop_only = deadband_text(&rests(0, 1.03, 2.17));
        assert!(
            loop_only.contains("1.03 %")
                && loop_only.contains("2.17 %")
                && !loop_only.contains("holds"),
            "{loop_only}"
        );
    }
}
