//! Compensation: the identified valve's imperfections answered in the set-point it is sent.
//!
//! A [`Compensator`] sits between the process controller and the valve. Each sample it takes
//! the controller's O_P and returns the set-point to send, built from a model file written by
//! `identify --out` or `diagnose --out`, with three parts that can each be switched off:
//!
//! - **backlash**: on a reversal the positioner must first move its chamber pressure across the
//!   stem's friction band (pin-cart II's cart) before the stem moves; the set-point gets a short
//!   kick in the new direction so that the positioner crosses it faster, planned on the model so
//!   that the pressure lands on the band's far side without carrying the stem past its target
//!   ([`kick`]). A kick can only make the positioner push harder up to its speed limit: a
//!   reversal that already runs at full flow cannot be shortened by any set-point.
//! - **deadband**: the inverse of the model's deadband (the valve stops short by half of it):
//!   the set-point goes half the band beyond the target, on the side the valve comes from
//!   ([`step`]).
//! - **calibration**: the inverse of the fitted gain and offset (`V_P = a O_P + b` at rest).
//!
//! The kick acts only while the model says the stem cannot move yet (the pressure inside the
//! band). The deadband step's side is the direction of the controller's move (closing moves get
//! it below the target, opening ones above), never the model's state, which a kick pulls past
//! the target; it is sent with a move that starts within the band, and after one from outside
//! it waits until the V_P read has come to rest in the band, so a stem that arrives fast is
//! not carried past the target; it lasts until the controller's next move. Both begin only on
//! moves of the controller larger than its own noise (three times its mean sample-to-sample
//! change, at least `min_move_pct`, two samples in a row): a noisy controller output is not a
//! sequence of reversals worth kicking (that would make the valve follow the noise).
//!
//! The model the compensator steps is the identified one in its friction-band form (the form
//! `diagnose` finds for a stem with Coulomb friction, `[effects] friction_band_pct`): the band
//! is crossed at the positioner's pushing speed, so a kick shortens it. A pin-cart II crossing
//! time `a_p V² + b_p V + c_p` (identify's form, eq. 7) does not depend on the set-point at
//! all; it is read as the band a 1 % reversal crosses in that time, `B = P_k · 1 % · T(V)`,
//! fitted as a band growing with opening (`open_slowdown`), so the kick follows the crossing
//! time at the current opening. On a valve that really crosses in a fixed time, kicks change
//! nothing. A stroke speed the model's log did not determine (`stroke_speed_undetermined`) is
//! not used: the compensator's models have no speed limit but the positioner's gain. Stick-slip
//! (`stickband_pct`, `breakaway_pct`) is not compensated, nor a positioner tolerance band fitted
//! with a breakaway (where the hunting ends).
//!
//! Guard rails: the set-point stays within the source's `op_min_pct..op_max_pct`; what
//! compensation adds to the controller's O_P changes by at most `max_rate_pct_per_s`; and the
//! [`guard`] compares, hold by hold, how far the valve goes past its target and how far from
//! it it rests with what the identified model, driven by the same set-points and read as the
//! valve is, says it does: when the holds beyond the model's by more than `guard_margin` and
//! the noise are more than chance makes, over the last windows of `guard_window_s`,
//! compensation switches itself off for good (the caller warns).
//!
//! Stepping allocates nothing. Not here: the daemon's log and metrics, the config's file
//! checks (`vb_daemon::config`), the bench.

pub mod guard;
mod kick;
mod step;

use std::path::PathBuf;

use serde::Deserialize;

use crate::model::composed;
use crate::model::{Effects, ModelError, ModelKind, ModelSpec, Valve};
use guard::Guard;
pub use guard::Window;
use kick::Plan;
use step::DeadbandStep;

