//! The plot of a valve's live health (`health-NAME.svg`), drawn from its health CSV: one panel
//! per figure in its own unit (dead time and reversal delay in s, stroke speeds in %/s, tracking
//! error in %), each with its baseline and its alarm limit as lines, the windows in alarm as
//! shaded spans, against loop time; the legend beside each panel, outside its plotting area.
//! A CSV that several runs appended to is drawn for its last run: its rows from the last where
//! loop time goes back (each run starts it at 0).
//!
//! Not here: estimating the figures or writing the CSV (`vb_daemon::monitor::health`).

use std::path::Path;

use plotters::prelude::*;

use vb_core::recording::health_log::{Figure, HealthRow};

use super::plot::{drawn, AFTER, AXIS_FONT, BEFORE, GREY};

/// One panel: its title, its unit and its figure.
const PANELS: [(&str, &str, Figure); 5] = [
    ("dead time", "s", Figure::DeadTime),
    ("reversal delay", "s", Figure::ReversalDelay),
    ("opening speed", "%/s", Figure::OpeningSpeed),
    ("closing speed", "%/s", Figure::ClosingSpeed),
    ("tracking error (RMS of O_P - V_P)", "%", Figure::Tracking),
];

/// Width of the plotting column and of the legend column beside it, and a panel's height, px.
const PLOT_W: u32 = 780;
const LEGEND_W: u32 = 150;
const PANEL_H: u32 = 210;

/// The rows of the health log's last run, as the plot reads them.
struct Table {
    t_h: Vec<f64>,
    rows: Vec<HealthRow>,
}

impl Table {
    /// The rows of the last run in the health log at `path`: from the last row where loop time
    /// goes back (each run starts it at 0).
    fn read(path: &Path) -> Result<Table, csv::Error> {
        let mut rows = HealthRow::read(path)?;
        let run = (1..rows.len())
            .rfind(|&k| rows[k].t_s <= rows[k - 1].t_s)
            .unwrap_or(0);
        rows.drain(..run);
        let t_h = rows.iter().map(|r| r.t_s / 3600.0).collect();
        Ok(Table { t_h, rows })
    }

    /// A figure's values, its baselines and its limits (NaN where not known).
    fn columns(&self, figure: Figure) -> [Vec<f64>; 3] {
        let k = figure as usize;
        let nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
        [
            self.rows.iter().map(|r| nan(r.figures[k])).collect(),
            self.rows.iter().map(|r| nan(r.base[k])).collect(),
            self.rows.iter().map(|r| nan(r.limits[k])).collect(),
        ]
    }

    /// The spans of loop time (h) in alarm: each alarmed row's window until the next row.
    fn alarm_spans(&self) -> Vec<(f64, f64)> {
        let t = &self.t_h;
        let step = if t.len() > 1 { t[1] - t[0] } else { 0.0 };
        let mut spans: Vec<(f64, f64)> = Vec::new();
        for k in (0..self.rows.len()).filter(|&k| self.rows[k].alarm) {
            let end = t.get(k + 1).copied().unwrap_or(t[k] + step);
            match spans.last_mut() {
                Some(last) if (last.1 - t[k]).abs() < 1e-9 => last.1 = end,
                _ => spans.push((t[k], end)),
            }
        }
        spans
    }
}

/// The SVG of the health CSV at `csv_path` for valve `valve` (empty when it has no window).
pub fn svg(valve: &str, csv_path: &Path) -> Result<String, csv::Error> {
    let table = Table::read(csv_path)?;
    let mut svg = String::new();
    if table.t_h.is_empty() {
        return Ok(svg);
    }
    {
        let height = PANEL_H * PANELS.len() as u32 + 40;
        let root =
            SVGBackend::with_string(&mut svg, (PLOT_W + LEGEND_W, height)).into_drawing_area();
        drawn(root.fill(&WHITE));
        let root = root.titled(
            &format!(
                "valve {valve}: health figures, their baseline and alarm limit; shaded: in alarm"
            ),
            ("sans-serif", 16),
        );
        let Ok(root) = root else {
            return Ok(String::new());
        };
        let spans = table.alarm_spans();
        for (area, panel) in root.split_evenly((PANELS.len(), 1)).iter().zip(PANELS) {
            let (plot, side) = area.split_horizontally(PLOT_W);
            draw_panel(&plot, &side, &table, &spans, panel);
        }
        drawn(root.present());
    }
    Ok(svg)
}

