//! One row of a recording file: finding the mapped columns in the header and parsing their
//! cells (numbers, wall-clock timestamps, missing values) into a [`Row`] or a [`Problem`].
//!
//! Only the mapped cells are parsed; the others may hold anything. A missing V_P (an empty,
//! `NaN`, `NULL`, `NA` or `N/A` cell, or a `status` other than `ok`) is not a problem: the row
//! keeps its place on the time grid with V_P = NaN.

use time::macros::format_description;
use time::PrimitiveDateTime;

use super::log_format::{self, Status};
use super::{ColumnMap, RecordingError};

/// The daemon's status column.
pub(super) const STATUS_COLUMN: &str = log_format::HEADER[3];

/// What one row holds.
pub(super) struct Row {
    /// Time, s (from the first timestamp read, when timestamps).
    pub t: f64,
    pub op: f64,
    /// NaN when missing; `None` when the file has no V_P column.
    pub vp: Option<f64>,
    /// The status cell, when the file has a status column.
    pub status: Option<String>,
}

/// Header positions of the mapped columns, and the state for parsing timestamps.
pub(super) struct Columns<'m> {
    /// One index, or two for `DATE+TIME`.
    t: Vec<usize>,
    op: usize,
    vp: Option<usize>,
    status: Option<usize>,
    map: &'m ColumnMap,
    /// Whether the time cells are timestamps: asked for, implied by `DATE+TIME`, or found on the
    /// first row (a cell that is no number but a timestamp, such as the daemon's `utc`).
    timestamps: Option<bool>,
    /// Scratch space for joining date and time.
    stamp: String,
    /// The first timestamp read, ns since 1970: times are kept relative to it, exactly.
    pub t_ref: Option<i128>,
}

impl<'m> Columns<'m> {
    /// Finds the mapped names (and a `status` column, if any) in the header, or lists those
    /// missing. `timestamps`: the time column is known to hold timestamps.
    pub(super) fn find(
        header: &[String],
        map: &'m ColumnMap,
        timestamps: bool,
    ) -> Result<Self, Vec<String>> {
        let mut missing = Vec::new();
        let mut index = |name: &str| {
            let i = header.iter().position(|h| h == name);
            if i.is_none() {
                missing.push(name.to_string());
            }
            i.unwrap_or(0)
        };
        let t = map.t_columns().map(&mut index).collect();
        let op = index(&map.op);
        let vp = map.vp.as_deref().map(&mut index);
        if !missing.is_empty() {
            return Err(missing);
        }
        Ok(Columns {
            t,
            op,
            vp,
            status: header.iter().position(|h| h == STATUS_COLUMN),
            map,
            timestamps: (timestamps || map.t_is_date_and_time()).then_some(true),
            stamp: String::new(),
            t_ref: None,
        })
    }

    /// One row. With timestamps, t is seconds from the first timestamp read (as written, no
    /// time zone; a trailing `Z` is UTC).
    pub(super) fn parse(&mut self, record: &csv::ByteRecord, width: usize) -> Result<Row, Problem> {
        if record.len() < width {
            return Err(Problem::Short {
                cells: record.len(),
            });
        }
        let cell =
            |i: usize| std::str::from_utf8(record.get(i).unwrap_or(b"")).unwrap_or("\u{fffd}");
        self.stamp.clear();
        for (k, &i) in self.t.iter().enumerate() {
            if k > 0 {
                self.stamp.push(' ');
            }
            self.stamp.push_str(cell(i));
        }
        let timestamps = *self.timestamps.get_or_insert_with(|| {
            self.stamp.parse::<f64>().is_err() && parse_timestamp(&self.stamp).is_some()
        });
        let t = if timestamps {
            let ns = parse_timestamp(&self.stamp).ok_or_else(|| Problem::BadTimestamp {
                column: self.map.t.clone(),
                cell: self.stamp.clone(),
            })?;
            (ns - *self.t_ref.get_or_insert(ns)) as f64 / 1e9
        } else {
            number(&self.map.t, cell(self.t[0]), MAX_TIME_S)?
        };
        let op = number(&self.map.op, cell(self.op), MAX_POSITION)?;
        let status = self.status.map(|i| cell(i).to_string());
        let vp = match (self.vp, &self.map.vp) {
            (Some(i), Some(name)) => match number(name, cell(i), MAX_POSITION) {
                Err(Problem::Missing { .. }) => Some(f64::NAN),
                _ if status
                    .as_deref()
                    .and_then(|s| s.parse::<Status>().ok())
                    .is_some_and(Status::is_failed_read) =>
                {
                    Some(f64::NAN)
                }
                v => Some(v?),
            },
            _ => None,
        };
        Ok(Row { t, op, vp, status })
    }
}

