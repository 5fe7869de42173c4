//! Several recording files as one: rotated logs (given one by one or as a directory) joined in
//! time order, the gaps between them kept as gaps.
//!
//! Files are ordered by their first time (for timestamps, their first wall-clock time) and must
//! not overlap; the times between them are handled as any gap ([`super::grid`]). Warnings of each
//! file are prefixed with its name. A directory stands for its `.csv` files: when it holds the
//! daemon's logs (`vb-STAMP.csv`, `vb-NAME-STAMP.csv`), those of one valve (`--valve NAME` when
//! there are several), and never the daemon's `health*.csv`; the files read are logged. Logs the
//! daemon compressed (`.csv.gz`) are read as they are. A file of a set may hold a single row
//! (the last of a rotated set often does), or none: a file with only its header, or an empty
//! one (a crash just after the log rotated), is skipped with a warning naming it. The set as a
//! whole needs two rows, and holds at most [`ReadOptions::max_rows`].

use std::path::{Path, PathBuf};

use super::grid::Rows;
use super::gzip;
use super::read::{read_file, MIN_ROWS};
use super::{ReadOptions, Recording, RecordingError};

/// Reads `paths` (files, or directories of `.csv` files) as one recording in time order.
pub fn read_all(paths: &[PathBuf], opts: &ReadOptions) -> Result<Recording, RecordingError> {
    let files = expand(paths, opts.valve.as_deref())?;
    let set = files.len() > 1;
    let mut parts = Vec::with_capacity(files.len());
    let mut warnings = Vec::new();
    let mut count = 0;
    for f in &files {
        let label = f.display().to_string();
        let (rows, ws) = read_file(f, opts, if set { 0 } else { MIN_ROWS }, count)?;
        if rows.t.is_empty() {
            let why = if ws.is_empty() {
                String::new()
            } else {
                format!(" ({})", ws.join("; "))
            };
            warnings.push(format!("{label}: no data rows{why}, skipped"));
            continue;
        }
        count += rows.t.len();
        parts.push((label, rows, ws));
    }
    let rows = join(parts, set, &mut warnings)?;
    // Named by the earliest file.
    let first = rows.files.first().map_or(String::new(), |f| f.1.clone());
    let source = match files.len() {
        1 => first,
        n => format!("{first} (+{} files)", n - 1),
    };
    if rows.t.len() < MIN_ROWS {
        return Err(RecordingError::TooFewRows {
            file: source,
            rows: rows.t.len(),
            dropped: 0,
        });
    }
    rows.into_recording(source, warnings, opts.max_rows)
}

/// The files `paths` stand for: the path itself, or a directory's recordings by name (see the
/// module documentation; `valve` chooses among the daemon logs of several valves).
fn expand(paths: &[PathBuf], valve: Option<&str>) -> Result<Vec<PathBuf>, RecordingError> {
    let mut out = Vec::new();
    for p in paths {
        if !p.is_dir() {
            out.push(p.clone());
            continue;
        }
        let label = p.display().to_string();
        let entries = std::fs::read_dir(p).map_err(|source| RecordingError::Io {
            file: label.clone(),
            action: "cannot read",
            source,
        })?;
        let (health, mut csv): (Vec<PathBuf>, Vec<PathBuf>) = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| f.is_file() && is_csv(f))
            .partition(|f| file_name(f).starts_with("health"));
        if !health.is_empty() {
            tracing::info!(
                "{label}: left out {} (the daemon's health figures)",
                crate::human::count(health.len() as u64, "health file")
            );
        }
        csv.sort();
        let chosen = one_valve(&label, without_half_compressed(&label, csv), valve)?;
        if chosen.is_empty() {
            return Err(RecordingError::NoFiles { dir: label });
        }
        tracing::info!(
            "{label}: reading {} ({} to {})",
            crate::human::count(chosen.len() as u64, "file"),
            file_name(&chosen[0]),
            file_name(&chosen[chosen.len() - 1])
        );
        out.extend(chosen);
    }
    Ok(out)
}

/// Of a directory's `.csv` files (sorted), the daemon logs of one valve, or every file when
/// none is a daemon log.
fn one_valve(
    dir: &str,
    files: Vec<PathBuf>,
    valve: Option<&str>,
) -> Result<Vec<PathBuf>, RecordingError> {
    let mut found: Vec<String> = Vec::new();
    for f in &files {
        if let Some(v) = log_valve(file_name(f)) {
            let v = if v.is_empty() { "(unnamed)" } else { v };
            if !found.iter().any(|x| x == v) {
                found.push(v.to_string());
            }
        }
    }
    let wanted = match (valve, found.as_slice()) {
        (None, []) => return Ok(files),
        (None, [one]) => one.clone(),
        (None, _) => {
            return Err(RecordingError::SeveralValves {
                dir: dir.into(),
                found,
            })
        }
        (Some(v), _) if found.iter().any(|x| x == v) => v.to_string(),
        (Some(v), _) => {
            return Err(RecordingError::NoSuchValve {
                dir: dir.into(),
                valve: v.into(),
                found,
            })
        }
    };
    let name = if wanted == "(unnamed)" { "" } else { &wanted };
    let (chosen, skipped): (Vec<PathBuf>, Vec<PathBuf>) = files
        .into_iter()
        .partition(|f| log_valve(file_name(f)) == Some(name));
    if !skipped.is_empty() {
        tracing::info!(
            "{dir}: left out {} that {} not valve {wanted}'s logs",
            crate::human::count(skipped.len() as u64, "file"),
            if skipped.len() == 1 { "is" } else { "are" }
        );
    }
    Ok(chosen)
}

