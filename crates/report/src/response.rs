//! A response test for people: the text `valve-bridge response-test` prints (the worst figures
//! per step size and direction, the signature, the spec's lines passed or failed) and its page
//! (the same tables, the signature and every step charted with its figures marked: the dead
//! time, T63 and T86 as bars at the level V_P must reach, ending where it did; the final value;
//! each reversal's dead band as a bar at V_P's extreme, ending where V_P left it).
//!
//! Not here: measuring ([`vb_analysis::response`]).

use std::fmt::Write;

use super::chart::Dataset;
use super::plot::{Series, AFTER, BEFORE, EXTRA, GREY, MEASURED, PURPLE};
use super::{esc, page};
use vb_analysis::response::spec::Line;
use vb_analysis::response::{ResponseTest, StepResult, Worst};
use vb_core::recording::Recording;

/// `0.452 s`, or `-` when there is none.
fn secs(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.3} s"))
}

/// `0.62 %`, or `-` (never `-0.00 %`).
fn pct(v: Option<f64>) -> String {
    // Rounded first, and plus 0 (a negative zero prints as `-0`).
    v.map_or("-".into(), |v| {
        format!("{:.2} %", (v * 100.0).round() / 100.0 + 0.0)
    })
}

/// A register's or lattice's step, `0.1 %`, or `none`.
fn step_of(v: f64) -> String {
    if v > 0.0 {
        format!("{} %", vb_core::human::num((v * 1e4).round() / 1e4))
    } else {
        "none".into()
    }
}

/// A step in a few words: `close 1 % at 50 % (reversal)`.
pub fn step_name(s: &StepResult) -> String {
    format!(
        "{} {} % at {} %{}",
        s.direction.name(),
        s.size_pct,
        s.opening_pct,
        if s.reversal { " (reversal)" } else { "" }
    )
}

/// One direction's worst figures: `0.452 s  0.901 s  4/4`, with the steps V_P never answered.
fn worst(w: &Worst) -> String {
    if w.steps == 0 {
        return "-".into();
    }
    let unanswered = match w.unanswered {
        0 => String::new(),
        n => format!(", {n} unanswered"),
    };
    let hidden = match w.hidden {
        0 => String::new(),
        n => format!(", {n} with a figure lost in a gap"),
    };
    format!(
        "{}  {}  {}/{} resolved{unanswered}{hidden}",
        secs(w.dead_time_s),
        secs(w.t86_s),
        w.resolved,
        w.steps
    )
}

/// A spec line as a sentence: `pass  steps 1-2 %: dead_time_s 0.452 <= 1 (close 1 % at 50 %)`.
pub fn line(l: &Line, r: &ResponseTest) -> String {
    let scope = match l.sizes_pct {
        Some((lo, Some(hi))) => format!("steps {lo}-{hi} % ({} measured)", l.steps),
        Some((lo, None)) => format!("steps from {lo} % ({} measured)", l.steps),
        None => "signature".into(),
    };
    let value = match (l.worst, l.sizes_pct) {
        (Some(w), _) => format!("{w:.3}"),
        (None, Some(_)) if l.steps == 0 => "no step measured".into(),
        (None, Some(_))
            if l.step
                .and_then(|i| r.steps.get(i))
                .is_some_and(|s| s.hidden_by_gap) =>
        {
            "lost in a gap of rows without V_P".into()
        }
        (None, Some(_)) => "not reached".into(),
        (None, None) => "not measured".into(),
    };
    let at = (l.step.and_then(|i| r.steps.get(i)))
        .map_or(String::new(), |s| format!(" ({})", step_name(s)));
    format!(
        "{}  {scope}: {} {value} {} {}{at}",
        if l.pass { "pass" } else { "FAIL" },
        l.figure,
        if l.pass { "<=" } else { "against" },
        l.limit
    )
}

