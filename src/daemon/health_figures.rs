//! The figures of one health window (dead time, reversal delay, stroke speeds, tracking error)
//! and their limits against a baseline: what the health thread estimates and compares, and what
//! the exporter publishes.
//!
//! Not here: the windows, the baseline's choice, the alarm and its outputs ([`super::health`]).

use super::config::HealthConfig;
use crate::metrics::stats::median;
use crate::metrics::steps::travel_speed;
use crate::metrics::steps::{analyse, StepOptions};
use crate::recording::RecordingView;

/// What counts as a step for the health delays: a jump of 0.5 % held 1 s, as for `steps`; its
/// delay ends when V_P has moved 2 % of it (and four noise sigmas), so the slewing of a large
/// step adds next to nothing and the delay is the dead time (with the reversal's crossing).
const DELAY_OPTIONS: StepOptions = StepOptions {
    min_size_pct: 0.5,
    fraction: 0.02,
    min_hold_s: 1.0,
};

/// What one window shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Figures {
    /// Steps that keep the direction, and reversals, in the window.
    pub same_steps: usize,
    pub reversals: usize,
    /// Median delay of same-direction steps, s (None: too few).
    pub dead_time_s: Option<f64>,
    /// Median delay of reversals, s (None: too few).
    pub reversal_delay_s: Option<f64>,
    /// Stroke speeds opening and closing (99.5th percentile over 0.1 s), %/s.
    pub opening_speed_pct_per_s: f64,
    pub closing_speed_pct_per_s: f64,
    /// RMS of O_P - V_P, %.
    pub tracking_rms_pct: f64,
}

impl Figures {
    /// The figures of `op` and `vp` sampled every `dt` s; a delay needs `min_steps` steps.
    pub fn of(op: &[f64], vp: &[f64], dt: f64, min_steps: usize) -> Figures {
        let rec = RecordingView {
            t: &[],
            op,
            vp,
            restarts: &[],
            dt,
        };
        let a = analyse(&rec, &DELAY_OPTIONS);
        // The median: a step held too briefly or lost in a slip does not move it.
        let delay = |reversal: bool| {
            let d: Vec<f64> = (a.steps.iter())
                .filter(|s| s.reversal == Some(reversal))
                .filter_map(|s| s.delay_s)
                .collect();
            (d.len() >= min_steps).then(|| median(&d)).flatten()
        };
        let n = op.len().min(vp.len()).max(1);
        Figures {
            same_steps: a.same.count,
            reversals: a.reversal.count,
            dead_time_s: delay(false),
            reversal_delay_s: delay(true),
            opening_speed_pct_per_s: travel_speed(vp, dt, Some(1.0)),
            closing_speed_pct_per_s: travel_speed(vp, dt, Some(-1.0)),
            tracking_rms_pct: (crate::metrics::sse(op, vp) / n as f64).sqrt(),
        }
    }

    /// Both delays could be measured.
    pub fn complete(&self) -> bool {
        self.dead_time_s.is_some() && self.reversal_delay_s.is_some()
    }

    /// The limit of each figure against `base`: a delay may rise by its `*_rise_s`, a stroke
    /// speed fall by `speed_drop`, the tracking error grow by `tracking_rise`.
    pub fn limits(base: &Figures, cfg: &HealthConfig) -> HealthLimits {
        HealthLimits {
            dead_time_s: base.dead_time_s.map(|d| d + cfg.dead_time_rise_s),
            reversal_delay_s: base.reversal_delay_s.map(|d| d + cfg.reversal_delay_rise_s),
            opening_speed_pct_per_s: base.opening_speed_pct_per_s * (1.0 - cfg.speed_drop),
            closing_speed_pct_per_s: base.closing_speed_pct_per_s * (1.0 - cfg.speed_drop),
            tracking_rms_pct: base.tracking_rms_pct * (1.0 + cfg.tracking_rise),
        }
    }

    /// What drifted past its limit against `base`, one phrase each (empty: healthy).
    pub fn drifts(&self, base: &Figures, cfg: &HealthConfig) -> Vec<String> {
        let lim = Figures::limits(base, cfg);
        let mut out = Vec::new();
        let delays = [
            (
                "dead time",
                self.dead_time_s,
                base.dead_time_s,
                lim.dead_time_s,
                cfg.dead_time_rise_s,
            ),
            (
                "reversal delay",
                self.reversal_delay_s,
                base.reversal_delay_s,
                lim.reversal_delay_s,
                cfg.reversal_delay_rise_s,
            ),
        ];
        for (what, now, then, limit, rise) in delays {
            if let (Some(now), Some(then), Some(limit)) = (now, then, limit) {
                if now > limit {
                    out.push(format!(
                        "{what} {now:.3} s against {then:.3} s (limit +{rise} s)"
                    ));
                }
            }
        }
        let speeds = [
            (
                "opening",
                self.opening_speed_pct_per_s,
                base.opening_speed_pct_per_s,
                lim.opening_speed_pct_per_s,
            ),
            (
                "closing",
                self.closing_speed_pct_per_s,
                base.closing_speed_pct_per_s,
                lim.closing_speed_pct_per_s,
            ),
        ];
        for (what, now, then, limit) in speeds {
            if then > 0.0 && now < limit {
                out.push(format!(
                    "{what} speed {now:.2} %/s against {then:.2} %/s (limit -{:.0} %)",
                    cfg.speed_drop * 100.0
                ));
            }
        }
        let (now, then) = (self.tracking_rms_pct, base.tracking_rms_pct);
        if now > lim.tracking_rms_pct {
            out.push(format!(
                "tracking error {now:.2} % against {then:.2} % (limit +{:.0} %)",
                cfg.tracking_rise * 100.0
            ));
        }
        out
    }
}

/// The limit of each figure against a baseline (a delay's: none while the baseline has none);
/// past one, the alarm is raised.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HealthLimits {
    /// Highest dead time, s.
    pub dead_time_s: Option<f64>,
    /// Highest reversal delay, s.
    pub reversal_delay_s: Option<f64>,
    /// Lowest stroke speeds, %/s.
    pub opening_speed_pct_per_s: f64,
    pub closing_speed_pct_per_s: f64,
    /// Highest RMS of O_P - V_P, %.
    pub tracking_rms_pct: f64,
}
