//! The identification report: the tables `valve-bridge identify` prints ([`text`]) and one
//! self-contained HTML page (interactive charts over inline SVG, no server, no external
//! files) with Table 1 (plus held-out scores and AIC/BIC), Table 2, the maintenance figures and
//! the plots of the paper: measured against every model over the whole recording and zoomed
//! into the worst windows (Figs. 8-10), the residuals, the step responses coloured by initial
//! opening (Figs. 5/6) and the delay against opening with its polynomial (Fig. 7).
//!
//! Only formats an [`Identification`]; computes nothing about the valve beyond choosing which
//! windows to zoom into.

use std::fmt::Write;

use plotters::style::RGBColor;

use super::chart::Dataset;
use super::plot::{self, Series, AFTER, BEFORE, EXTRA, MEASURED};
use super::{esc, page, row};
use crate::fit::determined::Why;
use crate::fit::{Identification, ModelFit};
use crate::metrics;
use crate::metrics::steps::StepAnalysis;
use crate::model::ModelKind;
use crate::recording::RecordingView;

/// Line colour of each model in the charts.
pub fn model_color(kind: ModelKind) -> RGBColor {
    match kind {
        ModelKind::Modelless => RGBColor(150, 150, 150),
        ModelKind::Delayed => RGBColor(148, 103, 189),
        ModelKind::Fopdt => BEFORE,
        ModelKind::Stiction => RGBColor(255, 127, 14),
        ModelKind::Pincart1 => EXTRA,
        ModelKind::Pincart2 => AFTER,
        ModelKind::Physical => RGBColor(44, 160, 44),
    }
}

/// Length of a zoom window, s (at least 30 samples).
const ZOOM_S: f64 = 10.0;
/// Number of worst windows zoomed into.
const ZOOMS: usize = 3;
/// Most step responses drawn.
const MAX_RESPONSES: usize = 400;
/// Largest normalised response drawn in the step overlay (share of the step).
const MAX_SHARE: f64 = 2.5;
/// Length of a drawn step response, s.
const RESPONSE_S: f64 = 4.0;

/// The `count` non-overlapping windows of `len` samples inside `mask` with the largest squared
/// error between `a` and `b`, largest first, as sample ranges.
pub fn worst_windows(
    a: &[f64],
    b: &[f64],
    mask: &[bool],
    len: usize,
    count: usize,
) -> Vec<std::ops::Range<usize>> {
    let n = a.len().min(b.len()).min(mask.len());
    if n < len || len == 0 {
        return Vec::new();
    }
    let e: Vec<f64> = (0..n)
        .map(|k| if mask[k] { (a[k] - b[k]).powi(2) } else { 0.0 })
        .collect();
    let mut sums: Vec<(f64, usize)> = Vec::new();
    let mut s: f64 = e[..len].iter().sum();
    let step = (len / 4).max(1);
    for start in 0..=n - len {
        if start > 0 {
            s += e[start + len - 1] - e[start - 1];
        }
        if start % step == 0 {
            sums.push((s, start));
        }
    }
    sums.sort_by(|x, y| y.0.total_cmp(&x.0));
    let mut out: Vec<std::ops::Range<usize>> = Vec::new();
    for (v, start) in sums {
        if out.len() == count || v <= 0.0 {
            break;
        }
        let r = start..start + len;
        if out.iter().all(|o| r.end <= o.start || r.start >= o.end) {
            out.push(r);
        }
    }
    out
}

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

