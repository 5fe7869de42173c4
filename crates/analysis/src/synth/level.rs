//! The closed level loop of synthetic recordings: an outlet valve holding a tank's level under a
//! PI controller, the inflow wandering (a slow random walk plus a sine) and the level sensor
//! noisy, so O_P moves gently and reverses often, the way a valve sees normal operation.
//!
//! [`LevelLoop`] is the plant and the controller without the valve: each sample, ask the
//! controller's O_P ([`LevelLoop::controller`]), put it through any valve (a model, or a model
//! behind a compensator), and hand the valve's position back to the tank ([`LevelLoop::tank`]).
//! Random draws come from the caller's generator, in a fixed order (the inflow's walk, then the
//! level sensor's noise), so a seed gives the same loop whatever drives the valve.

use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Tank area: level change per second for 1 % of flow imbalance is 1 / AREA %.
const AREA: f64 = 60.0;
/// Outflow per % of valve opening.
const OUTFLOW_PER_PCT: f64 = 1.0;
/// The PI controller's gain (O_P % per level %) and integral time, s.
const KP: f64 = 3.0;
const TI_S: f64 = 40.0;
/// The valve opening that balances the mean inflow, %: the controller's bias and the start.
pub const NOMINAL_OPENING_PCT: f64 = 40.0;
/// Standard deviations of the inflow's random walk (per √s) and of the level sensor's noise, %.
const WALK_PCT: f64 = 0.02;
const LEVEL_NOISE_PCT: f64 = 0.15;

/// The tank, its inflow and its PI level controller.
#[derive(Debug, Clone)]
pub struct LevelLoop {
    setpoint_pct: f64,
    level_pct: f64,
    integral: f64,
    drift_pct: f64,
    inflow_pct: f64,
    level_noise_pct: f64,
}

impl LevelLoop {
    /// The loop holding `level_pct`, at rest there with the inflow balanced.
    pub fn new(level_pct: f64) -> Self {
        LevelLoop {
            setpoint_pct: level_pct,
            level_pct,
            integral: 0.0,
            drift_pct: 0.0,
            inflow_pct: NOMINAL_OPENING_PCT,
            level_noise_pct: LEVEL_NOISE_PCT,
        }
    }

    /// The same loop with a level sensor of noise `level_noise_pct` (standard deviation, %),
    /// which the controller passes on to its output `KP` times.
    pub fn with_level_noise(self, level_noise_pct: f64) -> Self {
        LevelLoop {
            level_noise_pct,
            ..self
        }
    }

    /// The controller's O_P at `t_s` for a sample of `dt` s (draws the inflow's walk and the
    /// level sensor's noise), clamped to 0-100 %.
    pub fn controller(&mut self, t_s: f64, dt: f64, rng: &mut ChaCha8Rng) -> f64 {
        let walk: f64 = StandardNormal.sample(rng);
        self.drift_pct = (self.drift_pct + WALK_PCT * walk * dt.sqrt()).clamp(-8.0, 8.0);
        self.inflow_pct = NOMINAL_OPENING_PCT
            + self.drift_pct
            + 4.0 * (t_s * std::f64::consts::TAU / 120.0).sin();
        let noise: f64 = StandardNormal.sample(rng);
        let measured = self.level_pct + self.level_noise_pct * noise;
        let e = measured - self.setpoint_pct;
        self.integral += e * dt / TI_S;
        (NOMINAL_OPENING_PCT + KP * (e + self.integral)).clamp(0.0, 100.0)
    }

    /// The tank over a sample of `dt` s with the valve at `vp_pct`.
    pub fn tank(&mut self, vp_pct: f64, dt: f64) {
        self.level_pct += (self.inflow_pct - OUTFLOW_PER_PCT * vp_pct) / AREA * dt;
    }

    /// The true level minus the set-point, % (the process variable's error).
    pub fn error_pct(&self) -> f64 {
        self.level_pct - self.setpoint_pct
    }
}
