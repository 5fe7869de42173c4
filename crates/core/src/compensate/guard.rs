//! The guard of compensation: does the valve, with compensation, do worse than its model says
//! it does with compensation?
//!
//! Like is compared with like. The measured V_P is set against the identified model driven by
//! the same set-points sent (compensation included), never against the model driven by the
//! controller's O_P, so a model's own error (a stroke speed it gets wrong, say) is not read as
//! compensation's. And the model's V_P is read as the valve's is ([`Channel`]): with the noise
//! the guard measures on the V_P read and rounded to the register's resolution it measures, so
//! every figure of the two carries the same noise and the same steps. What is judged is what
//! compensation can do wrong, per hold (from one move of the controller to the next), on the
//! mean of the last [`SMOOTH`] rows of each:
//!
//! - **overshoot**: how far past the target it goes after the move (a kick or a deadband step
//!   that is too large carries the stem past it, a kick makes a sticking stem slip past it);
//! - **miss**: how far from the target it rests at the end of the hold (where both it and the
//!   model have been still for [`REST_S`]): a step on the wrong side, or too large.
//!
//! Reversals and travel (wear), counted through a deadband above the noise
//! ([`DEADBAND_MIN_PCT`], or [`NOISE_DEADBANDS`] times the noise measured), are reported, not
//! judged: a count through a deadband differs by whole deadbands between two reads of the same
//! stem, so one hold's count is no evidence, and what compensation adds to them by carrying the
//! stem past its target is its overshoot.
//!
//! A hold is judged only when compensation added something in it, so a controller's noise
//! that compensation leaves alone is not judged. In a judged hold a figure **exceeds** when the
//! valve's is beyond the model's by more than its allowance: the relative margin of the
//! model's plus half the deadband. Noise alone, and the small faults of a model close to the
//! valve, make a hold exceed now and then, in at most a share [`CHANCE_PER_HOLD`] of the holds;
//! so one hold decides nothing. At the end of each `window_s`, for each figure, the holds of that
//! window and the [`WINDOWS_POOLED`] - 1 before it are the evidence: when the holds that
//! exceed are more than chance gives (binomial, below [`SIGNIFICANCE`]) and fall in at least
//! two of those windows, the verdict is that compensation does worse than its model says,
//! naming the figure, in how many holds and by how much. The verdict is the caller's to act
//! on. The RMS of O_P - V_P is reported too (measured, the model's with compensation, the
//! model's without), not judged: on large steps it is the model's speed.
//!
//! Allocation-free: sums over the windows and a few samples per position. Not here: stepping
//! the models ([`super::Compensator`]).

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::metrics::{Travel, TravelCounter};

/// Rows in the mean the figures are counted on (a sensor's noise halves).
pub const SMOOTH: usize = 4;
/// The smallest deadband of the counts, %: twice a per-mille register's resolution, ten
/// standard deviations of a healthy sensor's noise on the mean of [`SMOOTH`] rows.
pub const DEADBAND_MIN_PCT: f64 = 0.2;
/// The deadband is at least this many times the noise measured on V_P.
pub const NOISE_DEADBANDS: f64 = 5.0;
/// How long a position must stay within the deadband to be at rest, s.
pub const REST_S: f64 = 0.5;
/// Windows whose holds are the evidence of a verdict.
pub const WINDOWS_POOLED: usize = 3;
/// The share of judged holds in which a figure may exceed its allowance by chance.
pub const CHANCE_PER_HOLD: f64 = 0.02;
/// Holds that exceed are beyond chance when chance gives as many with at most this
/// probability.
pub const SIGNIFICANCE: f64 = 0.01;
/// Time constant of the noise estimate, s.
const NOISE_TAU_S: f64 = 10.0;
/// Mean |second difference| of white noise, in its standard deviations: sqrt(6) sqrt(2/pi).
const D2_PER_SIGMA: f64 = 1.954;
/// Differences of V_P smaller than this are the same reading, %.
const SAME_READING_PCT: f64 = 1e-6;
/// A lattice finer than this is a continuous sensor's, %.
const MIN_RESOLUTION_PCT: f64 = 1e-3;
/// Seed of the noise the model's V_P is read with (a run is repeatable).
const CHANNEL_SEED: u64 = 0x5eed;

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

/// What a position did in the judged holds of a window.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wear {
    /// Direction changes counted through the deadband.
    pub reversals: usize,
    /// Distance counted through the deadband, %.
    pub travel_pct: f64,
    /// Sum over the holds of the farthest past the target, %.
    pub overshoot_pct: f64,
    /// Sum over the holds that ended at rest of the distance from the target, %.
    pub miss_pct: f64,
}

