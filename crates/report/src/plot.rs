//! SVG charts with plotters: time series (several lines over one time axis), scatter plots
//! (optionally with curves over them) and bundles of curves coloured on a blue-yellow scale.
//!
//! Charts come back as SVG text to embed in an HTML page. Long series are thinned to at most
//! [`MAX_POINTS`] points per line by keeping each bucket's min and max, so spikes survive.
//! Legends sit in a band below the plotting area, never over the data.
//!
//! Not here: the interactive versions of the time series (`super::chart`).

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Most points drawn per line.
pub const MAX_POINTS: usize = 4000;

/// One named line of a chart.
#[derive(Debug)]
pub struct Series<'a> {
    pub name: &'a str,
    pub y: &'a [f64],
    pub color: RGBColor,
}

/// Palette for the lines of a chart: measured, before, after, then extras.
pub const MEASURED: RGBColor = RGBColor(40, 40, 40);
pub const BEFORE: RGBColor = RGBColor(214, 39, 40);
pub const AFTER: RGBColor = RGBColor(31, 119, 180);
pub const EXTRA: RGBColor = RGBColor(44, 160, 44);
pub const GREY: RGBColor = RGBColor(150, 150, 150);
pub const PURPLE: RGBColor = RGBColor(148, 103, 189);

/// How a legend entry marks its series.
#[derive(Clone, Copy)]
enum Mark {
    Line,
    Dot,
}

/// One entry of a legend.
struct Entry<'a> {
    name: &'a str,
    color: RGBColor,
    mark: Mark,
}

/// Font of tick labels and axis titles: plotters writes a font size of 15 as 12.1 px in the
/// SVG, as legible as the page's text (its default of 12 came out at 9.7 px).
pub(crate) const AXIS_FONT: (&str, u32) = ("sans-serif", 15);

/// Height of a legend row, px.
const LEGEND_ROW: i32 = 18;
/// Width given to each character of a legend label, px: the SVG backend has no font metrics, so
/// labels are laid out at a generous average width of their sans-serif font ([`AXIS_FONT`]).
const CHAR_W: i32 = 8;

/// Where each entry of a legend `width` px wide goes (left to right, wrapped) and the legend's
/// height.
fn legend_layout(entries: &[Entry], width: i32) -> (Vec<(i32, i32)>, i32) {
    let (mut x, mut y) = (10, 4);
    let mut at = Vec::with_capacity(entries.len());
    for e in entries {
        let w = 36 + CHAR_W * e.name.chars().count() as i32;
        if x > 10 && x + w > width {
            (x, y) = (10, y + LEGEND_ROW);
        }
        at.push((x, y));
        x += w;
    }
    let height = if entries.is_empty() {
        0
    } else {
        y + LEGEND_ROW + 4
    };
    (at, height)
}

/// Logs a drawing step that failed; the rest of the plot is still drawn. The SVG backend
/// writes into a string, so only a coordinate or layout plotters refuses can fail a step.
pub(crate) fn drawn<T, E: std::fmt::Debug>(step: Result<T, E>) {
    if let Err(e) = step {
        tracing::warn!("a part of a plot could not be drawn: {e:?}");
    }
}

/// An SVG chart of `size` px with `entries` as a legend in a band below it; `draw` draws the
/// chart in the area above the band.
fn with_legend(
    size: (u32, u32),
    entries: &[Entry],
    draw: impl FnOnce(&DrawingArea<SVGBackend, Shift>),
) -> String {
    let (at, band) = legend_layout(entries, size.0 as i32);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (size.0, size.1 + band.max(0) as u32))
            .into_drawing_area();
        drawn(root.fill(&WHITE));
        let (chart, legend) = root.split_vertically(size.1);
        draw(&chart);
        for (e, &(x, y)) in entries.iter().zip(&at) {
            let mid = y + LEGEND_ROW / 2;
            drawn(match e.mark {
                Mark::Line => legend.draw(&PathElement::new(
                    vec![(x, mid), (x + 20, mid)],
                    e.color.stroke_width(2),
                )),
                Mark::Dot => legend.draw(&Circle::new((x + 10, mid), 3, e.color.filled())),
            });
            drawn(legend.draw(&Text::new(e.name, (x + 26, mid - 7), AXIS_FONT.into_font())));
        }
        drawn(root.present());
    }
    svg
}

