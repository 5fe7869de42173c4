//! The health log (`health-NAME.csv`): one row per health window of a valve, with its figures,
//! the alarm, each figure's baseline and alarm limit, and a note. The daemon's health thread
//! writes it and the health plot reads it back; [`HealthRow`] is the one type that does both,
//! so the columns are named once.
//!
//! Not here: measuring the figures (the daemon's `monitor::health`), opening files and writing
//! lines (the daemon's `runtime::log_file`), the plot (`vb-report`).

use std::path::Path;

use super::log_format::fixed;

/// The header of the health log: the figures, the alarm, each figure's baseline and limit
/// (empty until there is a baseline), the note.
pub const HEADER: [&str; 20] = [
    "t_s",
    "same_steps",
    "reversals",
    "dead_time_s",
    "reversal_delay_s",
    "opening_speed_pct_per_s",
    "closing_speed_pct_per_s",
    "tracking_rms_pct",
    "alarm",
    "dead_time_base_s",
    "dead_time_limit_s",
    "reversal_delay_base_s",
    "reversal_delay_limit_s",
    "opening_speed_base_pct_per_s",
    "opening_speed_limit_pct_per_s",
    "closing_speed_base_pct_per_s",
    "closing_speed_limit_pct_per_s",
    "tracking_rms_base_pct",
    "tracking_rms_limit_pct",
    "note",
];

/// A figure of a health window, in the order of [`HealthRow::figures`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    /// Median delay of same-direction steps, s.
    DeadTime,
    /// Median delay of reversals, s.
    ReversalDelay,
    /// Stroke speed opening, %/s.
    OpeningSpeed,
    /// Stroke speed closing, %/s.
    ClosingSpeed,
    /// RMS of O_P - V_P, %.
    Tracking,
}

impl Figure {
    /// Every figure, in the order of the log's columns.
    pub const ALL: [Figure; 5] = [
        Figure::DeadTime,
        Figure::ReversalDelay,
        Figure::OpeningSpeed,
        Figure::ClosingSpeed,
        Figure::Tracking,
    ];

    /// Its columns: the figure, its baseline and its limit.
    fn columns(self) -> [usize; 3] {
        let k = self as usize;
        [3 + k, 9 + 2 * k, 10 + 2 * k]
    }
}

/// One row of the health log. A window too short for figures has none (`figures` all `None`,
/// `steps` `None`); a valve without a baseline yet has no `base` and no `limits`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HealthRow {
    /// Loop time at the window's end, s.
    pub t_s: f64,
    /// Steps that keep the direction, and reversals, in the window.
    pub steps: Option<(usize, usize)>,
    /// The figures, by [`Figure`].
    pub figures: [Option<f64>; 5],
    /// The health alarm.
    pub alarm: bool,
    /// Each figure's baseline and its alarm limit, by [`Figure`].
    pub base: [Option<f64>; 5],
    pub limits: [Option<f64>; 5],
    /// Why there are no figures, or what the alarm says.
    pub note: String,
}

impl HealthRow {
    /// The row's cells, in the order of [`HEADER`] (times to 1 ms, figures to 4 decimals, an
    /// empty cell for what is not known).
    pub fn cells(&self) -> [String; 20] {
        let mut cells: [String; 20] = Default::default();
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| fixed(v, 4));
        cells[0] = fixed(self.t_s, 3);
        if let Some((same, reversals)) = self.steps {
            (cells[1], cells[2]) = (same.to_string(), reversals.to_string());
        }
        cells[8] = u8::from(self.alarm).to_string();
        for f in Figure::ALL {
            let [v, b, l] = f.columns();
            let k = f as usize;
            (cells[v], cells[b], cells[l]) =
                (opt(self.figures[k]), opt(self.base[k]), opt(self.limits[k]));
        }
        cells[19] = self.note.clone();
        cells
    }

    /// The rows of the health log at `path`, each cell found by its column's name (a column the
    /// file lacks, or a cell that is no number, reads as not known).
    pub fn read(path: &Path) -> Result<Vec<HealthRow>, csv::Error> {
        let mut r = csv::Reader::from_path(path)?;
        let header = r.headers()?.clone();
        let at = HEADER.map(|name| header.iter().position(|h| h == name));
        let mut rows = Vec::new();
        for rec in r.records() {
            let rec = rec?;
            let cell = |k: usize| at[k].and_then(|i| rec.get(i)).unwrap_or("");
            let num = |k: usize| cell(k).parse::<f64>().ok().filter(|v| v.is_finite());
            let mut row = HealthRow {
                t_s: num(0).unwrap_or(f64::NAN),
                steps: cell(1).parse().ok().zip(cell(2).parse().ok()),
                alarm: cell(8) == "1",
                note: cell(19).to_string(),
                ..HealthRow::default()
            };
            for f in Figure::ALL {
                let [v, b, l] = f.columns();
                let k = f as usize;
                (row.figures[k], row.base[k], row.limits[k]) = (num(v), num(b), num(l));
            }
            rows.push(row);
        }
        Ok(rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_columns_of_each_figure_are_named_for_it() {
        let stems = [
            "dead_time_",
            "reversal_delay_",
            "opening_speed_",
            "closing_speed_",
            "tracking_rms_",
        ];
        for (f, stem) in Figure::ALL.iter().zip(stems) {
            let [v, b, l] = f.columns().map(|c| HEADER[c]);
            assert!(
                v.starts_with(stem) && b.starts_with(stem) && l.starts_with(stem),
                "{f:?}"
            );
            assert!(
                b.contains("_base") && l.contains("_limit"),
                "{f:?}: {b} {l}"
            );
        }
    }

    #[test]
    fn a_row_reads_back_as_written() {
        let dir = tempfile::tempdir().unwrap();
        let rows = [
            HealthRow {
                t_s: 600.0,
                note: "too few steps, a note, with commas".into(),
                ..HealthRow::default()
            },
            HealthRow {
                t_s: 1200.0,
                steps: Some((31, 12)),
                figures: [Some(1.25), None, Some(42.5), Some(40.125), Some(0.5)],
                alarm: true,
                base: [Some(1.0), Some(1.5), Some(45.0), Some(44.0), Some(0.25)],
                limits: [Some(1.2), Some(1.8), Some(30.0), Some(30.0), Some(0.75)],
                note: String::new(),
            },
        ];
        let mut w = csv::Writer::from_path(dir.path().join("h.csv")).unwrap();
        w.write_record(HEADER).unwrap();
        for r in &rows {
            w.write_record(r.cells()).unwrap();
        }
        w.flush().unwrap();
        drop(w);
        assert_eq!(HealthRow::read(&dir.path().join("h.csv")).unwrap(), rows);
        assert_eq!(rows[1].cells()[3], "1.25");
        assert_eq!(rows[0].cells()[1], "");
    }
}
