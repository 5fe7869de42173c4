//! The guard of compensation: does the valve, with compensation, do what the model says it
//! does with compensation?
//!
//! Like is compared with like: the measured V_P against the identified model driven by the
//! same set-points sent (compensation included), never against the model driven by the
//! controller's O_P, so a model's own error (a stroke speed it gets wrong on large steps, say)
//! is not read as compensation's. What is judged is what compensation can add, all measurable
//! from the log with no twin of the valve, on the same figures for both positions:
//!
//! - **reversals** and **travel** (wear), counted through a deadband above the sensor's noise
//!   ([`DEADBAND_MIN_PCT`], or [`NOISE_DEADBANDS`] times the noise the guard measures on V_P)
//!   on a mean of the last [`SMOOTH`] rows;
//! - **overshoot**: how far the valve goes past the target, beyond half that deadband, after a move
//!   of the controller (a kick or a deadband step that is too large carries the stem past it);
//! - **miss**: how far from the target the valve comes to rest at the end of a hold (where both
//!   it and the model are still for [`REST_S`]): a step on the wrong side, a stuck valve.
//!
//! A hold runs from one move of the controller (its O_P leaving the compensator's gate around
//! where it last asked) to the next, and is judged only when compensation added something in
//! it, so a controller's noise that compensation leaves alone is not judged against a model
//! that filters it differently. Each `window_s`, a figure summed over the judged holds that
//! exceeds the model's by more than the relative margin and its slack ([`REVERSAL_SLACK`],
//! twice the deadband for travel, half of it for overshoot and for miss per rested hold)
//! makes the verdict: compensation does worse than its model says. The verdict is the
//! caller's to act on. The RMS of O_P - V_P is reported too (measured, the model's with
//! compensation, the model's without), not judged: on large steps it is the model's speed.
//!
//! Allocation-free: sums over the window and a few samples per position. Not here: stepping
//! the models ([`super::Compensator`]).

use crate::metrics::{Travel, TravelCounter};

/// Rows in the mean the figures are counted on (a sensor's noise halves).
pub const SMOOTH: usize = 4;
/// The smallest deadband of the counts, %: twice a per-mille register's resolution, ten
/// standard deviations of a healthy sensor's noise on the mean of [`SMOOTH`] rows.
pub const DEADBAND_MIN_PCT: f64 = 0.2;
/// The deadband is at least this many times the noise measured on V_P.
pub const NOISE_DEADBANDS: f64 = 5.0;
/// Reversals the valve may show beyond the model's (and the margin) in a window.
pub const REVERSAL_SLACK: f64 = 2.0;
/// How long a position must stay within the deadband to be at rest, s.
pub const REST_S: f64 = 0.5;
/// Time constant of the noise estimate, s.
const NOISE_TAU_S: f64 = 10.0;
/// Mean |second difference| of white noise, in its standard deviations: sqrt(6) sqrt(2/pi).
const D2_PER_SIGMA: f64 = 1.954;

/// One sample for the guard.
#[derive(Debug, Clone, Copy)]
pub(super) struct Sample {
    /// The controller's O_P, %.
    pub op: f64,
    /// Where the valve should come to rest for it, %.
    pub target: f64,
    /// The smallest move of the controller that counts, %.
    pub gate: f64,
    /// Compensation added something to this set-point.
    pub compensated: bool,
    /// The model's V_P for the set-points sent, %.
    pub model_with: f64,
    /// The model's V_P for the controller's O_P, %.
    pub model_without: f64,
    /// The V_P read (None when none was read), %.
    pub measured: Option<f64>,
}

/// What a position did over the judged holds of a window.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wear {
    /// Direction changes counted through the deadband.
    pub reversals: usize,
    /// Distance counted through the deadband, %.
    pub travel_pct: f64,
    /// Sum over the holds of the farthest past the target beyond half the deadband, %.
    pub overshoot_pct: f64,
    /// Sum over the holds that ended at rest of the distance from the target, %.
    pub miss_pct: f64,
}

/// The figure that exceeded the model's.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    Reversals,
    Travel,
    Overshoot,
    Miss,
}

impl Figure {
    /// The figure in words.
    pub fn name(self) -> &'static str {
        match self {
            Figure::Reversals => "reversals",
            Figure::Travel => "travel",
            Figure::Overshoot => "overshoot past the target",
            Figure::Miss => "distance from the target at rest",
        }
    }
}

