//! Time-only generators of the wanted opening O_P: random steps (the paper's experiment),
//! steps, ramp, sine, PRBS, replay and constant, with their parameters (serde).
//!
//! A [`Signal`] is asked `op_at(t_s)` with non-decreasing times and answers the O_P in %, or
//! `None` when it has nothing more to give (only a replay ends). Random generators are seeded
//! (ChaCha8) and depend on the time only, not on how often they are asked, so two runs that ask
//! at different times see the same signal. Asking never allocates.
//!
//! Both the daemon's sources (`vb_daemon::runtime::source`, which adds the clamp to `[source]`'s
//! range and the Modbus-server controller) and offline generation (`vb_analysis::synth`) use these.
//! Nothing here clamps, checks ranges (the owner of the parameters does), knows about valves or
//! reads files (a replay is handed the O_P samples already held on its grid).

use std::f64::consts::TAU;
use std::sync::Arc;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Slack when turning a time into a step or bit index, so `0.3 / 0.1` counts as 3, not 2.999...
const INDEX_EPS: f64 = 1e-9;

/// Random steps: levels uniform in `min_pct..=max_pct`, each held a time uniform in
/// `hold_min_s..=hold_max_s` (the paper's experiment with the defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomStepsParams {
    /// Lowest level, %.
    pub min_pct: f64,
    /// Highest level, %.
    pub max_pct: f64,
    /// Shortest hold, s.
    pub hold_min_s: f64,
    /// Longest hold, s.
    pub hold_max_s: f64,
    /// Seed of the levels and holds.
    pub seed: u64,
}

impl Default for RandomStepsParams {
    fn default() -> Self {
        RandomStepsParams {
            min_pct: 20.0,
            max_pct: 97.0,
            hold_min_s: 0.0,
            hold_max_s: 20.0,
            seed: 1,
        }
    }
}

/// A list of levels, each held for the same time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepsParams {
    /// The levels, %, in order.
    pub levels_pct: Vec<f64>,
    /// How long each level is held, s.
    pub hold_s: f64,
    /// Start again after the last level (otherwise hold it).
    #[serde(default = "yes")]
    pub repeat: bool,
}

fn yes() -> bool {
    true
}

/// A linear ramp, or a triangle going back and forth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RampParams {
    /// Start level, %.
    pub from_pct: f64,
    /// End level, %.
    pub to_pct: f64,
    /// Time from start to end, s.
    pub duration_s: f64,
    /// Go back and forth (triangle) instead of holding `to_pct` at the end.
    pub repeat: bool,
}

impl Default for RampParams {
    fn default() -> Self {
        RampParams {
            from_pct: 20.0,
            to_pct: 80.0,
            duration_s: 30.0,
            repeat: false,
        }
    }
}

/// A sine wave.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SineParams {
    /// Mean level, %.
    pub mean_pct: f64,
    /// Amplitude, %.
    pub amplitude_pct: f64,
    /// Period, s.
    pub period_s: f64,
}

impl Default for SineParams {
    fn default() -> Self {
        SineParams {
            mean_pct: 50.0,
            amplitude_pct: 20.0,
            period_s: 10.0,
        }
    }
}

/// A pseudo-random binary signal: mean ± amplitude, a new random level every 1/(2 band_hz) s.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PrbsParams {
    /// Mean level, %.
    pub mean_pct: f64,
    /// The two levels are mean ± amplitude, %.
    pub amplitude_pct: f64,
    /// Highest frequency excited, Hz: a new random level every 1/(2 band_hz) s.
    pub band_hz: f64,
    /// Seed of the levels.
    pub seed: u64,
}

impl Default for PrbsParams {
    fn default() -> Self {
        PrbsParams {
            mean_pct: 50.0,
            amplitude_pct: 10.0,
            band_hz: 1.0,
            seed: 1,
        }
    }
}

/// One fixed O_P.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstantParams {
    /// The O_P, %.
    pub op_pct: f64,
}

/// The paper's random steps, as a generator (seeded, time only).
#[derive(Debug, Clone)]
pub struct RandomSteps {
    rng: ChaCha8Rng,
    level_range: (f64, f64),
    hold_range: (f64, f64),
    level: f64,
    next_change_s: f64,
}

impl RandomSteps {
    /// The generator of `p`; its first level is drawn at time 0.
    pub fn new(p: &RandomStepsParams) -> Self {
        RandomSteps {
            rng: ChaCha8Rng::seed_from_u64(p.seed),
            level_range: (p.min_pct, p.max_pct.max(p.min_pct)),
            hold_range: (p.hold_min_s, p.hold_max_s.max(p.hold_min_s)),
            level: p.min_pct,
            next_change_s: 0.0,
        }
    }

    /// The level at `t_s` (draws every change up to that time).
    pub fn op_at(&mut self, t_s: f64) -> f64 {
        while t_s >= self.next_change_s {
            self.level = self.rng.gen_range(self.level_range.0..=self.level_range.1);
            let hold = self.rng.gen_range(self.hold_range.0..=self.hold_range.1);
            // A zero-length range of zero holds would never reach `t_s`.
            if hold <= 0.0 && self.hold_range.1 <= 0.0 {
                self.next_change_s = f64::INFINITY;
            }
            self.next_change_s += hold;
        }
        self.level
    }
}

