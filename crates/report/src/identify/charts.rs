//! The charts of the identification report: measured against every model over the whole
//! recording (opening with O_P, the measured V_P and the best model drawn; models whose lines
//! would hide each other named as one) and zoomed into the worst windows (Figs. 8-10), the
//! residuals, the step responses coloured by initial opening (Figs. 5/6) and the delay against
//! opening with its polynomial (Fig. 7).
//!
//! Not here: the tables and the text (the parent module).

use std::fmt::Write;

use plotters::style::RGBColor;

use super::super::chart::{Dataset, View};
use super::super::plot::{self, Series, AFTER, BEFORE, EXTRA, MEASURED};
use super::best_two;
use vb_analysis::fit::{Identification, ModelFit};
use vb_core::model::ModelKind;
use vb_core::recording::RecordingView;

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

/// Line colour of O_P in the charts.
const O_P_COLOR: RGBColor = RGBColor(23, 150, 170);
/// Largest difference between two models' simulated V_P over the scored samples, %, under which
/// their lines overlap at any zoom and the legend names them as one.
const SAME_PCT: f64 = 0.01;

/// The legend names of `models`' lines: a model whose V_P is within [`SAME_PCT`] of an earlier
/// one's over the `scored` samples is named with it (`Pin-cart I (the same as FOPDT)`).
fn series_names(models: &[&ModelFit], scored: &[bool]) -> Vec<String> {
    let diff = |a: &[f64], b: &[f64]| {
        (a.iter().zip(b).zip(scored))
            .filter(|(_, &s)| s)
            .map(|((x, y), _)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    (models.iter().enumerate())
        .map(|(i, r)| {
            let same = models[..i].iter().find(|o| diff(&o.sim, &r.sim) < SAME_PCT);
            match same {
                Some(o) => format!(
                    "{} (the same as {} within {SAME_PCT} %)",
                    r.kind.display_name(),
                    o.kind.display_name()
                ),
                None => r.kind.display_name().to_string(),
            }
        })
        .collect()
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

/// Measured against every model over the whole recording and in the worst windows, and the
/// residuals.
pub(super) fn curves_html(h: &mut String, rec: &RecordingView, id: &Identification) {
    let (t, op, vp) = (rec.t, rec.op, rec.vp);
    let n = t.len().min(op.len()).min(vp.len());
    let models: Vec<&ModelFit> = (id.rows.iter())
        .filter(|r| r.kind != ModelKind::Modelless)
        .collect();
    let names = series_names(&models, &id.scored_mask);
    let mut recording = vec![
        Series {
            name: "O_P",
            y: &op[..n],
            color: O_P_COLOR,
        },
        Series {
            name: "V_P measured",
            y: &vp[..n],
            color: MEASURED,
        },
    ];
    for (r, name) in models.iter().zip(&names) {
        recording.push(Series {
            name,
            y: &r.sim[..n],
            color: model_color(r.kind),
        });
    }
    let best_at = (best_two(id).0)
        .and_then(|b| models.iter().position(|r| r.kind == b.kind))
        .map(|i| i + 2);
    let data = Dataset::new("recording", t, &recording, 0..n);
    h.push_str("<h2>Measured and simulated V_P</h2><p class=\"vb-hint\">The chart opens with O_P, the measured V_P and the best model; click a model's name under it to draw it too.</p>");
    let view = View {
        shown: Some([0, 1].into_iter().chain(best_at).collect()),
        zoom: None,
    };
    h.push_str(&data.html_and_view(
        "whole recording (free run from the first sample)",
        "position (%)",
        "time (s)",
        &view,
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
pub(super) fn steps_section(h: &mut String, vp: &[f64], id: &Identification) {
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
