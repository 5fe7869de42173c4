//! The diagnosis report as one self-contained HTML page: the verdict a maintenance planner
//! acts on at the top (each finding's severity, what is wrong with its size, what it does to
//! control and what to do, linked to its evidence below), then the modeller's detail: the
//! findings with their evidence, fitted parameters and the measure each improved, the traces,
//! Table 1 on the held-out blocks, the recording against the model before and after (opening
//! zoomed on the worst mismatch), the residual, the worst windows and the step delays.
//!
//! Not here: the sentences themselves (the parent module, [`vb_core::vocabulary`]).

use std::fmt::Write;

use super::super::advice::cards;
use super::super::chart::{Dataset, View};
use super::super::plot::{self, Series, AFTER, BEFORE, EXTRA, MEASURED};
use super::super::verdict::plain_traces;
use super::super::{esc, page, prose, row};
use super::{
    advice, context, evidence, figures, measure, model_verdict, note, params_html, trace, verdict,
};
use vb_analysis::diagnose::Diagnosis;
use vb_core::recording::RecordingView;

/// Least stretch of time the whole-recording chart opens on around the worst mismatch, s.
const OPEN_ON_S: f64 = 20.0;

/// The diagnosis report of a recording as one self-contained HTML page.
pub fn html(title: &str, rec: &RecordingView, d: &Diagnosis) -> String {
    let mut h = String::new();
    let list = advice(d);
    if list.is_empty() {
        let _ = write!(h, "<p class=\"verdict\">{}</p>", prose(&verdict(d)));
    } else {
        h.push_str(&cards(&list, "#finding-"));
        let traces = plain_traces(d);
        if !traces.is_empty() {
            let _ = write!(
                h,
                "<p>Too small to act on: {}.</p>",
                prose(&traces.join("; "))
            );
        }
    }
    let _ = write!(
        h,
        "<p>Baseline: <b>{}</b>. Noise floor of V_P: {:.3} % (standard deviation). Final model: <b>{}</b>: {}.</p>",
        esc(&d.baseline.model),
        d.noise_floor_pct,
        esc(&d.final_model.model),
        esc(&figures(&d.figures))
    );
    for n in &d.notes {
        let _ = write!(h, "<p><i>Note: {}</i></p>", prose(&note(n)));
    }
    findings_html(&mut h, d);
    curves_html(&mut h, rec, d);
    steps_html(&mut h, d);
    h.push_str("<h2>All windows of the baseline</h2><table><tr><th>start (s)</th><th>end (s)</th><th>excess (%²)</th><th>context</th></tr>");
    for w in &d.mismatch_windows {
        let _ = write!(
            h,
            "<tr><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td></tr>",
            w.start_s,
            w.end_s,
            w.excess_sse,
            esc(&context(w))
        );
    }
    h.push_str("</table>");
    page(&format!("Diagnosis: {title}"), &h)
}

/// The findings and the held-out Table 1 rows.
fn findings_html(h: &mut String, d: &Diagnosis) {
    let _ = write!(
        h,
        "<h2>Findings</h2><p>For the modeller: {}</p>",
        prose(&model_verdict(d))
    );
    for f in &d.findings {
        let alternatives = if f.alternatives.is_empty() {
            String::new()
        } else {
            let names: Vec<&str> = f.alternatives.iter().map(|e| e.name()).collect();
            format!(" <small>(or, as well: {})</small>", names.join(", "))
        };
        let _ = write!(
            h,
            "<h3 id=\"finding-{0}\">{1} <small><code>{0}</code></small>{alternatives}</h3><p><b>{2}</b> (90 % interval)</p><p>{3}</p>{4}<p>Improved: {5}, ΔBIC {6:.0}</p>",
            f.effect.name(),
            esc(vb_core::vocabulary::words(f.effect).plain),
            esc(&f.size.words()),
            prose(&evidence(f)),
            params_html(f),
            esc(&measure(&f.measure)),
            f.delta_bic
        );
    }
    if !d.traces.is_empty() {
        h.push_str("<h2>Traces (not worth maintenance)</h2><ul>");
        for t in &d.traces {
            let _ = write!(h, "<li>{}</li>", prose(&trace(t)));
        }
        h.push_str("</ul>");
    }
    if let Some(c) = &d.heldout {
        let _ = write!(
            h,
            "<h2>Table 1 on the held-out blocks</h2><table><tr><th>model</th><th>MAE</th><th>MAE filtered</th>\
             <th>R²</th><th>SSE (%²)</th><th>Rel. SSE</th><th>samples</th></tr>{}{}</table>",
            row("before (baseline)", &c.before),
            row("after (final)", &c.after)
        );
        let notes = vb_core::metrics::table1_notes([&c.before, &c.after]);
        if !notes.is_empty() {
            let _ = write!(h, "<p class=\"vb-note\">{}</p>", esc(notes.trim()));
        }
    }
}

