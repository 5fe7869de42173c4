//! The figures of one health window (dead time, reversal delay, stroke speeds, tracking error),
//! their limits against a baseline, and which of them are in alarm ([`Held`]): what the health
//! thread estimates and compares, and what the exporter and the live page publish.
//!
//! A figure is in alarm from the first window that measures it past its limit until a window
//! measures it within it; a window with too few steps to measure a delay leaves that delay's
//! state as it was (not measuring is a state, never a reason for an alarm).
//!
//! Not here: the windows, the baseline's choice, the alarm and its outputs ([`crate::monitor::health`]).

use serde::Serialize;

use crate::config::HealthConfig;
use vb_core::metrics::stats::median;
use vb_core::metrics::steps::travel_speed;
use vb_core::metrics::steps::{analyse, StepOptions};
use vb_core::recording::RecordingView;

/// What counts as a step for the health delays: a jump of 0.5 % held 1 s, as for `steps`; its
/// delay ends when V_P has moved 2 % of it (and four noise sigmas), so the slewing of a large
/// step adds next to nothing and the delay is the dead time (with the reversal's crossing).
const DELAY_OPTIONS: StepOptions = StepOptions {
    min_size_pct: 0.5,
    fraction: 0.02,
    min_hold_s: 1.0,
};

/// One figure: its name, its unit, whether its limit is the highest value allowed (not the
/// lowest), and where it and its limit are.
struct Figure {
    name: &'static str,
    unit: &'static str,
    highest: bool,
    get: fn(&Figures) -> Option<f64>,
    limit: fn(&HealthLimits) -> Option<f64>,
}

/// The figures, in the order of the health log ([`vb_core::recording::health_log::Figure`]).
const FIGURES: [Figure; 5] = [
    Figure {
        name: "dead time",
        unit: "s",
        highest: true,
        get: |f| f.dead_time_s,
        limit: |l| l.dead_time_s,
    },
    Figure {
        name: "reversal delay",
        unit: "s",
        highest: true,
        get: |f| f.reversal_delay_s,
        limit: |l| l.reversal_delay_s,
    },
    Figure {
        name: "opening speed",
        unit: "%/s",
        highest: false,
        get: |f| Some(f.opening_speed_pct_per_s),
        limit: |l| Some(l.opening_speed_pct_per_s),
    },
    Figure {
        name: "closing speed",
        unit: "%/s",
        highest: false,
        get: |f| Some(f.closing_speed_pct_per_s),
        limit: |l| Some(l.closing_speed_pct_per_s),
    },
    Figure {
        name: "tracking error",
        unit: "%",
        highest: true,
        get: |f| Some(f.tracking_rms_pct),
        limit: |l| Some(l.tracking_rms_pct),
    },
];

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
    /// The figures in the order of the health log's ([`vb_core::recording::health_log::Figure`]).
    pub fn in_log_order(&self) -> [Option<f64>; 5] {
        FIGURES.map(|fig| (fig.get)(self))
    }

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
            tracking_rms_pct: (vb_core::metrics::sse(op, vp) / n as f64).sqrt(),
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

    /// Each figure beside its baseline and limit (each None while there is none), in the order
    /// of [`FIGURES`].
    pub fn judged(&self, base: Option<&Figures>, lim: Option<&HealthLimits>) -> [Judged; 5] {
        FIGURES.map(|fig| {
            let (now, base, limit) = (
                (fig.get)(self),
                base.and_then(fig.get),
                lim.and_then(fig.limit),
            );
            let past = match (now, base, limit) {
                (Some(now), Some(_), Some(limit)) if fig.highest => now > limit,
                (Some(now), Some(base), Some(limit)) => base > 0.0 && now < limit,
                _ => false,
            };
            Judged {
                name: fig.name,
                unit: fig.unit,
                now,
                base,
                limit,
                highest: fig.highest,
                past,
            }
        })
    }

    /// What drifted past its limit against `base`, one phrase each (empty: healthy).
    pub fn drifts(&self, base: &Figures, cfg: &HealthConfig) -> Vec<String> {
        let lim = Figures::limits(base, cfg);
        // How far each limit lies from the baseline, in the order of `judged`.
        let speed = format!("-{:.0} %", cfg.speed_drop * 100.0);
        let rules = [
            format!("+{} s", cfg.dead_time_rise_s),
            format!("+{} s", cfg.reversal_delay_rise_s),
            speed.clone(),
            speed,
            format!("+{:.0} %", cfg.tracking_rise * 100.0),
        ];
        (self.judged(Some(base), Some(&lim)).iter().zip(rules))
            .filter(|(j, _)| j.past)
            .map(|(j, rule)| {
                let digits = if j.unit == "s" { 3 } else { 2 };
                let (now, then) = (j.now.unwrap_or(f64::NAN), j.base.unwrap_or(f64::NAN));
                format!(
                    "{} {now:.digits$} {unit} against {then:.digits$} {unit} (limit {rule})",
                    j.name,
                    unit = j.unit
                )
            })
            .collect()
    }
}