/// `[valve.compensation]`: the model and the parts in use.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CompensationConfig {
    /// The model file (`identify --out`'s `pincart2.toml`, `diagnose --out`'s `model.toml`).
    pub model_file: Option<PathBuf>,
    /// Kick the set-point on reversals across the friction band.
    pub backlash: bool,
    /// Step half the deadband beyond the target.
    pub deadband: bool,
    /// Invert the fitted gain and offset.
    pub calibration: bool,
    /// The largest kick, % of travel.
    pub kick_max_pct: f64,
    /// The share of the modelled band a kick crosses (0-1); the positioner crosses the rest as
    /// without compensation, so an overestimated band carries the stem less far.
    pub kick_share: f64,
    /// How fast what compensation adds may change, %/s.
    pub max_rate_pct_per_s: f64,
    /// The smallest move of the controller's O_P that is compensated, % (the controller's own
    /// noise raises it).
    pub min_move_pct: f64,
    /// The guard's window, s: a verdict weighs the judged holds of the last
    /// [`guard::WINDOWS_POOLED`] windows.
    pub guard_window_s: f64,
    /// How much more (relative) the valve may overshoot and miss its target in a hold with
    /// compensation than its model says it does with it, on top of the allowance for noise.
    pub guard_margin: f64,
}

impl Default for CompensationConfig {
    fn default() -> Self {
        CompensationConfig {
            model_file: None,
            backlash: true,
            deadband: true,
            calibration: true,
            kick_max_pct: 10.0,
            kick_share: 0.8,
            max_rate_pct_per_s: 500.0,
            min_move_pct: 0.1,
            guard_window_s: 20.0,
            guard_margin: 0.1,
        }
    }
}

impl CompensationConfig {
    /// The first setting out of range: its key and what is allowed.
    pub fn violation(&self) -> Option<(&'static str, String)> {
        let checks: [(&'static str, f64, f64, f64, &str); 6] = [
            (
                "kick_max_pct",
                self.kick_max_pct,
                0.0,
                50.0,
                "the largest kick in %",
            ),
            (
                "kick_share",
                self.kick_share,
                0.0,
                1.0,
                "a share of the band",
            ),
            (
                "max_rate_pct_per_s",
                self.max_rate_pct_per_s,
                1.0,
                1e5,
                "a rate in %/s",
            ),
            ("min_move_pct", self.min_move_pct, 0.0, 10.0, "a move in %"),
            (
                "guard_window_s",
                self.guard_window_s,
                1.0,
                86400.0,
                "a window in s",
            ),
            (
                "guard_margin",
                self.guard_margin,
                0.0,
                10.0,
                "a relative margin (0.1 = 10 %)",
            ),
        ];
        checks
            .into_iter()
            .find(|(_, v, lo, hi, _)| !(v.is_finite() && (*lo..=*hi).contains(v)))
            .map(|(key, v, lo, hi, what)| {
                (key, format!("{} is out of range: {what}, {lo} to {hi}", crate::human::num(v)))
            })
            .or_else(|| {
                self.model_file.is_none().then(|| {
                    ("model_file", "is missing: name the model file `identify --out` or `diagnose --out` wrote (e.g. model_file = \"diag/model.toml\")".to_string())
                })
            })
    }
}

/// A compensator that cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum CompensateError {
    /// The model cannot be stepped.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The model is the physical simulator, not an identified model.
    #[error("model = \"physical\" is a simulator, not an identified model: compensate with the model `identify --out` or `diagnose --out` wrote from the valve's log")]
    Physical,
}

/// What the compensator took from the model, in the valve's units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identified {
    /// The friction band a reversal crosses, % (0: none).
    pub band_pct: f64,
    /// r: the band is crossed `1 + r V / 100` times slower at opening V (a chamber that grows).
    pub open_slowdown: f64,
    /// The positioner's gain, 1/s.
    pub gain_per_s: f64,
    /// The deadband, %.
    pub deadband_pct: f64,
    /// The deadband is the positioner's (no action while |O_P - V_P| is within half of it),
    /// not a band on the input.
    pub deadband_in_positioner: bool,
    /// Calibration: the valve settles at `gain * O_P + offset`.
    pub calibration_gain: f64,
    /// See `calibration_gain`, %.
    pub calibration_offset_pct: f64,
    /// The model's log determined its stroke speed; if not, the compensator's models have no
    /// speed limit but the positioner's gain.
    pub stroke_speed_known: bool,
}