/// A figure the guard judges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Figure {
    Overshoot,
    Miss,
}

impl Figure {
    /// Every figure, in the order they are judged.
    pub const ALL: [Figure; 2] = [Figure::Overshoot, Figure::Miss];

    /// The figure in words.
    pub fn name(self) -> &'static str {
        match self {
            Figure::Overshoot => "overshoot past the target",
            Figure::Miss => "distance from the target at rest",
        }
    }

    fn of(self, w: &Wear) -> f64 {
        match self {
            Figure::Overshoot => w.overshoot_pct,
            Figure::Miss => w.miss_pct,
        }
    }
}

/// How a figure stands over the pooled windows.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Evidence {
    /// Judged holds over the pooled windows.
    pub holds: usize,
    /// Holds in which the valve exceeded the model by more than the allowance.
    pub exceeding: usize,
    /// Pooled windows with judged holds.
    pub windows: usize,
    /// Mean excess of the valve over the model in the holds that exceeded, %.
    pub by_pct: f64,
    /// The probability that chance makes as many holds exceed.
    pub chance: f64,
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
    /// Holds judged in this window (compensation added something in them).
    pub holds: usize,
    /// The deadband the figures were counted through, %.
    pub deadband_pct: f64,
    /// The noise (standard deviation) and the resolution of the V_P read, as measured, %.
    pub noise_pct: f64,
    pub resolution_pct: f64,
    /// The valve's figures over this window's judged holds.
    pub measured: Wear,
    /// The model's over the same holds and rows, read as the valve's are.
    pub predicted: Wear,
    /// Each figure's evidence over the pooled windows, in the order of [`Figure::ALL`].
    pub evidence: [Evidence; 2],
    /// The first figure whose evidence is beyond chance.
    pub exceeded: Option<Figure>,
    /// Compensation does worse than its model says (a figure exceeded).
    pub worse: bool,
}

impl Window {
    /// The evidence of `figure`.
    pub fn evidence_of(&self, figure: Figure) -> Evidence {
        self.evidence[figure as usize]
    }
}

/// The model's V_P read as the valve's is: the noise measured on the V_P read added, and
/// rounded to the lattice of the readings.
#[derive(Debug, Clone)]
struct Channel {
    rng: ChaCha8Rng,
    /// Standard deviation of the sensor's noise before rounding, %.
    noise: f64,
    /// The register's resolution, % (0: continuous).
    resolution: f64,
    /// A point of the lattice: the first reading, %.
    origin: f64,
}

impl Channel {
    fn read(&mut self, x: f64) -> f64 {
        let n: f64 = StandardNormal.sample(&mut self.rng);
        let y = x + self.noise * n;
        if self.resolution > 0.0 {
            self.origin + ((y - self.origin) / self.resolution).round() * self.resolution
        } else {
            y
        }
    }
}

/// The figures of one position (the valve's, or the model's) through a hold.
#[derive(Debug, Clone, Default)]
struct Track {
    last: [f64; SMOOTH],
    filled: usize,
    counter: TravelCounter,
    /// The counter at the start of the hold.
    at_hold: Travel,
    /// Farthest past the target this hold, % (the move's direction), and that direction.
    peak: f64,
    dir: f64,
    /// The mean of the last rows, %.
    position: f64,
    /// Rows since the last counted move.
    still: u64,
}

