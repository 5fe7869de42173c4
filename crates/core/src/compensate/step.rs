//! The deadband step: where the set-point goes so that a valve with a deadband comes to rest at
//! its target, not short of it.
//!
//! A valve with a deadband stops as soon as it is within half the band of its set-point, on the
//! side it comes from; a set-point half the band beyond the target, on that side, brings it to
//! the target. Two things decide the step:
//!
//! - **its side** is the direction of the controller's move: the O_P where the controller last
//!   moved (by more than the compensator's gate) against where it asks now. It is never read off
//!   the model's state, which a kick pulls past the target for a while.
//! - **when it begins**: on a move that starts within the band (the valve, by the model, is
//!   within half the band of the new target) the valve cannot move without the step, so it is
//!   sent with the move. On a move from outside the band the positioner brings the valve into
//!   the band by itself, and a stem that arrives fast goes further into the band than a slow one
//!   (the pressure runs ahead of it); a step sent during the arrival would carry it past the
//!   target. So there the step waits until the V_P read has come to rest within the band (the
//!   mean of the last [`SMOOTH`] rows still for [`REST_ROWS`] rows), and then closes only what is
//!   left, at the slow speed of an error just outside the band.
//!
//! The step lasts until the controller leaves the place it asked for. Allocation-free; the model
//! state it reads and the gate belong to the caller ([`super::Compensator`]). Not here: the
//! kick, which a step adds to.

use super::guard::SMOOTH;

/// Rows the V_P read must stay still before a waiting step begins (0.1 s at 100 Hz: a stem
/// that stopped has settled on its spring by then).
pub(super) const REST_ROWS: u64 = 10;

/// Whether the step acts in the current hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// No move asked for since the last hold ended.
    Off,
    /// A move from outside the band: the valve is on its way.
    Waiting,
    /// Sent.
    On,
}

/// The V_P read, smoothed, and how long it has stayed still.
#[derive(Debug, Clone, Copy)]
struct Rest {
    last: [f64; SMOOTH],
    filled: usize,
    /// The mean the valve has stayed within the stillness threshold of, %.
    anchor: f64,
    still_rows: u64,
    /// The mean of the last rows, %.
    mean: f64,
}

impl Rest {
    fn new() -> Self {
        Rest {
            last: [0.0; SMOOTH],
            filled: 0,
            anchor: 0.0,
            still_rows: 0,
            mean: 0.0,
        }
    }

    /// Adds a row (None: no V_P was read, and stillness starts again).
    fn push(&mut self, vp: Option<f64>, still_pct: f64) {
        let Some(v) = vp else {
            (self.filled, self.still_rows) = (0, 0);
            return;
        };
        self.last[self.filled % SMOOTH] = v;
        self.filled += 1;
        if self.filled < SMOOTH {
            return;
        }
        let mean = self.last.iter().sum::<f64>() / SMOOTH as f64;
        self.mean = mean;
        if self.filled == SMOOTH || (mean - self.anchor).abs() > still_pct {
            (self.anchor, self.still_rows) = (mean, 0);
        } else {
            self.still_rows += 1;
        }
        // Keeps the count small; the ring's position only matters modulo SMOOTH.
        if self.filled >= 2 * SMOOTH {
            self.filled -= SMOOTH;
        }
    }

    /// Where the valve rests (the mean of the last rows, not the anchor, which a stem that
    /// crept to a stop less than the threshold from it lags), once it has been still for
    /// [`REST_ROWS`].
    fn at_rest(&self) -> Option<f64> {
        (self.still_rows >= REST_ROWS).then_some(self.mean)
    }
}

/// The deadband step of one compensator.
#[derive(Debug, Clone, Copy)]
pub(super) struct DeadbandStep {
    /// Half the model's deadband, %.
    half: f64,
    /// The controller's O_P where the direction of its moves was last decided.
    anchor_op: f64,
    /// The direction of the controller's last move, +1 or -1.
    dir: f64,
    state: State,
    /// The controller's O_P when it last asked for a move: the step lasts while it stays
    /// within the gate of it.
    held_op: f64,
    rest: Rest,
    /// The stillness threshold of the V_P read, %.
    still_pct: f64,
}

impl DeadbandStep {
    /// A step for a model deadband of `deadband_pct`.
    pub(super) fn new(deadband_pct: f64) -> Self {
        DeadbandStep {
            half: deadband_pct / 2.0,
            anchor_op: 0.0,
            dir: 1.0,
            state: State::Off,
            held_op: 0.0,
            rest: Rest::new(),
            still_pct: 0.0,
        }
    }