/// The frame of a line chart in `root`: `labels` (title, x axis, y axis), the ranges `x` and
/// `y`, and a mesh without the light grid lines; None when the ranges cannot be drawn.
fn framed<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    (title, x_label, y_label): (&str, &str, &str),
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Option<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>> {
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(42)
        .y_label_area_size(68)
        .build_cartesian_2d(x, y)
        .ok()?;
    drawn(
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .label_style(AXIS_FONT)
            .axis_desc_style(AXIS_FONT)
            .light_line_style(WHITE.mix(0.0))
            .draw(),
    );
    Some(chart)
}

/// The indices of the lowest and highest finite value of `y` over the non-empty `range`, in
/// time order (the first index twice when none is finite).
pub(crate) fn extremes(y: &[f64], range: std::ops::Range<usize>) -> (usize, usize) {
    let (mut lo, mut hi) = (range.start, range.start);
    for k in range {
        if y[k] < y[lo] || (y[lo].is_nan() && !y[k].is_nan()) {
            lo = k;
        }
        if y[k] > y[hi] || (y[hi].is_nan() && !y[k].is_nan()) {
            hi = k;
        }
    }
    (lo.min(hi), lo.max(hi))
}

/// Indices to draw for `range` of a series: all, or each bucket's min and max.
fn thin(y: &[f64], range: std::ops::Range<usize>) -> Vec<usize> {
    let n = range.len();
    if n <= MAX_POINTS {
        return range.collect();
    }
    let bucket = n.div_ceil(MAX_POINTS / 2);
    let mut out = Vec::with_capacity(MAX_POINTS + 2);
    let mut a = range.start;
    while a < range.end {
        let b = (a + bucket).min(range.end);
        let (lo, hi) = extremes(y, a..b);
        out.push(lo);
        out.push(hi);
        a = b;
    }
    out
}

/// A time-series chart of `series` against `t` (labelled `x_label`) over the samples `range`; a
/// missing value (NaN) breaks a series' line.
pub fn lines(
    title: &str,
    y_label: &str,
    x_label: &str,
    t: &[f64],
    series: &[Series],
    range: std::ops::Range<usize>,
) -> String {
    if range.is_empty() {
        return String::new();
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        for &v in s.y.get(range.clone()).unwrap_or_default() {
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-3);
    let (t0, t1) = (t[range.start], t[range.end - 1].max(t[range.start] + 1e-9));
    let entries: Vec<Entry> = (series.iter())
        .map(|s| Entry {
            name: s.name,
            color: s.color,
            mark: Mark::Line,
        })
        .collect();
    with_legend((900, 320), &entries, |root| {
        let labels = (title, x_label, y_label);
        let Some(mut chart) = framed(root, labels, t0..t1, (lo - pad)..(hi + pad)) else {
            return;
        };
        for s in series.iter().filter(|s| s.y.len() >= range.end) {
            let idx = thin(s.y, range.clone());
            // A missing value (NaN) is a gap: each run of values is a line of its own.
            for run in idx
                .split(|&k| !s.y[k].is_finite())
                .filter(|r| !r.is_empty())
            {
                drawn(chart.draw_series(LineSeries::new(
                    run.iter().map(|&k| (t[k], s.y[k])),
                    s.color.stroke_width(1),
                )));
            }
        }
    })
}

/// A named group of (x, y) points of one colour.
pub type PointGroup<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);