impl Track {
    fn push(&mut self, x: f64, (target, dir): (f64, f64), deadband: f64) {
        self.dir = dir;
        self.last[self.filled % SMOOTH] = x;
        self.filled += 1;
        if self.filled >= 2 * SMOOTH {
            self.filled -= SMOOTH;
        }
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
    fn end_hold(&mut self, target: f64, rest_rows: u64) -> (Wear, bool) {
        let now = self.counter.total();
        // Past the target beyond where it ends: a valve that rests past it misses, and does
        // not overshoot as well.
        let rests_past = (self.dir * (self.position - target)).max(0.0);
        let wear = Wear {
            reversals: now.reversals - self.at_hold.reversals,
            travel_pct: now.travel_pct - self.at_hold.travel_pct,
            overshoot_pct: (self.peak - rests_past).max(0.0),
            miss_pct: (self.position - target).abs(),
        };
        self.at_hold = now;
        self.peak = 0.0;
        (wear, self.filled >= SMOOTH && self.still >= rest_rows)
    }
}

/// The exceeding holds of one window, per figure.
#[derive(Debug, Clone, Copy, Default)]
struct Tally {
    holds: usize,
    exceeding: [usize; 2],
    /// Sum of the excess over the model in the holds that exceeded, %.
    by: [f64; 2],
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
    /// The valve's figures and the model's.
    tracks: [Track; 2],
    channel: Channel,
    /// The controller's O_P the hold began at, the direction of its move, the target now and
    /// whether compensation added something in it.
    hold_op: Option<f64>,
    hold_dir: f64,
    target: f64,
    acted: bool,
    judged: [Wear; 2],
    /// This window's tally, and the windows before it (the oldest first is overwritten).
    tallies: [Tally; WINDOWS_POOLED],
    windows: usize,
    deadband: f64,
    /// Mean |second difference| of V_P over consecutive rows, and the last two rows.
    d2: f64,
    d2_seen: u64,
    prev: [Option<f64>; 2],
    /// The step every step between two readings is a multiple of, % (infinite before the
    /// first, 0 for a continuous sensor).
    step: f64,
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
            channel: Channel {
                rng: ChaCha8Rng::seed_from_u64(CHANNEL_SEED),
                noise: 0.0,
                resolution: 0.0,
                origin: 0.0,
            },
            hold_op: None,
            hold_dir: 0.0,
            target: 0.0,
            acted: false,
            judged: [Wear::default(); 2],
            tallies: [Tally::default(); WINDOWS_POOLED],
            windows: 0,
            deadband: DEADBAND_MIN_PCT,
            d2: 0.0,
            d2_seen: 0,
            prev: [None; 2],
            step: f64::INFINITY,
        }
    }

    /// The standard deviation of the V_P read's noise, as measured so far, %.
    pub(super) fn noise_pct(&self) -> f64 {
        self.d2 / D2_PER_SIGMA
    }

    /// The resolution of the V_P read, as measured so far, % (0: none seen, or continuous).
    fn resolution_pct(&self) -> f64 {
        if self.step.is_finite() {
            self.step
        } else {
            0.0
        }
    }

    /// Adds a sample; returns the verdict when a window ends.
    pub(super) fn add(&mut self, s: Sample) -> Option<Window> {
        self.samples += 1;
        let hold_op = *self.hold_op.get_or_insert(s.op);
        let mut beyond_chance = false;
        if (s.op - hold_op).abs() > s.gate {
            beyond_chance = self.end_hold();
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
            self.measure(vp);
            let read = self.channel.read(s.model_with);
            let at = (s.target, self.hold_dir);
            self.tracks[0].push(vp, at, self.deadband);
            self.tracks[1].push(read, at, self.deadband);
        } else {
            self.prev = [None; 2];
        }
        // A hold that makes the evidence beyond chance ends the window at once.
        if self.samples < self.window_samples && !beyond_chance {
            return None;
        }
        if !beyond_chance {
            // A hold still running is judged as it stands, and goes on in the next window.
            self.end_hold();
        }
        let window = self.verdict();
        self.samples = 0;
        self.rows = 0;
        self.sq = [0.0; 3];
        self.judged = [Wear::default(); 2];
        self.windows += 1;
        self.tallies[self.windows % WINDOWS_POOLED] = Tally::default();
        window
    }

    /// Ends the hold: when compensation added something in it, its figures are added to the
    /// window's and each figure is tallied. True when the evidence is now beyond chance.
    fn end_hold(&mut self) -> bool {
        let rest = self.rest_rows;
        let (valve, valve_rests) = self.tracks[0].end_hold(self.target, rest);
        let (model, model_rests) = self.tracks[1].end_hold(self.target, rest);
        if !std::mem::take(&mut self.acted) || self.hold_dir == 0.0 {
            return false;
        }
        let rests = valve_rests && model_rests;
        for (sum, w) in self.judged.iter_mut().zip([valve, model]) {
            sum.reversals += w.reversals;
            sum.travel_pct += w.travel_pct;
            sum.overshoot_pct += w.overshoot_pct;
            if rests {
                sum.miss_pct += w.miss_pct;
            }
        }
        let (margin, deadband) = (self.margin, self.deadband);
        let tally = &mut self.tallies[self.windows % WINDOWS_POOLED];
        tally.holds += 1;
        for f in Figure::ALL {
            if f == Figure::Miss && !rests {
                continue;
            }
            let (v, m) = (f.of(&valve), f.of(&model));
            let slack = match f {
                Figure::Overshoot => deadband / 2.0,
                Figure::Miss => deadband,
            };
            if v - m > margin * m + slack {
                tally.exceeding[f as usize] += 1;
                tally.by[f as usize] += v - m;
            }
        }
        exceeded(&self.evidence()).is_some()
    }

    /// Measures the V_P read: its noise from the mean |second difference| of consecutive rows
    /// (a change of more than four times the mean, a move, counts as four), and its resolution,
    /// the largest step every step between two readings is a multiple of (a register's scale;
    /// finer than [`MIN_RESOLUTION_PCT`], a continuous sensor). The deadband of the counts and
    /// the channel the model is read through follow.
    fn measure(&mut self, vp: f64) {
        if self.rows == 1 {
            self.channel.origin = vp;
        }
        if let [_, Some(b)] = self.prev {
            let step = (vp - b).abs();
            if step > SAME_READING_PCT && self.step > 0.0 {
                self.step = common_step(self.step, step);
                if self.step < MIN_RESOLUTION_PCT {
                    self.step = 0.0;
                }
            }
        }
        if let [Some(a), Some(b)] = self.prev {
            self.d2_seen += 1;
            let clip = (4.0 * self.d2).max(DEADBAND_MIN_PCT);
            let weight = self.noise_weight.max(1.0 / self.d2_seen as f64);
            self.d2 += weight * ((vp - 2.0 * b + a).abs().min(clip) - self.d2);
        }
        self.prev = [self.prev[1], Some(vp)];
        let noise = self.noise_pct();
        self.deadband = DEADBAND_MIN_PCT.max(NOISE_DEADBANDS * noise);
        // The sensor's own noise: the read's, less what rounding to the resolution adds.
        let q = self.resolution_pct();
        self.channel.noise = (noise * noise - q * q / 12.0).max(0.0).sqrt();
        self.channel.resolution = q;
    }

    /// Each figure's evidence over the pooled windows.
    fn evidence(&self) -> [Evidence; 2] {
        let mut out = [Evidence::default(); 2];
        for (i, e) in out.iter_mut().enumerate() {
            let mut by = 0.0;
            // Slots of windows not yet judged are empty.
            for t in &self.tallies {
                e.holds += t.holds;
                e.exceeding += t.exceeding[i];
                e.windows += usize::from(t.holds > 0);
                by += t.by[i];
            }
            e.by_pct = by / e.exceeding.max(1) as f64;
            e.chance = chance_of(e.exceeding, e.holds);
        }
        out
    }

    /// The window's verdict (None without a row).
    fn verdict(&self) -> Option<Window> {
        if self.rows == 0 {
            return None;
        }
        let rms = |sq: f64| (sq / self.rows as f64).sqrt();
        let evidence = self.evidence();
        let exceeded = exceeded(&evidence);
        Some(Window {
            with_pct: rms(self.sq[0]),
            model_with_pct: rms(self.sq[1]),
            without_pct: rms(self.sq[2]),
            rows: self.rows,
            holds: self.tallies[self.windows % WINDOWS_POOLED].holds,
            deadband_pct: self.deadband,
            noise_pct: self.noise_pct(),
            resolution_pct: self.resolution_pct(),
            measured: self.judged[0],
            predicted: self.judged[1],
            evidence,
            exceeded,
            worse: exceeded.is_some(),
        })
    }
}