/// The text printed at the end of a test: what was read, the worst figures per size, the
/// signature and the spec's lines.
pub fn text(r: &ResponseTest, lines: &[Line]) -> String {
    let mut o = String::new();
    let res = &r.resolution;
    let _ = writeln!(
        o,
        "{} of {} planned steps{}; V_P noise {:.3} % (sd), lattice {}, set-point step {}: a move counts from {:.3} %",
        r.steps.len(),
        r.planned_steps,
        if r.complete { "" } else { " (the test did not run to its end)" },
        res.noise_pct,
        step_of(res.lattice_pct),
        step_of(res.setpoint_step_pct),
        res.threshold_pct
    );
    if !r.rows_without_vp.is_empty() {
        let counts: Vec<String> = (r.rows_without_vp.iter())
            .map(|(s, n)| format!("{n} {s}"))
            .collect();
        let _ = writeln!(
            o,
            "rows without V_P (passed over): {} of {}",
            counts.join(", "),
            r.rows
        );
    }
    let _ = writeln!(
        o,
        "\nsize      opening: dead time, T86              closing: dead time, T86"
    );
    for s in &r.summary {
        let _ = writeln!(
            o,
            "{:<8}  {:<38}  {}",
            format!("{} %", s.size_pct),
            worst(&s.open),
            worst(&s.close)
        );
    }
    let g = &r.signature;
    let _ = writeln!(
        o,
        "\nsignature: dead band {}, hysteresis {} ({} with the dead band); resolution {}",
        pct(g.dead_band_pct),
        pct(g.hysteresis_pct),
        pct(g.hysteresis_plus_dead_band_pct),
        pct(g.resolution_pct)
    );
    if !lines.is_empty() {
        let failed = lines.iter().filter(|l| !l.pass).count();
        let _ = writeln!(
            o,
            "\nspec: {} of {} lines pass",
            lines.len() - failed,
            lines.len()
        );
        for l in lines {
            let _ = writeln!(o, "  {}", line(l, r));
        }
    }
    o
}

/// The series every chart of the page draws: O_P, V_P and the marks.
struct Marks {
    dead: Vec<f64>,
    t63: Vec<f64>,
    t86: Vec<f64>,
    last: Vec<f64>,
    band: Vec<f64>,
}

impl Marks {
    /// The marks of `r` over a log of `n` rows with sample period `dt`.
    fn of(r: &ResponseTest, n: usize, dt: f64) -> Marks {
        let mut m = Marks {
            dead: vec![f64::NAN; n],
            t63: vec![f64::NAN; n],
            t86: vec![f64::NAN; n],
            last: vec![f64::NAN; n],
            band: vec![f64::NAN; n],
        };
        let bar = |y: &mut Vec<f64>, a: usize, time: Option<f64>, level: f64| {
            if let Some(t) = time {
                let b = (a + (t / dt).round() as usize + 1).min(n);
                y[a..b].fill(level);
            }
        };
        for s in r.steps.iter().filter(|s| s.measured) {
            let ((a, end), (v0, v_end)) = (s.rows, s.levels);
            let reach = |share: f64| v0 + share * (v_end - v0);
            bar(&mut m.dead, a, s.dead_time_s, v0);
            bar(
                &mut m.t63,
                a,
                s.t63_s,
                reach(vb_analysis::response::T63_SHARE),
            );
            bar(
                &mut m.t86,
                a,
                s.t86_s,
                reach(vb_analysis::response::T86_SHARE),
            );
            m.last[a..end].fill(v_end);
        }
        for rev in &r.signature.reversals {
            if let (a, Some(b), level) = rev.marks {
                m.band[a..(b + 1).min(n)].fill(level);
            }
        }
        m
    }
}

/// The page of a test of `valve` on the log `rec`: the tables, the signature and every step,
/// charted with their figures marked, and the spec's lines.
pub fn html(title: &str, rec: &Recording, r: &ResponseTest, lines: &[Line]) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<p>{} ({} rows at {} s). Figures measured on the logged V_P; a move counts from {:.3} % \
         (four noise standard deviations, {:.3} %, or the position's lattice, {}).</p>",
        esc(&rec.source),
        r.rows,
        vb_core::human::num(rec.sample_period),
        r.resolution.threshold_pct,
        r.resolution.noise_pct,
        step_of(r.resolution.lattice_pct)
    );
    if !lines.is_empty() {
        h.push_str("<h2>Spec</h2><table>");
        for l in lines {
            let _ = write!(h, "<tr><td class=\"l\">{}</td></tr>", esc(&line(l, r)));
        }
        h.push_str("</table>");
    }
    h.push_str("<h2>Worst figures per step size</h2><table><tr><th>size</th><th>opening: dead time, T86, resolved</th><th>closing</th></tr>");
    for s in &r.summary {
        let _ = write!(
            h,
            "<tr><td>{} %</td><td>{}</td><td>{}</td></tr>",
            s.size_pct,
            esc(&worst(&s.open)),
            esc(&worst(&s.close))
        );
    }
    h.push_str("</table>");
    let marks = Marks::of(r, rec.len(), rec.sample_period);
    let series = [
        Series {
            name: "O_P",
            y: &rec.op,
            color: GREY,
        },
        Series {
            name: "V_P",
            y: &rec.vp,
            color: MEASURED,
        },
        Series {
            name: "dead time",
            y: &marks.dead,
            color: BEFORE,
        },
        Series {
            name: "T63",
            y: &marks.t63,
            color: AFTER,
        },
        Series {
            name: "T86",
            y: &marks.t86,
            color: EXTRA,
        },
        Series {
            name: "final V_P",
            y: &marks.last,
            color: PURPLE,
        },
        Series {
            name: "dead band",
            y: &marks.band,
            color: BEFORE,
        },
    ];
    let data = Dataset::new("log", &rec.t, &series, 0..rec.len());
    h.push_str(&data.html());
    signature_section(&mut h, r, &data);
    steps_section(&mut h, rec, r, &data);
    page(title, &h)
}