/// A scatter chart of labelled point groups.
pub fn scatter(title: &str, x_label: &str, y_label: &str, groups: &[PointGroup]) -> String {
    scatter_lines(title, x_label, y_label, groups, &[])
}

/// A named polyline of (x, y) points of one colour, drawn over a scatter chart.
pub type Curve<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);

/// A scatter chart of labelled point groups with labelled curves over it (e.g. a fitted
/// polynomial); the axes span the points.
pub fn scatter_lines(
    title: &str,
    x_label: &str,
    y_label: &str,
    groups: &[PointGroup],
    curves: &[Curve],
) -> String {
    let pts = || groups.iter().flat_map(|g| g.2.iter());
    if pts().next().is_none() {
        return String::new();
    }
    let fold = |f: fn(&(f64, f64)) -> f64| {
        pts()
            .map(f)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
    };
    let (x0, x1) = fold(|p| p.0);
    let (y0, y1) = fold(|p| p.1);
    let entries: Vec<Entry> = (curves.iter().map(|c| (c.0, c.1, Mark::Line)))
        .chain(groups.iter().map(|g| (g.0, g.1, Mark::Dot)))
        .map(|(name, color, mark)| Entry { name, color, mark })
        .collect();
    with_legend((600, 360), &entries, |root| {
        let chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(42)
            .y_label_area_size(64)
            .build_cartesian_2d(
                (x0 - 1.0)..(x1 + 1.0),
                (y0 - 0.05).min(0.0)..(y1 * 1.1 + 0.05),
            );
        let Ok(mut chart) = chart else {
            return;
        };
        drawn(
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style(AXIS_FONT)
                .axis_desc_style(AXIS_FONT)
                .draw(),
        );
        for (_, color, points) in curves {
            drawn(chart.draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2),
            )));
        }
        for (_, color, points) in groups {
            drawn(chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled()))));
        }
    })
}

