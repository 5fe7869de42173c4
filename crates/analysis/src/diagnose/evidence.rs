//! Evidence for a finding, as numbers a person can check against the plots: where the model's
//! excess error lay, what the step delays, speeds and holds of the recording show, and what
//! the fit says, per effect.
//!
//! Everything here is typed and serialised into `--json` (`facts` of a finding, `outcome`,
//! `notes`); the sentences a person reads are rendered from it in `report::diagnose`.
//!
//! Not here: deciding anything (that is [`super::judge`]) or wording it.

use serde::Serialize;

use super::facts::Facts;
use super::locate::{Context, Window};
use super::size;
use super::stickslip;
use vb_core::metrics::stats;
use vb_core::metrics::steps::Population;
use vb_core::model::composed::{self, Effect, Knob};
use vb_core::model::ModelSpec;

/// The share of the model's excess error that lies in windows of some kinds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Share {
    /// Share of the excess error of all windows, 0-1.
    pub share: f64,
    /// Number of windows.
    pub windows: usize,
}

impl Share {
    fn of(windows: &[Window], kinds: &[Context]) -> Self {
        let total: f64 = windows.iter().map(|w| w.excess_sse).sum();
        let hits: Vec<&Window> = windows.iter().filter(|w| kinds.contains(&w.kind)).collect();
        let part: f64 = hits.iter().map(|w| w.excess_sse).sum();
        Share {
            share: if total > 0.0 { part / total } else { 0.0 },
            windows: hits.len(),
        }
    }
}

/// Where the excess error of the model before the finding lay, by what the valve was doing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Located {
    pub after_reversals: Share,
    pub during_moves: Share,
    pub at_rest: Share,
    pub near_limits: Share,
}

/// The step delays of the recording, split by direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Delays {
    /// Steps against the previous movement.
    pub reversal: Population,
    /// Steps in the same direction as the previous movement.
    pub same_direction: Population,
    /// Direction reversals of O_P in the whole recording.
    pub reversals_of_op: usize,
}

/// Stick-slip as the fit has it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum StickSlipModel {
    /// Inside the positioner loop: sticks when slow, breaks away this far beyond, overshoots;
    /// the positioner rests once a slip lands inside its tolerance band (0 = none).
    Breakaway {
        breakaway_pct: f64,
        gain_per_s: f64,
        tolerance_band_pct: f64,
    },
    /// Choudhury's on the valve's input.
    Input {
        stickband_pct: f64,
        jump_pct: f64,
        gain_per_s: f64,
    },
}

impl StickSlipModel {
    fn of(spec: &ModelSpec) -> Self {
        let g = |k| composed::get(spec, k);
        if g(Knob::Breakaway) > 0.0 {
            StickSlipModel::Breakaway {
                breakaway_pct: g(Knob::Breakaway),
                gain_per_s: g(Knob::Gain),
                tolerance_band_pct: g(Knob::PositionerDeadband),
            }
        } else {
            StickSlipModel::Input {
                stickband_pct: g(Knob::Stickband),
                jump_pct: g(Knob::Stickband) * g(Knob::JumpFraction),
                gain_per_s: g(Knob::Gain),
            }
        }
    }
}

/// A deadband: where the valve comes to rest against O_P, and the fitted band.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Rests {
    /// Mean settled V_P - O_P after opening and after closing, %, and hold counts.
    pub offset_after_opening_pct: f64,
    pub holds_opening: usize,
    pub offset_after_closing_pct: f64,
    pub holds_closing: usize,
    /// How far from O_P the valve rests, % ([`Facts::rest_distance_pct`]): the evidence
    /// of a loop that never holds O_P for 3 s (no holds).
    pub rest_distance_pct: f64,
    pub deadband_pct: f64,
}

/// Uneven stroke speeds: V_P's speeds each way as the recording shows its limits, and the
/// fit's limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Uneven {
    /// 99.9th percentile of V_P's opening and closing speeds ([`Facts::measured_speeds`]), %/s.
    pub open_speed: f64,
    pub close_speed: f64,
    /// Whether those are of the speeds V_P holds for 0.3 s or more.
    pub held: bool,
    pub fitted_open_pct_per_s: f64,
    pub fitted_close_pct_per_s: f64,
}

