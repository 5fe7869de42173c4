//! What the daemon runs beside its loop but does not own: diagnosing a valve's window and
//! drawing its health plot belong to the analysis and report layers above the runtime, so the
//! program that starts the daemon hands them in ([`Analysis`], filled by
//! `valve_bridge::live`) and the daemon imports none of them.
//!
//! Not here: when a window is diagnosed and what its history keeps ([`crate::monitor::diagnosis`]).

use std::path::Path;

use crate::monitor::diagnosis::history::Entry;
use vb_core::model::ModelSpec;
use vb_core::recording::RecordingView;

/// What one diagnosis of a window found.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowDiagnosis {
    /// The conclusion in words (as `diagnose` prints it).
    pub verdict: String,
    /// Findings first, then traces.
    pub effects: Vec<Entry>,
    /// The report's files (name, text), when one was asked for.
    pub report: Vec<(&'static str, String)>,
    /// The final model: the starting model of the valve's later windows once this diagnosis
    /// is its baseline.
    pub model: ModelSpec,
}

/// Diagnoses one valve's window, from the given model (the baseline's) or from scratch; with a
/// title, also renders its report. `Err`: why the window could not be diagnosed.
pub type DiagnoseWindow =
    fn(&RecordingView, Option<&ModelSpec>, Option<&str>) -> Result<WindowDiagnosis, String>;

/// Draws a valve's health CSV as SVG (empty when it holds no estimated window).
pub type PlotHealth = fn(&str, &Path) -> Result<String, String>;

/// The analysis the daemon may run beside its loop; what is left out is not done (`[diagnosis]`
/// without a diagnosis is refused at start).
#[derive(Debug, Clone, Copy, Default)]
pub struct Analysis {
    pub diagnose: Option<DiagnoseWindow>,
    pub plot_health: Option<PlotHealth>,
}