/// One figure's panel in `plot`, its legend in `side`.
fn draw_panel<DB: DrawingBackend>(
    plot: &DrawingArea<DB, plotters::coord::Shift>,
    side: &DrawingArea<DB, plotters::coord::Shift>,
    table: &Table,
    spans: &[(f64, f64)],
    (title, unit, figure): (&str, &str, Figure),
) {
    let t = &table.t_h;
    let ys = table.columns(figure);
    let finite = ys
        .iter()
        .flat_map(|y| y.iter())
        .copied()
        .filter(|v| v.is_finite());
    let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
        (l.min(v), h.max(v))
    });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let pad = ((hi - lo) * 0.08).max(1e-3);
    let (t0, t1) = (t[0], t[t.len() - 1].max(t[0] + 1e-9));
    let chart = ChartBuilder::on(plot)
        .caption(format!("{title} ({unit})"), AXIS_FONT)
        .margin(6)
        .x_label_area_size(44)
        .y_label_area_size(68)
        .build_cartesian_2d(t0..t1, (lo - pad)..(hi + pad));
    let Ok(mut chart) = chart else {
        return;
    };
    drawn(
        chart
            .configure_mesh()
            .x_desc("loop time (h)")
            .y_desc(unit)
            .label_style(AXIS_FONT)
            .axis_desc_style(AXIS_FONT)
            .light_line_style(WHITE.mix(0.0))
            .draw(),
    );
    let shade = BEFORE.mix(0.15).filled();
    drawn(chart.draw_series(
        (spans.iter()).map(|&(a, b)| Rectangle::new([(a, lo - pad), (b, hi + pad)], shade)),
    ));
    let styles = [
        ("figure", AFTER.stroke_width(2)),
        ("baseline", GREY.stroke_width(1)),
        ("alarm limit", BEFORE.stroke_width(1)),
    ];
    for (y, (_, style)) in ys.iter().zip(styles) {
        // A gap where the window could not measure the figure.
        let mut run = Vec::new();
        for (k, &v) in y.iter().enumerate() {
            if v.is_finite() {
                run.push((t[k], v));
            } else if !run.is_empty() {
                drawn(chart.draw_series(LineSeries::new(std::mem::take(&mut run), style)));
            }
        }
        drawn(chart.draw_series(LineSeries::new(run, style)));
    }
    let mut entries: Vec<(&str, ShapeStyle)> = styles.to_vec();
    entries.push(("in alarm", shade));
    for (i, (name, style)) in entries.iter().enumerate() {
        let y = 40 + 20 * i as i32;
        drawn(side.draw(&Rectangle::new([(4, y - 4), (22, y + 4)], *style)));
        drawn(side.draw(&Text::new(*name, (28, y - 7), AXIS_FONT)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alarmed_rows_become_spans_until_the_next_window() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("health.csv");
        let mut text = String::from("t_s,dead_time_s,dead_time_base_s,dead_time_limit_s,alarm\n");
        for (k, alarm) in [0, 1, 1, 0, 1].iter().enumerate() {
            let t = 600 + 60 * k;
            text += &format!("{t},0.4,0.4,0.6,{alarm}\n");
        }
        std::fs::write(&path, text).unwrap();
        let table = Table::read(&path).unwrap();
        let h = |s: f64| s / 3600.0;
        let spans = table.alarm_spans();
        assert_eq!(spans.len(), 2, "{spans:?}");
        assert!((spans[0].0 - h(660.0)).abs() < 1e-9 && (spans[0].1 - h(780.0)).abs() < 1e-9);
        assert!((spans[1].0 - h(840.0)).abs() < 1e-9 && (spans[1].1 - h(900.0)).abs() < 1e-9);
        let svg = svg("a", &path).unwrap();
        for text in ["dead time (s)", "alarm limit", "in alarm", "tracking error"] {
            assert!(svg.contains(text), "{text}");
        }
    }

    #[test]
    fn a_csv_of_several_runs_is_drawn_for_the_last() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("health.csv");
        let mut text = String::from("t_s,dead_time_s,alarm\n");
        for t in [600, 660, 720, 600, 660, 600, 660, 720, 780] {
            text += &format!("{t},0.4,0\n");
        }
        std::fs::write(&path, text).unwrap();
        let table = Table::read(&path).unwrap();
        let t: Vec<f64> = table.t_h.iter().map(|h| (h * 3600.0).round()).collect();
        assert_eq!(t, [600.0, 660.0, 720.0, 780.0]);
        assert_eq!(table.columns(Figure::DeadTime)[0], [0.4; 4]);
    }
}
