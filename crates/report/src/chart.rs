//! Interactive time-series charts of the report pages: the series as JSON in the page and the
//! vendored uPlot (`crates/core/src/assets/uplot/`, embedded, no network; the daemon's live page embeds the
//! same files) drawing them with drag-to-zoom on the time axis (double-click resets), live
//! values under the cursor, and the static SVG of [`plot::lines`] kept for a page without
//! scripts.
//!
//! A [`Dataset`] is written once per page and drawn by any number of charts, each over its own
//! stretch of time (the whole recording, a worst window), so a zoomed window costs no data.
//! [`assets`] gives the scripts and styles a page needs for its charts.
//!
//! Not here: the static charts themselves ([`plot`]).

use std::fmt::Write;
use std::ops::Range;

use serde::Serialize;

use super::esc;
use super::plot::{self, Series};

/// Most samples of a dataset written to a page; longer ones keep each bucket's extremes.
pub const MAX_SAMPLES: usize = 200_000;

/// The uPlot library, its styles and the script that draws every chart of a page.
use vb_core::assets::{UPLOT_CSS, UPLOT_JS};
const CHARTS_JS: &str = include_str!("assets/charts.js");

/// The series of one time axis as the page's charts read them.
#[derive(Serialize)]
struct Columns<'a> {
    x: Vec<Option<f64>>,
    y: Vec<Vec<Option<f64>>>,
    names: Vec<&'a str>,
    colors: Vec<String>,
}

/// How a chart opens: which series are drawn at first (the others are one click on their
/// legend entry away) and the stretch of time it opens zoomed on (a double-click shows all
/// of it).
#[derive(Debug, Default, Clone)]
pub struct View {
    /// Indices of the series drawn at first (all when None).
    pub shown: Option<Vec<usize>>,
    /// Loop times the chart opens zoomed on.
    pub zoom: Option<(f64, f64)>,
}

/// Series over one time axis, written once into a page and drawn by its charts.
#[derive(Debug)]
pub struct Dataset<'a> {
    id: &'a str,
    t: &'a [f64],
    series: &'a [Series<'a>],
    range: Range<usize>,
}