/// One window's verdict.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Window {
    /// RMS of O_P - V_P, measured with compensation, %.
    pub with_pct: f64,
    /// RMS of O_P - V_P of the model with compensation (driven by the set-points sent), %.
    pub model_with_pct: f64,
    /// RMS of O_P - V_P of the model without compensation (driven by the O_P), %.
    pub without_pct: f64,
    /// Rows that read a V_P.
    pub rows: usize,
    /// Holds judged (compensation added something in them).
    pub holds: usize,
    /// The deadband the figures were counted through, %.
    pub deadband_pct: f64,
    /// The valve's figures over the judged holds.
    pub measured: Wear,
    /// The model's figures with compensation over the same holds and rows.
    pub predicted: Wear,
    /// The first figure beyond the model's by more than the margin and its slack.
    pub exceeded: Option<Figure>,
    /// Compensation does worse than its model says (a figure exceeded).
    pub worse: bool,
}

/// The figures of one position (the valve's, or the model's) through a hold.
#[derive(Debug, Clone, Default)]
struct Track {
    last: [f64; SMOOTH],
    filled: usize,
    counter: TravelCounter,
    /// The counter at the start of the hold.
    at_hold: Travel,
    /// Farthest past the target this hold, % (the move's direction).
    peak: f64,
    /// The mean of the last rows, %.
    position: f64,
    /// Rows since the last counted move.
    still: u64,
}

impl Track {
    fn push(&mut self, x: f64, (target, dir): (f64, f64), deadband: f64) {
        self.last[self.filled % SMOOTH] = x;
        self.filled += 1;
        if self.filled < SMOOTH {
            return;
        }
        self.position = self.last.iter().sum::<f64>() / SMOOTH as f64;
        self.still = if self.counter.push(self.position, deadband) {
            0
        } else {
            self.still.saturating_add(1)
        };
        self.peak = self.peak.max(dir * (self.position - target));
    }

    /// The hold's figures, and whether the position ended it at rest; starts the next hold.
    fn end_hold(&mut self, target: f64, deadband: f64, rest_rows: u64) -> (Wear, bool) {
        let now = self.counter.total();
        let wear = Wear {
            reversals: now.reversals - self.at_hold.reversals,
            travel_pct: now.travel_pct - self.at_hold.travel_pct,
            overshoot_pct: (self.peak - deadband / 2.0).max(0.0),
            miss_pct: (self.position - target).abs(),
        };
        self.at_hold = now;
        self.peak = 0.0;
        (wear, self.filled >= SMOOTH && self.still >= rest_rows)
    }
}

/// The running window.
#[derive(Debug, Clone)]
pub(super) struct Guard {
    window_samples: u64,
    margin: f64,
    rest_rows: u64,
    noise_weight: f64,
    samples: u64,
    rows: usize,
    sq: [f64; 3],
    /// The valve's and the model's figures.
    tracks: [Track; 2],
    /// The controller's O_P the hold began at, the direction of its move, the target now and
    /// whether compensation added something in it.
    hold_op: Option<f64>,
    hold_dir: f64,
    target: f64,
    acted: bool,
    holds: usize,
    judged: [Wear; 2],
    deadband: f64,
    /// Mean |second difference| of V_P over consecutive rows, and the last two rows.
    d2: f64,
    d2_seen: u64,
    prev: [Option<f64>; 2],
}

impl Guard {
    /// A guard judging every `window_s` (at a sample period of `dt` s) with the relative
    /// `margin`.
    pub(super) fn new(window_s: f64, dt: f64, margin: f64) -> Self {
        Guard {
            window_samples: (window_s / dt).round().max(1.0) as u64,
            margin,
            rest_rows: (REST_S / dt).round() as u64,
            noise_weight: dt / NOISE_TAU_S,
            samples: 0,
            rows: 0,
            sq: [0.0; 3],
            tracks: [Track::default(), Track::default()],
            hold_op: None,
            hold_dir: 0.0,
            target: 0.0,
            acted: false,
            holds: 0,
            judged: [Wear::default(); 2],
            deadband: DEADBAND_MIN_PCT,
            d2: 0.0,
            d2_seen: 0,
            prev: [None; 2],
        }
    }

