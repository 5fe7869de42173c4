//! Reading recording files: [`read`], [`read_from`] and their [`ReadOptions`].
//!
//! The input is parsed as it is read (only the rows are kept), a UTF-8 BOM is skipped, and the
//! CSV is parsed with surrounding whitespace trimmed; a line longer than
//! [`MAX_LINE_BYTES`](super::MAX_LINE_BYTES) or more rows than [`ReadOptions::max_rows`] stop
//! the reading with an error. Only the mapped columns are parsed; the others may hold anything.
//! A problem on the last line is forgiven when that line looks cut off (fewer cells than the
//! header, or no trailing newline); a cut inside the last cell that still leaves a valid number
//! cannot be told from a complete row.

use std::io::{self, Read};
use std::path::Path;

use super::cells::{Columns, Problem};
use super::grid::Rows;
use super::limits::{Capped, MAX_LINE_BYTES, MAX_ROWS, READ_AHEAD};
use super::{gzip, ColumnMap, Recording, RecordingError};

/// How to read a recording file. Each field matches the command-line flag named in the errors.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadOptions {
    /// Which columns hold t, O_P and V_P (`--columns`). `vp=` reads O_P only.
    pub columns: ColumnMap,
    /// Drop rows whose time or O_P cell is empty, `NaN`, `NULL`, `NA` or `N/A`, with a counted
    /// warning (`--skip-missing`); otherwise such a row is an error. The dropped rows leave
    /// gaps in time, handled as any gap. A missing V_P never needs it: the row stays, without
    /// V_P.
    pub skip_missing: bool,
    /// The file runs newest row first: read it backwards (`--reverse`).
    pub reverse_sorted: bool,
    /// The time column holds wall-clock timestamps `YYYY-MM-DD HH:MM:SS[.fff][Z]` (or with `T`
    /// between date and time) instead of seconds (`--timestamps`); implied by `t=DATE+TIME`,
    /// and by a first time cell that is a timestamp rather than a number (the daemon's `utc`
    /// column). Times become seconds from the first row, as written (no time zone).
    pub timestamps: bool,
    /// Factor applied to O_P and V_P (`--scale`, e.g. 100 for fractions of full travel).
    pub scale: f64,
    /// Of a directory holding the daemon logs of several valves, the valve whose logs to read
    /// (`--valve`, its `[[valve]] name`).
    pub valve: Option<String>,
    /// Most rows the recording holds, of all its files together and with its gaps filled
    /// ([`MAX_ROWS`] by default; the `replay` source asks for fewer); more is an error naming
    /// the limit and the file.
    pub max_rows: usize,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            columns: ColumnMap::default(),
            skip_missing: false,
            reverse_sorted: false,
            timestamps: false,
            scale: 1.0,
            valve: None,
            max_rows: MAX_ROWS,
        }
    }
}

/// Reads and checks the recording at `path`.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<Recording, RecordingError> {
    let (rows, warnings) = read_file(path, opts, MIN_ROWS, 0)?;
    rows.into_recording(path.display().to_string(), warnings, opts.max_rows)
}

/// Reads and checks a recording from any reader; `label` names it in errors and in
/// [`Recording::source`].
pub fn read_from<R: Read>(
    reader: R,
    label: &str,
    opts: &ReadOptions,
) -> Result<Recording, RecordingError> {
    let (rows, warnings) = read_rows(reader, label, opts, MIN_ROWS, 0)?;
    rows.into_recording(label.into(), warnings, opts.max_rows)
}

/// The fewest rows a recording has.
pub(super) const MIN_ROWS: usize = 2;

/// [`read_rows`] of the file at `path`, gzip or not, with what the gzip reader tolerated.
pub(super) fn read_file(
    path: &Path,
    opts: &ReadOptions,
    min_rows: usize,
    rows_before: usize,
) -> Result<(Rows, Vec<String>), RecordingError> {
    let label = path.display().to_string();
    let mut input = gzip::open(path).map_err(|source| RecordingError::Io {
        file: label.clone(),
        action: "cannot read",
        source,
    })?;
    let (rows, mut warnings) = read_rows(&mut input, &label, opts, min_rows, rows_before)?;
    warnings.extend(input.warning());
    Ok((rows, warnings))
}