impl<'a> Dataset<'a> {
    /// The samples `range` of `series` against `t`, named `id` in the page (letters, digits, `-`).
    pub fn new(id: &'a str, t: &'a [f64], series: &'a [Series<'a>], range: Range<usize>) -> Self {
        let range = range.start.min(t.len())..range.end.min(t.len());
        Self {
            id,
            t,
            series,
            range,
        }
    }

    /// The sample indices written: all, or when there are more than [`MAX_SAMPLES`], each
    /// bucket's lowest and highest value of every series, so no spike is lost.
    fn kept(&self) -> Vec<usize> {
        let n = self.range.len();
        let series: Vec<&[f64]> = (self.series.iter())
            .filter(|s| s.y.len() >= self.range.end)
            .map(|s| s.y)
            .collect();
        if n <= MAX_SAMPLES || series.is_empty() {
            return self.range.clone().collect();
        }
        let bucket = n.div_ceil(MAX_SAMPLES / (2 * series.len())).max(1);
        let mut out = Vec::with_capacity(MAX_SAMPLES + 2 * series.len());
        let mut a = self.range.start;
        while a < self.range.end {
            let b = (a + bucket).min(self.range.end);
            let first = out.len();
            for y in &series {
                let (lo, hi) = plot::extremes(y, a..b);
                out.extend([lo, hi]);
            }
            out[first..].sort_unstable();
            out.dedup();
            a = b;
        }
        out
    }

    /// The `<script type="application/json">` holding the dataset; once per page, before or
    /// after its charts.
    pub fn html(&self) -> String {
        let kept = self.kept();
        let column = |y: &[f64], digits: i32| -> Vec<Option<f64>> {
            if y.len() < self.range.end {
                return vec![None; kept.len()];
            }
            kept.iter().map(|&k| rounded(y[k], digits)).collect()
        };
        // Times to 1/100 of the mean sample interval.
        let n = self.range.len().max(2) as f64;
        let dt = (self.t.get(self.range.clone()).unwrap_or_default())
            .last()
            .zip(self.t.get(self.range.start))
            .map_or(1.0, |(b, a)| (b - a) / (n - 1.0));
        let x_digits = (2 - dt.max(1e-9).log10().floor() as i32).clamp(0, 9);
        let columns = Columns {
            x: column(self.t, x_digits),
            y: (self.series.iter())
                .map(|s| {
                    column(
                        s.y,
                        digits_for(s.y.get(self.range.clone()).unwrap_or_default()),
                    )
                })
                .collect(),
            names: self.series.iter().map(|s| s.name).collect(),
            colors: (self.series.iter())
                .map(|s| format!("rgb({},{},{})", s.color.0, s.color.1, s.color.2))
                .collect(),
        };
        let json = serde_json::to_string(&columns).unwrap_or_else(|_| "null".into());
        let mut h = format!(
            "<script type=\"application/json\" id=\"vb-data-{}\">{}</script>",
            self.id,
            json.replace("</", "<\\/")
        );
        if kept.len() < self.range.len() {
            let _ = write!(
                h,
                "<p class=\"vb-note\">The interactive charts below show {} of the {} samples \
                 (for each stretch, every series' lowest and highest value), to keep this page small; \
                 the tables use every sample.</p>",
                kept.len(),
                self.range.len()
            );
        }
        h
    }

    /// The dataset ([`Self::html`]) and its chart over all of its samples.
    pub fn html_and_chart(&self, title: &str, y_label: &str, x_label: &str) -> String {
        self.html() + &self.chart(title, y_label, x_label, self.range.clone())
    }

    /// The dataset ([`Self::html`]) and its chart over all of its samples, opening as `view`
    /// says.
    pub fn html_and_view(&self, title: &str, y_label: &str, x_label: &str, view: &View) -> String {
        let labels = (title, y_label, x_label);
        self.html() + &self.chart_in(labels, self.range.clone(), view)
    }

    /// A chart of the dataset over the samples `range` (all of it, or a window inside it):
    /// interactive where scripts run, the static SVG of [`plot::lines`] where they do not.
    pub fn chart(&self, title: &str, y_label: &str, x_label: &str, range: Range<usize>) -> String {
        self.chart_in((title, y_label, x_label), range, &View::default())
    }

    /// [`Self::chart`] labelled `(title, y_label, x_label)`, opening as `view` says (the static
    /// SVG shows every series over all of `range`).
    fn chart_in(
        &self,
        (title, y_label, x_label): (&str, &str, &str),
        range: Range<usize>,
        view: &View,
    ) -> String {
        let svg = plot::lines(title, y_label, x_label, self.t, self.series, range.clone());
        if svg.is_empty() {
            return svg;
        }
        let mut window = if range == self.range {
            String::new()
        } else {
            format!(
                " data-x0=\"{}\" data-x1=\"{}\"",
                self.t[range.start],
                self.t[range.end - 1]
            )
        };
        if let Some(shown) = &view.shown {
            let list: Vec<String> = shown.iter().map(usize::to_string).collect();
            let _ = write!(window, " data-shown=\"{}\"", list.join(","));
        }
        if let Some((a, b)) = view.zoom {
            let _ = write!(window, " data-zoom0=\"{a}\" data-zoom1=\"{b}\"");
        }
        format!(
            "<div class=\"vb-chart\" data-set=\"{}\" data-title=\"{}\" data-x=\"{}\" data-y=\"{}\"{window}>\
             <noscript>{svg}</noscript></div>",
            self.id,
            attr(title),
            attr(x_label),
            attr(y_label)
        )
    }
}

/// Text for an HTML attribute in double quotes.
fn attr(s: &str) -> String {
    esc(s).replace('"', "&quot;")
}

/// Decimals that keep 1/100,000 of the span of `y` (at most 9).
fn digits_for(y: &[f64]) -> i32 {
    let (lo, hi) = (y.iter().filter(|v| v.is_finite()))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let span = (hi - lo).max(1e-9);
    if !span.is_finite() {
        return 3;
    }
    (5 - span.log10().floor() as i32).clamp(0, 9)
}

