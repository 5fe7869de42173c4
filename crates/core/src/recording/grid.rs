//! The time grid of a recording: rows in time order, gaps kept as gaps.
//!
//! The sample period is the median interval (or the mean of the regular intervals when the two
//! agree to 1e-6, which averages out times written as decimals). An interval longer than 1.5
//! periods is a **gap**; time is never compressed:
//! - a short gap, at most [`FILLED_ROWS_ANY`] missing rows, or at most [`FILLED_ROWS_MAX`] rows
//!   lasting at most [`LONG_GAP_S`], is filled with rows on the grid that have O_P held (a
//!   command keeps its value until the next one) and no V_P; a model runs through them;
//! - a longer gap keeps the rows on both sides at their times and starts a new segment: the
//!   index of its first row is a **restart**, where a simulation starts again from the measured
//!   V_P, since nothing is known about what the valve did meanwhile. Each one gets a warning
//!   naming its line.
//!
//! Rows without a V_P (NaN) stay where they are; analysis simulates through them and leaves
//! them out of every cost, metric and fit.

use super::{Recording, RecordingError};
use crate::human::num;

/// A gap that lasts longer than this (and lacks more than [`FILLED_ROWS_ANY`] rows) splits the
/// recording, s.
pub const LONG_GAP_S: f64 = 1.0;
/// Most rows a gap of at most [`LONG_GAP_S`] is filled with.
const FILLED_ROWS_MAX: usize = 100;
/// A gap of at most this many missing rows is filled however long it lasts (slowly sampled
/// files: one lost sample of a 30 s log is not a new segment).
const FILLED_ROWS_ANY: usize = 10;
/// An interval longer than this many sample periods is a gap.
const GAP_FACTOR: f64 = 1.5;
/// Long gaps named one by one in the warnings; the rest are counted.
const NAMED_GAPS: usize = 3;
/// Status of the rows that fill a gap.
pub const GAP_STATUS: &str = "gap";

/// Parsed rows, each with where it came from (file and line) for errors and warnings.
#[derive(Default)]
pub(super) struct Rows {
    pub line: Vec<u64>,
    pub t: Vec<f64>,
    pub op: Vec<f64>,
    /// NaN when missing; empty when there is no V_P column.
    pub vp: Vec<f64>,
    /// Empty when there is no status column.
    pub status: Vec<String>,
    /// Where each file's rows start, and the file's label.
    pub files: Vec<(usize, String)>,
    /// For timestamps: the first row's time, ns since 1970 (the times are relative to it).
    pub t_ref_ns: Option<i128>,
}

impl Rows {
    pub(super) fn push(&mut self, line: u64, row: super::cells::Row) {
        self.line.push(line);
        self.t.push(row.t);
        self.op.push(row.op);
        self.vp.extend(row.vp);
        self.status.extend(row.status);
    }

    /// Removes the last row; returns its line.
    pub(super) fn pop(&mut self) -> u64 {
        self.t.pop();
        self.op.pop();
        self.vp.pop();
        self.status.pop();
        self.line.pop().unwrap_or(0)
    }

    /// Appends `other` (a later file) after these rows.
    pub(super) fn append(&mut self, mut other: Rows) {
        let at = self.t.len();
        self.files
            .extend(other.files.drain(..).map(|(k, f)| (k + at, f)));
        self.line.append(&mut other.line);
        self.t.append(&mut other.t);
        self.op.append(&mut other.op);
        self.vp.append(&mut other.vp);
        self.status.append(&mut other.status);
    }

    /// The file and line of row `i`.
    fn file_line(&self, i: usize) -> (&str, u64) {
        let file = self
            .files
            .iter()
            .rev()
            .find(|(start, _)| *start <= i)
            .map_or("in-memory", |(_, f)| f.as_str());
        (file, self.line.get(i).copied().unwrap_or(0))
    }

    /// `file:line` of row `i`.
    fn place(&self, i: usize) -> String {
        let (file, line) = self.file_line(i);
        format!("{file}:{line}")
    }

    /// Reverses a newest-first file when asked, then checks that time increases strictly.
    pub(super) fn order(&mut self, file: &str, reverse: bool) -> Result<(), RecordingError> {
        let decreasing = self.t.windows(2).all(|w| w[1] < w[0]);
        let increasing = self.t.windows(2).all(|w| w[1] > w[0]);
        if reverse {
            if increasing {
                return Err(RecordingError::AlreadyForward { file: file.into() });
            }
            self.line.reverse();
            self.t.reverse();
            self.op.reverse();
            self.vp.reverse();
            self.status.reverse();
        } else if decreasing {
            return Err(RecordingError::NewestFirst { file: file.into() });
        }
        match (1..self.t.len()).find(|&i| self.t[i] <= self.t[i - 1]) {
            Some(i) => Err(RecordingError::NotIncreasing {
                file: file.into(),
                line: self.line[i],
                t: self.t[i],
                prev_line: self.line[i - 1],
                prev_t: self.t[i - 1],
            }),
            None => Ok(()),
        }
    }

