//! The analysis the daemon runs beside its loop ([`crate::daemon::Analysis`]): live diagnosis
//! of a valve's window (its verdict, its effects and its report) and the health plot.
//!
//! Not here: when windows are diagnosed, the history and its alarms (`daemon::monitor::diagnosis`).

use std::path::Path;
use std::sync::OnceLock;

use rayon::ThreadPool;

use crate::daemon::monitor::analysis::{Analysis, WindowDiagnosis};
use crate::daemon::monitor::diagnosis::history::Entry;
use crate::diagnose::{diagnose, Diagnosis};
use crate::model::ModelSpec;
use crate::priority::lowest_priority;
use crate::recording::RecordingView;

/// Everything the daemon can run beside its loop.
pub fn analysis() -> Analysis {
    Analysis {
        diagnose: Some(diagnose_window),
        plot_health: Some(|valve: &str, csv: &Path| {
            crate::report::health::svg(valve, csv).map_err(|e| e.to_string())
        }),
    }
}

/// The pool live diagnoses run on, built at the first: its threads (`vb-diagnose-<i>`) run at
/// the lowest priority, as the daemon's diagnosis thread does, so a diagnosis's parallel work
/// takes only CPU time nothing else wants. A pool that cannot be started fails that window's
/// diagnosis with the reason, and the next window tries again.
fn pool() -> Result<&'static ThreadPool, String> {
    static POOL: OnceLock<ThreadPool> = OnceLock::new();
    if let Some(pool) = POOL.get() {
        return Ok(pool);
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .thread_name(|i| format!("vb-diagnose-{i}"))
        .start_handler(|_| lowest_priority())
        .build()
        .map_err(|e| format!("cannot start the diagnosis pool: {e}"))?;
    Ok(POOL.get_or_init(|| pool))
}

/// Diagnoses a window as `diagnose` (with `--model base`) does a recording, on the low-priority
/// [`pool`]; with `title`, its report's files too.
fn diagnose_window(
    rec: &RecordingView,
    base: Option<&ModelSpec>,
    title: Option<&str>,
) -> Result<WindowDiagnosis, String> {
    pool()?.install(|| {
        let d = diagnose(rec, base, &|_, _| {}).map_err(|e| e.to_string())?;
        Ok(WindowDiagnosis {
            verdict: crate::report::verdict::verdict(&d),
            effects: entries(&d),
            report: title.map_or_else(Vec::new, |t| {
                crate::report::diagnose::files(t, rec, &d).to_vec()
            }),
            model: d.final_model.spec,
        })
    })
}

/// The effects of `d`: findings, then traces.
fn entries(d: &Diagnosis) -> Vec<Entry> {
    let findings = (d.findings.iter()).map(|f| Entry::new(f.effect, true, f.size));
    let traces = (d.traces.iter()).map(|t| Entry::new(t.effect, false, t.size));
    findings.chain(traces).collect()
}