/// `v` rounded to `digits` decimals; `None` when not finite (a gap in the chart).
fn rounded(v: f64, digits: i32) -> Option<f64> {
    let scale = 10f64.powi(digits);
    v.is_finite().then(|| (v * scale).round() / scale)
}

/// The styles and scripts a page needs to draw the charts in `body` (nothing when it has none);
/// placed at the end of the page's body.
pub fn assets(body: &str) -> String {
    if !body.contains("class=\"vb-chart\"") {
        return String::new();
    }
    format!(
        "<style>{UPLOT_CSS}.vb-chart{{margin:8px 0}}.vb-hint,.vb-note{{color:#555;font-size:.85em}}</style>\
         <script>{UPLOT_JS}</script><script>{CHARTS_JS}</script>"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot::{AFTER, MEASURED};

    #[test]
    fn a_dataset_is_json_and_its_charts_name_it() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 / 100.0).collect();
        let mut y: Vec<f64> = t.iter().map(|x| 50.0 + x.sin()).collect();
        y[10] = f64::NAN;
        let series = [
            Series {
                name: "V_P </script>",
                y: &y,
                color: MEASURED,
            },
            Series {
                name: "absent",
                y: &[],
                color: AFTER,
            },
        ];
        let d = Dataset::new("rec", &t, &series, 0..1000);
        let h = d.html();
        assert!(
            !h.contains("V_P </script>") && !h.contains("vb-note"),
            "{h}"
        );
        let json = &h[h.find('>').unwrap() + 1..h.rfind("</script>").unwrap()];
        let v: serde_json::Value = serde_json::from_str(json).unwrap();
        assert_eq!(v["x"].as_array().unwrap().len(), 1000);
        assert_eq!(v["y"][0][10], serde_json::Value::Null);
        assert_eq!(v["y"][0][1].as_f64(), Some(50.01));
        assert!(v["y"][1].as_array().unwrap().iter().all(|x| x.is_null()));
        assert_eq!(v["colors"][0], "rgb(40,40,40)");
        let whole = d.chart("all \"of\" it", "%", "time (s)", 0..1000);
        assert!(whole.contains("data-set=\"rec\"") && !whole.contains("data-x0"));
        assert!(whole.contains("<noscript><svg") && whole.contains("all &quot;of&quot; it"));
        let zoom = d.chart("zoom", "%", "time (s)", 100..200);
        assert!(zoom.contains("data-x0=\"1\" data-x1=\"1.99\""), "{zoom}");
        let view = View {
            shown: Some(vec![0]),
            zoom: Some((2.5, 4.0)),
        };
        let opened = d.html_and_view("v", "%", "time (s)", &view);
        assert!(opened.contains(" data-shown=\"0\" data-zoom0=\"2.5\" data-zoom1=\"4\""));
        assert!(assets(&zoom).contains("uPlot") && assets("<p>no charts</p>").is_empty());
    }

    #[test]
    fn long_datasets_keep_every_spike_and_say_so() {
        let n = 3 * MAX_SAMPLES;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 0.01).collect();
        let mut a = vec![0.0; n];
        let mut b = vec![1.0; n];
        a[123_457] = 9.0;
        b[400_001] = -7.0;
        let series = [
            Series {
                name: "a",
                y: &a,
                color: MEASURED,
            },
            Series {
                name: "b",
                y: &b,
                color: AFTER,
            },
        ];
        let d = Dataset::new("long", &t, &series, 0..n);
        let kept = d.kept();
        assert!(kept.len() <= MAX_SAMPLES + 4 && kept.len() >= MAX_SAMPLES / 4);
        assert!(kept.windows(2).all(|w| w[0] < w[1]));
        assert!(kept.contains(&123_457) && kept.contains(&400_001));
        assert!(d
            .html()
            .contains(&format!("show {} of the {n} samples", kept.len())));
    }
}