/// The compensator of one valve: its settings, its models and their state.
#[derive(Debug, Clone)]
pub struct Compensator {
    parts: Parts,
    identified: Identified,
    dt: f64,
    op_min: f64,
    op_max: f64,
    /// The model in friction-band form, without dead time, stepped with the set-points sent:
    /// the state each new set-point meets when it reaches the valve.
    inverse: Valve,
    /// The model as identified, stepped with the set-points sent: the valve with compensation
    /// as the model sees it, for the guard.
    with: Valve,
    /// The model as identified, stepped with the controller's O_P: the valve without
    /// compensation, for the guard's report.
    without: Valve,
    guard: Guard,
    active: bool,
    started: bool,
    last_t: f64,
    last_op: f64,
    last_sent: f64,
    /// What compensation adds now (set-point minus controller's O_P), %.
    excursion: f64,
    /// Mean |change of the controller's O_P| per sample, %, over `seen` samples.
    noise: f64,
    seen: u64,
    /// Samples in a row the controller has asked for a move beyond the gate, and which way.
    asked_run: u32,
    asked_dir: f64,
    /// The deadband step: its side, when it begins and ends.
    step: DeadbandStep,
    /// The gate of the last sample, %.
    gate: f64,
    /// A kick or a deadband step shaped the last set-point (not the calibration alone).
    shaping: bool,
}

/// The settings a compensator keeps.
#[derive(Debug, Clone, Copy)]
struct Parts {
    backlash: bool,
    deadband: bool,
    calibration: bool,
    kick_max: f64,
    share: f64,
    rate: f64,
    min_move: f64,
}

/// Most missed samples stepped through at once (10 s at 100 Hz); a longer gap restarts.
const MAX_GAP_SAMPLES: u64 = 1000;
/// Time constant of the controller's noise estimate, s.
const NOISE_TAU_S: f64 = 10.0;
/// A move counts as the controller's when larger than this many mean sample-to-sample changes.
const NOISE_FACTOR: f64 = 3.0;
/// ... and asked for this many samples in a row (white noise seldom is, twice over).
const PERSIST: u32 = 2;
/// Set-points closer than this are the same, % (rounding of the arithmetic).
const SAME_PLACE_PCT: f64 = 1e-9;

impl Compensator {
    /// The compensator of `cfg` for `model`, at a sample period of `dt` s, sending set-points
    /// within `op_min..op_max` %.
    pub fn new(
        cfg: &CompensationConfig,
        model: &ModelSpec,
        dt: f64,
        (op_min, op_max): (f64, f64),
    ) -> Result<Self, CompensateError> {
        if model.model == ModelKind::Physical {
            return Err(CompensateError::Physical);
        }
        let model = &without_undetermined_speed(model);
        let (inverse_spec, identified) = inverse_model(model, dt, (op_min, op_max));
        Ok(Compensator {
            parts: Parts {
                backlash: cfg.backlash && identified.band_pct > 0.0,
                deadband: cfg.deadband && steps_for(identified.deadband_pct, cfg.min_move_pct),
                calibration: cfg.calibration
                    && (identified.calibration_gain != 1.0
                        || identified.calibration_offset_pct != 0.0),
                kick_max: cfg.kick_max_pct,
                share: cfg.kick_share,
                rate: cfg.max_rate_pct_per_s * dt,
                min_move: cfg.min_move_pct,
            },
            identified,
            dt,
            op_min,
            op_max,
            inverse: Valve::new(&inverse_spec, dt)?,
            with: Valve::new(model, dt)?,
            without: Valve::new(model, dt)?,
            guard: Guard::new(cfg.guard_window_s, dt, cfg.guard_margin),
            active: true,
            started: false,
            last_t: 0.0,
            last_op: 0.0,
            last_sent: 0.0,
            excursion: 0.0,
            noise: 0.0,
            seen: 0,
            asked_run: 0,
            asked_dir: 0.0,
            step: DeadbandStep::new(identified.deadband_pct),
            gate: 0.0,
            shaping: false,
        })
    }

    /// What the compensator took from the model.
    pub fn identified(&self) -> Identified {
        self.identified
    }

