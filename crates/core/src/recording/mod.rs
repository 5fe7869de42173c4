//! The recording format: CSV files of a valve's wanted opening O_P and actual position V_P over
//! time, as logged by the daemon and read by the analysis side.
//!
//! A recording file has the header `t_s,op_pct,vp_pct` (time in s, O_P and V_P in %) and one
//! row per sample at a constant sample period (100 Hz is typical, any rate works). Extra columns
//! are ignored on reading; other names are mapped with a [`ColumnMap`] (`--columns`).
//!
//! - [`read`] / [`read_from`]: load and check a file into a [`Recording`]. Every problem is a
//!   one-line [`RecordingError`] naming file, line, column, what was expected and the option
//!   that fixes it. Tolerated: a UTF-8 BOM, CRLF line ends, non-UTF-8 text in unmapped
//!   columns; with a warning: a last line cut off by a crash, irregular sampling, values that
//!   look like fractions instead of percent, an empty file among several ([`read_all`]).
//!   Refused before they fill memory: a line longer than [`MAX_LINE_BYTES`], more rows than
//!   [`MAX_ROWS`]. With options: rows with missing values (`--skip-missing`),
//!   newest-row-first files (`--reverse`), wall-clock timestamps in one or two columns
//!   (`--timestamps`, `t=DATE+TIME`), files without V_P (`vp=`), scaling (`--scale`). See
//!   [`ReadOptions`].
//! - [`write()`] / [`write_columns`]: save columns with shortest round-trip number formatting, so
//!   reading back gives the identical `f64` values.
//! - [`gzip`]: the daemon's compressed logs (`.csv.gz`), read as they are by every reader.
//! - [`resample_zoh`]: hold a piecewise-constant signal (O_P) onto another sample period.
//!
//! Not here: interpolation of missing V_P (a missing value is dropped or refused, never
//! invented), unit conversion beyond a scale factor, time zones (timestamps are taken as given,
//! without daylight-saving handling), and any analysis of the signals.

mod cells;
mod columns;
mod error;
pub mod grid;
pub mod gzip;
pub mod health_log;
mod join;
mod limits;
pub mod log_format;
mod read;
mod resample;
mod write;

pub use columns::{ColumnMap, ColumnMapError};
pub use error::RecordingError;
pub use join::read_all;
pub use limits::{MAX_LINE_BYTES, MAX_ROWS};
pub use read::{read, read_from, ReadOptions};
pub use resample::resample_zoh;
pub use write::{write, write_columns};

/// A checked recording: at least two rows, strictly increasing finite times, finite O_P; V_P
/// finite or NaN (missing). Gaps in time are filled or kept as restarts (see [`grid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// Sample times, s. As in the file for numeric times; from the first row for timestamps.
    pub t: Vec<f64>,
    /// Wanted opening O_P, % (times [`ReadOptions::scale`]).
    pub op: Vec<f64>,
    /// Valve position V_P, % (times the scale); NaN where a row has none (an empty cell, a
    /// status other than `ok`, a filled gap); empty when the file has no V_P (`vp=`).
    pub vp: Vec<f64>,
    /// The `status` column when the file has one (the daemon's logs), `gap` on rows that fill
    /// a gap; empty otherwise.
    pub status: Vec<String>,
    /// Indices of the rows right after a long gap: simulations start again there from the
    /// measured V_P. Increasing, never 0.
    pub restarts: Vec<usize>,
    /// Interval between samples, s: the median interval, or the mean interval when the two
    /// agree to 1e-6, which averages out the rounding of times written as decimals (0.01
    /// rather than 0.009999999999990905).
    pub sample_period: f64,
    /// Where it came from: the path (the first of several joined files), a label, or
    /// `in-memory`.
    pub source: String,
    /// What was tolerated or looks odd (also logged with `tracing::warn!`).
    pub warnings: Vec<String>,
}

