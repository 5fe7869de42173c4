//! A fleet's page: its valves ranked by consequence for the process (the rule stated at the
//! top), each row coloured by its severity with what is wrong and what to do in a line per
//! finding, the figures maintenance acts on (a figure beyond what a healthy valve shows in
//! bold), each valve linked to its own diagnosis report and each finding to its evidence there,
//! and the valves that could not be diagnosed with their errors.

use std::fmt::Write;

use super::table::{Fleet, ValveSummary};
use crate::advice::{class, lines};
use crate::{esc, page};
use vb_core::vocabulary;

/// `value` with `digits` decimals, bold when `over`; `-` when absent.
fn cell(value: Option<f64>, digits: usize, over: bool) -> String {
    match value {
        Some(v) if over => format!("<td><b>{v:.digits$}</b></td>"),
        Some(v) => format!("<td>{v:.digits$}</td>"),
        None => "<td>-</td>".into(),
    }
}

fn valve_row(h: &mut String, rank: usize, v: &ValveSummary, f: &Fleet) {
    let l = &f.limits;
    let name = match &v.report {
        Some(r) => format!("<a href=\"{}\">{}</a>", esc(r), esc(&v.valve)),
        None => esc(&v.valve),
    };
    let beyond = |x: Option<f64>, limit: f64| x.is_some_and(|x| x > limit);
    let slow = |x: Option<f64>| x.is_some_and(|x| x < l.stroke_speed_pct_per_s);
    let what = if v.advice.is_empty() {
        "nothing worth maintenance".to_string()
    } else {
        lines(&v.advice)
    };
    let evidence = match &v.report {
        Some(r) if !v.advice.is_empty() => {
            format!(
                " <a href=\"{}#finding-{}\">evidence</a>",
                esc(r),
                esc(&v.advice[0].effect)
            )
        }
        _ => String::new(),
    };
    let _ = write!(
        h,
        "<tr class=\"{}\"><td>{rank}</td><td class=\"l\">{name}</td><td class=\"l\">{}</td><td>{:.1}</td><td class=\"l what\">{what}{evidence}</td>{}{}{}{}{}</tr>",
        class(v.severity),
        v.severity.map_or("none", vocabulary::Severity::name),
        v.priority,
        cell(v.dead_time_s, 2, beyond(v.dead_time_s, l.dead_time_s)),
        cell(v.reversal_delay_s, 2, beyond(v.reversal_delay_s, l.reversal_delay_s)),
        cell(v.friction_band_pct, 2, beyond(v.friction_band_pct, l.friction_band_pct)),
        cell(v.stroke_speed_open_pct_per_s, 1, slow(v.stroke_speed_open_pct_per_s)),
        cell(v.stroke_speed_close_pct_per_s, 1, slow(v.stroke_speed_close_pct_per_s)),
    );
}

/// The fleet page (`index.html` of `valve-bridge fleet --out`).
pub fn html(f: &Fleet) -> String {
    let l = &f.limits;
    let mut h = String::new();
    let _ = write!(
        h,
        "<p>{} valves diagnosed, {} could not be. Summaries: <a href=\"summary.csv\">summary.csv</a>, <a href=\"summary.json\">summary.json</a>; each valve's full diagnosis is linked from its name.</p>\
         <p class=\"rule\"><b>Ranked by consequence for the process.</b> {}</p>\
         <p>Figures beyond a healthy valve's in bold (dead time {} s, reversal delay {} s, friction band {} %, stroke speed at least {} %/s).</p>",
        f.diagnosed,
        f.failed,
        esc(&vocabulary::rule()),
        l.dead_time_s,
        l.reversal_delay_s,
        l.friction_band_pct,
        l.stroke_speed_pct_per_s
    );
    h.push_str("<style>table.fleet{font-size:.92em}table.fleet td.what{min-width:340px}table.fleet td:nth-child(2){white-space:nowrap}table.fleet tr.sev-high td:first-child{border-left:6px solid #c62828}</style>\
        <table class=\"fleet\"><tr><th>rank</th><th>valve</th><th>severity</th><th>priority</th><th>what is wrong, and what to do</th><th>dead time, s</th><th>reversal delay, s</th><th>friction band, %</th><th>opening speed at half travel, %/s</th><th>closing speed, %/s</th></tr>");
    let ok = f.valves.iter().filter(|v| v.error.is_none());
    for (i, v) in ok.enumerate() {
        valve_row(&mut h, i + 1, v, f);
    }
    h.push_str("</table>");
    if f.failed > 0 {
        h.push_str("<h2>Not diagnosed</h2><table><tr><th>valve</th><th>error</th></tr>");
        for v in f.valves.iter().filter(|v| v.error.is_some()) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"l\">{}</td></tr>",
                esc(&v.valve),
                esc(v.error.as_deref().unwrap_or(""))
            );
        }
        h.push_str("</table>");
    }
    page("Fleet diagnosis", &h)
}
