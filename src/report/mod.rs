//! Reports people look at: the words, tables and self-contained HTML pages (interactive charts
//! with inline SVG fallbacks, no server, no external files) of the analysis results.
//!
//! - [`diagnose`]: a diagnosis's sentences (evidence, verdict, notes), its text, its `--json`
//!   document and its page (the recording against the model before and after, the residual,
//!   the worst windows zoomed in, the step-delay evidence and the Table 1 rows).
//! - [`identify`]: an identification's page (Tables 1 and 2, the paper's Figs. 5-10).
//! - [`fleet`]: a fleet's page (its valves ranked for maintenance, each linked to its own page),
//!   from the rows of [`fleet_table`] (which `crate::fleet` fills from the diagnoses).
//! - [`plot`]: the SVG charts.
//! - [`chart`]: the interactive time-series charts (uPlot, embedded), the SVG kept for a page
//!   without scripts.
//! - [`response`]: a response test's text and page (every step and the signature charted with
//!   its figures marked, the spec's lines).
//! - [`live`]: the analysis the daemon runs beside its loop (a window's diagnosis and report,
//!   the health plot), handed to it as a [`crate::daemon::Analysis`].
//!
//! The pages share one skeleton ([`page`]); [`write_files`] saves a report's files. This module
//! only formats results; it computes nothing about the valve.

pub mod chart;
pub mod diagnose;
pub mod fleet;
pub mod fleet_table;
pub mod health;
pub mod identify;
pub mod live;
pub mod plot;
pub mod readme;
pub mod response;
pub mod verdict;

use std::fmt::Write;
use std::path::{Path, PathBuf};

/// A report file that cannot be written.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot write: {source}; check that the output directory is writable", path.display())]
pub struct WriteError {
    /// The file or directory that failed.
    pub path: PathBuf,
    /// The cause.
    pub source: std::io::Error,
}

/// Creates `dir` (and its parents) and writes each `(name, text)` into it; returns the paths.
pub fn write_files(dir: &Path, files: &[(&str, String)]) -> Result<Vec<PathBuf>, WriteError> {
    std::fs::create_dir_all(dir).map_err(|source| WriteError {
        path: dir.to_path_buf(),
        source,
    })?;
    files
        .iter()
        .map(|(name, text)| {
            let path = dir.join(name);
            std::fs::write(&path, text).map_err(|source| WriteError {
                path: path.clone(),
                source,
            })?;
            Ok(path)
        })
        .collect()
}

use crate::metrics::Scores;

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A whole HTML page titled `heading` (also its first heading) around `body`.
fn page(heading: &str, body: &str) -> String {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>{0}</title><style>\
         body{{font-family:sans-serif;max-width:960px;margin:auto;color:#222}}\
         table{{border-collapse:collapse;margin:6px 0}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:right}}\
         td:first-child{{text-align:left}}td.l{{text-align:left}}.verdict{{font-size:1.15em;background:#eef;padding:8px}}\
         </style></head><body><h1>{0}</h1>{1}{2}</body></html>",
        esc(heading),
        body,
        chart::assets(body)
    );
    h
}

/// A Table 1 row of the HTML tables.
fn row(name: &str, s: &Scores) -> String {
    let filtered = if s.filtered {
        format!("{:.3} %", s.mae_filtered)
    } else {
        "n/a".into()
    };
    format!(
        "<tr><td>{}</td><td>{:.3} %</td><td>{filtered}</td><td>{:.2} %</td><td>{:.3}</td><td>{:.2} %</td><td>{}</td></tr>",
        esc(name),
        s.mae,
        100.0 * s.r2,
        s.sse,
        100.0 * s.rel_sse,
        s.n
    )
}
