//! Fleet analysis: many recordings (one valve each, or many valves in one wide historian export)
//! diagnosed in parallel, each valve summed up in the figures maintenance acts on, and the fleet
//! ranked by how much attention each valve needs.
//!
//! - [`jobs`]: which valves a directory holds (every CSV file, or every tag of a
//!   [`ValveMap`] in every file) as [`Job`]s.
//! - [`diagnose_valve`]: one job read, diagnosed by [`vb_analysis::diagnose::diagnose`] (nothing of
//!   the analysis is redone here), its report files written, and summarised as a
//!   [`ValveSummary`]; a valve that cannot be read or diagnosed becomes a summary with its
//!   one-line error, so one bad file never stops a fleet.
//! - [`run`]: every job in parallel (rayon), then [`Fleet::ranked`].
//! - [`write`]: `summary.csv`, `summary.json` and `index.html` (the page links each valve's own
//!   report).
//!
//! The Python package calls the same functions, so a fleet diagnosed on a cluster through it
//! gives the same rows and the same ranking as `valve-bridge fleet`.

mod jobs;
pub mod page;
mod summary;
pub mod table;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

pub use jobs::{jobs, Columns, FleetError, Job, ValveMap};
pub use summary::{Fleet, Limits, ValveSummary};

use crate::WriteError;
use vb_core::recording::{self, ReadOptions};

/// Where a valve's own report lives, relative to the fleet's output directory.
pub fn valve_dir(valve: &str) -> String {
    format!("valves/{valve}")
}

/// Reads, diagnoses and summarises one valve; with `out`, writes its report, final model and
/// diagnosis JSON under `out/valves/<valve>/` (a valve name that is no safe folder name, as a
/// job built by hand may hold, is refused). Never fails: a problem is the summary's `error`.
pub fn diagnose_valve(job: &Job, read: &ReadOptions, out: Option<&Path>) -> ValveSummary {
    if out.is_some() && jobs::safe(&job.valve) != job.valve {
        let e = format!(
            "valve name `{}` cannot name its report's folder: use letters, digits, `.`, `-` and \
             `_`, and not `.` or `..` alone (the fleet's jobs are named so)",
            job.valve
        );
        return ValveSummary::failed(job, e);
    }
    let opts = job.read_options(read);
    let rec = match recording::read(&job.path, &opts) {
        Ok(r) => r,
        Err(e) => return ValveSummary::failed(job, e.to_string()),
    };
    let d = match vb_analysis::diagnose::diagnose(&rec.view(), None, &|_, _| {}) {
        Ok(d) => d,
        Err(e) => return ValveSummary::failed(job, format!("diagnosing {}: {e}", job.source())),
    };
    let mut s = ValveSummary::of(job, &rec, &d);
    if let Some(out) = out {
        let dir = valve_dir(&s.valve);
        let files = crate::diagnose::files(&job.source(), &rec.view(), &d);
        match crate::write_files(&out.join(&dir), &files) {
            Ok(_) => s.report = Some(format!("{dir}/report.html")),
            Err(e) => s.error = Some(e.to_string()),
        }
    }
    s
}

/// Diagnoses every job in parallel and ranks the fleet. `progress(done, total)` is called as
/// valves finish (from worker threads).
pub fn run(
    jobs: &[Job],
    read: &ReadOptions,
    out: Option<&Path>,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Fleet {
    let done = AtomicUsize::new(0);
    let rows = jobs
        .par_iter()
        .map(|job| {
            let s = diagnose_valve(job, read, out);
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
            s
        })
        .collect();
    Fleet::ranked(rows)
}

/// Writes `summary.csv`, `summary.json` and `index.html` of `fleet` into `out`.
pub fn write(out: &Path, fleet: &Fleet) -> Result<Vec<PathBuf>, WriteError> {
    let json = serde_json::to_string_pretty(fleet).unwrap_or_else(|_| "null".into());
    crate::write_files(
        out,
        &[
            ("summary.csv", fleet.csv()),
            ("summary.json", json),
            ("index.html", page::html(fleet)),
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_job_whose_name_is_no_safe_folder_writes_nothing() {
        let out = tempfile::tempdir().unwrap();
        let fleet = out.path().join("fleet");
        for valve in ["..", "a/../..", "/etc", ""] {
            let job = Job {
                valve: valve.into(),
                path: out.path().join("missing.csv"),
                tag: None,
                columns: None,
            };
            let s = diagnose_valve(&job, &ReadOptions::default(), Some(&fleet));
            let e = s.error.unwrap_or_default();
            assert!(
                e.starts_with(&format!(
                    "valve name `{valve}` cannot name its report's folder"
                )),
                "{e}"
            );
            assert!(s.report.is_none());
        }
        assert!(!fleet.exists());
    }
}