/// A pseudo-random binary signal as a generator (seeded, time only).
#[derive(Debug, Clone)]
pub struct Prbs {
    rng: ChaCha8Rng,
    mean: f64,
    amplitude: f64,
    bit_s: f64,
    bits_drawn: u64,
    high: bool,
}

impl Prbs {
    /// The generator of `p`.
    pub fn new(p: &PrbsParams) -> Self {
        Prbs {
            rng: ChaCha8Rng::seed_from_u64(p.seed),
            mean: p.mean_pct,
            amplitude: p.amplitude_pct,
            bit_s: 1.0 / (2.0 * p.band_hz),
            bits_drawn: 0,
            high: false,
        }
    }

    /// The level at `t_s`.
    pub fn op_at(&mut self, t_s: f64) -> f64 {
        // Draw every bit up to this time, so the sequence does not depend on skipped times.
        let bits_due = (t_s / self.bit_s + INDEX_EPS).floor() as u64 + 1;
        while self.bits_drawn < bits_due {
            self.high = self.rng.gen::<bool>();
            self.bits_drawn += 1;
        }
        if self.high {
            self.mean + self.amplitude
        } else {
            self.mean - self.amplitude
        }
    }
}

/// Any time-only O_P generator.
#[derive(Debug, Clone)]
pub enum Signal {
    /// The paper's experiment.
    RandomSteps(RandomSteps),
    /// Levels held in turn.
    Steps(StepsParams),
    /// A ramp or triangle.
    Ramp(RampParams),
    /// A sine wave.
    Sine(SineParams),
    /// A pseudo-random binary signal.
    Prbs(Prbs),
    /// Recorded O_P held on a grid of `period_s`: slot k (the time rounded to the grid) is entry
    /// k; ends with the samples.
    Replay { op: Arc<Vec<f64>>, period_s: f64 },
    /// One fixed O_P.
    Constant(f64),
}

impl Signal {
    /// The O_P at `t_s` (s from the start), unclamped; `None` once a replay (or an empty list
    /// of steps) has nothing to give.
    pub fn op_at(&mut self, t_s: f64) -> Option<f64> {
        Some(match self {
            Signal::RandomSteps(g) => g.op_at(t_s),
            Signal::Steps(s) => {
                let i = (t_s / s.hold_s + INDEX_EPS).floor() as usize;
                let n = s.levels_pct.len();
                let i = if s.repeat {
                    i.checked_rem(n)?
                } else {
                    i.min(n.checked_sub(1)?)
                };
                s.levels_pct[i]
            }
            Signal::Ramp(r) => {
                let phase = t_s / r.duration_s;
                let frac = if r.repeat {
                    let p = phase % 2.0;
                    if p <= 1.0 {
                        p
                    } else {
                        2.0 - p
                    }
                } else {
                    phase.min(1.0)
                };
                r.from_pct + (r.to_pct - r.from_pct) * frac
            }
            Signal::Sine(w) => w.mean_pct + w.amplitude_pct * (TAU * t_s / w.period_s).sin(),
            Signal::Prbs(g) => g.op_at(t_s),
            Signal::Replay { op, period_s } => *op.get((t_s / *period_s).round() as usize)?,
            Signal::Constant(v) => *v,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_steps_depend_on_time_only() {
        let p = RandomStepsParams {
            seed: 3,
            ..RandomStepsParams::default()
        };
        let mut every = RandomSteps::new(&p);
        let all: Vec<f64> = (0..30_000).map(|k| every.op_at(k as f64 * 0.01)).collect();
        let mut sparse = RandomSteps::new(&p);
        for k in (0..30_000).step_by(777) {
            assert_eq!(sparse.op_at(k as f64 * 0.01), all[k]);
        }
        assert!(all.iter().all(|v| (20.0..=97.0).contains(v)));
    }

    #[test]
    fn zero_holds_do_not_hang_and_empty_steps_end() {
        let mut g = RandomSteps::new(&RandomStepsParams {
            hold_min_s: 0.0,
            hold_max_s: 0.0,
            ..RandomStepsParams::default()
        });
        let first = g.op_at(0.0);
        assert_eq!(g.op_at(5.0), first);
        let mut s = Signal::Steps(StepsParams {
            levels_pct: vec![],
            hold_s: 1.0,
            repeat: true,
        });
        assert_eq!(s.op_at(0.0), None);
    }

    #[test]
    fn replay_holds_each_sample_and_ends() {
        let mut s = Signal::Replay {
            op: Arc::new(vec![1.0, 2.0]),
            period_s: 0.5,
        };
        // Times are rounded to the nearest slot of the grid.
        let got: Vec<Option<f64>> = [0.0, 0.2, 0.5, 0.74, 1.0].map(|t| s.op_at(t)).to_vec();
        assert_eq!(got, [Some(1.0), Some(1.0), Some(2.0), Some(2.0), None]);
    }
}
