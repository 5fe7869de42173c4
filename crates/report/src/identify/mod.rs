//! The identification report: the tables `valve-bridge identify` prints ([`text`]) and one
//! self-contained HTML page (interactive charts over inline SVG, no server, no external
//! files) opening with the best model in plain words ([`best_line`]), then Table 1 (plus
//! held-out scores and AIC/BIC), Table 2, the maintenance figures and the plots of the paper
//! ([`charts`]).
//!
//! Only formats an [`Identification`]; computes nothing about the valve beyond choosing which
//! windows to zoom into.

mod charts;

use std::fmt::Write;

use super::{esc, page, row};
use charts::{curves_html, steps_section};
pub use charts::{model_color, worst_windows};
use vb_analysis::fit::determined::Why;
use vb_analysis::fit::{Identification, ModelFit};
use vb_core::metrics;
use vb_core::metrics::steps::StepAnalysis;
use vb_core::recording::RecordingView;

/// One row of Table 2: a fitted parameter's name, value, unit and, when the recording does not
/// pin it down, why.
struct ParamRow {
    name: &'static str,
    value: String,
    unit: &'static str,
    undetermined: Option<&'static str>,
}

/// Table 2's rows of a model: its parameters in physical units, then any parameter of the
/// search the recording does not pin down that has no row of its own.
fn param_rows(r: &ModelFit) -> Vec<ParamRow> {
    let why = |name: &str| {
        (r.undetermined.iter().find(|u| u.name == name)).map(|u| match u.why {
            Why::AtBound => "not determined: at a bound of its range",
            Why::Flat => "not determined: the error is flat along it",
        })
    };
    let params = r.params();
    let mut rows: Vec<ParamRow> = (params.iter())
        .map(|&(name, v, unit)| ParamRow {
            name,
            value: fmt_param(v),
            unit,
            undetermined: why(name),
        })
        .collect();
    for u in &r.undetermined {
        if params.iter().all(|p| p.0 != u.name) {
            rows.push(ParamRow {
                name: u.name,
                value: fmt_param(u.value),
                unit: "",
                undetermined: why(u.name),
            });
        }
    }
    rows
}

/// An optional figure with two decimals, or a dash.
fn opt(x: Option<f64>) -> String {
    x.filter(|v| v.is_finite())
        .map_or("–".into(), |v| format!("{v:.2}"))
}

/// The model that did best on the blocks it was not fitted on (lowest held-out SSE), and the
/// next best.
fn best_two(id: &Identification) -> (Option<&ModelFit>, Option<&ModelFit>) {
    let mut rows: Vec<&ModelFit> = (id.rows.iter())
        .filter(|r| r.heldout.sse.is_finite())
        .collect();
    rows.sort_by(|a, b| a.heldout.sse.total_cmp(&b.heldout.sse));
    (rows.first().copied(), rows.get(1).copied())
}

/// The best model in plain words: which, how closely it follows the valve, and by how much it
/// beats the next best.
pub fn best_line(id: &Identification) -> Option<String> {
    let (best, next) = best_two(id);
    let best = best?;
    let pct = |x: f64| format!("{:.2} %", 100.0 * x);
    let mut line = format!(
        "Best model: {}. Over the whole recording its V_P is {:.3} % from the measured one on \
         average; on the blocks it was not fitted on, its error is {} of the error of taking \
         V_P = O_P (held-out Rel. SSE)",
        best.kind.display_name(),
        best.scores.mae,
        pct(best.heldout.rel_sse)
    );
    if let Some(n) = next {
        let _ = write!(
            line,
            ", against {} for the next best, {}",
            pct(n.heldout.rel_sse),
            n.kind.display_name()
        );
    }
    Some(line + ".")
}

/// The identification report of a recording as one HTML page.
pub fn html(title: &str, rec: &RecordingView, id: &Identification) -> String {
    let mut h = String::new();
    if let Some(line) = best_line(id) {
        let _ = write!(h, "<p class=\"verdict\">{}</p>", esc(&line));
    }
    tables_html(&mut h, id);
    figures_html(&mut h, id);
    curves_html(&mut h, rec, id);
    steps_section(&mut h, rec.vp, id);
    page(&format!("Identification: {title}"), &h)
}

