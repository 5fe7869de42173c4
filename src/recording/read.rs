//! Reading recording files: [`read`], [`read_from`] and their [`ReadOptions`].
//!
//! The whole input is read into memory (recordings are a few MB), a UTF-8 BOM is skipped, and
//! the CSV is parsed with surrounding whitespace trimmed. Only the mapped columns are parsed;
//! the others may hold anything. A problem on the last line is forgiven when that line looks
//! cut off (fewer cells than the header, or no trailing newline); a cut inside the last cell
//! that still leaves a valid number cannot be told from a complete row.

use std::io::Read;
use std::path::Path;

use time::macros::format_description;
use time::PrimitiveDateTime;

use super::{ColumnMap, Recording, RecordingError};

/// How to read a recording file. Each field matches the command-line flag named in the errors.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadOptions {
    /// Which columns hold t, O_P and V_P (`--columns`). `vp=` reads O_P only.
    pub columns: ColumnMap,
    /// Drop rows whose mapped cells are empty, `NaN`, `NULL`, `NA` or `N/A`, with a counted
    /// warning (`--skip-missing`); otherwise such a row is an error. The dropped rows leave
    /// gaps in time, which the irregular-sampling warning reports if they are many.
    pub skip_missing: bool,
    /// The file runs newest row first: read it backwards (`--reverse`).
    pub reverse_sorted: bool,
    /// The time column holds wall-clock timestamps `YYYY-MM-DD HH:MM:SS[.fff]` (or with `T`
    /// between date and time) instead of seconds (`--timestamps`); implied by `t=DATE+TIME`.
    /// Times become seconds from the first row, as written (no time zone).
    pub timestamps: bool,
    /// Factor applied to O_P and V_P (`--scale`, e.g. 100 for fractions of full travel).
    pub scale: f64,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            columns: ColumnMap::default(),
            skip_missing: false,
            reverse_sorted: false,
            timestamps: false,
            scale: 1.0,
        }
    }
}

/// Reads and checks the recording at `path`.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<Recording, RecordingError> {
    let label = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|source| RecordingError::Io {
        file: label.clone(),
        action: "cannot read",
        source,
    })?;
    read_from(file, &label, opts)
}

/// Reads and checks a recording from any reader; `label` names it in errors and in
/// [`Recording::source`].
pub fn read_from<R: Read>(
    mut reader: R,
    label: &str,
    opts: &ReadOptions,
) -> Result<Recording, RecordingError> {
    if !(opts.scale.is_finite() && opts.scale != 0.0) {
        return Err(RecordingError::Invalid {
            file: label.into(),
            detail: format!("--scale {} must be a finite, non-zero factor", opts.scale),
        });
    }
    let mut bytes = Vec::new();
    reader
        .read_to_end(&mut bytes)
        .map_err(|source| RecordingError::Io {
            file: label.into(),
            action: "cannot read",
            source,
        })?;
    let body = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(&bytes);
    let ends_with_newline = matches!(body.last(), Some(b'\n' | b'\r'));
    let mut csv = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .from_reader(body);
    let csv_error = |e: csv::Error| RecordingError::Csv {
        file: label.into(),
        line: e.position().map_or(1, |p| p.line()),
        message: e.to_string(),
    };
    // Bytes, not strings: only the mapped cells need to be text, so a Latin-1 unit in another
    // column's name or cells does not stop the load.
    let header: Vec<String> = csv
        .byte_headers()
        .map_err(csv_error)?
        .iter()
        .map(|h| String::from_utf8_lossy(h).into_owned())
        .collect();
    let mut cols = Columns::find(&header, &opts.columns).map_err(|missing| {
        RecordingError::MissingColumns {
            file: label.into(),
            missing,
            found: header.clone(),
        }
    })?;
    let timestamps = opts.timestamps || opts.columns.t_is_date_and_time();

    let mut rows = Rows::default();
    let mut skipped = (0usize, 0u64); // (count, first line)
    let mut pending: Option<(u64, Problem)> = None; // a bad row, forgiven only if it is the last
    let mut record = csv::ByteRecord::new();
    while csv.read_byte_record(&mut record).map_err(csv_error)? {
        let line = record.position().map_or(0, |p| p.line());
        if let Some((line, problem)) = pending.take() {
            return Err(problem.into_error(label, line, header.len()));
        }
        match cols.parse(&record, header.len(), timestamps) {
            Ok((t, op, vp)) => rows.push(line, t, op * opts.scale, vp.map(|v| v * opts.scale)),
            Err(Problem::Missing { .. }) if opts.skip_missing => {
                if skipped.0 == 0 {
                    skipped.1 = line;
                }
                skipped.0 += 1;
            }
            Err(problem) => pending = Some((line, problem)),
        }
    }

    let mut warnings = Vec::new();
    let mut dropped = skipped.0;
    if skipped.0 > 0 {
        warnings.push(format!(
            "dropped {} row(s) with a missing value (first at line {})",
            skipped.0, skipped.1
        ));
    }
    if let Some((line, problem)) = pending {
        if !problem.looks_cut(ends_with_newline) {
            return Err(problem.into_error(label, line, header.len()));
        }
        warnings.push(format!("dropped line {line}: it looks cut off ({problem})"));
        dropped += 1;
    }
    if rows.t.len() < 2 {
        return Err(RecordingError::TooFewRows {
            file: label.into(),
            rows: rows.t.len(),
            dropped,
        });
    }
    rows.order(label, opts.reverse_sorted)?;
    if timestamps {
        let t0 = rows.t[0];
        rows.t.iter_mut().for_each(|t| *t -= t0);
    }
    Ok(Recording::assemble(
        rows.t,
        rows.op,
        rows.vp,
        label.into(),
        warnings,
    ))
}

