//! A fleet's page: its valves ranked by attention, the figures maintenance acts on (a figure
//! beyond what a healthy valve shows in bold), each valve linked to its own diagnosis report,
//! and the valves that could not be diagnosed with their errors.

use std::fmt::Write;

use super::fleet_table::{Fleet, ValveSummary};
use super::{esc, page};

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
    let findings = if v.findings.is_empty() {
        "none".to_string()
    } else {
        let sized = (v.findings.iter().enumerate())
            .map(|(i, f)| match v.sizes.get(i) {
                Some(size) => format!("{f}: {size}"),
                None => f.clone(),
            })
            .collect::<Vec<_>>();
        sized.join(", ")
    };
    let _ = write!(
        h,
        "<tr><td>{rank}</td><td class=\"l\">{name}</td><td>{:.2}</td><td class=\"l\">{}</td>{}{}{}{}{}<td class=\"l\">{}</td></tr>",
        v.attention,
        esc(&findings),
        cell(v.dead_time_s, 2, beyond(v.dead_time_s, l.dead_time_s)),
        cell(v.reversal_delay_s, 2, beyond(v.reversal_delay_s, l.reversal_delay_s)),
        cell(v.friction_band_pct, 2, beyond(v.friction_band_pct, l.friction_band_pct)),
        cell(v.stroke_speed_open_pct_per_s, 1, slow(v.stroke_speed_open_pct_per_s)),
        cell(v.stroke_speed_close_pct_per_s, 1, slow(v.stroke_speed_close_pct_per_s)),
        esc(v.verdict.as_deref().unwrap_or("")),
    );
}

/// The fleet page (`index.html` of `valve-bridge fleet --out`).
pub fn html(f: &Fleet) -> String {
    let l = &f.limits;
    let mut h = String::new();
    let _ = write!(
        h,
        "<p>{} valves diagnosed, {} could not be. Ranked by attention: the number of findings plus how far each figure lies beyond a healthy valve's (dead time {} s, reversal delay {} s, friction band {} %, stroke speed at least {} %/s; beyond in bold). Summaries: <a href=\"summary.csv\">summary.csv</a>, <a href=\"summary.json\">summary.json</a>.</p>",
        f.diagnosed, f.failed, l.dead_time_s, l.reversal_delay_s, l.friction_band_pct, l.stroke_speed_pct_per_s
    );
    h.push_str("<table><tr><th>rank</th><th>valve</th><th>attention</th><th>findings</th><th>dead time, s</th><th>reversal delay, s</th><th>friction band, %</th><th>stroke speed at half travel opening, %/s</th><th>closing, %/s</th><th>verdict</th></tr>");
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