/// What was scored, Table 1, the held-out scores and Table 2.
fn tables_html(h: &mut String, id: &Identification) {
    let wins: Vec<String> = id
        .windows
        .iter()
        .map(|w| format!("{:.2}–{:.2} s", w.start_s, w.end_s))
        .collect();
    let _ = write!(
        h,
        "<p>{} samples at {} s. Windows fitted and scored ({}): {}. {} samples scored; held out: {} ({}).</p>",
        id.n_samples,
        vb_core::human::num(id.sample_period_s),
        if id.windows_auto {
            "saturation at 0/100 % left out automatically"
        } else {
            "given"
        },
        esc(&wins.join(", ")),
        id.n_scored,
        id.n_heldout,
        esc(&id.split.describe())
    );
    h.push_str(
        "<h2>Table 1: free-run simulation error over the windows</h2><table><tr><th>model</th><th>MAE</th>\
         <th>MAE filtered</th><th>R²</th><th>SSE (%²)</th><th>Rel. SSE</th><th>samples</th></tr>",
    );
    for r in &id.rows {
        h.push_str(&row(r.kind.display_name(), &r.scores));
    }
    let notes = metrics::table1_notes(id.rows.iter().map(|r| &r.scores));
    if !notes.is_empty() {
        let _ = write!(
            h,
            "</table><p class=\"vb-note\">{}</p><table>",
            esc(notes.trim())
        );
    }
    h.push_str("</table><h2>Held-out scores and information criteria</h2><p>Held out: each model fitted on the fit blocks only and scored on the blocks it never saw. AIC and BIC over all scored samples (lower is better).</p>\
        <table><tr><th>model</th><th>held-out SSE (%²)</th><th>held-out Rel. SSE</th><th>parameters</th><th>AIC</th><th>BIC</th></tr>");
    for r in &id.rows {
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.3}</td><td>{:.2} %</td><td>{}</td><td>{:.1}</td><td>{:.1}</td></tr>",
            r.kind.display_name(),
            r.heldout.sse,
            100.0 * r.heldout.rel_sse,
            r.n_params,
            r.aic,
            r.bic
        );
    }
    h.push_str("</table><h2>Table 2: fitted parameters</h2><table><tr><th>model</th><th>parameter</th><th>value</th><th>unit</th><th>determined by the recording</th></tr>");
    for r in &id.rows {
        let rows = param_rows(r);
        if rows.is_empty() {
            let _ = write!(
                h,
                "<tr><td>{}</td><td class=\"l\" colspan=\"4\">no parameters</td></tr>",
                r.kind.display_name()
            );
        }
        for (i, p) in rows.iter().enumerate() {
            let model = if i == 0 {
                format!(
                    "<td rowspan=\"{}\">{}</td>",
                    rows.len(),
                    r.kind.display_name()
                )
            } else {
                String::new()
            };
            let _ = write!(
                h,
                "<tr>{model}<td class=\"l\"><code>{}</code></td><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
                p.name,
                p.value,
                esc(p.unit),
                p.undetermined.map_or("yes".into(), |w| format!("<b>{w}</b>"))
            );
        }
    }
    h.push_str("</table>");
}

/// The maintenance figures of every fitted model.
fn figures_html(h: &mut String, id: &Identification) {
    h.push_str("<h2>Maintenance figures of the fitted models</h2><p>Measured by running standard tests through each fitted model around 50 % opening: steps of 1 % and 10 % approached from below, a 0.05 %/s ramp up and down, and a 10–90–10 % stroke.</p>\
        <table><tr><th>model</th><th>dead time (s)</th><th>1 % T63 / T86 (s)</th><th>10 % T63 / T86 (s)</th><th>dead band in ramp (%)</th><th>backlash / band parameter (%)</th><th>stick-slip (%)</th><th>max speed open / close (%/s)</th></tr>");
    for r in &id.rows {
        let f = &r.figures;
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{:.3}</td><td>{} / {}</td><td>{} / {}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td><td>{:.1} / {:.1}</td></tr>",
            r.kind.display_name(),
            f.dead_time_s,
            opt(f.t63_small_s),
            opt(f.t86_small_s),
            opt(f.t63_large_s),
            opt(f.t86_large_s),
            f.dead_band_pct,
            f.backlash_pct,
            f.stick_slip_pct,
            f.max_speed_open_pct_per_s,
            f.max_speed_close_pct_per_s
        );
    }
    h.push_str("</table>");
}

/// The tables `valve-bridge identify` prints for the recording `source`.
pub fn text(source: &str, duration_s: f64, id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{source}: {} samples at {} s ({duration_s:.1} s)",
        id.n_samples,
        vb_core::human::num(id.sample_period_s),
    );
    let list: Vec<String> = id
        .windows
        .iter()
        .map(|w| format!("{:.2}-{:.2}", w.start_s, w.end_s))
        .collect();
    if id.windows_auto {
        let _ = writeln!(
            o,
            "windows (saturation at 0/100 % left out automatically; choose with --windows): {}",
            list.join(",")
        );
    } else {
        let _ = writeln!(o, "windows (given): {}", list.join(","));
    }
    let _ = writeln!(
        o,
        "{} samples scored; held out: {} ({})",
        id.n_scored,
        id.n_heldout,
        id.split.describe()
    );
    o.push_str(&steps_summary(&id.steps));
    let _ = writeln!(o, "\nTable 1: free-run simulation error over the windows");
    let _ = writeln!(o, "{}", metrics::table1_header());
    for r in &id.rows {
        let _ = writeln!(
            o,
            "{}",
            metrics::table1_row(r.kind.display_name(), &r.scores)
        );
    }
    o.push_str(&metrics::table1_notes(id.rows.iter().map(|r| &r.scores)));
    if let Some(line) = best_line(id) {
        let _ = writeln!(o, "{line}");
    }
    let _ = writeln!(
        o,
        "\nHeld-out (fitted on the fit blocks only) and information criteria over the windows"
    );
    let _ = writeln!(
        o,
        "{:<20} {:>14} {:>10} {:>8} {:>14} {:>14}",
        "model", "held-out SSE", "Rel. SSE", "params", "AIC", "BIC"
    );
    for r in &id.rows {
        let _ = writeln!(
            o,
            "{:<20} {:>14.3} {:>9.2}% {:>8} {:>14.1} {:>14.1}",
            r.kind.display_name(),
            r.heldout.sse,
            100.0 * r.heldout.rel_sse,
            r.n_params,
            r.aic,
            r.bic
        );
    }
    o.push_str(&parameters_text(id));
    let sims: usize = id.rows.iter().map(|r| r.evals).sum();
    let _ = writeln!(
        o,
        "\nidentified in {:.2} s ({sims} full-length simulations equivalent)",
        id.elapsed_s
    );
    o
}

