//! Reports people look at: the words, tables and self-contained HTML pages (interactive charts
//! with inline SVG fallbacks, no server, no external files) of the analysis results, and the
//! fleet, whose result is a ranked page.
//!
//! - [`diagnose`]: a diagnosis's sentences (evidence, verdict, notes), its text, its `--json`
//!   document and its page (the verdict a maintenance planner acts on, then the recording
//!   against the model before and after, the residual, the worst windows zoomed in, the
//!   step-delay evidence and the Table 1 rows).
//! - [`verdict`]: the verdicts in words (the planner's, from [`vb_core::vocabulary`], and the
//!   modeller's), the sizes and figures; [`advice`]: the planner's findings as HTML.
//! - [`identify`]: an identification's page (Tables 1 and 2, the paper's Figs. 5-10).
//! - [`fleet`]: many recordings diagnosed in parallel, summed up in a table (`fleet::table`) and
//!   written as a page (`fleet::page`: its valves ranked for maintenance, each linked to its own).
//! - [`plot`]: the SVG charts.
//! - [`chart`]: the interactive time-series charts (uPlot, embedded), the SVG kept for a page
//!   without scripts.
//! - [`response`]: a response test's text and page (every step and the signature charted with
//!   its figures marked, the spec's lines).
//!
//! The pages share one skeleton ([`page`]); [`write_files`] saves a report's files. The pages only
//! format results; they compute nothing about the valve.

pub mod advice;
pub mod chart;
pub mod diagnose;
pub mod fleet;
pub mod health;
pub mod identify;
pub mod plot;
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

use vb_core::metrics::Scores;

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// A sentence for an HTML page: escaped, with each span between backticks (a command, a
/// config key) set as code rather than shown with its backticks. An unpaired backtick stays.
fn prose(s: &str) -> String {
    let parts: Vec<&str> = s.split('`').collect();
    let mut h = String::new();
    for (i, part) in parts.iter().enumerate() {
        match (i % 2 == 1, i + 1 < parts.len() || i % 2 == 0) {
            (true, true) => {
                let _ = write!(h, "<code>{}</code>", esc(part));
            }
            (true, false) => {
                let _ = write!(h, "`{}", esc(part));
            }
            _ => h.push_str(&esc(part)),
        }
    }
    h
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
         .card{{padding:6px 10px;margin:6px 0;border-left:6px solid #999}}\
         .sev-high{{background:#fde2df;border-color:#c62828}}.sev-medium{{background:#fff3d6;border-color:#e6a100}}\
         .sev-low{{background:#eef4fb;border-color:#6b8fb8}}.sev-none{{background:#eef7ee;border-color:#5a9a5a}}\
         </style></head><body><h1>{0}</h1>{1}{2}</body></html>",
        esc(heading),
        body,
        chart::assets(body)
    );
    h
}

/// A Table 1 row of the HTML tables (a figure that cannot be given is `n/a`, as in the text;
/// [`vb_core::metrics::not_given`] says why).
fn row(name: &str, s: &Scores) -> String {
    let [mae, filtered, r2, sse, rel, n] = vb_core::metrics::table1_cells(s);
    let pct = |c: String| c.replace('%', " %");
    format!(
        "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{sse}</td><td>{}</td><td>{n}</td></tr>",
        esc(name),
        pct(mae),
        pct(filtered),
        pct(r2),
        pct(rel)
    )
}

#[cfg(test)]
mod tests {
    use super::prose;

    #[test]
    fn prose_sets_backticked_spans_as_code_and_escapes_the_rest() {
        assert_eq!(
            prose("run `[source] kind = \"ramp\"` & see <here>"),
            "run <code>[source] kind = \"ramp\"</code> &amp; see &lt;here&gt;"
        );
        assert_eq!(prose("a `b` c `d"), "a <code>b</code> c `d");
        assert_eq!(prose("plain"), "plain");
    }
}