    /// Which parts act (a part the model gives nothing to do is off), in words.
    pub fn describe(&self) -> String {
        let id = &self.identified;
        let mut parts = Vec::new();
        if self.parts.backlash {
            parts.push(format!(
                "backlash (friction band {:.2} %, positioner gain {:.1} /s{})",
                id.band_pct,
                id.gain_per_s,
                if id.open_slowdown > 0.0 {
                    format!(", {:.2} times slower fully open", 1.0 + id.open_slowdown)
                } else {
                    String::new()
                }
            ));
        }
        if self.parts.deadband {
            parts.push(format!("deadband ({:.2} %)", id.deadband_pct));
        }
        if self.parts.calibration {
            parts.push(format!(
                "calibration (V_P = {:.4} O_P {:+.3} %)",
                id.calibration_gain, id.calibration_offset_pct
            ));
        }
        let mut what = if parts.is_empty() {
            "nothing (the model has no band, deadband or calibration the enabled parts answer)"
                .to_string()
        } else {
            parts.join(", ")
        };
        if id.deadband_pct > 0.0 && !steps_for(id.deadband_pct, self.parts.min_move) {
            what += &format!(
                "; its deadband of {:.3} % is left alone (half of it is less than the smallest move compensated, {:.2} %)",
                id.deadband_pct, self.parts.min_move
            );
        }
        if id.stroke_speed_known {
            what
        } else {
            format!("{what}; the model's stroke speed is not used (its log did not determine it)")
        }
    }

    /// True until the guard has switched compensation off.
    pub fn active(&self) -> bool {
        self.active
    }

    /// The set-point to send for the controller's O_P `op` (%) at loop time `t_s`, within the
    /// set-point range. Times must not decrease; missed samples between calls are stepped
    /// through with the set-point held, as a valve holds it.
    pub fn setpoint(&mut self, op: f64, t_s: f64) -> f64 {
        self.catch_up(op, t_s);
        self.shaping = false;
        let wanted = if self.active { self.shape(op) } else { op };
        let excursion = (wanted - op).clamp(
            self.excursion - self.parts.rate,
            self.excursion + self.parts.rate,
        );
        let sent = (op + excursion).clamp(self.op_min, self.op_max);
        self.excursion = sent - op;
        self.inverse.step(sent);
        (self.last_t, self.last_op, self.last_sent) = (t_s, op, sent);
        sent
    }

    /// The V_P read for the last set-point (None when none was read); returns the guard's
    /// verdict when a window ends. A window judged worse switches compensation off for good.
    pub fn observe(&mut self, vp_pct: Option<f64>) -> Option<Window> {
        self.step.observe(vp_pct, self.guard.noise_pct());
        let window = self.guard.add(guard::Sample {
            op: self.last_op,
            target: self.base(self.last_op),
            gate: self.gate,
            compensated: self.shaping,
            model_with: self.with.step(self.last_sent),
            model_without: self.without.step(self.last_op),
            measured: vp_pct,
        })?;
        if window.worse {
            self.active = false;
        }
        Some(window)
    }

    /// Starts the models at rest at the first O_P, or steps them through missed samples.
    fn catch_up(&mut self, op: f64, t_s: f64) {
        if self.started {
            let missed = ((t_s - self.last_t) / self.dt).round() - 1.0;
            if missed < MAX_GAP_SAMPLES as f64 {
                for _ in 0..missed.max(0.0) as u64 {
                    self.inverse.step(self.last_sent);
                    self.with.step(self.last_sent);
                    self.without.step(self.last_op);
                }
                return;
            }
        }
        self.started = true;
        self.inverse.reset(op, self.calibrated(op));
        self.with.reset(op, self.calibrated(op));
        self.without.reset(op, self.calibrated(op));
        (self.last_op, self.last_sent, self.excursion) = (op, op, 0.0);
        self.step.reset(op);
    }

    /// Where the valve settles for the O_P `op` by the model's calibration, %.
    fn calibrated(&self, op: f64) -> f64 {
        self.identified.calibration_gain * op + self.identified.calibration_offset_pct
    }

