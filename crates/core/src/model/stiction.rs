//! The data-driven stiction model of Choudhury, Thornhill & Shah (2005).
//!
//! Two parameters in percent of travel: S (stickband plus deadband) and J (slip jump). The valve
//! sticks whenever the (delayed) controller output stops or reverses. It breaks loose when the
//! input has moved more than S away from where it stuck after a reversal, or more than J when it
//! carries on in the same direction; it then jumps and follows the input at an offset of
//! `(S - J) / 2`. The original flowchart is written for the valve's input velocity sign; here a
//! zero velocity counts as "stopped", like the flowchart's `v = 0` branch.

use serde::{Deserialize, Serialize};

/// Stiction parameters (Table 2: stickband, jumpband; dead time lives in the valve).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StictionParams {
    /// S: stickband plus deadband, % of travel (>= 0).
    pub stickband_pct: f64,
    /// J: slip jump, % of travel (0 <= J <= S).
    pub jumpband_pct: f64,
}

/// Running state of the stiction core.
#[derive(Debug, Clone)]
pub(crate) struct Stiction {
    s: f64,
    j: f64,
    /// Output (valve position).
    y: f64,
    /// Previous input.
    u_prev: f64,
    /// Stuck, and the input where it stuck.
    stuck: bool,
    u_stuck: f64,
    /// Direction of the last movement: +1, -1, or 0 before any movement.
    dir: f64,
}

impl Stiction {
    pub(crate) fn new(p: &StictionParams) -> Self {
        Stiction {
            s: p.stickband_pct,
            j: p.jumpband_pct,
            y: 0.0,
            u_prev: 0.0,
            stuck: true,
            u_stuck: 0.0,
            dir: 0.0,
        }
    }

    pub(crate) fn reset(&mut self, u0: f64, vp0: f64) {
        self.y = vp0;
        self.u_prev = u0;
        self.stuck = true;
        self.u_stuck = u0;
        self.dir = 0.0;
    }

    #[inline]
    pub(crate) fn step(&mut self, u: f64) -> f64 {
        let du = u - self.u_prev;
        self.u_prev = u;
        if !self.stuck {
            if du != 0.0 && du.signum() == self.dir {
                self.y = u - self.dir * (self.s - self.j) / 2.0;
                return self.y;
            }
            // The input stopped or reversed: the valve sticks where it is.
            self.stuck = true;
            self.u_stuck = u - du;
        }
        let away = u - self.u_stuck;
        let d = away.signum();
        // Same direction: only the stickband J; reversal (or first move): the whole band S.
        let threshold = if d == self.dir { self.j } else { self.s };
        if away != 0.0 && away.abs() > threshold {
            self.stuck = false;
            self.dir = d;
            self.y = u - d * (self.s - self.j) / 2.0;
        }
        self.y
    }

    /// Overrides the position after the travel range clamped it.
    #[inline]
    pub(crate) fn set_position(&mut self, v: f64) {
        self.y = v;
    }

    /// True while the valve is stuck (used by tests of the stickband).
    #[cfg(test)]
    pub(crate) fn is_stuck(&self) -> bool {
        self.stuck
    }
}