/// Header positions of the mapped columns, and the state for parsing timestamps.
struct Columns<'m> {
    /// One index, or two for `DATE+TIME`.
    t: Vec<usize>,
    op: usize,
    vp: Option<usize>,
    map: &'m ColumnMap,
    /// Scratch space for joining date and time.
    stamp: String,
    /// The first timestamp read, ns since 1970: times are kept relative to it, exactly.
    t_ref: Option<i128>,
}

impl<'m> Columns<'m> {
    /// Finds the mapped names in the header, or lists those missing.
    fn find(header: &[String], map: &'m ColumnMap) -> Result<Self, Vec<String>> {
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
        if missing.is_empty() {
            Ok(Columns {
                t,
                op,
                vp,
                map,
                stamp: String::new(),
                t_ref: None,
            })
        } else {
            Err(missing)
        }
    }

    /// One row's (t, O_P, V_P). With timestamps, t is seconds from the first timestamp read
    /// (as written, no time zone).
    fn parse(
        &mut self,
        record: &csv::ByteRecord,
        width: usize,
        timestamps: bool,
    ) -> Result<(f64, f64, Option<f64>), Problem> {
        if record.len() < width {
            return Err(Problem::Short {
                cells: record.len(),
            });
        }
        let cell =
            |i: usize| std::str::from_utf8(record.get(i).unwrap_or(b"")).unwrap_or("\u{fffd}");
        let t = if timestamps {
            self.stamp.clear();
            for (k, &i) in self.t.iter().enumerate() {
                if k > 0 {
                    self.stamp.push(' ');
                }
                self.stamp.push_str(cell(i));
            }
            let ns = parse_timestamp(&self.stamp).ok_or_else(|| Problem::BadTimestamp {
                column: self.map.t.clone(),
                cell: self.stamp.clone(),
            })?;
            (ns - *self.t_ref.get_or_insert(ns)) as f64 / 1e9
        } else {
            number(&self.map.t, cell(self.t[0]), MAX_TIME_S)?
        };
        let op = number(&self.map.op, cell(self.op), MAX_POSITION)?;
        let vp = match (self.vp, &self.map.vp) {
            (Some(i), Some(name)) => Some(number(name, cell(i), MAX_POSITION)?),
            _ => None,
        };
        Ok((t, op, vp))
    }
}