/// The valve a daemon log file is named for (`vb-NAME-STAMP.csv`, compressed or not; "" for
/// `vb-STAMP.csv`), or None for any other name. STAMP is `YYYYMMDDTHHMMSSZ`, with `-N` when the name was taken.
fn log_valve(name: &str) -> Option<&str> {
    if !gzip::is_recording_name(name) {
        return None;
    }
    let rest = gzip::stem(name).strip_prefix("vb-")?;
    let stamp_at = |i: usize| {
        let s = rest.as_bytes().get(i..i + 16)?;
        let digits = |r: std::ops::Range<usize>| s[r].iter().all(u8::is_ascii_digit);
        let tail = &rest[i + 16..];
        let tail_ok = tail.is_empty()
            || tail
                .strip_prefix('-')
                .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        (digits(0..8) && s[8] == b'T' && digits(9..15) && s[15] == b'Z' && tail_ok).then_some(())
    };
    if stamp_at(0).is_some() {
        return Some("");
    }
    let dash = (0..rest.len())
        .rev()
        .find(|&i| rest.as_bytes()[i] == b'-' && stamp_at(i + 1).is_some())?;
    Some(&rest[..dash])
}

fn file_name(f: &Path) -> &str {
    f.file_name().and_then(|n| n.to_str()).unwrap_or("")
}

fn is_csv(f: &Path) -> bool {
    gzip::is_recording_name(file_name(f))
}

/// `files` (sorted) without a `NAME.csv.gz` whose `NAME.csv` is there too: a compression cut
/// short by a crash leaves both, and the plain one is certainly whole.
fn without_half_compressed(dir: &str, files: Vec<PathBuf>) -> Vec<PathBuf> {
    let names: Vec<String> = files.iter().map(|f| file_name(f).to_string()).collect();
    let twin = |name: &str| {
        name.len() > 3
            && name[name.len() - 3..].eq_ignore_ascii_case(".gz")
            && names.iter().any(|n| n == &name[..name.len() - 3])
    };
    let (twins, kept): (Vec<PathBuf>, Vec<PathBuf>) =
        files.into_iter().partition(|f| twin(file_name(f)));
    for t in &twins {
        tracing::warn!(
            "{dir}: left out {} (its plain .csv is there too)",
            file_name(t)
        );
    }
    kept
}

/// The rows of all parts in time order, checked for overlaps.
fn join(
    mut parts: Vec<(String, Rows, Vec<String>)>,
    prefix: bool,
    warnings: &mut Vec<String>,
) -> Result<Rows, RecordingError> {
    let stamped: Vec<&String> = parts
        .iter()
        .filter(|p| p.1.t_ref_ns.is_some())
        .map(|p| &p.0)
        .collect();
    if let (Some(first), Some(second)) = (
        stamped.first(),
        parts.iter().find(|p| p.1.t_ref_ns.is_none()).map(|p| &p.0),
    ) {
        return Err(RecordingError::MixedTimes {
            first: (*first).clone(),
            second: second.clone(),
        });
    }
    // Timestamps: every file's times from the earliest file's first row.
    if let Some(origin) = parts.iter().filter_map(|p| p.1.t_ref_ns).min() {
        for (_, rows, _) in &mut parts {
            let shift = (rows.t_ref_ns.unwrap_or(origin) - origin) as f64 / 1e9;
            rows.t.iter_mut().for_each(|t| *t += shift);
        }
    }
    parts.sort_by(|a, b| a.1.t[0].total_cmp(&b.1.t[0]));
    let mut all: Option<Rows> = None;
    for (label, rows, ws) in parts {
        warnings.extend(
            ws.into_iter()
                .map(|w| if prefix { format!("{label}: {w}") } else { w }),
        );
        match &mut all {
            None => all = Some(rows),
            Some(acc) => {
                let (end, start) = (acc.t[acc.t.len() - 1], rows.t[0]);
                if end >= start {
                    return Err(RecordingError::Overlap {
                        first: acc.files.last().map_or(String::new(), |f| f.1.clone()),
                        first_line: acc.line[acc.line.len() - 1],
                        first_end: end,
                        second: label,
                        second_line: rows.line[0],
                        second_start: start,
                    });
                }
                acc.append(rows);
            }
        }
    }
    all.ok_or_else(|| RecordingError::NoFiles {
        dir: "(no input)".into(),
    })
}

#[cfg(test)]
mod tests {
    use super::log_valve;

    #[test]
    fn daemon_log_names_tell_their_valve() {
        assert_eq!(log_valve("vb-20261125T101500Z.csv"), Some(""));
        assert_eq!(log_valve("vb-20261125T101500Z-2.csv"), Some(""));
        assert_eq!(log_valve("vb-level-20261125T101500Z.csv"), Some("level"));
        assert_eq!(log_valve("vb-level-20261125T101500Z.csv.gz"), Some("level"));
        assert_eq!(
            log_valve("vb-my-valve_2-20261125T101500Z-1.csv"),
            Some("my-valve_2")
        );
        for other in [
            "health-level.csv",
            "vb-level.csv",
            "vb-level-20261125T101500.csv",
            "vb-20261125T101500Z-.csv",
            "recording.csv",
        ] {
            assert_eq!(log_valve(other), None, "{other}");
        }
    }
}