    /// Adds a sample; returns the verdict when a window ends.
    pub(super) fn add(&mut self, s: Sample) -> Option<Window> {
        self.samples += 1;
        let hold_op = *self.hold_op.get_or_insert(s.op);
        if (s.op - hold_op).abs() > s.gate {
            self.end_hold();
            self.hold_dir = (s.op - hold_op).signum();
            self.hold_op = Some(s.op);
        }
        self.acted |= s.compensated;
        self.target = s.target;
        if let Some(vp) = s.measured {
            self.rows += 1;
            self.sq[0] += (s.op - vp).powi(2);
            self.sq[1] += (s.op - s.model_with).powi(2);
            self.sq[2] += (s.op - s.model_without).powi(2);
            self.noise(vp);
            let at = (s.target, self.hold_dir);
            self.tracks[0].push(vp, at, self.deadband);
            self.tracks[1].push(s.model_with, at, self.deadband);
        } else {
            self.prev = [None; 2];
        }
        if self.samples < self.window_samples {
            return None;
        }
        // A hold still running is judged as it stands, and goes on in the next window.
        self.end_hold();
        let window = self.verdict();
        self.samples = 0;
        self.rows = 0;
        self.sq = [0.0; 3];
        self.holds = 0;
        self.judged = [Wear::default(); 2];
        self.deadband = DEADBAND_MIN_PCT.max(NOISE_DEADBANDS * self.d2 / D2_PER_SIGMA);
        window
    }

    /// Ends the hold: its figures count when compensation added something in it.
    fn end_hold(&mut self) {
        let (db, rest) = (self.deadband, self.rest_rows);
        let (valve, valve_rests) = self.tracks[0].end_hold(self.target, db, rest);
        let (model, model_rests) = self.tracks[1].end_hold(self.target, db, rest);
        if !std::mem::take(&mut self.acted) || self.hold_dir == 0.0 {
            return;
        }
        self.holds += 1;
        let rests = valve_rests && model_rests;
        for (sum, w) in self.judged.iter_mut().zip([valve, model]) {
            sum.reversals += w.reversals;
            sum.travel_pct += w.travel_pct;
            sum.overshoot_pct += w.overshoot_pct;
            if rests {
                sum.miss_pct += w.miss_pct;
            }
        }
    }

    /// The noise of V_P from the mean |second difference| of consecutive rows (a change of
    /// more than four times the mean, a move, counts as four).
    fn noise(&mut self, vp: f64) {
        if let [Some(a), Some(b)] = self.prev {
            self.d2_seen += 1;
            let clip = (4.0 * self.d2).max(DEADBAND_MIN_PCT);
            let weight = self.noise_weight.max(1.0 / self.d2_seen as f64);
            self.d2 += weight * ((vp - 2.0 * b + a).abs().min(clip) - self.d2);
        }
        self.prev = [self.prev[1], Some(vp)];
    }