/// What is wrong with one row, before knowing whether it is the last.
#[derive(Debug)]
enum Problem {
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
    fn looks_cut(&self, ends_with_newline: bool) -> bool {
        matches!(self, Problem::Short { .. }) || !ends_with_newline
    }

    fn into_error(self, file: &str, line: u64, width: usize) -> RecordingError {
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
                    expected: "a timestamp YYYY-MM-DD HH:MM:SS[.fff]",
                    hint,
                }
            }
        }
    }
}

/// Largest magnitude of an O_P or V_P value as written: no instrument reads beyond it in any
/// unit, and squares of it stay finite (SSE, R²).
const MAX_POSITION: f64 = 1e6;
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

/// Nanoseconds since 1970-01-01 00:00:00 of `YYYY-MM-DD HH:MM:SS[.fff]` (space or `T` between).
fn parse_timestamp(s: &str) -> Option<i128> {
    let format = format_description!(
        "[year]-[month]-[day][first [ ][T]][hour]:[minute]:[second][optional [.[subsecond]]]"
    );
    let dt = PrimitiveDateTime::parse(s, &format).ok()?;
    Some(dt.assume_utc().unix_timestamp_nanos())
}

/// `2024-11-27`, `23:59:00` or both: worth suggesting `--timestamps`.
fn looks_like_date_or_time(cell: &str) -> bool {
    let b = cell.as_bytes();
    cell.contains(':') || (b.len() >= 10 && b[4] == b'-' && b[7] == b'-')
}

/// The parsed columns, with each row's line for errors about time order.
#[derive(Default)]
struct Rows {
    line: Vec<u64>,
    t: Vec<f64>,
    op: Vec<f64>,
    vp: Vec<f64>,
}

impl Rows {
    fn push(&mut self, line: u64, t: f64, op: f64, vp: Option<f64>) {
        self.line.push(line);
        self.t.push(t);
        self.op.push(op);
        self.vp.extend(vp);
    }

    /// Reverses a newest-first file when asked, then checks that time increases strictly.
    fn order(&mut self, file: &str, reverse: bool) -> Result<(), RecordingError> {
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
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str, opts: &ReadOptions) -> Result<Recording, RecordingError> {
        read_from(text.as_bytes(), "rec.csv", opts)
    }

    fn err(text: &str, opts: &ReadOptions) -> String {
        let e = load(text, opts).unwrap_err().to_string();
        assert!(!e.contains('\n'), "one line: {e}");
        e
    }

    fn opts(columns: &str) -> ReadOptions {
        ReadOptions {
            columns: columns.parse().unwrap(),
            ..ReadOptions::default()
        }
    }

    const GOOD: &str = "t_s,op_pct,vp_pct\n0,10,11\n0.01,20,12.5\n0.02,30,14\n";

    #[test]
    fn reads_the_default_format_exactly() {
        let r = load(GOOD, &ReadOptions::default()).unwrap();
        assert_eq!(r.t, [0.0, 0.01, 0.02]);
        assert_eq!(r.op, [10.0, 20.0, 30.0]);
        assert_eq!(r.vp, [11.0, 12.5, 14.0]);
        assert_eq!(r.sample_period, 0.01);
        assert_eq!(r.source, "rec.csv");
        assert!(r.warnings.is_empty(), "{:?}", r.warnings);
    }

    #[test]
    fn bom_crlf_spaces_extra_columns_and_mapping() {
        let text = "\u{feff}time , extra, CV,POS\r\n0, a, 1.5, 2\r\n1, b, 2.5, 3\r\n";
        let r = load(text, &opts("t=time,op=CV,vp=POS")).unwrap();
        assert_eq!(
            (r.op.as_slice(), r.vp.as_slice()),
            ([1.5, 2.5].as_slice(), [2.0, 3.0].as_slice())
        );
        assert_eq!(r.sample_period, 1.0);
        // O_P only.
        let r = load("t_s,op_pct\n0,5\n1,6\n", &opts("vp=")).unwrap();
        assert!(r.vp.is_empty());
        assert_eq!(r.op, [5.0, 6.0]);
    }

