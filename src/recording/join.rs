//! Several recording files as one: rotated logs (given one by one or as a directory) joined in
//! time order, the gaps between them kept as gaps.
//!
//! Files are ordered by their first time (for timestamps, their first wall-clock time) and must
//! not overlap; the times between them are handled as any gap ([`super::grid`]). Warnings of each
//! file are prefixed with its name. A directory stands for its `.csv` files.

use std::path::{Path, PathBuf};

use super::grid::Rows;
use super::read::read_rows;
use super::{ReadOptions, Recording, RecordingError};

/// Reads `paths` (files, or directories of `.csv` files) as one recording in time order.
pub fn read_all(paths: &[PathBuf], opts: &ReadOptions) -> Result<Recording, RecordingError> {
    let files = expand(paths)?;
    let mut parts = Vec::with_capacity(files.len());
    for f in &files {
        let label = f.display().to_string();
        let file = std::fs::File::open(f).map_err(|source| RecordingError::Io {
            file: label.clone(),
            action: "cannot read",
            source,
        })?;
        let (rows, warnings) = read_rows(file, &label, opts)?;
        parts.push((label, rows, warnings));
    }
    let mut warnings = Vec::new();
    let rows = join(parts, files.len() > 1, &mut warnings)?;
    // Named by the earliest file.
    let first = rows.files.first().map_or(String::new(), |f| f.1.clone());
    let source = match files.len() {
        1 => first,
        n => format!("{first} (+{} files)", n - 1),
    };
    Ok(rows.into_recording(source, warnings))
}

/// The files `paths` stand for: a directory's `.csv` files by name, or the path itself.
fn expand(paths: &[PathBuf]) -> Result<Vec<PathBuf>, RecordingError> {
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
        let mut csv: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| f.is_file() && is_csv(f))
            .collect();
        if csv.is_empty() {
            return Err(RecordingError::NoFiles { dir: label });
        }
        csv.sort();
        out.extend(csv);
    }
    Ok(out)
}

fn is_csv(f: &Path) -> bool {
    f.extension().is_some_and(|e| e.eq_ignore_ascii_case("csv"))
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