/// Stick-slip judged by the slips of V_P ([`super::stickslip`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Slips {
    /// Measured slips: count, mean and spread of their sizes, %.
    pub count: usize,
    pub size_pct: f64,
    pub size_sd_pct: f64,
    /// Smallest move that counts as a slip, %, and how fast it must be done, s.
    pub threshold_pct: f64,
    pub within_s: f64,
    /// Median time between slips, s.
    pub median_interval_s: f64,
    /// Successive slips that reverse (hunting), of how many pairs.
    pub reversing: usize,
    pub successive: usize,
    /// Slips of the model before, and of the stick-slip model, whole recording.
    pub slips_before: usize,
    pub slips_after: usize,
    pub size_after_pct: f64,
    pub model: StickSlipModel,
    /// Held-out pieces where the model's slip histogram is closer to the measured one, of
    /// how many that differ.
    pub pieces_closer: usize,
    pub pieces_compared: usize,
    /// One-sided signed-rank p-value of that.
    pub p_value: f64,
    /// Summed histogram distance, in slips, before and after.
    pub distance_before: f64,
    pub distance_after: f64,
    /// Named by the number of slips the model before misses (the fitted model matches them
    /// only in part).
    pub by_count: bool,
}

/// What the data and the fit say, per effect.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Detail {
    DeadTime {
        dead_time_s: f64,
        was_s: f64,
    },
    Backlash {
        /// Extra time V_P stays flat after a reversal, at half travel, s.
        crossing_half_open_s: f64,
        /// Closed and fully open, when it depends on the opening.
        crossing_closed_s: Option<f64>,
        crossing_open_s: Option<f64>,
        /// The friction band crossed at the positioner's speed, %, when fitted as one.
        friction_band_pct: Option<f64>,
    },
    StateDependentDelay {
        /// Mean reversal delay below and above 50 % opening, s.
        reversal_below_half_s: Option<f64>,
        reversal_above_half_s: Option<f64>,
        /// How many times slower fully open than closed (the slowdown variant).
        open_vs_closed: Option<f64>,
        /// Cart-crossing time closed and open (the pin-cart II polynomial variant), s.
        crossing_closed_s: Option<f64>,
        crossing_open_s: Option<f64>,
    },
    SlewRate {
        /// 99.9th percentile of V_P's opening and closing speed, %/s.
        open_speed: f64,
        close_speed: f64,
        slew_pct_per_s: f64,
        /// The closing limit of a model with a limit each way (`slew_pct_per_s` opens), %/s.
        #[serde(skip_serializing_if = "Option::is_none")]
        closing_slew_pct_per_s: Option<f64>,
        /// The positioner's gain, 1/s, of a valve slow through it: its speed stays proportional
        /// to its error and reaches no limit (`slew_pct_per_s` is then not its stroke).
        #[serde(skip_serializing_if = "Option::is_none")]
        gain_per_s: Option<f64>,
    },
    Asymmetry(Uneven),
    MinSpeed {
        min_speed_pct_per_s: f64,
    },
    Stiction {
        /// Holds of O_P where the settled V_P jumped by more than five noise sigmas, of all.
        holds_with_jumps: usize,
        holds: usize,
        model: StickSlipModel,
    },
    Slips(Slips),
    Deadband(Rests),
    Saturation {
        travel_min_pct: f64,
        travel_max_pct: f64,
        /// How far the drive winds up past the stop, %.
        windup_pct: f64,
    },
    Quantization {
        lattice_pct: f64,
    },
    Calibration {
        /// Mean settled V_P - O_P over all holds, %.
        mean_offset_pct: f64,
        holds: usize,
        gain: f64,
        offset_pct: f64,
    },
}

/// The evidence for one finding.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Evidence {
    pub located: Located,
    pub delays: Delays,
    pub detail: Detail,
}

impl Evidence {
    /// The evidence for `effect` as fitted in `spec`, added to `before`.
    pub(crate) fn of(
        effect: Effect,
        spec: &ModelSpec,
        before: &ModelSpec,
        facts: &Facts,
        windows: &[Window],
        sigma: f64,
    ) -> Self {
        Evidence {
            located: located(windows),
            delays: delays(facts),
            detail: detail(effect, spec, before, facts, sigma),
        }
    }