/// The first figure whose `evidence` is beyond chance: holds that exceed more than chance
/// makes exceed (below [`SIGNIFICANCE`]), from holds of at least two windows.
fn exceeded(evidence: &[Evidence; 2]) -> Option<Figure> {
    Figure::ALL.into_iter().find(|&f| {
        let e = evidence[f as usize];
        e.windows >= 2 && e.chance < SIGNIFICANCE
    })
}

/// The largest step both `a` and `b` are whole multiples of (Euclid's algorithm, remainders
/// below [`SAME_READING_PCT`] taken as none), %; `b` when `a` is infinite.
fn common_step(a: f64, b: f64) -> f64 {
    if !a.is_finite() {
        return b;
    }
    let (mut a, mut b) = (a.max(b), a.min(b));
    while b > SAME_READING_PCT {
        let r = a % b;
        // A remainder a hair short of `b` is none.
        let r = if b - r <= SAME_READING_PCT { 0.0 } else { r };
        (a, b) = (b, r);
    }
    a
}

/// The probability that at least `k` of `n` holds exceed by chance, each with probability
/// [`CHANCE_PER_HOLD`] (the binomial tail).
fn chance_of(k: usize, n: usize) -> f64 {
    if k == 0 {
        return 1.0;
    }
    let p = CHANCE_PER_HOLD;
    // P(X < k) summed term by term: C(n, i) p^i (1 - p)^(n - i).
    let mut term = (1.0 - p).powi(n as i32);
    let mut below = 0.0;
    for i in 0..k.min(n + 1) {
        below += term;
        term *= (n - i) as f64 / (i + 1) as f64 * p / (1.0 - p);
    }
    (1.0 - below).max(0.0)
}

#[cfg(test)]
#[path = "guard_tests.rs"]
mod tests;