    /// Starts again at rest at the controller's O_P `op`.
    pub(super) fn reset(&mut self, op: f64) {
        (self.anchor_op, self.held_op, self.state) = (op, op, State::Off);
        self.rest = Rest::new();
    }

    /// What the step adds to the wanted core input this sample, %: for the controller's O_P
    /// `op`, `moving` when it asks for a move now, `target` where the valve should rest and
    /// `valve` where the model says it is (both at the core, in the V_P's units), and the
    /// compensator's `gate`.
    pub(super) fn offset(
        &mut self,
        op: f64,
        moving: bool,
        (target, valve): (f64, f64),
        gate: f64,
    ) -> f64 {
        if moving {
            let new_move = (op - self.anchor_op).abs() > gate;
            if new_move {
                self.dir = (op - self.anchor_op).signum();
                self.anchor_op = op;
            }
            if new_move || self.state == State::Off {
                self.state = if (target - valve).abs() <= self.half {
                    State::On
                } else {
                    State::Waiting
                };
            }
            self.held_op = op;
        } else if self.state != State::Off && (op - self.held_op).abs() > gate {
            self.state = State::Off;
        }
        if self.state == State::Waiting {
            let arrived = self
                .rest
                .at_rest()
                .is_some_and(|at| (at - target).abs() <= self.half + self.still_pct);
            if arrived {
                self.state = State::On;
            }
        }
        match self.state {
            State::On => self.dir * self.half,
            State::Off | State::Waiting => 0.0,
        }
    }

    /// The direction of the controller's last move, +1 (opening) or -1 (closing).
    pub(super) fn dir(&self) -> f64 {
        self.dir
    }

    /// The V_P read for the last set-point (None when none was read), with the noise of the
    /// reading `noise_pct` (standard deviation, %).
    pub(super) fn observe(&mut self, vp: Option<f64>, noise_pct: f64) {
        // The mean of SMOOTH rows moves by chance within a few of its standard deviations;
        // a stem creeping slower than that in 0.1 s carries nothing past the target.
        self.still_pct = (4.0 * noise_pct / (SMOOTH as f64).sqrt()).max(STILL_MIN_PCT);
        self.rest.push(vp, self.still_pct);
    }
}

/// The smallest stillness threshold, %: a per-mille register's step.
const STILL_MIN_PCT: f64 = 0.1;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_side_is_the_controller_s_move_and_a_move_from_outside_waits_for_rest() {
        let mut s = DeadbandStep::new(0.6);
        s.reset(50.0);
        // A move down of 1 %, from outside the band: no step while the valve is on its way.
        assert_eq!(s.offset(49.0, true, (49.0, 50.0), 0.1), 0.0);
        for vp in [49.9, 49.6, 49.4] {
            s.observe(Some(vp), 0.02);
            assert_eq!(s.offset(49.0, true, (49.0, 49.5), 0.1), 0.0);
        }
        // At rest 0.2 % short of it (above: the valve comes from above): the step goes below.
        for _ in 0..2 * (SMOOTH as u64 + REST_ROWS) {
            s.observe(Some(49.2), 0.02);
            s.offset(49.0, false, (49.0, 49.2), 0.1);
        }
        assert_eq!(s.offset(49.0, false, (49.0, 49.2), 0.1), -0.3);
        // A move up of 0.2 %, within the band: the step is sent with it, on the new side.
        assert_eq!(s.offset(49.2, true, (49.2, 49.1), 0.1), 0.3);
        // The controller leaves the place it asked for without a move yet: no step.
        assert_eq!(s.offset(49.35, false, (49.35, 49.2), 0.1), 0.0);
    }

    #[test]
    fn a_missing_reading_starts_the_stillness_again() {
        let mut r = Rest::new();
        for _ in 0..SMOOTH as u64 + REST_ROWS {
            r.push(Some(50.0), 0.1);
        }
        assert_eq!(r.at_rest(), Some(50.0));
        r.push(None, 0.1);
        assert_eq!(r.at_rest(), None);
    }

    #[test]
    fn a_stem_that_creeps_to_a_stop_rests_where_it_stopped() {
        // Per-mille readings stepping down a register step at a time, a threshold of 0.15 %:
        // the anchor is a mean taken on the way down, and the rest is where the readings end.
        let mut r = Rest::new();
        for vp in [49.6, 49.5, 49.4] {
            for _ in 0..SMOOTH as u64 + REST_ROWS {
                r.push(Some(vp), 0.15);
            }
        }
        assert!((r.anchor - 49.4).abs() > 0.01, "{r:?}");
        assert!(
            r.at_rest().is_some_and(|at| (at - 49.4).abs() < 1e-9),
            "{r:?}"
        );
    }
}