/// Table 2 and the maintenance figures as text.
fn parameters_text(id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "\nTable 2: fitted parameters");
    let _ = writeln!(
        o,
        "{:<20} {:<24} {:>12} {:<6} determined by the recording",
        "model", "parameter", "value", "unit"
    );
    for r in &id.rows {
        let rows = param_rows(r);
        if rows.is_empty() {
            let _ = writeln!(o, "{:<20} -", r.kind.display_name());
        }
        for (i, p) in rows.iter().enumerate() {
            let _ = writeln!(
                o,
                "{:<20} {:<24} {:>12} {:<6} {}",
                if i == 0 { r.kind.display_name() } else { "" },
                p.name,
                p.value,
                p.unit,
                p.undetermined.unwrap_or("yes")
            );
        }
    }
    let _ = writeln!(
        o,
        "\nMaintenance figures of the fitted models (simulated tests around 50 %)"
    );
    let _ = writeln!(
        o,
        "{:<20} {:>7} {:>14} {:>14} {:>9} {:>9} {:>10} {:>10} {:>10}",
        "model",
        "T_d s",
        "1% T63/T86 s",
        "10% T63/T86 s",
        "band %",
        "B_L/S %",
        "slip %",
        "open %/s",
        "close %/s"
    );
    for r in &id.rows {
        let f = &r.figures;
        let _ = writeln!(
            o,
            "{:<20} {:>7.3} {:>14} {:>14} {:>9.3} {:>9.3} {:>10.3} {:>10.1} {:>10.1}",
            r.kind.display_name(),
            f.dead_time_s,
            format!("{}/{}", opt(f.t63_small_s), opt(f.t86_small_s)),
            format!("{}/{}", opt(f.t63_large_s), opt(f.t86_large_s)),
            f.dead_band_pct,
            f.backlash_pct,
            f.stick_slip_pct,
            f.max_speed_open_pct_per_s,
            f.max_speed_close_pct_per_s
        );
    }
    o
}

/// The step-delay populations and the polynomial (identify and steps print them).
pub fn steps_summary(s: &StepAnalysis) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "steps: {} found; delay to {:.0} % of the step: same direction {} ; reversal {}",
        s.steps.len(),
        100.0 * s.options_fraction,
        s.same,
        s.reversal
    );
    let poly = match (&s.reversal_poly, &s.pincart2) {
        (Some(p), Some(c)) => format!(
            "reversal delay = {} V² + {} V + {} s; pin-cart II crossing time: a_p = {}, b_p = {}, c_p = {} ({:.3}/{:.3}/{:.3} s at 0/50/100 %)",
            fmt_param(p.a),
            fmt_param(p.b),
            fmt_param(p.c),
            fmt_param(c.a_p),
            fmt_param(c.b_p),
            fmt_param(c.c_p),
            c.at_0_50_100_s[0],
            c.at_0_50_100_s[1],
            c.at_0_50_100_s[2]
        ),
        (Some(p), None) => format!(
            "reversal delay = {} V² + {} V + {} s (no same-direction steps: no pin-cart II seed)",
            fmt_param(p.a),
            fmt_param(p.b),
            fmt_param(p.c)
        ),
        _ => "reversal polynomial: not enough reversals (needs 5 spread over 10 % of travel)".into(),
    };
    let _ = writeln!(o, "{poly}");
    o
}

/// Each step of the analysis, one line each, times from `t0` (s).
pub fn steps_list(s: &StepAnalysis, t0: f64) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{:>10} {:>9} {:>9} {:>10} {:>9}",
        "t (s)", "from %", "step %", "direction", "delay s"
    );
    for st in &s.steps {
        let _ = writeln!(
            o,
            "{:>10.2} {:>9.2} {:>+9.2} {:>10} {:>9}",
            t0 + st.t_s,
            st.from_pct,
            st.size_pct,
            match st.reversal {
                Some(true) => "reversal",
                Some(false) => "same",
                None => "first",
            },
            st.delay_s.map_or("-".into(), fmt_param)
        );
    }
    o
}

/// Four significant digits, scientific for very small or large magnitudes.
pub fn fmt_param(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}