    /// The same evidence with the fit's numbers read from `spec` (the final model, after the
    /// joint refit), so a finding quotes the values the final model has; the dead time it was
    /// before stays.
    pub(crate) fn in_final(&mut self, effect: Effect, spec: &ModelSpec, facts: &Facts, sigma: f64) {
        let mut detail = detail(effect, spec, spec, facts, sigma);
        if let (Detail::DeadTime { was_s, .. }, Detail::DeadTime { was_s: before, .. }) =
            (&mut detail, &self.detail)
        {
            *was_s = *before;
        }
        self.detail = detail;
    }

    /// The evidence for stick-slip judged by its slips.
    pub(crate) fn of_slips(
        c: &stickslip::Candidate,
        facts: &Facts,
        windows: &[Window],
        dt: f64,
    ) -> Self {
        let s = &c.slips_measured;
        let (size_pct, size_sd_pct, count) = stats::mean_sd(s.iter().map(|x| x.size_pct.abs()));
        let gaps: Vec<f64> = s
            .windows(2)
            .map(|w| (w[1].k - w[0].k) as f64 * dt)
            .collect();
        let (size_after_pct, _, slips_after) =
            stats::mean_sd(c.slips_after.iter().map(|x| x.size_pct.abs()));
        let slips = Slips {
            count,
            size_pct,
            size_sd_pct,
            threshold_pct: facts.slip_scale.threshold_pct,
            within_s: facts.slip_scale.span as f64 * dt,
            median_interval_s: stats::median(&gaps).unwrap_or(0.0),
            reversing: s
                .windows(2)
                .filter(|w| w[0].size_pct * w[1].size_pct < 0.0)
                .count(),
            successive: count.saturating_sub(1),
            slips_before: c.slips_before.len(),
            slips_after,
            size_after_pct,
            model: StickSlipModel::of(&c.spec),
            pieces_closer: c.held.better,
            pieces_compared: c.held.better + c.held.worse,
            p_value: c.held.p_value,
            distance_before: c.held.distance_before,
            distance_after: c.held.distance_after,
            by_count: c.by_count && !c.held.slips_alike(),
        };
        Evidence {
            located: located(windows),
            delays: delays(facts),
            detail: Detail::Slips(slips),
        }
    }
}

fn located(windows: &[Window]) -> Located {
    Located {
        after_reversals: Share::of(windows, &[Context::Reversal]),
        during_moves: Share::of(windows, &[Context::LargeStep, Context::Move]),
        at_rest: Share::of(windows, &[Context::Rest]),
        near_limits: Share::of(windows, &[Context::NearLimit]),
    }
}

fn delays(facts: &Facts) -> Delays {
    let of = |rev: bool| {
        let d: Vec<f64> = facts
            .steps
            .iter()
            .filter(|s| s.reversal == rev)
            .map(|s| s.delay_s)
            .collect();
        Population::of(&d)
    };
    Delays {
        reversal: of(true),
        same_direction: of(false),
        reversals_of_op: facts.reversals,
    }
}

/// Time a friction band costs a 5 % reversal at half travel, s: the band crossed at the
/// positioner's speed for that error (at least a sample's worth of nothing).
fn band_crossing_s(spec: &ModelSpec) -> f64 {
    let g = |k| composed::get(spec, k);
    let slow = composed::half_open(spec);
    let speed = (g(Knob::Gain) * 5.0)
        .max(g(Knob::MinSpeed))
        .min(g(Knob::Slew))
        / slow;
    g(Knob::FrictionBand) / speed.max(1e-9)
}

/// Mean settled V_P - O_P over the holds `approach` selects, and their count.
fn hold_offset(facts: &Facts, approach: impl Fn(f64) -> bool) -> (f64, usize) {
    let (m, _, n) = stats::mean_sd(
        facts
            .holds
            .iter()
            .filter(|h| approach(h.approach))
            .map(|h| h.vp_pct - h.op_pct),
    );
    (m, n)
}