/// One figure of a window beside its baseline and limit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Judged {
    /// `dead time`, `opening speed`, ...
    pub name: &'static str,
    /// `s`, `%/s` or `%`.
    pub unit: &'static str,
    pub now: Option<f64>,
    pub base: Option<f64>,
    pub limit: Option<f64>,
    /// The limit is the highest value allowed (a delay, the tracking error), not the lowest (a
    /// stroke speed).
    pub highest: bool,
    /// Past its limit: a drift the alarm is raised for.
    pub past: bool,
}

/// A figure in alarm: what it was when last measured against its limit, and since when.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Held {
    /// `dead time`, `opening speed`, ...
    pub name: &'static str,
    pub unit: &'static str,
    /// The figure when last measured, its limit and its baseline then.
    pub now: f64,
    pub limit: f64,
    pub base: f64,
    /// The limit is the highest value allowed, not the lowest.
    pub highest: bool,
    /// Loop time of the window that first measured it past its limit in this alarm, s.
    pub since_t_s: f64,
    /// Loop time of the last window that measured it, s.
    pub measured_t_s: f64,
}

impl Held {
    /// Each figure's alarm after the window ending at `t_s` judged `judged` (in the order of
    /// [`FIGURES`]): raised or renewed where measured past its limit, cleared where measured
    /// within it, kept where not measured.
    pub fn update(held: &mut [Option<Held>; 5], judged: &[Judged; 5], t_s: f64) {
        for (h, j) in held.iter_mut().zip(judged) {
            let (Some(now), Some(limit)) = (j.now, j.limit) else {
                continue;
            };
            *h = j.past.then(|| Held {
                name: j.name,
                unit: j.unit,
                now,
                limit,
                base: j.base.unwrap_or(f64::NAN),
                highest: j.highest,
                since_t_s: h.map_or(t_s, |h| h.since_t_s),
                measured_t_s: t_s,
            });
        }
    }

    /// The alarm of a figure this window could not measure: `reversal delay not measured in
    /// this window (too few steps): in alarm since 1020.0 s, last 1.290 s against its limit
    /// 1.260 s at 1080.0 s`.
    pub fn unmeasured(&self) -> String {
        let d = if self.unit == "s" { 3 } else { 2 };
        format!(
            "{} not measured in this window (too few steps): in alarm since {:.1} s, last {:.d$} {u} \
             against its limit {:.d$} {u} at {:.1} s",
            self.name,
            self.since_t_s,
            self.now,
            self.limit,
            self.measured_t_s,
            u = self.unit
        )
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

impl HealthLimits {
    /// The limits in the order of the health log's figures.
    pub fn in_log_order(&self) -> [Option<f64>; 5] {
        FIGURES.map(|fig| (fig.limit)(self))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The five figures of a window: the reversal delay as given (None: too few steps to
    /// measure it), against a limit of 1.0 s; the others measured within their limits.
    fn window(reversal_delay_s: Option<f64>) -> [Judged; 5] {
        let now = Figures {
            same_steps: 4,
            reversals: if reversal_delay_s.is_some() { 4 } else { 1 },
            dead_time_s: Some(0.3),
            reversal_delay_s,
            opening_speed_pct_per_s: 10.0,
            closing_speed_pct_per_s: 10.0,
            tracking_rms_pct: 0.5,
        };
        let base = Figures {
            reversal_delay_s: Some(0.4),
            ..now
        };
        let lim = HealthLimits {
            dead_time_s: Some(0.6),
            reversal_delay_s: Some(1.0),
            opening_speed_pct_per_s: 5.0,
            closing_speed_pct_per_s: 5.0,
            tracking_rms_pct: 2.0,
        };
        now.judged(Some(&base), Some(&lim))
    }

    #[test]
    fn an_alarm_holds_from_past_its_limit_to_within_it_and_too_few_steps_raise_none() {
        let mut held = [None; 5];
        // Too few steps to measure: a state, not an alarm.
        Held::update(&mut held, &window(None), 10.0);
        assert_eq!(held, [None; 5]);
        // Past its limit: raised, with its figure, its limit and since when.
        Held::update(&mut held, &window(Some(1.3)), 20.0);
        let raised = held[1].expect("the reversal delay in alarm");
        assert_eq!((raised.now, raised.limit, raised.base), (1.3, 1.0, 0.4));
        assert_eq!((raised.since_t_s, raised.measured_t_s), (20.0, 20.0));
        assert!(held.iter().enumerate().all(|(i, h)| i == 1 || h.is_none()));
        // Not measured: kept as last measured; measured past again: since when unchanged.
        Held::update(&mut held, &window(None), 30.0);
        assert_eq!(held[1], Some(raised));
        Held::update(&mut held, &window(Some(1.2)), 40.0);
        let renewed = held[1].expect("still in alarm");
        assert_eq!(
            (renewed.now, renewed.since_t_s, renewed.measured_t_s),
            (1.2, 20.0, 40.0)
        );
        assert!(renewed
            .unmeasured()
            .contains("in alarm since 20.0 s, last 1.200 s"));
        // Measured within its limit: cleared.
        Held::update(&mut held, &window(Some(0.5)), 50.0);
        assert_eq!(held, [None; 5]);
    }
}
