//! [`RecordingError`]: every way a recording can fail to load or save, as one line that says
//! where (file, line, column), what was expected and which option fixes it.

/// A recording that cannot be read, checked or written.
///
/// `file` is the path (or the label given to [`read_from`](super::read_from)); `line` is the
/// 1-based line in that file, the header being line 1. Options are named by their command-line
/// flags; each maps to one [`ReadOptions`](super::ReadOptions) field.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file cannot be opened, read or written.
    #[error("{file}: {action}: {source}")]
    Io {
        /// Path or label.
        file: String,
        /// `cannot read` or `cannot write`.
        action: &'static str,
        /// The cause.
        source: std::io::Error,
    },
    /// The CSV itself is malformed (e.g. not UTF-8).
    #[error("{file}:{line}: malformed CSV: {message}")]
    Csv {
        /// Path or label.
        file: String,
        /// Line of the bad record.
        line: u64,
        /// What the CSV parser said.
        message: String,
    },
    /// The header lacks a mapped column.
    #[error(
        "{file}:1: no column {}; the header has {}; name the columns with --columns t=TIME,op=OP,vp=VP (vp= for a file without V_P)",
        quoted(missing),
        if found.is_empty() { "no columns (empty file?)".to_string() } else { quoted(found) }
    )]
    MissingColumns {
        /// Path or label.
        file: String,
        /// The mapped names not found.
        missing: Vec<String>,
        /// The header as found.
        found: Vec<String>,
    },
    /// A line (or a run of blank lines) longer than
    /// [`MAX_LINE_BYTES`](super::MAX_LINE_BYTES): a damaged file, a decompression bomb,
    /// or a device that never ends, refused before it fills memory.
    #[error("{file}:{line}: no line ends within {limit} bytes (1 MiB, the longest line a recording may have); the file is damaged or no recording (a decompression bomb, a device such as /dev/zero)")]
    LineTooLong {
        /// Path or label.
        file: String,
        /// The line where the long one starts.
        line: u64,
        /// The limit, bytes.
        limit: usize,
    },
    /// More rows than a recording holds ([`MAX_ROWS`](super::MAX_ROWS), or fewer for a
    /// replay), as read or with its gaps filled.
    #[error("{file}:{line}: more than {limit} rows on the time grid ({} h at 100 Hz), the most a recording holds: cut the file, or read fewer files", crate::human::num(*limit as f64 / 360_000.0))]
    TooManyRows {
        /// Path or label.
        file: String,
        /// The line read, or after the gap filled, when the rows passed the limit.
        line: u64,
        /// The limit, rows.
        limit: usize,
    },
    /// A row with fewer cells than the header, before the last line.
    #[error("{file}:{line}: {cells} cells but the header has {expected}; only a cut-off last line is tolerated")]
    ShortRow {
        /// Path or label.
        file: String,
        /// Line of the row.
        line: u64,
        /// Cells in the row.
        cells: usize,
        /// Cells in the header.
        expected: usize,
    },
    /// An empty, `NaN`, `NULL` or `NA` cell where a time or O_P is needed.
    #[error("{file}:{line}: column `{column}` has no value (`{cell}`); expected a number; --skip-missing drops such rows (they leave a gap)")]
    MissingValue {
        /// Path or label.
        file: String,
        /// Line of the row.
        line: u64,
        /// Column name.
        column: String,
        /// The cell as written (empty for an empty cell).
        cell: String,
    },
    /// A cell that is not a finite number (or not a timestamp, with `--timestamps`).
    #[error("{file}:{line}: column `{column}`: `{cell}` is not {expected}{hint}")]
    BadCell {
        /// Path or label.
        file: String,
        /// Line of the row.
        line: u64,
        /// Column name (`DATE+TIME` for joined columns).
        column: String,
        /// The cell as written.
        cell: String,
        /// What the cell should be.
        expected: &'static str,
        /// `; ...` with the option that fixes it, or empty.
        hint: &'static str,
    },
    /// Time does not increase from one row to the next.
    #[error("{file}:{line}: time {t} s is not after {prev_t} s (line {prev_line}); times must increase strictly")]
    NotIncreasing {
        /// Path or label.
        file: String,
        /// Line of the offending row.
        line: u64,
        /// Its time, s.
        t: f64,
        /// Line of the row before it (in time order).
        prev_line: u64,
        /// That row's time, s.
        prev_t: f64,
    },
    /// Every row is older than the one above it.
    #[error("{file}: times decrease on every row (newest row first); --reverse reads the file oldest first")]
    NewestFirst {
        /// Path or label.
        file: String,
    },
    /// `--reverse` on a file that already runs forward in time.
    #[error("{file}: --reverse was given but the times already increase; drop --reverse")]
    AlreadyForward {
        /// Path or label.
        file: String,
    },
    /// Fewer than two usable rows.
    #[error("{file}: {rows} usable data row(s){}; a recording needs at least 2", if *dropped > 0 { format!(" ({dropped} dropped)") } else { String::new() })]
    TooFewRows {
        /// Path or label.
        file: String,
        /// Rows kept.
        rows: usize,
        /// Rows dropped (missing values, cut-off last line).
        dropped: usize,
    },
    /// Two joined files cover the same time.
    #[error("{first}:{first_line}: ends at {} s, after {second}:{second_line} starts at {} s; joined files must not overlap in time (files of separate daemon runs: read their `utc` column with --columns t=utc)", crate::human::num(*first_end), crate::human::num(*second_start))]
    Overlap {
        /// The earlier file.
        first: String,
        /// Its last line.
        first_line: u64,
        /// Its last time, s.
        first_end: f64,
        /// The later file.
        second: String,
        /// Its first data line.
        second_line: u64,
        /// Its first time, s.
        second_start: f64,
    },
    /// Joined files where some have timestamps and others seconds.
    #[error("{first} has wall-clock timestamps but {second} has times in seconds; join files of one kind")]
    MixedTimes {
        /// A file with timestamps.
        first: String,
        /// A file with seconds.
        second: String,
    },
    /// A directory given as input holds no `.csv` file.
    #[error(
        "{dir}: no .csv file in this directory; give the recording files or a directory of them"
    )]
    NoFiles {
        /// The directory.
        dir: String,
    },
    /// A directory holds the daemon logs of several valves and none was chosen.
    #[error("{dir} holds the logs of {} valves ({}): choose one with --valve NAME", found.len(), found.join(", "))]
    SeveralValves {
        /// The directory.
        dir: String,
        /// The valves whose logs it holds (`(unnamed)` for an unnamed valve's).
        found: Vec<String>,
    },
    /// `--valve` names a valve whose logs the directory does not hold.
    #[error("{dir} holds no logs of valve {valve} (--valve); it holds those of: {}", found.join(", "))]
    NoSuchValve {
        /// The directory.
        dir: String,
        /// The valve asked for.
        valve: String,
        /// The valves whose logs it holds.
        found: Vec<String>,
    },
    /// In-memory data that cannot form a recording, or columns of different lengths to write.
    #[error("{file}: {detail}")]
    Invalid {
        /// Path or label.
        file: String,
        /// What is wrong.
        detail: String,
    },
}

/// `` `a`, `b` `` for a list of names, control characters escaped (one printable line).
fn quoted(names: &[String]) -> String {
    names
        .iter()
        .map(|n| {
            let shown: String = n
                .chars()
                .flat_map(|c| {
                    let e: Vec<char> = if c.is_control() {
                        c.escape_default().collect()
                    } else {
                        vec![c]
                    };
                    e
                })
                .collect();
            format!("`{shown}`")
        })
        .collect::<Vec<_>>()
        .join(", ")
}