    /// The input the valve's core should get for the controller's O_P `op`, where it comes to
    /// rest: `op` itself when the calibration is inverted, else what the valve makes of `op`.
    fn base(&self, op: f64) -> f64 {
        if self.parts.calibration {
            op
        } else {
            self.calibrated(op)
        }
    }

    /// The set-point the enabled parts want for the controller's O_P `op`.
    fn shape(&mut self, op: f64) -> f64 {
        let id = self.identified;
        let base = self.base(op);
        // Kick and deadband step only while the controller asks for a move.
        let cart = (self.inverse.pin_reach(1.0)).map_or(base, |r| r.cart_pct);
        let moving = self.moving(op, base - cart);
        // The step keeps the direction of the controller's moves whether or not it is sent.
        let step = self.step.offset(op, moving, (base, cart), self.gate);
        let step = if self.parts.deadband { step } else { 0.0 };
        // A kick only in the direction of the controller's move: a model whose kick pulled its
        // input target past the wish would otherwise ask for a kick back.
        let kick = if moving && (base - cart).signum() == self.step.dir() {
            self.kick(base - cart)
        } else {
            0.0
        };
        let shaped = base + kick + step;
        self.shaping = (shaped - base).abs() > SAME_PLACE_PCT;
        (shaped - id.calibration_offset_pct) / id.calibration_gain
    }

    /// Whether the controller asks the valve to move: `asked` (the wanted core input minus
    /// the cart) beyond the gate, the same way, for [`PERSIST`] samples in a row. The gate is
    /// `min_move_pct`, or [`NOISE_FACTOR`] times the mean |change| of `op` a sample (a plain
    /// mean over the first [`NOISE_TAU_S`], then exponential; a change of more than four times
    /// the mean, a step, counts as four).
    fn moving(&mut self, op: f64, asked: f64) -> bool {
        self.seen += 1;
        let du = (op - self.last_op).abs();
        let clip = (4.0 * self.noise).max(self.parts.min_move);
        let weight = (self.dt / NOISE_TAU_S).max(1.0 / self.seen as f64);
        self.noise += weight * (du.min(clip) - self.noise);
        let gate = self.parts.min_move.max(NOISE_FACTOR * self.noise);
        self.gate = gate;
        self.asked_run = if asked.abs() <= gate {
            0
        } else if asked.signum() == self.asked_dir {
            self.asked_run.saturating_add(1)
        } else {
            self.asked_dir = asked.signum();
            1
        };
        self.asked_run >= PERSIST
    }

    /// The kick for an error `e` of the core input to the cart, signed, % at the core.
    fn kick(&self, e: f64) -> f64 {
        let dir = e.signum();
        let reach = match self.inverse.pin_reach(dir) {
            Some(r) if self.parts.backlash => r,
            _ => return 0.0,
        };
        let plan = Plan {
            error_pct: e.abs(),
            room_pct: reach.to_side_pct - (1.0 - self.parts.share) * reach.band_pct,
            speed: |x: f64| self.inverse.pin_speed(dir * x).unwrap_or(0.0),
            dt: self.dt,
            step_pct: self.parts.rate * self.identified.calibration_gain,
            max_pct: self.parts.kick_max * self.identified.calibration_gain,
        };
        dir * plan.kick()
    }
}

/// Whether a deadband of `deadband_pct` is stepped for, given the smallest move compensated
/// `min_move_pct`: a step smaller than that is below the resolution and noise the compensator
/// ignores everywhere else; a deadband that small (a trace a fit puts in a model) is as likely
/// not there, and stepping for it would hold a valve without one off its target by the step.
fn steps_for(deadband_pct: f64, min_move_pct: f64) -> bool {
    deadband_pct / 2.0 >= min_move_pct
}

/// `model` with a stroke speed its log did not determine taken out: no limit but the
/// positioner's gain (a kick planned on a speed the valve may not have would stop short of its
/// plan, not overshoot it, and the guard's figures do not hang on a speed).
fn without_undetermined_speed(model: &ModelSpec) -> ModelSpec {
    let mut spec = model.clone();
    if spec.stroke_speed_undetermined {
        if let Some(p) = spec.pincart2.as_mut() {
            p.dy_max_pct_per_s = composed::NO_LIMIT_PCT_PER_S;
        }
        spec.effects.closing_slew_pct_per_s = 0.0;
    }
    spec
}