/// Colour of a value 0-1 on a blue (0) to yellow (1) scale, like the paper's Fig. 6.
pub fn blue_to_yellow(x: f64) -> RGBColor {
    let x = if x.is_finite() {
        x.clamp(0.0, 1.0)
    } else {
        0.0
    };
    // Endpoints and middle of a viridis-like ramp.
    let stops = [
        (68.0, 1.0, 84.0),
        (33.0, 145.0, 140.0),
        (253.0, 231.0, 37.0),
    ];
    let (a, b, f) = if x < 0.5 {
        (stops[0], stops[1], x * 2.0)
    } else {
        (stops[1], stops[2], x * 2.0 - 1.0)
    };
    let mix = |p: f64, q: f64| (p + (q - p) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Many unlabelled curves of their own colours over shared axes (e.g. step responses
/// coloured by initial opening); `note` is drawn as the legend's only entry.
pub fn curves(
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[(RGBColor, Vec<(f64, f64)>)],
    note: &str,
) -> String {
    let pts = || {
        curves
            .iter()
            .flat_map(|c| c.1.iter())
            .filter(|p| p.1.is_finite())
    };
    if pts().next().is_none() {
        return String::new();
    }
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for p in pts() {
        x0 = x0.min(p.0);
        x1 = x1.max(p.0);
        y0 = y0.min(p.1);
        y1 = y1.max(p.1);
    }
    let pad = ((y1 - y0) * 0.05).max(1e-3);
    let entries: Vec<Entry> = (!note.is_empty())
        .then_some(Entry {
            name: note,
            color: blue_to_yellow(0.5),
            mark: Mark::Line,
        })
        .into_iter()
        .collect();
    with_legend((900, 360), &entries, |root| {
        let labels = (title, x_label, y_label);
        let x = x0..x1.max(x0 + 1e-9);
        let Some(mut chart) = framed(root, labels, x, (y0 - pad)..(y1 + pad)) else {
            return;
        };
        for (color, points) in curves {
            drawn(chart.draw_series(LineSeries::new(
                points.iter().copied(),
                color.mix(0.8).stroke_width(1),
            )));
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_the_extremes() {
        let y: Vec<f64> = (0..100_000)
            .map(|k| if k == 54_321 { 9.0 } else { 0.0 })
            .collect();
        let idx = thin(&y, 0..y.len());
        assert!(idx.len() <= MAX_POINTS + 2);
        assert!(idx.contains(&54_321));
    }

    /// The y coordinate of the text element reading `label` in `svg`.
    fn text_y(svg: &str, label: &str) -> f64 {
        let end = svg.find(&format!(">\n{label}\n</text>")).expect(label);
        let tag = &svg[svg[..end].rfind("<text").unwrap()..end];
        let y = &tag[tag.find(" y=\"").unwrap() + 4..];
        y[..y.find('"').unwrap()].parse().unwrap()
    }

    #[test]
    fn legends_are_below_the_plotting_area() {
        let t: Vec<f64> = (0..500).map(|k| k as f64 * 0.01).collect();
        let series: Vec<Series> = ["O_P", "V_P measured", "pin-cart II", "FOPDT", "stiction"]
            .iter()
            .map(|name| Series {
                name,
                y: &t,
                color: MEASURED,
            })
            .collect();
        let svg = lines("x", "%", "time (s)", &t, &series, 0..500);
        for s in &series {
            assert!(text_y(&svg, s.name) > 320.0, "{}", s.name);
        }
        let s = scatter_lines(
            "s",
            "a",
            "b",
            &[("reversal", AFTER, vec![(1.0, 2.0), (3.0, 1.0)])],
            &[("fit", BEFORE, vec![(1.0, 1.5), (3.0, 1.5)])],
        );
        assert!(text_y(&s, "reversal") > 360.0 && text_y(&s, "fit") > 360.0);
        let c = curves(
            "c",
            "t",
            "y",
            &[(AFTER, vec![(0.0, 0.0), (1.0, 1.0)])],
            "note",
        );
        assert!(text_y(&c, "note") > 360.0);
        // Many entries wrap onto further rows, each still below the chart and inside the SVG.
        let names: Vec<String> = (0..12).map(|k| format!("a long series name {k}")).collect();
        let many: Vec<Series> = (names.iter())
            .map(|name| Series {
                name,
                y: &t,
                color: AFTER,
            })
            .collect();
        let svg = lines("x", "%", "time (s)", &t, &many, 0..500);
        let last = text_y(&svg, &names[11]);
        assert!(last > text_y(&svg, &names[0]) && last > 320.0);
    }

    #[test]
    fn charts_are_svg() {
        let t: Vec<f64> = (0..500).map(|k| k as f64 * 0.01).collect();
        let y: Vec<f64> = t.iter().map(|x| x.sin()).collect();
        let svg = lines(
            "x",
            "%",
            "time (s)",
            &t,
            &[Series {
                name: "sin",
                y: &y,
                color: MEASURED,
            }],
            0..500,
        );
        assert!(svg.starts_with("<svg") && svg.contains("sin"));
        let s = scatter("s", "a", "b", &[("g", AFTER, vec![(1.0, 2.0), (3.0, 1.0)])]);
        assert!(s.contains("<circle"));
        let s = scatter_lines(
            "s",
            "a",
            "b",
            &[("g", AFTER, vec![(1.0, 2.0), (3.0, 1.0)])],
            &[("fit", BEFORE, vec![(1.0, 1.5), (3.0, 1.5)])],
        );
        assert!(s.contains("<circle") && s.contains("fit"));
        let c = curves(
            "c",
            "t",
            "y",
            &[(blue_to_yellow(0.0), vec![(0.0, 0.0), (1.0, 1.0)])],
            "blue: closed",
        );
        assert!(c.starts_with("<svg") && c.contains("blue: closed"));
        assert_eq!(blue_to_yellow(1.0), RGBColor(253, 231, 37));
    }
}