fn detail(
    effect: Effect,
    spec: &ModelSpec,
    before: &ModelSpec,
    facts: &Facts,
    sigma: f64,
) -> Detail {
    let g = |k| composed::get(spec, k);
    let slowed = g(Knob::Slowdown) > 0.0;
    match effect {
        Effect::DeadTime => Detail::DeadTime {
            dead_time_s: g(Knob::DeadTime),
            was_s: composed::get(before, Knob::DeadTime),
        },
        Effect::Backlash if g(Knob::FrictionBand) > 0.0 => Detail::Backlash {
            crossing_half_open_s: band_crossing_s(spec),
            crossing_closed_s: None,
            crossing_open_s: None,
            friction_band_pct: Some(g(Knob::FrictionBand)),
        },
        Effect::Backlash => Detail::Backlash {
            crossing_half_open_s: g(Knob::Crossing) * composed::half_open(spec),
            crossing_closed_s: slowed.then(|| g(Knob::Crossing)),
            crossing_open_s: slowed.then(|| g(Knob::Crossing) * (1.0 + g(Knob::Slowdown))),
            friction_band_pct: None,
        },
        Effect::StateDependentDelay => {
            let mean = |below: bool| {
                let d: Vec<f64> = facts
                    .steps
                    .iter()
                    .filter(|s| s.reversal && (s.from_pct < 50.0) == below)
                    .map(|s| s.delay_s)
                    .collect();
                (!d.is_empty()).then(|| d.iter().sum::<f64>() / d.len() as f64)
            };
            Detail::StateDependentDelay {
                reversal_below_half_s: mean(true),
                reversal_above_half_s: mean(false),
                open_vs_closed: slowed.then(|| 1.0 + g(Knob::Slowdown)),
                crossing_closed_s: (!slowed).then(|| g(Knob::Crossing)),
                crossing_open_s: (!slowed)
                    .then(|| g(Knob::Crossing) + 100.0 * g(Knob::CrossingSlope)),
            }
        }
        Effect::SlewRate => Detail::SlewRate {
            open_speed: facts.open_speed,
            close_speed: facts.close_speed,
            slew_pct_per_s: g(Knob::Slew),
            closing_slew_pct_per_s: Some(g(Knob::ClosingSlew)).filter(|&c| c > 0.0),
            gain_per_s: None,
        },
        Effect::Asymmetry => {
            let ((open_speed, close_speed), held) = facts.measured_speeds();
            Detail::Asymmetry(Uneven {
                open_speed,
                close_speed,
                held,
                fitted_open_pct_per_s: g(Knob::Slew),
                fitted_close_pct_per_s: g(Knob::ClosingSlew),
            })
        }
        Effect::MinSpeed => Detail::MinSpeed {
            min_speed_pct_per_s: g(Knob::MinSpeed),
        },
        Effect::Stiction => Detail::Stiction {
            holds_with_jumps: facts
                .holds
                .iter()
                .filter(|h| h.max_jump_pct > 5.0 * sigma.max(0.01))
                .count(),
            holds: facts.holds.len(),
            model: StickSlipModel::of(spec),
        },
        Effect::Deadband => {
            let (up, nu) = hold_offset(facts, |a| a > 0.0);
            let (down, nd) = hold_offset(facts, |a| a < 0.0);
            Detail::Deadband(Rests {
                offset_after_opening_pct: up,
                holds_opening: nu,
                offset_after_closing_pct: down,
                holds_closing: nd,
                rest_distance_pct: facts.rest_distance_pct,
                deadband_pct: size::deadband(spec),
            })
        }
        Effect::Saturation => Detail::Saturation {
            travel_min_pct: spec.travel.min_pct,
            travel_max_pct: spec.travel.max_pct,
            windup_pct: g(Knob::Windup),
        },
        Effect::Quantization => Detail::Quantization {
            lattice_pct: g(Knob::Quantum),
        },
        Effect::Calibration => {
            let (mean_offset_pct, holds) = hold_offset(facts, |_| true);
            Detail::Calibration {
                mean_offset_pct,
                holds,
                gain: g(Knob::CalGain),
                offset_pct: g(Knob::CalOffset),
            }
        }
    }
}
