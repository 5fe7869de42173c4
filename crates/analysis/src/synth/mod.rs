//! Synthetic recordings: any model file driven by the paper's random steps, small steps,
//! ramps, a mix of those, or a closed level-control loop, with seeded measurement noise. For
//! demos, tests and benchmarks that need a recording whose physics is known (an effect hidden
//! on purpose, or none at all); [`physical`] builds physical valves with one named effect, and
//! [`digital`] simulates a digital positioner apart from the project's models, recorded
//! through the same excitations ([`record`] takes any [`Actuator`]).
//!
//! The closed loop is an outlet valve holding a tank level under a PI controller ([`level`]),
//! so O_P moves gently and reverses often, the way a valve sees normal operation. The
//! open-loop excitations live in [`excite`]. A physical valve (`model = "physical"`) has its
//! own sensor with its own noise (`[physical] sensor_noise_pct`, seeded by its `noise_seed`),
//! so no noise is added to it here. [`logged`] turns a recording into what the daemon's log
//! would hold of it (per mille, lost replies). Nothing here reads or writes files.

pub mod digital;
pub mod excite;
pub mod level;
pub mod logged;
pub mod physical;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use excite::{OpenLoop, Ramps, SmallSteps};
pub use level::LevelLoop;
use vb_core::model::{ModelError, ModelKind, ModelSpec, Valve};
use vb_core::recording::{Recording, RecordingError};

/// A synthetic recording that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    #[error(transparent)]
    Model(#[from] ModelError),
    #[error(transparent)]
    Recording(#[from] RecordingError),
    #[error(transparent)]
    Digital(#[from] digital::DigitalError),
    #[error("noise of {0} %: must be a finite standard deviation >= 0")]
    Noise(f64),
    #[error("noise of {0} % on a physical valve: its sensor makes its own noise ([physical] sensor_noise_pct); pass 0")]
    NoiseOnPhysical(f64),
}

/// What drives the valve.
#[derive(Debug, Clone, Copy)]
pub enum Excitation {
    /// The paper's experiment: levels uniform in 20-97 %, holds uniform in 0-20 s.
    RandomSteps,
    /// A PI level loop around `level_pct` (gentle, continuous moves with many small reversals).
    ClosedLoop { level_pct: f64 },
    /// The same loop with a level sensor of `level_noise_pct` (the default loop's is 0.15 %):
    /// the controller's output as noisy as that makes it.
    NoisyLoop {
        level_pct: f64,
        level_noise_pct: f64,
    },
    /// Steps of 0.2-2 % held 2-10 s around a level wandering near `around_pct`, with reversals.
    SmallSteps { around_pct: f64 },
    /// Slow (0.2-2 %/s) and fast (5-30 %/s) ramps between random levels, with holds.
    Ramps,
    /// Random steps, then ramps, then small steps around `low_pct`, a third of the time each.
    Mixed { low_pct: f64 },
}

impl Excitation {
    /// A short name for tables (`random_steps`, `closed_loop`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Excitation::RandomSteps => "random_steps",
            Excitation::ClosedLoop { .. } => "closed_loop",
            Excitation::NoisyLoop { .. } => "noisy_loop",
            Excitation::SmallSteps { .. } => "small_steps",
            Excitation::Ramps => "ramps",
            Excitation::Mixed { .. } => "mixed",
        }
    }
}

/// A valve a recording can be made of: put at rest, then stepped one sample at a time.
/// [`Valve`] is one (any model file); [`digital`]'s positioner is another, written apart from
/// the models.
pub trait Actuator {
    /// At rest at V_P `vp_pct` with O_P `op_pct` (the excitation's first value).
    fn reset(&mut self, op_pct: f64, vp_pct: f64);
    /// One sample with O_P `op_pct`: the recorded V_P.
    fn step(&mut self, op_pct: f64) -> f64;
}

impl Actuator for Valve {
    fn reset(&mut self, op_pct: f64, vp_pct: f64) {
        Valve::reset(self, op_pct, vp_pct);
    }

    fn step(&mut self, op_pct: f64) -> f64 {
        Valve::step(self, op_pct)
    }
}

/// Runs `spec` for `duration_s` at `dt` under `excitation`, adding Gaussian noise of
/// `noise_pct` (standard deviation, %) to the recorded V_P (0 for a physical valve, whose
/// sensor is noisy by itself). Deterministic for a given `seed`.
pub fn generate(
    spec: &ModelSpec,
    excitation: Excitation,
    duration_s: f64,
    dt: f64,
    noise_pct: f64,
    seed: u64,
) -> Result<Recording, SynthError> {
    if spec.model == ModelKind::Physical && noise_pct != 0.0 {
        return Err(SynthError::NoiseOnPhysical(noise_pct));
    }
    let mut valve = Valve::new(spec, dt)?;
    record(&mut valve, excitation, duration_s, dt, noise_pct, seed)
}

