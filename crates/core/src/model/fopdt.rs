//! First order plus dead time with unity DC gain (the dead time lives in [`super::Valve`]).
//!
//! `V_P(k+1) = V_P(k) + (1 - exp(-dt/tau)) * (u(k) - V_P(k))`: the exact discretisation of
//! `tau * dV/dt = u - V` for an input held over each sample (zero-order hold).

use serde::{Deserialize, Serialize};

/// FOPDT parameters (Table 2: time constant and time delay; DC gain is 1).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FopdtParams {
    /// Time constant tau in seconds (> 0).
    pub time_constant_s: f64,
}

/// Running state of the FOPDT core.
#[derive(Debug, Clone)]
pub(crate) struct Fopdt {
    alpha: f64,
    v: f64,
}

impl Fopdt {
    pub(crate) fn new(p: &FopdtParams, dt: f64) -> Self {
        Fopdt {
            alpha: 1.0 - (-dt / p.time_constant_s).exp(),
            v: 0.0,
        }
    }

    pub(crate) fn reset(&mut self, vp0: f64) {
        self.v = vp0;
    }

    #[inline]
    pub(crate) fn step(&mut self, u: f64) -> f64 {
        self.v += self.alpha * (u - self.v);
        self.v
    }

    /// Overrides the position after the travel range clamped it.
    #[inline]
    pub(crate) fn set_position(&mut self, v: f64) {
        self.v = v;
    }
}
