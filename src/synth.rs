//! Synthetic recordings: any model file driven by the paper's random steps or by a closed
//! level-control loop, with seeded measurement noise. For demos, tests and benchmarks that need
//! a recording whose physics is known (an effect hidden on purpose, or none at all).
//!
//! The closed loop is an outlet valve holding a tank level: a PI controller sets O_P from the
//! measured level, the inflow wanders (a slow random walk plus a sine), and the level sensor is
//! noisy, so O_P moves gently and reverses often, the way a valve sees normal operation. Nothing
//! here reads or writes files.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::model::{ModelError, ModelSpec, Valve};
use crate::recording::{Recording, RecordingError};
use crate::signal::{RandomSteps, RandomStepsParams};

/// A synthetic recording that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error("noise of {0} %: must be a finite standard deviation >= 0")]
    Noise(f64),
}

/// What drives the valve.
#[derive(Debug, Clone, Copy)]
pub enum Excitation {
    /// The paper's experiment: levels uniform in 20-97 %, holds uniform in 0-20 s.
    RandomSteps,
    /// A PI level loop around `level_pct` (gentle, continuous moves with many small reversals).
    ClosedLoop { level_pct: f64 },
}

/// Runs `spec` for `duration_s` at `dt` under `excitation`, adding Gaussian noise of
/// `noise_pct` (standard deviation, %) to the recorded V_P. Deterministic for a given `seed`.
pub fn generate(
    spec: &ModelSpec,
    excitation: Excitation,
    duration_s: f64,
    dt: f64,
    noise_pct: f64,
    seed: u64,
) -> Result<Recording, SynthError> {
    let n = (duration_s / dt).round() as usize;
    let mut valve = Valve::new(spec, dt)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_pct).map_err(|_| SynthError::Noise(noise_pct))?;
    let (mut t, mut op, mut vp) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    match excitation {
        Excitation::RandomSteps => {
            let mut source = RandomSteps::new(&RandomStepsParams {
                seed,
                ..RandomStepsParams::default()
            });
            let first = source.op_at(0.0);
            valve.reset(first, first);
            for k in 0..n {
                let tk = k as f64 * dt;
                let u = source.op_at(tk);
                t.push(tk);
                op.push(u);
                vp.push(valve.step(u) + noise.sample(&mut rng));
            }
        }
        Excitation::ClosedLoop { level_pct } => {
            // Tank: A dh/dt = q_in - c * V_P (level and flows in %), outlet valve around 40 %.
            let (area, c) = (60.0, 1.0);
            let (kp, ti) = (3.0, 40.0);
            let walk = Normal::new(0.0, 0.02).map_err(|_| SynthError::Noise(0.02))?;
            let level_noise = Normal::new(0.0, 0.15).map_err(|_| SynthError::Noise(0.15))?;
            let (mut level, mut integral, mut drift) = (level_pct, 0.0, 0.0);
            let mut v = 40.0;
            valve.reset(v, v);
            for k in 0..n {
                let tk = k as f64 * dt;
                drift = (drift + walk.sample(&mut rng) * dt.sqrt()).clamp(-8.0, 8.0);
                let inflow = 40.0 + drift + 4.0 * (tk * std::f64::consts::TAU / 120.0).sin();
                let measured = level + level_noise.sample(&mut rng);
                let e = measured - level_pct;
                integral += e * dt / ti;
                let u = (40.0 + kp * (e + integral)).clamp(0.0, 100.0);
                v = valve.step(u);
                level += (inflow - c * v) / area * dt;
                t.push(tk);
                op.push(u);
                vp.push(v + noise.sample(&mut rng));
            }
        }
    }
    Ok(Recording::from_vectors(t, op, vp)?)
}