/// Runs `valve` for `duration_s` at `dt` under `excitation`, as [`generate`] runs a model
/// file: the same O_P for the same `seed`, whatever the valve does with it (in closed loop the
/// tank and controller draw from the generator in the same order).
pub fn record(
    valve: &mut impl Actuator,
    excitation: Excitation,
    duration_s: f64,
    dt: f64,
    noise_pct: f64,
    seed: u64,
) -> Result<Recording, SynthError> {
    let n = (duration_s / dt).round() as usize;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, noise_pct).map_err(|_| SynthError::Noise(noise_pct))?;
    let mut rec = Columns::with_capacity(n);
    let mut open = match excitation {
        Excitation::ClosedLoop { level_pct } => {
            let plant = LevelLoop::new(level_pct);
            closed_loop(valve, plant, n, dt, &noise, &mut rng, &mut rec);
            return Ok(Recording::from_vectors(rec.t, rec.op, rec.vp)?);
        }
        Excitation::NoisyLoop {
            level_pct,
            level_noise_pct,
        } => {
            let plant = LevelLoop::new(level_pct).with_level_noise(level_noise_pct);
            closed_loop(valve, plant, n, dt, &noise, &mut rng, &mut rec);
            return Ok(Recording::from_vectors(rec.t, rec.op, rec.vp)?);
        }
        Excitation::RandomSteps => OpenLoop::random_steps(seed),
        Excitation::SmallSteps { around_pct } => OpenLoop::Small(SmallSteps::new(around_pct, seed)),
        Excitation::Ramps => OpenLoop::Ramps(Ramps::new(seed)),
        Excitation::Mixed { low_pct } => OpenLoop::mixed(low_pct, duration_s, seed),
    };
    let first = open.op_at(0.0);
    valve.reset(first, first);
    for k in 0..n {
        let tk = k as f64 * dt;
        let u = open.op_at(tk);
        rec.push(tk, u, valve.step(u) + noise.sample(&mut rng));
    }
    Ok(Recording::from_vectors(rec.t, rec.op, rec.vp)?)
}

/// The three columns of a recording being made.
struct Columns {
    t: Vec<f64>,
    op: Vec<f64>,
    vp: Vec<f64>,
}

impl Columns {
    fn with_capacity(n: usize) -> Self {
        Columns {
            t: Vec::with_capacity(n),
            op: Vec::with_capacity(n),
            vp: Vec::with_capacity(n),
        }
    }

    fn push(&mut self, t: f64, op: f64, vp: f64) {
        self.t.push(t);
        self.op.push(op);
        self.vp.push(vp);
    }
}

/// The PI level loop `plant` through `valve`, V_P recorded with `noise`.
fn closed_loop(
    valve: &mut impl Actuator,
    mut plant: LevelLoop,
    n: usize,
    dt: f64,
    noise: &Normal<f64>,
    rng: &mut ChaCha8Rng,
    rec: &mut Columns,
) {
    valve.reset(level::NOMINAL_OPENING_PCT, level::NOMINAL_OPENING_PCT);
    for k in 0..n {
        let tk = k as f64 * dt;
        let u = plant.controller(tk, dt, rng);
        let v = valve.step(u);
        plant.tank(v, dt);
        rec.push(tk, u, v + noise.sample(rng));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::composed::Effect;

    #[test]
    fn every_excitation_is_deterministic_for_a_seed() {
        let spec = physical::with_effect(Effect::Backlash, 1.0);
        for ex in [
            Excitation::RandomSteps,
            Excitation::ClosedLoop { level_pct: 50.0 },
            Excitation::NoisyLoop {
                level_pct: 50.0,
                level_noise_pct: 0.4,
            },
            Excitation::SmallSteps { around_pct: 40.0 },
            Excitation::Ramps,
            Excitation::Mixed { low_pct: 30.0 },
        ] {
            let a = generate(&spec, ex, 60.0, 0.01, 0.0, 4).unwrap();
            let b = generate(&spec, ex, 60.0, 0.01, 0.0, 4).unwrap();
            assert_eq!((a.op.clone(), a.vp.clone()), (b.op, b.vp), "{}", ex.name());
            let c = generate(&spec, ex, 60.0, 0.01, 0.0, 5).unwrap();
            assert_ne!(a.op, c.op, "{}", ex.name());
            assert_eq!(a.len(), 6000);
        }
    }

    #[test]
    fn physical_valves_bring_their_own_noise() {
        let e = generate(&physical::healthy(), Excitation::Ramps, 30.0, 0.01, 0.1, 1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sensor_noise_pct"), "{e}");
    }
}
