//! The response test's analysis: what the valve did in a response test's log, read against the
//! plan the test walked ([`vb_core::response_plan::Plan`]). Every figure is measured on the
//! logged V_P, never on a model, through a threshold that the log's own noise and position
//! lattice set (four noise standard deviations, one lattice step, whichever is larger), so a
//! noisy or coarsely read position is not taken for motion; rows without V_P (lost or late
//! replies) are counted and passed over, never read as a position.
//!
//! - [`analyse`]: each planned step of the log ([`StepResult`]: dead time, T63, T86, overshoot,
//!   final error, whether the valve resolved it), the signature ([`Signature`]: dead band,
//!   hysteresis, resolution) and the worst figures per size and direction ([`SizeSummary`]).
//! - [`spec`]: a spec's limits checked against them.
//!
//! The log is aligned with the plan by its O_P: the test sends exactly the plan's levels, so the
//! k-th jump of O_P is the k-th planned move (a hold at the level O_P already has shows no jump
//! and is passed over), and the signature's ramp, once started, keeps the plan's timing.
//!
//! Not here: running the test (the daemon's `vb_daemon::response`), words and pages
//! (`vb_report::response`).

mod signature;
pub mod spec;
mod step;
#[cfg(test)]
mod tests;

use serde::Serialize;

use crate::diagnose::facts::lattice;
use crate::diagnose::locate::noise_floor;
use vb_core::recording::Recording;
use vb_core::response_plan::{Move, Plan};

pub use signature::{Reversal, Signature};
pub use step::{DEAD_TIME_SHARE, T63_SHARE, T86_SHARE};

/// Why a log cannot be read as a response test.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ResponseError {
    /// The log has no V_P.
    #[error("{0}: the log has no measured V_P: a response test reads the valve's position")]
    NoPosition(String),
    /// The log's O_P takes none of the plan's steps.
    #[error("{0}: none of the plan's steps is in the log's O_P: is it the log of a response test of this plan?")]
    NoSteps(String),
}

/// The direction of a step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Direction {
    Open,
    Close,
}

impl Direction {
    /// The direction of a move of O_P by `d`.
    pub fn of(d: f64) -> Direction {
        if d >= 0.0 {
            Direction::Open
        } else {
            Direction::Close
        }
    }

    /// +1 opening, -1 closing.
    pub fn sign(self) -> f64 {
        match self {
            Direction::Open => 1.0,
            Direction::Close => -1.0,
        }
    }

    /// `open` or `close`.
    pub fn name(self) -> &'static str {
        match self {
            Direction::Open => "open",
            Direction::Close => "close",
        }
    }
}

/// How finely the log reads the position: what a move must exceed to count.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resolution {
    /// Noise standard deviation of V_P, % (from its second differences).
    pub noise_pct: f64,
    /// Spacing of the lattice V_P is read on, % (0: none found).
    pub lattice_pct: f64,
    /// The set-point register's resolution, % (0: any value): a step reaches the valve rounded
    /// to it.
    pub setpoint_step_pct: f64,
    /// The smallest move of V_P taken for motion, %: four noise standard deviations or one
    /// lattice step, whichever is larger.
    pub threshold_pct: f64,
}

/// The least threshold, %: a noiseless emulated valve's log still rounds to 0.0001 %.
const MIN_THRESHOLD_PCT: f64 = 0.001;

impl Resolution {
    /// The resolution of a log whose V_P is `vp`, sent through a set-point register of
    /// resolution `setpoint_step_pct`.
    pub fn of(vp: &[f64], setpoint_step_pct: f64) -> Resolution {
        let noise_pct = noise_floor(vp);
        let lattice_pct = lattice(vp);
        Resolution {
            noise_pct,
            lattice_pct,
            setpoint_step_pct,
            threshold_pct: (4.0 * noise_pct).max(lattice_pct).max(MIN_THRESHOLD_PCT),
        }
    }

    /// `op` as the set-point register holds it.
    pub fn sent(&self, op: f64) -> f64 {
        match self.setpoint_step_pct {
            q if q > 0.0 => (op / q).round() * q,
            _ => op,
        }
    }
}

