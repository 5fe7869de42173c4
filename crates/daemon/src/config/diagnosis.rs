//! `[diagnosis]`: the live diagnosis of every valve (cadence, window, whether a health alarm
//! triggers one) and its checks. It is fed by the health check, so it needs `[health]`.
//!
//! Checking only: the diagnosis is [`crate::monitor::diagnosis`]'s.

use serde::Deserialize;

use super::Check;
use vb_core::toml_file::TomlError;

/// `[diagnosis]`: off when the table is absent.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DiagnosisConfig {
    /// How often each valve is diagnosed, s of loop time.
    pub every_s: f64,
    /// The window of rows each diagnosis reads (the last of the valve's), s of loop time.
    pub window_s: f64,
    /// A health alarm also triggers a diagnosis of the valve at once.
    pub on_alarm: bool,
    /// Write the full report (`report.html`, `model.toml`, `diagnosis.json`) of each diagnosis
    /// in `diagnosis-<valve>/<t_s>/` beside the history.
    pub reports: bool,
}

impl Default for DiagnosisConfig {
    fn default() -> Self {
        DiagnosisConfig {
            every_s: 1800.0,
            window_s: 1200.0,
            on_alarm: true,
            reports: true,
        }
    }
}

impl DiagnosisConfig {
    /// The checks of `[diagnosis]`, for a loop of period `period_s`; `health` says whether the
    /// config has a `[health]` table.
    pub(super) fn check_in(
        &self,
        c: &Check<'_>,
        period_s: f64,
        health: bool,
    ) -> Result<(), TomlError> {
        let t = "diagnosis";
        if !health {
            return Err(c.bad(
                t,
                "",
                "the live diagnosis is fed with the rows of the health check and triggered by its \
                 alarms: add a [health] table (its defaults will do)"
                    .into(),
            ));
        }
        c.range(
            t,
            "window_s",
            self.window_s,
            (2000.0 * period_s).max(30.0),
            86_400.0,
            "a window in s, at least 30 s and 2000 cycles (diagnosis needs steps to judge)",
        )?;
        c.range(
            t,
            "every_s",
            self.every_s,
            60.0,
            7.0 * 86_400.0,
            "a cadence in s, a minute to a week",
        )
    }
}