/// What analysis reads of a recording, borrowed: the columns, the restarts and the sample
/// period. Made by [`Recording::view`], or from plain slices (a simulation, a test).
#[derive(Debug, Clone, Copy)]
pub struct RecordingView<'a> {
    /// Sample times, s.
    pub t: &'a [f64],
    /// Wanted opening O_P, %.
    pub op: &'a [f64],
    /// Valve position V_P, % (NaN where missing; empty when not measured).
    pub vp: &'a [f64],
    /// Rows where a simulation restarts from the measured V_P (after long gaps).
    pub restarts: &'a [usize],
    /// Interval between samples, s.
    pub dt: f64,
}

impl RecordingView<'_> {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.op.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.op.is_empty()
    }

    /// Whether sample `k` has a measured V_P.
    pub fn has_vp(&self, k: usize) -> bool {
        self.vp.get(k).is_some_and(|v| v.is_finite())
    }
}

impl Recording {
    /// The columns, restarts and sample period, borrowed, for analysis.
    pub fn view(&self) -> RecordingView<'_> {
        RecordingView {
            t: &self.t,
            op: &self.op,
            vp: &self.vp,
            restarts: &self.restarts,
            dt: self.sample_period,
        }
    }

    /// A recording from in-memory columns (`vp` may be empty, and NaN where missing), with the
    /// same checks, gap handling and warnings as a file; `source` is `in-memory`.
    pub fn from_vectors(t: Vec<f64>, op: Vec<f64>, vp: Vec<f64>) -> Result<Self, RecordingError> {
        let invalid = |detail: String| RecordingError::Invalid {
            file: "in-memory".into(),
            detail,
        };
        if op.len() != t.len() || !(vp.is_empty() || vp.len() == t.len()) {
            return Err(invalid(format!(
                "column lengths differ: t {}, op {}, vp {} (vp may be empty)",
                t.len(),
                op.len(),
                vp.len()
            )));
        }
        if t.len() < 2 {
            return Err(RecordingError::TooFewRows {
                file: "in-memory".into(),
                rows: t.len(),
                dropped: 0,
            });
        }
        for (name, col) in [("t", &t), ("op", &op)] {
            if let Some(i) = col.iter().position(|v| !v.is_finite()) {
                return Err(invalid(format!(
                    "{name}[{i}] is {}; expected a finite number",
                    col[i]
                )));
            }
        }
        if let Some(i) = vp.iter().position(|v| v.is_infinite()) {
            return Err(invalid(format!(
                "vp[{i}] is {}; expected a finite number or NaN (missing)",
                vp[i]
            )));
        }
        if let Some(i) = (1..t.len()).find(|&i| t[i] <= t[i - 1]) {
            return Err(invalid(format!(
                "t[{i}] = {} s is not after t[{}] = {} s; times must increase strictly",
                t[i],
                i - 1,
                t[i - 1]
            )));
        }
        let n = t.len() as u64;
        let rows = grid::Rows {
            line: (0..n).collect(),
            t,
            op,
            vp,
            status: Vec::new(),
            files: Vec::new(),
            t_ref_ns: None,
        };
        rows.into_recording("in-memory".into(), Vec::new(), MAX_ROWS)
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether there are no samples (never true for a checked recording).
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// Time from the first to the last sample, s.
    pub fn duration(&self) -> f64 {
        match (self.t.first(), self.t.last()) {
            (Some(a), Some(b)) => b - a,
            _ => 0.0,
        }
    }

    /// Builds a recording from the grid: adds the fraction warning and logs the warnings.
    fn assemble(
        g: grid::Grid,
        sample_period: f64,
        source: String,
        mut warnings: Vec<String>,
    ) -> Self {
        let values = || g.op.iter().chain(g.vp.iter().filter(|v| !v.is_nan()));
        if values().all(|v| (0.0..=1.05).contains(v)) {
            let what = if g.vp.is_empty() {
                "O_P lies"
            } else {
                "O_P and V_P lie"
            };
            warnings.push(format!(
                "{what} within [0, 1.05]: looks like fractions of full travel, not percent; \
                 --scale 100 converts"
            ));
        }
        for w in &warnings {
            tracing::warn!(file = %source, "{w}");
        }
        Recording {
            t: g.t,
            op: g.op,
            vp: g.vp,
            status: g.status,
            restarts: g.restarts,
            sample_period,
            source,
            warnings,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vectors_checks_and_measures() {
        let r =
            Recording::from_vectors(vec![0.0, 0.5, 1.0], vec![10.0, 20.0, 30.0], vec![]).unwrap();
        assert_eq!((r.len(), r.duration(), r.sample_period), (3, 1.0, 0.5));
        assert!(r.warnings.is_empty() && r.vp.is_empty() && !r.is_empty());
        assert_eq!(r.source, "in-memory");

        let e = Recording::from_vectors(vec![0.0, 1.0], vec![1.0], vec![]).unwrap_err();
        assert!(e.to_string().contains("lengths differ: t 2, op 1"), "{e}");
        let e = Recording::from_vectors(vec![0.0], vec![1.0], vec![1.0]).unwrap_err();
        assert!(
            matches!(e, RecordingError::TooFewRows { rows: 1, .. }),
            "{e}"
        );
        let e = Recording::from_vectors(vec![0.0, 1.0], vec![1.0, 2.0], vec![3.0, f64::INFINITY])
            .unwrap_err();
        assert!(e.to_string().contains("vp[1] is inf"), "{e}");
        let e = Recording::from_vectors(vec![0.0, 1.0, 1.0], vec![5.0; 3], vec![]).unwrap_err();
        assert!(
            e.to_string().contains("t[2] = 1 s is not after t[1] = 1 s"),
            "{e}"
        );
    }

    #[test]
    fn irregular_sampling_is_counted_with_the_worst_interval() {
        // 200 intervals of 0.01 s, three of them 0.014 s or 0.015 s (not gaps): 1.5 % deviate.
        let mut t = vec![0.0];
        for i in 0..200 {
            let dt = match i {
                50 | 120 => 0.014,
                130 => 0.015,
                _ => 0.01,
            };
            t.push(t[t.len() - 1] + dt);
        }
        let n = t.len();
        let r = Recording::from_vectors(t, vec![50.0; n], vec![50.0; n]).unwrap();
        assert!((r.sample_period - 0.01).abs() < 1e-12, "the median");
        assert_eq!(r.warnings.len(), 1, "{:?}", r.warnings);
        let w = &r.warnings[0];
        assert!(
            w.starts_with("irregular sampling: 3 of 200 intervals"),
            "{w}"
        );
        assert!(w.contains("worst: 0.015 s"), "{w}");
        // Two deviating intervals in 200 (1 %) is still regular.
        let mut t: Vec<f64> = (0..=200).map(|k| k as f64 * 0.01).collect();
        t[100] = 0.995;
        let r = Recording::from_vectors(t, vec![50.0; 201], vec![]).unwrap();
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    }

    #[test]
    fn a_regular_grid_written_as_decimals_gets_its_exact_period() {
        let t: Vec<f64> = (0..60000)
            .map(|k| format!("{:.2}", k as f64 * 0.01).parse().unwrap())
            .collect();
        let r = Recording::from_vectors(t, vec![50.0; 60000], vec![]).unwrap();
        assert_eq!(r.sample_period, 0.01);
    }

    #[test]
    fn fractions_are_flagged() {
        let r = Recording::from_vectors(vec![0.0, 1.0], vec![0.2, 1.0], vec![0.1, 1.04]).unwrap();
        assert_eq!(r.warnings.len(), 1);
        assert!(r.warnings[0].contains("--scale 100"), "{:?}", r.warnings);
        let r = Recording::from_vectors(vec![0.0, 1.0], vec![0.2, 1.0], vec![0.1, 2.0]).unwrap();
        assert!(r.warnings.is_empty());
    }
}