/// The identification report of a recording as one HTML page.
pub fn html(title: &str, rec: &RecordingView, id: &Identification) -> String {
    let mut h = String::new();
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
        crate::human::num(id.sample_period_s),
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

/// Measured against every model over the whole recording and in the worst windows, and the
/// residuals.
fn curves_html(h: &mut String, rec: &RecordingView, id: &Identification) {
    let (t, op, vp) = (rec.t, rec.op, rec.vp);
    let n = t.len().min(op.len()).min(vp.len());
    let mut recording = vec![
        Series {
            name: "O_P",
            y: &op[..n],
            color: RGBColor(190, 190, 190),
        },
        Series {
            name: "V_P measured",
            y: &vp[..n],
            color: MEASURED,
        },
    ];
    for r in id.rows.iter().filter(|r| r.kind != ModelKind::Modelless) {
        recording.push(Series {
            name: r.kind.display_name(),
            y: &r.sim[..n],
            color: model_color(r.kind),
        });
    }
    let data = Dataset::new("recording", t, &recording, 0..n);
    h.push_str("<h2>Measured and simulated V_P</h2>");
    h.push_str(&data.html_and_chart(
        "whole recording (free run from the first sample)",
        "position (%)",
        "time (s)",
    ));
    let best = id
        .rows
        .iter()
        .filter(|r| r.scores.sse.is_finite())
        .min_by(|a, b| a.scores.sse.total_cmp(&b.scores.sse));
    if let Some(best) = best {
        let len = ((ZOOM_S / id.sample_period_s).round() as usize).max(30);
        let zooms = worst_windows(vp, &best.sim, &id.scored_mask, len, ZOOMS);
        if !zooms.is_empty() {
            let _ = write!(
                h,
                "<h2>Worst windows of the best model ({})</h2>",
                best.kind.display_name()
            );
        }
        for z in zooms {
            let a = z.start.saturating_sub(len / 5);
            let b = (z.end + len / 5).min(n);
            h.push_str(&data.chart(
                &format!("{:.1}–{:.1} s", t[a], t[b - 1]),
                "position (%)",
                "time (s)",
                a..b,
            ));
        }
    }
    let residuals: Vec<(ModelKind, Vec<f64>)> = id
        .rows
        .iter()
        .filter(|r| r.kind != ModelKind::Modelless)
        .map(|r| {
            (
                r.kind,
                vp[..n].iter().zip(&r.sim).map(|(m, s)| m - s).collect(),
            )
        })
        .collect();
    let res_series: Vec<Series> = residuals
        .iter()
        .map(|(k, y)| Series {
            name: k.display_name(),
            y,
            color: model_color(*k),
        })
        .collect();
    let data = Dataset::new("residual", t, &res_series, 0..n);
    h.push_str("<h2>Residual over time</h2>");
    h.push_str(&data.html_and_chart("measured − simulated V_P", "residual (%)", "time (s)"));
}

/// Figs. 5/6 and 7: step responses coloured by initial opening, delay against opening.
fn steps_section(h: &mut String, vp: &[f64], id: &Identification) {
    let s = &id.steps;
    let dt = id.sample_period_s;
    let _ = write!(
        h,
        "<h2>Step delays (Section 4.1)</h2><p>{} steps; delay until V_P covered {:.0} % of the step. Same direction: {}. Reversal: {}.</p>",
        s.steps.len(),
        100.0 * s.options_fraction,
        s.same,
        s.reversal
    );
    if let (Some(p), Some(c)) = (&s.reversal_poly, &s.pincart2) {
        let _ = write!(
            h,
            "<p>Reversal delay = {:.4e} V² + {:.4e} V + {:.4} s. Pin-cart II from it: a_p = {:.4e}, b_p = {:.4e}, c_p = {:.4} (crossing {:.3} / {:.3} / {:.3} s at 0 / 50 / 100 %).</p>",
            p.a, p.b, p.c, c.a_p, c.b_p, c.c_p, c.at_0_50_100_s[0], c.at_0_50_100_s[1], c.at_0_50_100_s[2]
        );
    }
    let len = ((RESPONSE_S / dt).round() as usize).max(3);
    let (lo, hi) = s
        .steps
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), st| {
            (l.min(st.from_pct), u.max(st.from_pct))
        });
    let curves: Vec<(RGBColor, Vec<(f64, f64)>)> = s
        .steps
        .iter()
        .filter_map(|st| st.reversal.map(|r| (st, r)))
        .take(MAX_RESPONSES)
        .map(|(st, rev)| {
            let v0 = vp[st.index - 1];
            let sign = st.size_pct.signum() * if rev { -1.0 } else { 1.0 };
            let end = st.hold_end.min(st.index + len).min(vp.len());
            let pts = (st.index - 1..end)
                .map(|k| {
                    (
                        (k as f64 - st.index as f64 + 1.0) * dt,
                        sign * (vp[k] - v0) / st.size_pct.abs(),
                    )
                })
                .collect();
            (
                plot::blue_to_yellow((st.from_pct - lo) / (hi - lo).max(1e-9)),
                pts,
            )
        })
        .collect();
    // A small step taken while the valve still travels from the previous one normalises to many
    // times its size and would squash every other curve: such responses are left out (counted).
    let all = curves.len();
    let curves: Vec<_> = curves
        .into_iter()
        .filter(|(_, pts)| pts.iter().all(|p: &(f64, f64)| p.1.abs() <= MAX_SHARE))
        .collect();
    let left_out = match all - curves.len() {
        0 => String::new(),
        n => format!("; {n} steps beyond ±{MAX_SHARE} left out"),
    };
    h.push_str(&plot::curves(
        "step responses, normalised: up = same direction, down = reversal (Fig. 6)",
        "time since the step (s)",
        "share of the step",
        &curves,
        &format!("colour: initial opening, blue {lo:.0} % to yellow {hi:.0} %{left_out}"),
    ));
    let pts = |rev: bool| {
        s.steps
            .iter()
            .filter(|st| st.reversal == Some(rev))
            .filter_map(|st| st.delay_s.map(|d| (st.from_pct, d)))
            .collect::<Vec<_>>()
    };
    let mut lines = Vec::new();
    if s.same.count > 0 && lo.is_finite() {
        lines.push((
            "mean same-direction delay",
            MEASURED,
            vec![(lo, s.same.mean_s), (hi, s.same.mean_s)],
        ));
    }
    if let Some(p) = &s.reversal_poly {
        lines.push((
            "reversal polynomial",
            BEFORE,
            (0..=50)
                .map(|i| {
                    let v = lo + (hi - lo) * i as f64 / 50.0;
                    (v, p.at(v))
                })
                .collect(),
        ));
    }
    h.push_str(&plot::scatter_lines(
        "delay against initial opening (Fig. 7)",
        "V_P at the step (%)",
        "delay (s)",
        &[
            ("same direction", AFTER, pts(false)),
            ("reversal", BEFORE, pts(true)),
        ],
        &lines,
    ));
}

/// The tables `valve-bridge identify` prints for the recording `source`.
pub fn text(source: &str, duration_s: f64, id: &Identification) -> String {
    let mut o = String::new();
    let _ = writeln!(
        o,
        "{source}: {} samples at {} s ({duration_s:.1} s)",
        id.n_samples,
        crate::human::num(id.sample_period_s),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worst_windows_do_not_overlap_and_find_the_bump() {
        let a = vec![0.0; 1000];
        let mut b = vec![0.0; 1000];
        for v in &mut b[500..520] {
            *v = 3.0;
        }
        for v in &mut b[100..110] {
            *v = 1.0;
        }
        let mask = vec![true; 1000];
        let w = worst_windows(&a, &b, &mask, 50, 3);
        assert_eq!(w.len(), 2);
        assert!(w[0].start <= 500 && w[0].end >= 520, "{w:?}");
        assert!(w[1].start <= 100 && w[1].end >= 110, "{w:?}");
    }
}
