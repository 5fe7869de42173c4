//! Open-loop excitations of synthetic recordings: the paper's random steps, small steps around
//! a wandering level, slow and fast ramps with holds, and a mix of the three.
//!
//! Every generator is seeded (ChaCha8) and, like [`vb_core::signal`]'s, depends on the time only:
//! events (a new level, a ramp) are drawn as the asked time passes them. Nothing here knows about
//! valves or noise; the closed loop, which needs the valve's answer, lives in the parent module.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use vb_core::signal::{RandomSteps, RandomStepsParams};

/// Small steps: 0.2-2 % each, held 2-10 s, around a level that wanders within ±30 % of
/// `around_pct` (10-90 %, a new one every 1-3 min); a step heads for that level nine times out of ten
/// when it is more than 1 % away, else either way, so reversals are frequent.
#[derive(Debug, Clone)]
pub struct SmallSteps {
    rng: ChaCha8Rng,
    around: f64,
    /// How far the level it heads for wanders from `around`, %.
    wander: f64,
    level: f64,
    target: f64,
    next_step_s: f64,
    next_target_s: f64,
}

impl SmallSteps {
    /// Small steps starting at `around_pct` (taken within 15-85 %; the level stays in 5-95 %).
    pub fn new(around_pct: f64, seed: u64) -> Self {
        Self::wandering(around_pct, 30.0, seed)
    }

    /// Small steps that stay around `around_pct` (the level they head for does not wander):
    /// many reversals at one opening, as a log for sizing a valve's lost motion there needs.
    pub fn staying(around_pct: f64, seed: u64) -> Self {
        Self::wandering(around_pct, 0.0, seed)
    }

    fn wandering(around_pct: f64, wander: f64, seed: u64) -> Self {
        let around = around_pct.clamp(15.0, 85.0);
        SmallSteps {
            rng: ChaCha8Rng::seed_from_u64(seed),
            around,
            wander,
            level: around,
            target: around,
            next_step_s: 0.0,
            next_target_s: 0.0,
        }
    }

    /// The O_P at `t_s`.
    pub fn op_at(&mut self, t_s: f64) -> f64 {
        while t_s >= self.next_target_s {
            self.target =
                (self.around + self.rng.gen_range(-self.wander..=self.wander)).clamp(10.0, 90.0);
            self.next_target_s += self.rng.gen_range(60.0..=180.0);
        }
        while t_s >= self.next_step_s {
            if self.next_step_s > 0.0 {
                let size = self.rng.gen_range(0.2..=2.0);
                let gap = self.target - self.level;
                let toward = if gap.abs() > 1.0 {
                    self.rng.gen_bool(0.9)
                } else {
                    self.rng.gen_bool(0.5)
                };
                let up = (gap >= 0.0) == toward;
                self.level = (self.level + if up { size } else { -size }).clamp(5.0, 95.0);
            }
            self.next_step_s += self.rng.gen_range(2.0..=10.0);
        }
        self.level
    }
}

/// Ramps: a hold of 2-15 s, then a ramp to a new level in 10-90 %, slow (0.2-2 %/s) or fast
/// (5-30 %/s) with equal odds, then a hold again.
#[derive(Debug, Clone)]
pub struct Ramps {
    rng: ChaCha8Rng,
    /// The segment in force: from (`t0`, `from`) to (`t1`, `to`); a hold has `from == to`.
    t0: f64,
    t1: f64,
    from: f64,
    to: f64,
    holding: bool,
}

impl Ramps {
    /// Ramps starting with a hold at a random level.
    pub fn new(seed: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let level = rng.gen_range(20.0..=80.0);
        let hold = rng.gen_range(2.0..=15.0);
        Ramps {
            rng,
            t0: 0.0,
            t1: hold,
            from: level,
            to: level,
            holding: true,
        }
    }

    /// The O_P at `t_s`.
    pub fn op_at(&mut self, t_s: f64) -> f64 {
        while t_s >= self.t1 {
            let here = self.to;
            self.t0 = self.t1;
            self.from = here;
            if self.holding {
                self.to = self.rng.gen_range(10.0..=90.0);
                let rate = if self.rng.gen_bool(0.5) {
                    self.rng.gen_range(0.2..=2.0)
                } else {
                    self.rng.gen_range(5.0..=30.0)
                };
                self.t1 = self.t0 + ((self.to - here).abs() / rate).max(0.01);
            } else {
                self.to = here;
                self.t1 = self.t0 + self.rng.gen_range(2.0..=15.0);
            }
            self.holding = !self.holding;
        }
        let frac = ((t_s - self.t0) / (self.t1 - self.t0)).clamp(0.0, 1.0);
        self.from + (self.to - self.from) * frac
    }
}

/// An open-loop excitation, ready to be asked `op_at(t)`.
#[derive(Debug, Clone)]
pub(super) enum OpenLoop {
    Random(RandomSteps),
    Small(SmallSteps),
    Ramps(Ramps),
    /// Random steps, then ramps, then small steps (boxed: three generators in one).
    Mixed(Box<Mixed>),
}