/// The model in the form the compensator steps (friction band, no dead time, no stick-slip,
/// no sensor), and what it took from it.
fn inverse_model(
    model: &ModelSpec,
    dt: f64,
    (op_min, op_max): (f64, f64),
) -> (ModelSpec, Identified) {
    let mut spec = composed::compose(model, dt);
    let e = spec.effects;
    // A tolerance band fitted with stick-slip inside the loop is where its hunting ends: a
    // step across it starts the next slip, so it goes uncompensated with the stick-slip.
    let stepped_band = if e.breakaway_pct > 0.0 {
        0.0
    } else {
        e.positioner_deadband_pct
    };
    let mut identified = Identified {
        band_pct: 0.0,
        open_slowdown: e.open_slowdown,
        gain_per_s: 0.0,
        deadband_pct: e.deadband_pct.max(stepped_band),
        deadband_in_positioner: stepped_band > e.deadband_pct,
        calibration_gain: e.calibration_gain,
        calibration_offset_pct: e.calibration_offset_pct,
        stroke_speed_known: !model.stroke_speed_undetermined,
    };
    if let Some(mut p) = spec.pincart2 {
        (identified.band_pct, identified.open_slowdown) = if e.friction_band_pct > 0.0 {
            (e.friction_band_pct, e.open_slowdown)
        } else {
            crossing_as_band(&p, e.open_slowdown, (op_min, op_max))
        };
        identified.gain_per_s = p.p_gain_per_s;
        (p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.0);
        spec.pincart2 = Some(p);
    }
    spec.dead_time_s = 0.0;
    spec.effects = Effects {
        calibration_gain: e.calibration_gain,
        calibration_offset_pct: e.calibration_offset_pct,
        deadband_pct: e.deadband_pct,
        positioner_deadband_pct: e.positioner_deadband_pct,
        closing_slew_pct_per_s: e.closing_slew_pct_per_s,
        open_slowdown: identified.open_slowdown,
        friction_band_pct: identified.band_pct,
        stop_windup_pct: e.stop_windup_pct,
        ..Effects::default()
    };
    (spec, identified)
}

/// Pin-cart II's crossing time as a friction band: the band a 1 % reversal crosses in the
/// crossing time at the positioner's gain, `P_k · 1 % · T(V)`, with `T(V)` (eq. 7, slowed by
/// `slowdown` as the core does) fitted over the set-point range as `c (1 + r V / 100)`; returns
/// the band at closed, `P_k c`, and `r`. No crossing time: no band.
fn crossing_as_band(
    p: &crate::model::PinCart2Params,
    slowdown: f64,
    (op_min, op_max): (f64, f64),
) -> (f64, f64) {
    let t = |v: f64| p.crossing_time_s(v) * crate::model::slower_at(slowdown, v);
    // Least squares of a line through T over the range (31 points).
    let n = 31.0;
    let (sx, sy, sxx, sxy) = (0..=30)
        .map(|i| op_min + (op_max - op_min) * f64::from(i) / 30.0)
        .fold((0.0, 0.0, 0.0, 0.0), |(a, b, c, d), x| {
            (a + x, b + t(x), c + x * x, d + x * t(x))
        });
    let (mean_x, mean_t) = (sx / n, sy / n);
    let var = sxx - sx * mean_x;
    let slope = if var > 0.0 {
        (sxy - sx * mean_t) / var
    } else {
        0.0
    };
    let at_closed = mean_t - slope * mean_x;
    // A crossing time that shrinks with opening, or a line through zero, keeps its mean.
    let (c, r) = if slope > 0.0 && at_closed > 0.05 * mean_t {
        (at_closed, 100.0 * slope / at_closed)
    } else {
        (mean_t, 0.0)
    };
    if c <= 0.0 {
        return (0.0, 0.0);
    }
    ((p.p_gain_per_s * c).min(20.0), r.min(20.0))
}

#[cfg(test)]
mod tests;