/// The signature's figures, its reversals and its chart.
fn signature_section(h: &mut String, r: &ResponseTest, data: &Dataset) {
    let g = &r.signature;
    let _ = write!(
        h,
        "<h2>Signature</h2><p>Dead band {}, hysteresis {} ({} with the dead band), resolution \
         (the smallest step size resolved with every larger one) {}.</p>",
        pct(g.dead_band_pct),
        pct(g.hysteresis_pct),
        pct(g.hysteresis_plus_dead_band_pct),
        pct(g.resolution_pct)
    );
    if g.rows.is_empty() {
        return;
    }
    h.push_str("<table><tr><th>reversal</th><th>at O_P</th><th>dead band</th></tr>");
    for rev in &g.reversals {
        let _ = write!(
            h,
            "<tr><td>to {} at {:.1} s</td><td>{:.2} %</td><td>{}</td></tr>",
            rev.direction.name(),
            rev.t_s,
            rev.at_pct,
            pct(rev.dead_band_pct)
        );
    }
    h.push_str("</table>");
    h.push_str(&data.chart(
        "the slow ramp out and back: the dead band marked at V_P's extreme after each reversal",
        "%",
        "time (s)",
        g.rows.clone(),
    ));
}

/// The table of every step and a chart of each.
fn steps_section(h: &mut String, rec: &Recording, r: &ResponseTest, data: &Dataset) {
    h.push_str("<h2>Steps</h2><table><tr><th>t (s)</th><th>step</th><th>sent</th><th>dead time</th><th>T63</th><th>T86</th><th>overshoot</th><th>final error</th><th>resolved</th><th>rows without V_P</th></tr>");
    for s in &r.steps {
        let _ = write!(
            h,
            "<tr><td>{:.1}</td><td class=\"l\">{}</td><td>{:+.2} %</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            s.t_s,
            esc(&step_name(s)),
            s.sent_size_pct,
            secs(s.dead_time_s),
            secs(s.t63_s),
            secs(s.t86_s),
            pct(s.overshoot_pct),
            pct(s.final_error_pct),
            if !s.measured { "not measured" } else if s.resolved { "yes" } else { "no" },
            s.missing_rows
        );
    }
    h.push_str("</table>");
    let before = ((0.5 / rec.sample_period).round() as usize).max(1);
    for s in &r.steps {
        let (a, end) = s.rows;
        let title = format!(
            "{}: dead time {}, T63 {}, T86 {}, overshoot {}",
            step_name(s),
            secs(s.dead_time_s),
            secs(s.t63_s),
            secs(s.t86_s),
            pct(s.overshoot_pct)
        );
        h.push_str(&data.chart(&title, "%", "time (s)", a.saturating_sub(before)..end));
    }
}

/// The `response.json` document: the valve, the plan (as named and as run), the figures and
/// the spec's lines.
pub fn json(
    valve: &str,
    plan_name: &str,
    plan: &vb_core::response_plan::Plan,
    r: &ResponseTest,
    lines: &[Line],
) -> serde_json::Value {
    let mut doc = serde_json::to_value(r).unwrap_or_default();
    if let Some(map) = doc.as_object_mut() {
        map.insert("valve".into(), valve.into());
        map.insert("plan_name".into(), plan_name.into());
        map.insert(
            "plan".into(),
            serde_json::to_value(plan).unwrap_or_default(),
        );
        map.insert(
            "spec".into(),
            serde_json::to_value(lines).unwrap_or_default(),
        );
    }
    doc
}