    /// The recording: gaps filled or kept as restarts, with the warnings (logged too); an error
    /// when filling the gaps would make more than `max_rows` rows. The rows are in strictly
    /// increasing time, at least two.
    pub(super) fn into_recording(
        self,
        source: String,
        mut warnings: Vec<String>,
        max_rows: usize,
    ) -> Result<Recording, RecordingError> {
        let (period, irregular) = sampling(&self.t);
        warnings.extend(irregular);
        if let Some(first) = self.vp.iter().position(|v| v.is_nan()) {
            let count = self.vp.iter().filter(|v| v.is_nan()).count();
            warnings.push(format!(
                "{count} row(s) have no V_P (first at {}): simulated through, not scored",
                self.place(first)
            ));
        }
        let mut out =
            Grid::with_capacity(self.t.len(), !self.vp.is_empty(), !self.status.is_empty());
        let mut filled = (0usize, 0usize, None); // (gaps, rows, first place)
        let mut long = Vec::new();
        for i in 0..self.t.len() {
            if i > 0 {
                let d = self.t[i] - self.t[i - 1];
                if is_gap(d, period) {
                    let missing = ((d / period).round() as usize).saturating_sub(1).max(1);
                    if missing <= FILLED_ROWS_ANY || (missing <= FILLED_ROWS_MAX && d <= LONG_GAP_S)
                    {
                        if out.t.len() + missing + (self.t.len() - i) > max_rows {
                            let (file, line) = self.file_line(i);
                            return Err(RecordingError::TooManyRows {
                                file: file.into(),
                                line,
                                limit: max_rows,
                            });
                        }
                        out.fill(self.t[i - 1], d, missing, self.op[i - 1]);
                        filled.0 += 1;
                        filled.1 += missing;
                        filled.2.get_or_insert_with(|| self.place(i));
                    } else {
                        out.restarts.push(out.t.len());
                        long.push((d, self.place(i)));
                    }
                }
            }
            out.t.push(self.t[i]);
            out.op.push(self.op[i]);
            out.vp.extend(self.vp.get(i));
            out.status.extend(self.status.get(i).cloned());
        }
        if let (n, rows, Some(place)) = filled {
            warnings.push(format!(
                "{n} gap(s) in time filled with {rows} row(s) without V_P, O_P held (first before {place})"
            ));
        }
        for (d, place) in long.iter().take(NAMED_GAPS) {
            warnings.push(format!(
                "time jumps by {} s before {place}: a gap, kept; simulation restarts from the measured V_P after it",
                num(*d)
            ));
        }
        if long.len() > NAMED_GAPS {
            warnings.push(format!(
                "and {} more gap(s) longer than {LONG_GAP_S} s",
                long.len() - NAMED_GAPS
            ));
        }
        Ok(Recording::assemble(out, period, source, warnings))
    }
}

/// Whether an interval `d` is a gap at sample period `period` (a hair of tolerance: times
/// written as decimals land on 1.5 periods exactly or a rounding above it).
fn is_gap(d: f64, period: f64) -> bool {
    d > GAP_FACTOR * period * (1.0 + 1e-6)
}

/// The columns on the grid, being built.
pub(super) struct Grid {
    pub t: Vec<f64>,
    pub op: Vec<f64>,
    pub vp: Vec<f64>,
    pub status: Vec<String>,
    pub restarts: Vec<usize>,
    has_vp: bool,
    has_status: bool,
}

impl Grid {
    fn with_capacity(n: usize, has_vp: bool, has_status: bool) -> Self {
        Grid {
            t: Vec::with_capacity(n),
            op: Vec::with_capacity(n),
            vp: Vec::with_capacity(if has_vp { n } else { 0 }),
            status: Vec::new(),
            restarts: Vec::new(),
            has_vp,
            has_status,
        }
    }

    /// `missing` rows evenly spaced inside the interval `d` after `t0`, O_P held, no V_P.
    fn fill(&mut self, t0: f64, d: f64, missing: usize, op: f64) {
        for j in 1..=missing {
            self.t.push(t0 + d * j as f64 / (missing + 1) as f64);
            self.op.push(op);
            if self.has_vp {
                self.vp.push(f64::NAN);
            }
            if self.has_status {
                self.status.push(GAP_STATUS.into());
            }
        }
    }
}

/// The sample period (see [`Recording::sample_period`]) and, when more than 1 % of the
/// intervals that are not gaps differ from the median by more than 10 %, a warning with their
/// count and the worst one. `t` has at least two samples.
fn sampling(t: &[f64]) -> (f64, Option<String>) {
    let mut dt: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let m = dt.len();
    dt.sort_unstable_by(f64::total_cmp);
    let median = if m % 2 == 1 {
        dt[m / 2]
    } else {
        (dt[m / 2 - 1] + dt[m / 2]) / 2.0
    };
    let mut count = 0;
    let mut regular = 0usize;
    let mut worst = (0.0, 0.0, 0.0); // (|deviation|, interval, start time)
    for w in t.windows(2) {
        let d = w[1] - w[0];
        if is_gap(d, median) {
            continue;
        }
        regular += 1;
        let dev = (d - median).abs();
        if dev > 0.1 * median {
            count += 1;
            if dev > worst.0 {
                worst = (dev, d, w[0]);
            }
        }
    }
    let warning = (count * 100 > regular).then(|| {
        format!(
            "irregular sampling: {count} of {regular} intervals differ by more than 10 % from the \
             median {} s (worst: {} s after t = {} s)",
            num(median),
            num(worst.1),
            num(worst.2)
        )
    });
    // Only without gaps: the span is then exact (no sum of rounded differences).
    let mean = (t[m] - t[0]) / m as f64;
    let period = if regular == m && (mean - median).abs() <= 1e-6 * median {
        mean
    } else {
        median
    };
    (period, warning)
}
