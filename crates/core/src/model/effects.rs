//! Extra physics that can be added to any model: the effects diagnosis names and adds.
//!
//! Each effect is a parameter of the composed valve that is off at its default, so "add a
//! deadband" means setting `deadband_pct`, not writing a new model. Effects that live inside
//! the pin-cart II core (backlash, state-dependent delay, slew rate, minimum speed) are
//! parameters of [`super::PinCart2Params`] (plus `closing_slew_pct_per_s`, `open_slowdown`,
//! `breakaway_pct`, `friction_band_pct`, `stop_windup_pct` and `positioner_deadband_pct` here,
//! which only pin-cart II uses); the others wrap any core:
//!
//! ```text
//! O_P ─▶ T_d ─▶ calibration ─▶ deadband ─▶ stiction ─▶ core ─▶ travel clamp ─▶ quantization ─▶ V_P
//! ```
//!
//! Stiction acts on the valve's input, as in Choudhury et al. (2005) where the stiction model
//! is driven by the controller output; the core then adds the actuator's dynamics.
//! Quantization is the position sensor's resolution: it changes what is reported, not the
//! valve's state. Asymmetry (a slower closing slew rate) is applied by the pin-cart II core.

use serde::{Deserialize, Serialize};

use super::stiction::Stiction;
use super::StictionParams;

/// Effect parameters (`[effects]` in a model file); every default means "absent".
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    /// Steady-state gain from O_P to the position the valve settles at (1 = none).
    #[serde(skip_serializing_if = "is_one")]
    pub calibration_gain: f64,
    /// Steady-state offset, % (0 = none): the valve settles at `gain * O_P + offset`.
    #[serde(skip_serializing_if = "is_zero")]
    pub calibration_offset_pct: f64,
    /// Positioner deadband, % (0 = none): the target only moves once O_P leaves a band of this
    /// width around it, so the valve stops short by up to half the band.
    #[serde(skip_serializing_if = "is_zero")]
    pub deadband_pct: f64,
    /// Stick-slip on the input (Choudhury S), % (0 = none).
    #[serde(skip_serializing_if = "is_zero")]
    pub stickband_pct: f64,
    /// Slip jump on the input (Choudhury J), % (0 <= J <= S).
    #[serde(skip_serializing_if = "is_zero")]
    pub jumpband_pct: f64,
    /// Position sensor resolution, % (0 = continuous).
    #[serde(skip_serializing_if = "is_zero")]
    pub quantization_pct: f64,
    /// Closing slew rate of pin-cart II, %/s, when it differs from the opening one (0 = same).
    #[serde(skip_serializing_if = "is_zero")]
    pub closing_slew_pct_per_s: f64,
    /// Opening-dependent slowdown r of pin-cart II (0 = none): its proportional gain P_k scales
    /// by `1 / (1 + r V / 100)`, so fully open responds `1 + r` times slower than closed.
    #[serde(skip_serializing_if = "is_zero")]
    pub open_slowdown: f64,
    /// Stick-slip inside pin-cart II's loop, % (0 = none): a valve that slows below this many %
    /// per second sticks until the positioner has pushed this far beyond the cart's side, then
    /// slips the whole way, so it overshoots and hunts around a steady O_P.
    #[serde(skip_serializing_if = "is_zero")]
    pub breakaway_pct: f64,
    /// Friction band of pin-cart II, % (0 = none): the cart is this wide, and on a reversal
    /// the pin crosses it at the positioner's own speed (eqs. 4-5, with the error to the cart)
    /// instead of in eq. (7)'s crossing time. The lost time of a reversal then depends on how
    /// hard the positioner pushes, as it does when a chamber's pressure must cross a Coulomb
    /// friction band before the stem moves.
    #[serde(skip_serializing_if = "is_zero")]
    pub friction_band_pct: f64,
    /// Wind-up of pin-cart II at a travel stop, % (0 = none): while the valve sits on a stop
    /// and O_P asks for more, the pin (the positioner's drive, a chamber's pressure) goes on
    /// this far beyond the stop, and must come back before the valve leaves it.
    #[serde(skip_serializing_if = "is_zero")]
    pub stop_windup_pct: f64,
    /// Deadband of pin-cart II's positioner, % (0 = none): the pin does not move while
    /// |O_P - V_P| is within half this band and answers in full outside it, as a positioner
    /// that ignores small errors. Unlike `deadband_pct` (a band on the input, after which the
    /// valve closes in on the shifted target ever more slowly), the valve arrives at the
    /// band's edge still moving at the positioner's speed there and stops at once.
    #[serde(skip_serializing_if = "is_zero")]
    pub positioner_deadband_pct: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

impl Default for Effects {
    fn default() -> Self {
        Effects {
            calibration_gain: 1.0,
            calibration_offset_pct: 0.0,
            deadband_pct: 0.0,
            stickband_pct: 0.0,
            jumpband_pct: 0.0,
            quantization_pct: 0.0,
            closing_slew_pct_per_s: 0.0,
            open_slowdown: 0.0,
            breakaway_pct: 0.0,
            friction_band_pct: 0.0,
            stop_windup_pct: 0.0,
            positioner_deadband_pct: 0.0,
        }
    }
}

impl Effects {
    /// True when no effect is set.
    pub fn is_none(&self) -> bool {
        *self == Effects::default()
    }
}

/// Running state of the effects around a core.
#[derive(Debug, Clone)]
pub(crate) struct EffectState {
    /// False when calibration, deadband and stiction are all off: the input passes untouched.
    shapes_input: bool,
    gain: f64,
    offset: f64,
    half_band: f64,
    target: f64,
    stiction: Option<Stiction>,
    quantum: f64,
}

impl EffectState {
    pub(crate) fn new(e: &Effects) -> Self {
        EffectState {
            shapes_input: e.calibration_gain != 1.0
                || e.calibration_offset_pct != 0.0
                || e.deadband_pct > 0.0
                || e.stickband_pct > 0.0,
            gain: e.calibration_gain,
            offset: e.calibration_offset_pct,
            half_band: e.deadband_pct / 2.0,
            target: 0.0,
            stiction: (e.stickband_pct > 0.0).then(|| {
                Stiction::new(&StictionParams {
                    stickband_pct: e.stickband_pct,
                    jumpband_pct: e.jumpband_pct,
                })
            }),
            quantum: e.quantization_pct,
        }
    }

    /// At rest with the target at the calibrated `u0` and the valve at `vp0`.
    pub(crate) fn reset(&mut self, u0: f64, vp0: f64) {
        self.target = self.gain * u0 + self.offset;
        if let Some(s) = &mut self.stiction {
            s.reset(self.target, vp0);
        }
    }

    /// The deadband's target, % (moves only while calibration, deadband or stiction is on).
    pub(crate) fn target(&self) -> f64 {
        self.target
    }

    /// Calibration, deadband and stiction: the input the core is driven with.
    #[inline]
    pub(crate) fn input(&mut self, u: f64) -> f64 {
        if !self.shapes_input {
            return u;
        }
        let u = self.gain * u + self.offset;
        if u - self.target > self.half_band {
            self.target = u - self.half_band;
        } else if self.target - u > self.half_band {
            self.target = u + self.half_band;
        }
        match &mut self.stiction {
            Some(s) => s.step(self.target),
            None => self.target,
        }
    }

    /// The reported position: rounded to the sensor lattice.
    #[inline]
    pub(crate) fn output(&self, v: f64) -> f64 {
        if self.quantum > 0.0 {
            (v / self.quantum).round() * self.quantum
        } else {
            v
        }
    }
}
