//! Reports people look at: self-contained HTML pages with inline SVG charts and tables.
//!
//! [`diagnosis_html`] turns a [`Diagnosis`] and its recording into one page (no server, no
//! external files): the recording against the model before and after, the residual, the worst
//! windows zoomed in, the step-delay evidence and the Table 1 rows.
//! [`identify::identification_html`] does the same for an identification (Tables 1 and 2, the
//! paper's Figs. 5-10). This module only formats results; it computes nothing about the valve.

pub mod identify;
pub mod plot;

use std::fmt::Write;

use crate::diagnose::Diagnosis;
use crate::metrics::Scores;
use plot::{Series, AFTER, BEFORE, EXTRA, MEASURED};

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

fn row(name: &str, s: &Scores) -> String {
    let filtered = if s.filtered {
        format!("{:.3} %", s.mae_filtered)
    } else {
        "n/a".into()
    };
    format!(
        "<tr><td>{}</td><td>{:.3} %</td><td>{filtered}</td><td>{:.2} %</td><td>{:.3}</td><td>{:.2} %</td><td>{}</td></tr>",
        esc(name),
        s.mae,
        100.0 * s.r2,
        s.sse,
        100.0 * s.rel_sse,
        s.n
    )
}

/// The diagnosis report of a recording (`t`, `op`, `vp`) as one self-contained HTML page.
pub fn diagnosis_html(title: &str, t: &[f64], op: &[f64], vp: &[f64], d: &Diagnosis) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>{0}</title><style>\
         body{{font-family:sans-serif;max-width:960px;margin:auto;color:#222}}\
         table{{border-collapse:collapse}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}\
         td:first-child{{text-align:left}}.verdict{{font-size:1.15em;background:#eef;padding:8px}}</style></head><body>\
         <h1>Diagnosis: {0}</h1><p class=\"verdict\">{1}</p>",
        esc(title),
        esc(&d.verdict)
    );
    let _ = write!(
        h,
        "<p>Baseline: <b>{}</b>. Noise floor of V_P: {:.3} % (standard deviation). Final model: <b>{}</b>.</p>",
        esc(&d.baseline.model),
        d.noise_floor_pct,
        esc(&d.final_model.model)
    );
    for n in &d.notes {
        let _ = write!(h, "<p><i>Note: {}</i></p>", esc(n));
    }
    h.push_str("<h2>Findings</h2>");
    if d.findings.is_empty() {
        h.push_str("<p>None.</p>");
    }
    for f in &d.findings {
        let _ = write!(
            h,
            "<h3>{}</h3><p>{}</p><p>Parameters: <code>{}</code><br>Held-out SSE {:.2} → {:.2} %², ΔBIC {:.0}</p>",
            f.effect.name(),
            esc(&f.evidence),
            esc(&serde_json::Value::Object(f.params.clone()).to_string()),
            f.heldout_sse_before,
            f.heldout_sse_after,
            f.delta_bic
        );
    }
    if let Some(c) = &d.heldout {
        let _ = write!(
            h,
            "<h2>Table 1 on the held-out blocks</h2><table><tr><th>model</th><th>MAE</th><th>MAE filtered</th>\
             <th>R²</th><th>SSE (%²)</th><th>Rel. SSE</th><th>samples</th></tr>{}{}</table>",
            row("before (baseline)", &c.before),
            row("after (final)", &c.after)
        );
    }
    let n = t.len();
    let lines = |title: &str, range: std::ops::Range<usize>| {
        plot::lines(
            title,
            "position (%)",
            t,
            &[
                Series {
                    name: "O_P",
                    y: op,
                    color: EXTRA,
                },
                Series {
                    name: "V_P measured",
                    y: vp,
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
            ],
            range,
        )
    };
    h.push_str("<h2>Whole recording</h2>");
    h.push_str(&lines("measured and simulated V_P", 0..n));
    let before: Vec<f64> = vp.iter().zip(&d.sim_before).map(|(m, s)| m - s).collect();
    let after: Vec<f64> = vp.iter().zip(&d.sim_after).map(|(m, s)| m - s).collect();
    h.push_str(&plot::lines(
        "residual (measured - simulated)",
        "residual (%)",
        t,
        &[
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
        ],
        0..n,
    ));
    let mut worst = d.mismatch_windows.clone();
    worst.sort_by(|a, b| b.excess_sse.total_cmp(&a.excess_sse));
    let _ = write!(
        h,
        "<h2>Mismatch windows: {} before, {} after</h2><p>The worst, zoomed in (±3 s):</p>",
        d.mismatch_windows.len(),
        d.windows_after.len()
    );
    let dt = if n > 1 { t[1] - t[0] } else { 1.0 };
    for w in worst.iter().take(4) {
        let a = (((w.start_s - t[0]) / dt - 3.0 / dt).max(0.0) as usize).min(n.saturating_sub(1));
        let b = ((((w.end_s - t[0]) / dt) + 3.0 / dt) as usize).clamp(a + 1, n);
        h.push_str(&lines(
            &format!("{:.1}-{:.1} s: {}", w.start_s, w.end_s, w.context),
            a..b,
        ));
    }
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
    h.push_str("<h2>All windows of the baseline</h2><table><tr><th>start (s)</th><th>end (s)</th><th>excess (%²)</th><th>context</th></tr>");
    for w in &d.mismatch_windows {
        let _ = write!(
            h,
            "<tr><td>{:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{}</td></tr>",
            w.start_s,
            w.end_s,
            w.excess_sse,
            esc(&w.context)
        );
    }
    h.push_str("</table></body></html>");
    h
}