/// Random steps, then ramps, then small steps around a low opening, a third of the duration
/// each (starting at `ramps_s` and `small_s`).
#[derive(Debug, Clone)]
pub(super) struct Mixed {
    random: RandomSteps,
    ramps: Ramps,
    small: SmallSteps,
    ramps_s: f64,
    small_s: f64,
}

impl OpenLoop {
    /// The paper's random steps of seed `seed`.
    pub(super) fn random_steps(seed: u64) -> Self {
        OpenLoop::Random(RandomSteps::new(&RandomStepsParams {
            seed,
            ..RandomStepsParams::default()
        }))
    }

    /// The mix over `duration_s`, its small steps around `low_pct`.
    pub(super) fn mixed(low_pct: f64, duration_s: f64, seed: u64) -> Self {
        OpenLoop::Mixed(Box::new(Mixed {
            random: RandomSteps::new(&RandomStepsParams {
                seed,
                ..RandomStepsParams::default()
            }),
            ramps: Ramps::new(seed.wrapping_add(1)),
            small: SmallSteps::new(low_pct, seed.wrapping_add(2)),
            ramps_s: duration_s / 3.0,
            small_s: 2.0 * duration_s / 3.0,
        }))
    }

    pub(super) fn op_at(&mut self, t_s: f64) -> f64 {
        match self {
            OpenLoop::Random(g) => g.op_at(t_s),
            OpenLoop::Small(g) => g.op_at(t_s),
            OpenLoop::Ramps(g) => g.op_at(t_s),
            OpenLoop::Mixed(m) => {
                if t_s < m.ramps_s {
                    m.random.op_at(t_s)
                } else if t_s < m.small_s {
                    m.ramps.op_at(t_s - m.ramps_s)
                } else {
                    m.small.op_at(t_s - m.small_s)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(g: &mut OpenLoop, seconds: f64) -> Vec<f64> {
        (0..(seconds * 100.0) as usize)
            .map(|k| g.op_at(k as f64 * 0.01))
            .collect()
    }

    #[test]
    fn small_steps_are_small_held_and_reverse() {
        let op = series(&mut OpenLoop::Small(SmallSteps::new(40.0, 3)), 600.0);
        let steps: Vec<f64> = op
            .windows(2)
            .map(|w| w[1] - w[0])
            .filter(|d| *d != 0.0)
            .collect();
        assert!(steps.iter().all(|d| (0.2..=2.0 + 1e-9).contains(&d.abs())));
        // 600 s of holds of 2-10 s: about a hundred steps, many of them reversals.
        assert!((60..=300).contains(&steps.len()), "{}", steps.len());
        let reversals = steps.windows(2).filter(|w| w[0] * w[1] < 0.0).count();
        assert!(
            reversals * 4 > steps.len(),
            "{reversals} of {}",
            steps.len()
        );
        assert!(op.iter().all(|v| (15.0..=65.0).contains(v)));
    }

    #[test]
    fn small_steps_that_stay_reverse_around_their_level() {
        let op = series(&mut OpenLoop::Small(SmallSteps::staying(50.0, 1000)), 200.0);
        let steps: Vec<f64> = (op.windows(2).map(|w| w[1] - w[0]))
            .filter(|d| *d != 0.0)
            .collect();
        let reversals = steps.windows(2).filter(|w| w[0] * w[1] < 0.0).count();
        // Within a step or two of the level, and a reversal every other step or so.
        assert!(op.iter().all(|v| (46.0..=54.0).contains(v)));
        assert!(
            reversals * 3 >= steps.len(),
            "{reversals} of {}",
            steps.len()
        );
    }

    #[test]
    fn ramps_are_slow_and_fast_with_holds() {
        let op = series(&mut OpenLoop::Ramps(Ramps::new(5)), 900.0);
        let speeds: Vec<f64> = op.windows(2).map(|w| (w[1] - w[0]).abs() / 0.01).collect();
        let held = speeds.iter().filter(|s| **s < 1e-9).count();
        let slow = speeds.iter().filter(|s| (0.15..2.1).contains(*s)).count();
        let fast = speeds.iter().filter(|s| (4.9..30.1).contains(*s)).count();
        assert!(
            held > 10_000 && slow > 3_000 && fast > 500,
            "{held} {slow} {fast}"
        );
        assert!(op.iter().all(|v| (10.0..=90.0).contains(v)));
    }

    #[test]
    fn mixed_ends_in_small_steps_around_a_low_opening() {
        let mut g = OpenLoop::mixed(30.0, 600.0, 9);
        let op = series(&mut g, 600.0);
        let tail = &op[40_000..];
        assert!(tail.iter().all(|v| (5.0..=55.0).contains(v)));
        let mut again = OpenLoop::mixed(30.0, 600.0, 9);
        assert_eq!(series(&mut again, 600.0), op);
    }
}
