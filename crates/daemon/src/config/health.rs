//! `[health]`: the live health check of every valve (window, cadence, steps needed, alarm
//! limits) and its checks. A valve's own `health_baseline_model` (in its `[valve]` table) makes
//! a model file its baseline instead of the first window.
//!
//! Checking only: the estimation is [`crate::monitor::health`]'s.

use serde::Deserialize;

use super::Check;
use vb_core::toml_file::TomlError;

/// `[health]`: off when the table is absent.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HealthConfig {
    /// The sliding window the figures are estimated over, s of loop time.
    pub window_s: f64,
    /// How often the figures are estimated, s of loop time.
    pub every_s: f64,
    /// Steps of O_P a delay needs in the window (each kind: same-direction, reversal).
    pub min_steps: usize,
    /// Alarm when the dead time exceeds the baseline's by this much, s.
    pub dead_time_rise_s: f64,
    /// Alarm when the reversal delay exceeds the baseline's by this much, s.
    pub reversal_delay_rise_s: f64,
    /// Alarm when an opening or closing stroke speed falls below the baseline's by this share
    /// (0.3 = 30 % slower).
    pub speed_drop: f64,
    /// Alarm when the tracking error (RMS of O_P - V_P) exceeds the baseline's by this share
    /// (1.0 = twice as large).
    pub tracking_rise: f64,
}

impl Default for HealthConfig {
    fn default() -> Self {
        HealthConfig {
            window_s: 600.0,
            every_s: 60.0,
            min_steps: 5,
            dead_time_rise_s: 0.2,
            reversal_delay_rise_s: 0.3,
            speed_drop: 0.3,
            tracking_rise: 1.0,
        }
    }
}

impl HealthConfig {
    /// The checks of `[health]`, for a loop of period `period_s`.
    pub(super) fn check_in(&self, c: &Check<'_>, period_s: f64) -> Result<(), TomlError> {
        let t = "health";
        c.range(
            t,
            "window_s",
            self.window_s,
            (100.0 * period_s).max(10.0),
            86_400.0,
            "a window in s, at least 100 cycles",
        )?;
        c.range(
            t,
            "every_s",
            self.every_s,
            period_s,
            self.window_s,
            "a cadence in s, at most window_s",
        )?;
        c.range(
            t,
            "min_steps",
            self.min_steps as f64,
            2.0,
            1000.0,
            "steps of each kind a delay needs",
        )?;
        c.range(
            t,
            "dead_time_rise_s",
            self.dead_time_rise_s,
            0.0,
            60.0,
            "a rise in s",
        )?;
        c.range(
            t,
            "reversal_delay_rise_s",
            self.reversal_delay_rise_s,
            0.0,
            60.0,
            "a rise in s",
        )?;
        c.range(t, "speed_drop", self.speed_drop, 0.0, 1.0, "a share, 0-1")?;
        c.range(
            t,
            "tracking_rise",
            self.tracking_rise,
            0.0,
            100.0,
            "a share (1.0 = twice the baseline)",
        )
    }
}