/// One planned step and what the valve did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StepResult {
    /// When O_P stepped, s from the start of the log.
    pub t_s: f64,
    /// O_P before the step, %.
    pub start_pct: f64,
    /// The opening of the plan it was taken around, %.
    pub opening_pct: f64,
    /// The planned size, %.
    pub size_pct: f64,
    /// The change of the set-point the valve received (after its register's rounding), %,
    /// signed.
    pub sent_size_pct: f64,
    pub direction: Direction,
    /// Whether it goes against the previous movement of O_P.
    pub reversal: bool,
    /// Until V_P moved a tenth of the step (and at least the threshold), s.
    pub dead_time_s: Option<f64>,
    /// Until V_P covered 63.2 % of its final change, s (resolved steps).
    pub t63_s: Option<f64>,
    /// Until V_P covered 86.5 % of its final change, s (resolved steps).
    pub t86_s: Option<f64>,
    /// How far V_P went past its final value, % of its final change (0 within the threshold;
    /// resolved steps).
    pub overshoot_pct: Option<f64>,
    /// Set-point minus the final V_P, in the step's direction, %: positive when the valve
    /// stopped short, negative past it.
    pub final_error_pct: Option<f64>,
    /// The final V_P minus the V_P before, in the step's direction, %.
    pub moved_pct: Option<f64>,
    /// Whether V_P moved at least half the step (and the threshold) within the hold.
    pub resolved: bool,
    /// Whether V_P moved the dead time's share of the step at all within the hold.
    pub answered: bool,
    /// Whether a figure was left out because its crossing (or, for the overshoot, the time
    /// within twice T86) fell in more than three rows without V_P.
    pub hidden_by_gap: bool,
    /// How long the step was held, s.
    pub hold_s: f64,
    /// Rows without V_P from just before the step to the end of its hold. A figure whose
    /// crossing follows more than three of them in a row is left out: it could lie anywhere in
    /// the gap.
    pub missing_rows: usize,
    /// False when V_P is missing all through the half second before the step or the end of its
    /// hold: nothing of it can be measured.
    pub measured: bool,
    /// Row of the step, one past the end of its hold.
    #[serde(skip)]
    pub rows: (usize, usize),
    /// V_P before the step and at its end, %.
    #[serde(skip)]
    pub levels: (f64, f64),
}

/// The worst figures of the steps of one size and direction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Worst {
    /// Steps measured.
    pub steps: usize,
    /// Of those, resolved.
    pub resolved: usize,
    /// Of those, the ones V_P never answered (it never moved the dead time's share).
    pub unanswered: usize,
    /// Of those, the ones with a figure left out for rows without V_P.
    pub hidden: usize,
    /// The longest dead time of the answered ones, s.
    pub dead_time_s: Option<f64>,
    /// The longest T86 of the resolved ones, s.
    pub t86_s: Option<f64>,
}

/// The worst figures of one step size, opening and closing.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SizeSummary {
    pub size_pct: f64,
    pub open: Worst,
    pub close: Worst,
}

/// Everything a response test's log shows.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ResponseTest {
    /// Every planned step found in the log, in order.
    pub steps: Vec<StepResult>,
    pub signature: Signature,
    /// Per step size, the worst figures opening and closing.
    pub summary: Vec<SizeSummary>,
    pub resolution: Resolution,
    /// Rows in the log.
    pub rows: usize,
    /// Rows without V_P, by the status the log gives them (`timeout`, `error`, ...).
    pub rows_without_vp: std::collections::BTreeMap<String, usize>,
    /// Steps the plan makes.
    pub planned_steps: usize,
    /// Whether the log holds every step of the plan and all of its signature.
    pub complete: bool,
}

/// Two O_P levels closer than this are one, %: half the log's 0.0001 %.
const LEVEL_EPS: f64 = 5e-5;

/// Reads the log `rec` of a response test of `plan`, whose set-points went through a register
/// of resolution `setpoint_step_pct` (0 for none).
pub fn analyse(
    rec: &Recording,
    plan: &Plan,
    setpoint_step_pct: f64,
) -> Result<ResponseTest, ResponseError> {
    if rec.vp.len() != rec.op.len() || !rec.vp.iter().any(|v| v.is_finite()) {
        return Err(ResponseError::NoPosition(rec.source.clone()));
    }
    let moves = plan.moves();
    let aligned = align(&rec.op, &moves);
    let planned_steps = (moves.iter())
        .filter(|m| matches!(m, Move::Hold { step: Some(_), .. }))
        .count();
    if aligned.steps.is_empty() && planned_steps > 0 {
        return Err(ResponseError::NoSteps(rec.source.clone()));
    }
    let res = Resolution::of(&rec.vp, setpoint_step_pct);
    let still_rows = ((plan.hold.still_s / rec.sample_period).round() as usize).max(1);
    let steps: Vec<StepResult> = (aligned.steps.iter())
        .map(|a| step::measure(rec, a, &res, still_rows))
        .collect();
    let mut signature = match (aligned.ramp_start, &plan.signature) {
        (Some(start), Some(sig)) => signature::measure(rec, start, sig, &res),
        _ => Signature::default(),
    };
    signature.resolution_pct = smallest_resolved(&steps, &plan.sizes_pct);
    let signature_done = plan.signature.is_none() || signature.reversals.len() == 2;
    let mut rows_without_vp = std::collections::BTreeMap::new();
    for (k, v) in rec.vp.iter().enumerate() {
        if !v.is_finite() {
            let status = rec.status.get(k).map_or("missing", String::as_str);
            *rows_without_vp.entry(status.to_string()).or_insert(0) += 1;
        }
    }
    Ok(ResponseTest {
        summary: summary(&steps, &plan.sizes_pct),
        complete: steps.len() == planned_steps && signature_done,
        steps,
        signature,
        resolution: res,
        rows: rec.len(),
        rows_without_vp,
        planned_steps,
    })
}