    /// The window's verdict (None without a row).
    fn verdict(&self) -> Option<Window> {
        if self.rows == 0 {
            return None;
        }
        let rms = |sq: f64| (sq / self.rows as f64).sqrt();
        let [valve, model] = self.judged;
        let db = self.deadband;
        let checks = [
            (
                Figure::Overshoot,
                valve.overshoot_pct,
                model.overshoot_pct,
                db / 2.0,
            ),
            (
                Figure::Miss,
                valve.miss_pct,
                model.miss_pct,
                db / 2.0 * self.holds as f64,
            ),
            (
                Figure::Reversals,
                valve.reversals as f64,
                model.reversals as f64,
                REVERSAL_SLACK,
            ),
            (Figure::Travel, valve.travel_pct, model.travel_pct, 2.0 * db),
        ];
        let exceeded = checks
            .into_iter()
            .find(|&(_, v, m, slack)| self.holds > 0 && v > (1.0 + self.margin) * m + slack)
            .map(|c| c.0);
        Some(Window {
            with_pct: rms(self.sq[0]),
            model_with_pct: rms(self.sq[1]),
            without_pct: rms(self.sq[2]),
            rows: self.rows,
            holds: self.holds,
            deadband_pct: db,
            measured: valve,
            predicted: model,
            exceeded,
            worse: exceeded.is_some(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample of a controller at `op` whose valve reads `vp` where the model says `model`.
    fn sample(op: f64, model: f64, vp: Option<f64>) -> Sample {
        Sample {
            op,
            target: op,
            gate: 0.1,
            compensated: true,
            model_with: model,
            model_without: model,
            measured: vp,
        }
    }

    /// `n` samples at O_P `op`, the model at `model` and the valve at `vp`; the last verdict.
    fn hold(g: &mut Guard, n: usize, op: f64, model: f64, vp: Option<f64>) -> Option<Window> {
        (0..n).filter_map(|_| g.add(sample(op, model, vp))).last()
    }

    #[test]
    fn a_valve_resting_away_from_where_its_model_rests_is_a_miss() {
        // Windows of 2 s at 100 Hz: a move to 50 %, the model there, the valve at 48 %.
        let mut g = Guard::new(2.0, 0.01, 0.1);
        hold(&mut g, 50, 48.0, 48.0, Some(48.0));
        let w = hold(&mut g, 150, 50.0, 50.0, Some(48.0)).unwrap();
        assert_eq!((w.rows, w.holds), (200, 1));
        assert_eq!(w.exceeded, Some(Figure::Miss));
        assert!((w.measured.miss_pct - 2.0).abs() < 1e-9 && w.predicted.miss_pct == 0.0);
        assert!((w.with_pct - (0.75f64 * 4.0).sqrt()).abs() < 1e-9, "{w:?}");
        // Where both rest at the target, nothing exceeds.
        let mut g = Guard::new(2.0, 0.01, 0.1);
        hold(&mut g, 50, 48.0, 48.0, Some(48.0));
        let w = hold(&mut g, 150, 50.0, 50.0, Some(50.0)).unwrap();
        assert!(!w.worse && w.holds == 1, "{w:?}");
    }

    #[test]
    fn a_valve_carried_past_its_target_overshoots() {
        // A move up to 50 %: the model lands on it, the valve goes 0.6 % past and comes back.
        let mut g = Guard::new(2.0, 0.01, 0.1);
        hold(&mut g, 20, 49.0, 49.0, Some(49.0));
        hold(&mut g, 30, 50.0, 50.0, Some(50.6));
        let w = hold(&mut g, 150, 50.0, 50.0, Some(50.0)).unwrap();
        assert_eq!(w.exceeded, Some(Figure::Overshoot), "{w:?}");
        assert!((w.measured.overshoot_pct - 0.5).abs() < 1e-9, "{w:?}");
        assert_eq!(w.measured.reversals, 1);
    }

    #[test]
    fn holds_compensation_left_alone_and_rows_without_v_p_are_not_judged() {
        let mut g = Guard::new(1.0, 0.01, 0.1);
        let off = |op: f64, vp: f64| Sample {
            compensated: false,
            ..sample(op, op, Some(vp))
        };
        for k in 0..100 {
            // A valve far from its model, but compensation added nothing.
            let op = if k < 50 { 40.0 } else { 45.0 };
            if let Some(w) = g.add(off(op, 30.0)) {
                assert_eq!((w.holds, w.worse), (0, false), "{w:?}");
            }
        }
        // No V_P in a whole window: nothing to judge.
        let mut g = Guard::new(0.02, 0.01, 0.1);
        g.add(sample(50.0, 50.0, None));
        assert_eq!(g.add(sample(50.0, 50.0, None)), None);
    }

    #[test]
    fn the_deadband_rises_above_the_sensor_s_noise() {
        // 0.2 % of noise on a resting valve: counted through the minimum deadband it would be
        // reversals; the guard measures the noise and counts through five times it.
        let mut g = Guard::new(10.0, 0.01, 0.1);
        let mut x: u64 = 1;
        let mut noisy = || {
            // A small linear congruential generator: uniform noise of 0.2 % standard deviation.
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            0.2 * 3f64.sqrt() * (2.0 * (x >> 11) as f64 / (1u64 << 53) as f64 - 1.0)
        };
        let mut last = None;
        for k in 0..3000 {
            let op = if k < 10 { 49.0 } else { 50.0 };
            last = g.add(sample(op, op, Some(op + noisy()))).or(last);
        }
        let w = last.unwrap();
        assert!(w.deadband_pct > 0.5 && w.deadband_pct < 1.5, "{w:?}");
        assert!(!w.worse, "{w:?}");
    }
}