/// What is wrong with one row, before knowing whether it is the last.
#[derive(Debug)]
pub(super) enum Problem {
    Short {
        cells: usize,
    },
    Missing {
        column: String,
        cell: String,
    },
    NotNumber {
        column: String,
        cell: String,
    },
    OutOfRange {
        column: String,
        cell: String,
        max: f64,
    },
    BadTimestamp {
        column: String,
        cell: String,
    },
}

impl std::fmt::Display for Problem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Problem::Short { cells } => write!(f, "{cells} cells"),
            Problem::Missing { column, .. } => write!(f, "no value in `{column}`"),
            Problem::NotNumber { column, cell }
            | Problem::OutOfRange { column, cell, .. }
            | Problem::BadTimestamp { column, cell } => write!(f, "`{cell}` in `{column}`"),
        }
    }
}

impl Problem {
    /// Whether this problem on the last line means the line was cut off mid-write.
    pub(super) fn looks_cut(&self, ends_with_newline: bool) -> bool {
        matches!(self, Problem::Short { .. }) || !ends_with_newline
    }

    pub(super) fn into_error(self, file: &str, line: u64, width: usize) -> RecordingError {
        let file = file.to_string();
        match self {
            Problem::Short { cells } => RecordingError::ShortRow {
                file,
                line,
                cells,
                expected: width,
            },
            Problem::Missing { column, cell } => RecordingError::MissingValue {
                file,
                line,
                column,
                cell,
            },
            Problem::NotNumber { column, cell } => {
                let hint = if looks_like_date_or_time(&cell) {
                    "; it looks like a date or clock time: --timestamps reads wall-clock times \
                     (t=DATE+TIME joins separate date and time columns)"
                } else {
                    ""
                };
                RecordingError::BadCell {
                    file,
                    line,
                    column,
                    cell,
                    expected: "a finite number",
                    hint,
                }
            }
            Problem::OutOfRange { column, cell, max } => RecordingError::BadCell {
                file,
                line,
                column,
                cell,
                expected: if max == MAX_TIME_S {
                    "a time within ±1e11 s"
                } else {
                    "a value within ±1e6 (a position in %, or raw units scaled by --scale)"
                },
                hint: "",
            },
            Problem::BadTimestamp { column, cell } => {
                let hint = if cell.parse::<f64>().is_ok() {
                    "; it is a number: drop --timestamps to read times in seconds"
                } else {
                    ""
                };
                RecordingError::BadCell {
                    file,
                    line,
                    column,
                    cell,
                    expected: "a timestamp YYYY-MM-DD HH:MM:SS[.fff][Z]",
                    hint,
                }
            }
        }
    }
}

/// Largest magnitude of an O_P or V_P value as written: no instrument reads beyond it in any
/// unit, and squares of it stay finite (SSE, R²).
pub(super) const MAX_POSITION: f64 = 1e6;
/// Largest magnitude of a time in seconds (3,000 years).
const MAX_TIME_S: f64 = 1e11;

/// A finite number of magnitude at most `max`, or the problem with the cell.
fn number(column: &str, cell: &str, max: f64) -> Result<f64, Problem> {
    let missing = cell.is_empty()
        || ["nan", "null", "na", "n/a"]
            .iter()
            .any(|m| cell.eq_ignore_ascii_case(m));
    if missing {
        return Err(Problem::Missing {
            column: column.into(),
            cell: cell.into(),
        });
    }
    match cell.parse::<f64>() {
        Ok(v) if v.abs() <= max => Ok(v),
        Ok(v) if v.is_finite() => Err(Problem::OutOfRange {
            column: column.into(),
            cell: cell.into(),
            max,
        }),
        _ => Err(Problem::NotNumber {
            column: column.into(),
            cell: cell.into(),
        }),
    }
}

/// Nanoseconds since 1970-01-01 00:00:00 of `YYYY-MM-DD HH:MM:SS[.fff]` (space or `T` between,
/// optionally ending in `Z`, as the daemon's `utc` column).
fn parse_timestamp(s: &str) -> Option<i128> {
    let format = format_description!(
        "[year]-[month]-[day][first [ ][T]][hour]:[minute]:[second][optional [.[subsecond]]]"
    );
    let s = s.strip_suffix('Z').unwrap_or(s);
    let dt = PrimitiveDateTime::parse(s, &format).ok()?;
    Some(dt.assume_utc().unix_timestamp_nanos())
}

/// `2024-11-27`, `23:59:00` or both: worth suggesting `--timestamps`.
fn looks_like_date_or_time(cell: &str) -> bool {
    let b = cell.as_bytes();
    cell.contains(':') || (b.len() >= 10 && b[4] == b'-' && b[7] == b'-')
}