/// A planned step found in the log: its row, the next change of O_P (or the log's end), the
/// plan's step and whether it reverses the previous movement of O_P.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Found {
    pub(crate) row: usize,
    pub(crate) end: usize,
    pub(crate) step: vb_core::response_plan::Step,
    pub(crate) reversal: bool,
}

/// The planned steps of a log and the row where the signature's ramp started.
#[derive(Debug, Default)]
struct Aligned {
    steps: Vec<Found>,
    ramp_start: Option<usize>,
}

/// The log's O_P `op` read against the plan's `moves` (see the module documentation).
fn align(op: &[f64], moves: &[Move]) -> Aligned {
    let changed = |k: usize| (op[k] - op[k - 1]).abs() > LEVEL_EPS;
    let mut out = Aligned::default();
    let (mut m, mut last_dir) = (1, 0.0);
    let mut level = op.first().copied().unwrap_or(f64::NAN);
    for k in 1..op.len() {
        // Holds at the level O_P is at show no jump.
        while let Some(Move::Hold { op_pct, .. }) = moves.get(m) {
            if (op_pct - level).abs() > LEVEL_EPS {
                break;
            }
            m += 1;
        }
        if !changed(k) {
            continue;
        }
        let dir = (op[k] - op[k - 1]).signum();
        match moves.get(m) {
            Some(&Move::Hold { op_pct, step }) if (op[k] - op_pct).abs() <= LEVEL_EPS => {
                if let Some(step) = step {
                    let end = (k + 1..op.len()).find(|&j| changed(j)).unwrap_or(op.len());
                    let reversal = last_dir != 0.0 && dir != last_dir;
                    out.steps.push(Found {
                        row: k,
                        end,
                        step,
                        reversal,
                    });
                }
                level = op_pct;
                m += 1;
            }
            Some(Move::Ramp { .. }) => {
                // The ramp's first slot still sends the level it starts from.
                out.ramp_start = Some(k - 1);
                return out;
            }
            // A change the plan does not make: the stop action's go-to at the end.
            _ => {}
        }
        last_dir = dir;
    }
    out
}

/// The smallest planned size at which every measured step of that size and of every larger
/// one was resolved; `None` when the largest was not.
fn smallest_resolved(steps: &[StepResult], sizes: &[f64]) -> Option<f64> {
    let mut sizes = sizes.to_vec();
    sizes.sort_by(|a, b| b.total_cmp(a));
    let mut smallest = None;
    for s in sizes {
        let of_size: Vec<&StepResult> = (steps.iter())
            .filter(|r| r.measured && r.size_pct == s)
            .collect();
        if of_size.is_empty() {
            continue;
        }
        if !of_size.iter().all(|r| r.resolved) {
            break;
        }
        smallest = Some(s);
    }
    smallest
}

/// The worst figures of each planned size, opening and closing.
fn summary(steps: &[StepResult], sizes: &[f64]) -> Vec<SizeSummary> {
    let worst = |size: f64, dir: Direction| {
        let of: Vec<&StepResult> = (steps.iter())
            .filter(|r| r.measured && r.size_pct == size && r.direction == dir)
            .collect();
        let max = |f: &dyn Fn(&StepResult) -> Option<f64>| {
            of.iter().filter_map(|r| f(r)).reduce(f64::max)
        };
        Worst {
            steps: of.len(),
            resolved: of.iter().filter(|r| r.resolved).count(),
            unanswered: of.iter().filter(|r| !r.answered).count(),
            hidden: of.iter().filter(|r| r.hidden_by_gap).count(),
            dead_time_s: max(&|r| r.dead_time_s),
            t86_s: max(&|r| r.t86_s),
        }
    };
    (sizes.iter())
        .map(|&size_pct| SizeSummary {
            size_pct,
            open: worst(size_pct, Direction::Open),
            close: worst(size_pct, Direction::Close),
        })
        .collect()
}