/// The checked rows of one file in time order (times from its first row for timestamps, with
/// that row's time in ns since 1970), and what was tolerated; fewer than `min_rows` rows is an
/// error (a file of a set may be short, or empty: the set is a recording), and so are more
/// than [`ReadOptions::max_rows`] with the `rows_before` of the set's files already read.
pub(super) fn read_rows<R: Read>(
    reader: R,
    label: &str,
    opts: &ReadOptions,
    min_rows: usize,
    rows_before: usize,
) -> Result<(Rows, Vec<String>), RecordingError> {
    if !(opts.scale.is_finite() && opts.scale != 0.0 && opts.scale.abs() <= MAX_SCALE) {
        return Err(RecordingError::Invalid {
            file: label.into(),
            detail: format!(
                "--scale {} must be a finite, non-zero factor of magnitude at most {MAX_SCALE}",
                opts.scale
            ),
        });
    }
    let (mut csv, header) = parser(reader, label)?;
    let mut rows = Rows::default();
    rows.files.push((0, label.to_string()));
    if header.is_empty() && min_rows == 0 {
        return Ok((rows, vec!["empty file, not even a header".into()]));
    }
    let mut cols = Columns::find(&header, &opts.columns, opts.timestamps).map_err(|missing| {
        RecordingError::MissingColumns {
            file: label.into(),
            missing,
            found: header.clone(),
        }
    })?;

    let mut skipped = (0usize, 0u64); // (count, first line)
    let mut pending: Option<(u64, Problem)> = None; // a bad row, forgiven only if it is the last
    let mut record = csv::ByteRecord::new();
    let mut count = rows_before;
    loop {
        csv.get_mut().row_done();
        let start = csv.position().line();
        match csv.read_byte_record(&mut record) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) => return Err(csv_error(&csv, e, label, start)),
        }
        let line = record.position().map_or(start, |p| p.line());
        count += 1;
        if count > opts.max_rows {
            return Err(RecordingError::TooManyRows {
                file: label.into(),
                line,
                limit: opts.max_rows,
            });
        }
        if let Some((line, problem)) = pending.take() {
            return Err(problem.into_error(label, line, header.len()));
        }
        match cols.parse(&record, header.len()) {
            Ok(mut row) => {
                row.op *= opts.scale;
                row.vp = row.vp.map(|v| v * opts.scale);
                rows.push(line, row);
            }
            Err(Problem::Missing { .. }) if opts.skip_missing => {
                if skipped.0 == 0 {
                    skipped.1 = line;
                }
                skipped.0 += 1;
            }
            Err(problem) => pending = Some((line, problem)),
        }
    }
    let ends_with_newline = csv.get_ref().ends_with_newline();

    let mut warnings = Vec::new();
    let mut dropped = skipped.0;
    // A last line without its newline whose V_P is empty was cut inside its last cell.
    let cut_vp =
        !ends_with_newline && pending.is_none() && rows.vp.last().is_some_and(|v| v.is_nan());
    if cut_vp {
        let line = rows.pop();
        warnings.push(format!(
            "dropped line {line}: it looks cut off (no value in `vp`)"
        ));
        dropped += 1;
    }
    if skipped.0 > 0 {
        warnings.push(format!(
            "dropped {} row(s) without a time or O_P (first at line {}); they leave gaps",
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
    if rows.t.len() < min_rows {
        return Err(RecordingError::TooFewRows {
            file: label.into(),
            rows: rows.t.len(),
            dropped,
        });
    }
    if rows.t.len() > 1 {
        rows.order(label, opts.reverse_sorted)?;
    }
    if let (Some(t_ref), Some(&t0)) = (cols.t_ref, rows.t.first()) {
        rows.t.iter_mut().for_each(|t| *t -= t0);
        rows.t_ref_ns = Some(t_ref + (t0 * 1e9).round() as i128);
    }
    Ok((rows, warnings))
}

/// The CSV parser of a recording, over its input without BOM, its lines capped.
type Parser<R> = csv::Reader<Capped<io::Chain<io::Cursor<Vec<u8>>, R>>>;

/// The parser of `reader` (named `label`), and the header it has read.
fn parser<R: Read>(reader: R, label: &str) -> Result<(Parser<R>, Vec<String>), RecordingError> {
    let input = without_bom(reader).map_err(|source| RecordingError::Io {
        file: label.into(),
        action: "cannot read",
        source,
    })?;
    let mut csv = csv::ReaderBuilder::new()
        .flexible(true)
        .trim(csv::Trim::All)
        .buffer_capacity(READ_AHEAD)
        .from_reader(Capped::new(input));
    // Bytes, not strings: only the mapped cells need to be text, so a Latin-1 unit in another
    // column's name or cells does not stop the load.
    let header = match csv.byte_headers() {
        Ok(h) => h
            .iter()
            .map(|h| String::from_utf8_lossy(h).into_owned())
            .collect(),
        Err(e) => return Err(csv_error(&csv, e, label, 1)),
    };
    Ok((csv, header))
}

/// `reader` without the UTF-8 byte order mark it may start with.
fn without_bom<R: Read>(mut reader: R) -> io::Result<io::Chain<io::Cursor<Vec<u8>>, R>> {
    let mut head = Vec::with_capacity(3);
    (&mut reader).take(3).read_to_end(&mut head)?;
    if head == b"\xEF\xBB\xBF" {
        head.clear();
    }
    Ok(io::Cursor::new(head).chain(reader))
}

/// The error of a CSV read that failed in the row starting at `line`: the line limit, the
/// input (a damaged gzip stream, a device), or the CSV itself.
fn csv_error<R: Read>(csv: &Parser<R>, e: csv::Error, label: &str, line: u64) -> RecordingError {
    let file = label.to_string();
    if csv.get_ref().exceeded() {
        return RecordingError::LineTooLong {
            file,
            line,
            limit: MAX_LINE_BYTES,
        };
    }
    let message = e.to_string();
    let line = e.position().map_or(line, |p| p.line());
    match e.into_kind() {
        csv::ErrorKind::Io(source) => RecordingError::Io {
            file,
            action: "cannot read",
            source,
        },
        _ => RecordingError::Csv {
            file,
            line,
            message,
        },
    }
}

/// Largest magnitude of `--scale`: with values within ±1e6, scaled values stay far from
/// overflow in any sum of squares.
const MAX_SCALE: f64 = 1e6;

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
    fn missing_values_keep_their_rows_and_missing_times_are_errors_or_gaps() {
        // A missing V_P keeps its row, without V_P.
        let text = "t_s,op_pct,vp_pct\n0,1,2\n1,2,\n2,3,NaN\n3,4,NULL\n4,5,6\n";
        let r = load(text, &ReadOptions::default()).unwrap();
        assert_eq!(r.t, [0.0, 1.0, 2.0, 3.0, 4.0]);
        assert_eq!(r.vp.iter().filter(|v| v.is_nan()).count(), 3);
        assert_eq!(
            r.warnings,
            ["3 row(s) have no V_P (first at rec.csv:3): simulated through, not scored"]
        );
        // A missing O_P is an error, or with --skip-missing a dropped row, which leaves a gap.
        let text = "t_s,op_pct,vp_pct\n0,1,2\n1,,3\n2,3,4\n3,4,5\n4,5,6\n";
        let e = err(text, &ReadOptions::default());
        assert_eq!(
            e,
            "rec.csv:3: column `op_pct` has no value (``); expected a number; \
             --skip-missing drops such rows (they leave a gap)"
        );
        let skip = ReadOptions {
            skip_missing: true,
            ..ReadOptions::default()
        };
        let r = load(text, &skip).unwrap();
        assert_eq!(r.t, [0.0, 1.0, 2.0, 3.0, 4.0], "the gap is filled");
        assert_eq!(r.op[1], 1.0, "O_P held through the gap");
        assert!(r.vp[1].is_nan());
        assert_eq!(
            r.warnings[0],
            "dropped 1 row(s) without a time or O_P (first at line 3); they leave gaps"
        );
        // Too few left.
        let e = err("t_s,op_pct,vp_pct\n0,1,2\n1,na,2\n", &skip);
        assert_eq!(
            e,
            "rec.csv: 1 usable data row(s) (1 dropped); a recording needs at least 2"
        );
    }

    #[test]
    fn the_status_column_is_kept_and_rows_not_ok_have_no_position() {
        let text =
            "t_s,op_pct,vp_pct,status\n0,1,2,ok\n0.01,1,,timeout\n0.02,1,2.5,error\n0.03,1,3,ok\n";
        let r = load(text, &ReadOptions::default()).unwrap();
        assert_eq!(r.status, ["ok", "timeout", "error", "ok"]);
        assert_eq!(r.vp[0], 2.0);
        assert!(r.vp[1].is_nan() && r.vp[2].is_nan());
        assert_eq!(r.vp[3], 3.0);
    }

    #[test]
    fn gaps_in_time_are_filled_or_restart_with_a_warning_naming_the_line() {
        // 10 Hz; a 0.5 s gap after line 4 (4 missing rows) is filled, a 3,600 s jump at
        // line 8 is kept as a restart.
        let mut text = String::from("t_s,op_pct,vp_pct,status\n");
        for t in [0.0, 0.1, 0.2, 0.7, 0.8, 0.9, 3600.9, 3601.0, 3601.1] {
            text += &format!("{t},50,50,ok\n");
        }
        let r = load(&text, &ReadOptions::default()).unwrap();
        assert_eq!(r.len(), 13);
        assert!(
            (r.t[3] - 0.3).abs() < 1e-12 && (r.t[6] - 0.6).abs() < 1e-12,
            "{:?}",
            r.t
        );
        assert!(r.vp[3..7].iter().all(|v| v.is_nan()));
        assert_eq!(&r.status[3..7], ["gap"; 4]);
        assert_eq!(r.restarts, [10]);
        assert_eq!(r.t[10], 3600.9, "never compressed");
        assert_eq!(r.sample_period, 0.1);
        assert_eq!(
            r.warnings,
            [
                "1 gap(s) in time filled with 4 row(s) without V_P, O_P held (first before rec.csv:5)",
                "time jumps by 3600 s before rec.csv:8: a gap, kept; simulation restarts from \
                 the measured V_P after it"
            ]
        );
    }

    #[test]
    fn the_daemons_utc_column_loads_as_timestamps() {
        let text = "t_s,op_pct,vp_pct,utc\n0,1,2,2026-11-23T19:27:09.045Z\n0.01,1,2,2026-11-23T19:27:09.055Z\n";
        let r = load(text, &opts("t=utc")).unwrap();
        assert_eq!(r.len(), 2);
        assert!((r.t[1] - 0.01).abs() < 1e-9, "{:?}", r.t);
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
            "rec.csv:2: column `stamp`: `2024-13-01 00:00:00` is not a timestamp YYYY-MM-DD HH:MM:SS[.fff][Z]"
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
        assert_eq!(
            e,
            "rec.csv: --scale 0 must be a finite, non-zero factor of magnitude at most 1000000"
        );
    }

    #[test]
    fn io_errors_name_the_file() {
        let e = read(Path::new("/no/such/rec.csv"), &ReadOptions::default()).unwrap_err();
        assert!(
            e.to_string().starts_with("/no/such/rec.csv: cannot read: "),
            "{e}"
        );
    }

    proptest::proptest! {
        /// Arbitrary bytes give a recording or a one-line error naming the input; never a
        /// panic, and a recording holds only finite times and O_P.
        #[test]
        fn any_bytes_load_or_fail_on_one_line(body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..400)) {
            let mut bytes = b"t_s,op_pct,vp_pct,status\n".to_vec();
            bytes.extend(body);
            match read_from(&bytes[..], "fuzz.csv", &ReadOptions::default()) {
                Ok(r) => proptest::prop_assert!(r.t.iter().chain(&r.op).all(|v| v.is_finite())),
                Err(e) => {
                    let e = e.to_string();
                    proptest::prop_assert!(!e.contains('\n') && e.starts_with("fuzz.csv"), "{e}");
                }
            }
        }

        /// Rows of plausible cells (numbers, blanks, NULL, huge values, timestamps) in any order.
        #[test]
        fn plausible_rows_load_or_fail_on_one_line(rows in proptest::collection::vec(
            ("-?[0-9]{1,4}(\\.[0-9]{1,3})?|1e308|NULL||2024-01-01 00:00:0[0-9]", "-?[0-9]{1,3}|NaN|1e400|", "-?[0-9]{1,3}|"), 0..30)) {
            let mut text = String::from("t_s,op_pct,vp_pct\n");
            for (t, op, vp) in rows {
                text += &format!("{t},{op},{vp}\n");
            }
            if let Err(e) = read_from(text.as_bytes(), "fuzz.csv", &ReadOptions::default()) {
                proptest::prop_assert!(!e.to_string().contains('\n'), "{e}");
            }
        }
    }
}