/// The whole recording, the residual, and the worst windows zoomed in.
fn curves_html(h: &mut String, rec: &RecordingView, d: &Diagnosis) {
    let (t, n) = (rec.t, rec.len());
    let recording = [
        Series {
            name: "O_P",
            y: rec.op,
            color: EXTRA,
        },
        Series {
            name: "V_P measured",
            y: rec.vp,
            color: MEASURED,
        },
        Series {
            name: "baseline",
            y: &d.sim_before,
            color: BEFORE,
        },
        Series {
            name: "final",
            y: &d.sim_after,
            color: AFTER,
        },
    ];
    let data = Dataset::new("recording", t, &recording, 0..n);
    h.push_str("<h2>Whole recording</h2>");
    // Over a long recording the lines overlap into one: the chart opens on the worst mismatch.
    let worst = (d.mismatch_windows.iter()).max_by(|a, b| a.excess_sse.total_cmp(&b.excess_sse));
    let zoom = worst
        .map(|w| {
            let mid = 0.5 * (w.start_s + w.end_s);
            let half = (0.5 * (w.end_s - w.start_s) + 3.0).max(OPEN_ON_S / 2.0);
            ((mid - half).max(t[0]), (mid + half).min(t[n - 1]))
        })
        .filter(|(a, b)| b - a < 0.8 * (t[n - 1] - t[0]));
    let title = match zoom {
        Some((a, b)) => format!(
            "measured and simulated V_P, opened on the worst mismatch ({a:.0}-{b:.0} s; double-click for the whole recording)"
        ),
        None => "measured and simulated V_P".into(),
    };
    let view = View { shown: None, zoom };
    h.push_str(&data.html_and_view(&title, "position (%)", "time (s)", &view));
    let residual =
        |sim: &[f64]| -> Vec<f64> { rec.vp.iter().zip(sim).map(|(m, s)| m - s).collect() };
    let (before, after) = (residual(&d.sim_before), residual(&d.sim_after));
    let residuals = [
        Series {
            name: "baseline",
            y: &before,
            color: BEFORE,
        },
        Series {
            name: "final",
            y: &after,
            color: AFTER,
        },
    ];
    let res = Dataset::new("residual", t, &residuals, 0..n);
    h.push_str(&res.html_and_chart(
        "residual (measured - simulated)",
        "residual (%)",
        "time (s)",
    ));
    let mut worst = d.mismatch_windows.clone();
    worst.sort_by(|a, b| b.excess_sse.total_cmp(&a.excess_sse));
    let _ = write!(
        h,
        "<h2>Mismatch windows: {} before, {} after</h2><p>The worst, zoomed in (±3 s):</p>",
        d.mismatch_windows.len(),
        d.windows_after.len()
    );
    let dt = rec.dt;
    for w in worst.iter().take(4) {
        let a = (((w.start_s - t[0]) / dt - 3.0 / dt).max(0.0) as usize).min(n.saturating_sub(1));
        let b = ((((w.end_s - t[0]) / dt) + 3.0 / dt) as usize).clamp(a + 1, n);
        h.push_str(&data.chart(
            &format!("{:.1}-{:.1} s: {}", w.start_s, w.end_s, context(w)),
            "position (%)",
            "time (s)",
            a..b,
        ));
    }
}

/// The step delays against opening.
fn steps_html(h: &mut String, d: &Diagnosis) {
    let steps = |rev: bool| {
        d.steps
            .iter()
            .filter(|s| s.reversal == rev)
            .map(|s| (s.from_pct, s.delay_s))
            .collect::<Vec<_>>()
    };
    let scatter = plot::scatter(
        "step delay against opening (evidence for backlash and state-dependent delay)",
        "V_P at the step (%)",
        "delay (s)",
        &[
            ("same direction", AFTER, steps(false)),
            ("reversal", BEFORE, steps(true)),
        ],
    );
    if !scatter.is_empty() {
        h.push_str("<h2>Step delays</h2>");
        h.push_str(&scatter);
    }
}