    #[test]
    fn missing_columns_list_what_was_found() {
        let e = err("time,CV,POS\n0,1,2\n1,2,3\n", &ReadOptions::default());
        assert_eq!(
            e,
            "rec.csv:1: no column `t_s`, `op_pct`, `vp_pct`; the header has `time`, `CV`, `POS`; \
             name the columns with --columns t=TIME,op=OP,vp=VP (vp= for a file without V_P)"
        );
        let e = err("", &ReadOptions::default());
        assert!(e.contains("the header has no columns (empty file?)"), "{e}");
    }

    #[test]
    fn non_numeric_cells_name_line_and_column() {
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,abc,3\n2,1,2\n",
            &ReadOptions::default(),
        );
        assert_eq!(
            e,
            "rec.csv:3: column `op_pct`: `abc` is not a finite number"
        );
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,inf,3\n2,1,2\n",
            &ReadOptions::default(),
        );
        assert!(e.starts_with("rec.csv:3: column `op_pct`: `inf`"), "{e}");
    }

    #[test]
    fn missing_values_are_errors_or_counted_drops() {
        let text = "t_s,op_pct,vp_pct\n0,1,2\n1,2,\n2,3,NaN\n3,4,NULL\n4,5,6\n";
        let e = err(text, &ReadOptions::default());
        assert_eq!(
            e,
            "rec.csv:3: column `vp_pct` has no value (``); expected a number; \
             --skip-missing drops such rows"
        );
        let skip = ReadOptions {
            skip_missing: true,
            ..ReadOptions::default()
        };
        let r = load(text, &skip).unwrap();
        assert_eq!(r.t, [0.0, 4.0]);
        assert_eq!(
            r.warnings[0],
            "dropped 3 row(s) with a missing value (first at line 3)"
        );
        // Too few left.
        let e = err("t_s,op_pct,vp_pct\n0,1,2\n1,2,na\n", &skip);
        assert_eq!(
            e,
            "rec.csv: 1 usable data row(s) (1 dropped); a recording needs at least 2"
        );
    }

    #[test]
    fn too_few_rows() {
        let e = err("t_s,op_pct,vp_pct\n0,1,2\n", &ReadOptions::default());
        assert_eq!(
            e,
            "rec.csv: 1 usable data row(s); a recording needs at least 2"
        );
    }

    #[test]
    fn time_must_increase_and_newest_first_is_recognised() {
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,1,2\n1,1,2\n2,1,2\n",
            &ReadOptions::default(),
        );
        assert_eq!(
            e,
            "rec.csv:4: time 1 s is not after 1 s (line 3); times must increase strictly"
        );
        let backwards = "t_s,op_pct,vp_pct\n2,30,3\n1,20,2\n0,10,1\n";
        let e = err(backwards, &ReadOptions::default());
        assert_eq!(
            e,
            "rec.csv: times decrease on every row (newest row first); \
             --reverse reads the file oldest first"
        );
        let reverse = ReadOptions {
            reverse_sorted: true,
            ..ReadOptions::default()
        };
        let r = load(backwards, &reverse).unwrap();
        assert_eq!(
            (r.t.as_slice(), r.op.as_slice()),
            ([0.0, 1.0, 2.0].as_slice(), [10.0, 20.0, 30.0].as_slice())
        );
        assert_eq!(r.vp, [1.0, 2.0, 3.0]);
        let e = err(GOOD, &reverse);
        assert!(e.contains("drop --reverse"), "{e}");
        // Reversed, a mostly-backwards file still names the offending line.
        let e = err("t_s,op_pct,vp_pct\n3,1,2\n1,1,2\n2,1,2\n0,1,2\n", &reverse);
        assert!(
            e.starts_with("rec.csv:3: time 1 s is not after 2 s (line 4)"),
            "{e}"
        );
    }

    #[test]
    fn a_cut_off_last_line_is_dropped_with_a_warning() {
        for cut in ["2,3", "2,3,4e", "2,3,"] {
            let text = format!("t_s,op_pct,vp_pct\n0,1,2\n1,2,3\n{cut}");
            let r = load(&text, &ReadOptions::default()).unwrap();
            assert_eq!(r.len(), 2, "{cut}");
            assert!(
                r.warnings[0].starts_with("dropped line 4: it looks cut off"),
                "{:?}",
                r.warnings
            );
        }
        // Fewer cells is a cut even with a newline; a bad cell on a complete last line is not.
        let r = load(
            "t_s,op_pct,vp_pct\n0,1,2\n1,2,3\n2,3\n",
            &ReadOptions::default(),
        )
        .unwrap();
        assert_eq!(r.len(), 2);
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,2,3\n2,3,x\n",
            &ReadOptions::default(),
        );
        assert!(e.starts_with("rec.csv:4: column `vp_pct`: `x`"), "{e}");
        // A short row before the last line is an error.
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,2\n2,3,4\n",
            &ReadOptions::default(),
        );
        assert_eq!(
            e,
            "rec.csv:3: 2 cells but the header has 3; only a cut-off last line is tolerated"
        );
    }

    #[test]
    fn timestamps_in_one_or_two_columns() {
        let text = "date,time,CO\n2024-11-21,00:00:00,40\n2024-11-21,00:01:00,41\n2024-11-21,00:02:30.5,42\n";
        let e = err(text, &opts("t=time,op=CO,vp="));
        assert_eq!(
            e,
            "rec.csv:2: column `time`: `00:00:00` is not a finite number; it looks like a date or \
             clock time: --timestamps reads wall-clock times (t=DATE+TIME joins separate date \
             and time columns)"
        );
        let r = load(text, &opts("t=date+time,op=CO,vp=")).unwrap();
        assert_eq!(r.t, [0.0, 60.0, 150.5]);
        let one = "stamp,op_pct,vp_pct\n2024-11-21T23:59:59,1,2\n2024-11-22 00:00:01,1,2\n";
        let ts = ReadOptions {
            timestamps: true,
            ..opts("t=stamp")
        };
        assert_eq!(load(one, &ts).unwrap().t, [0.0, 2.0]);
        let e = err("stamp,op_pct,vp_pct\n2024-13-01 00:00:00,1,2\n0,1,2\n", &ts);
        assert_eq!(
            e,
            "rec.csv:2: column `stamp`: `2024-13-01 00:00:00` is not a timestamp YYYY-MM-DD HH:MM:SS[.fff]"
        );
        let e = err("stamp,op_pct,vp_pct\n0,1,2\n1,1,2\n", &ts);
        assert!(
            e.ends_with("it is a number: drop --timestamps to read times in seconds"),
            "{e}"
        );
    }

    #[test]
    fn scale_converts_fractions_and_silences_the_warning() {
        let text = "t_s,op_pct,vp_pct\n0,0.25,0.2\n1,0.5,0.45\n";
        let r = load(text, &ReadOptions::default()).unwrap();
        assert!(
            r.warnings[0].contains("looks like fractions"),
            "{:?}",
            r.warnings
        );
        let r = load(
            text,
            &ReadOptions {
                scale: 100.0,
                ..ReadOptions::default()
            },
        )
        .unwrap();
        assert_eq!((r.op[1], r.vp[1]), (50.0, 45.0));
        assert!(r.warnings.is_empty());
    }

    #[test]
    fn latin1_in_other_columns_is_harmless_and_scale_must_be_sane() {
        let text = b"t_s,op_pct,vp_pct,T_\xb0C\n0,1,2,\xb5\n1,2,3,x\n";
        let r = read_from(&text[..], "rec.csv", &ReadOptions::default()).unwrap();
        assert_eq!(r.vp, [2.0, 3.0]);
        let e = err(
            "t_s,op_pct,vp_pct\n0,1,2\n1,2,3\n",
            &ReadOptions {
                scale: 0.0,
                ..ReadOptions::default()
            },
        );
        assert_eq!(e, "rec.csv: --scale 0 must be a finite, non-zero factor");
    }

    #[test]
    fn io_errors_name_the_file() {
        let e = read(Path::new("/no/such/rec.csv"), &ReadOptions::default()).unwrap_err();
        assert!(
            e.to_string().starts_with("/no/such/rec.csv: cannot read: "),
            "{e}"
        );
    }
}
