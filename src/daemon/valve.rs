//! The valve backend seam: one transaction per cycle, "write O_P, read V_P".
//!
//! [`Backend`] is an enum with one variant per `[valve] kind`. Each variant implements
//! `transact(op_pct, k)`: send the wanted opening for loop slot `k`, return the measured position,
//! or a [`Fault`] that the log records as `timeout`, `error` or `disconnected`. A transaction
//! runs on the loop thread's current-thread tokio runtime, so a network backend can `await` its
//! I/O (with its own timeout, well inside one period) without any other thread.
//!
//! Adding a backend (Modbus RTU/TCP): add a `ValveKind` variant and its `[valve.<kind>]` table in
//! `config.rs`, a variant here, its arm in [`Backend::new`], [`Backend::transact`] and
//! [`Backend::is_simulated`]. Nothing else in the daemon changes.
//!
//! The `emulated` backend steps a [`crate::model::Valve`] once per slot, in real time: slots the
//! loop skipped are stepped with the O_P the valve was holding, so the emulated valve never falls
//! behind the clock, and the log (which shows that held O_P in skipped rows) replays exactly
//! through [`crate::model::Valve::simulate`]. It starts at rest at its first O_P
//! (`reset(op0, op0)`). Optional Gaussian measurement noise is added to the reported V_P only.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::config::{ValveConfig, ValveKind};
use crate::model::{ModelError, Valve};

/// Why a transaction gave no V_P: the Modbus client's fault kinds, shared by every backend.
pub use crate::modbus::client::Fault;

/// A valve the loop can drive.
#[derive(Debug)]
pub enum Backend {
    /// A model advanced in real time.
    Emulated(Emulated),
}

impl Backend {
    /// The backend `[valve]` selects, for a loop of period `period_s`.
    pub fn new(cfg: &ValveConfig, period_s: f64) -> Result<Backend, ModelError> {
        match cfg.kind {
            ValveKind::Emulated => {
                let e = &cfg.emulated;
                let spec = e.model_spec()?;
                let noise = if e.noise_std_pct > 0.0 {
                    let normal =
                        Normal::new(0.0, e.noise_std_pct).map_err(|_| ModelError::Param {
                            model: spec.model,
                            key: "valve.emulated.noise_std_pct".into(),
                            value: e.noise_std_pct,
                            allowed: "a standard deviation in %, >= 0".into(),
                        })?;
                    Some((normal, ChaCha8Rng::seed_from_u64(e.noise_seed)))
                } else {
                    None
                };
                Ok(Backend::Emulated(Emulated {
                    valve: Valve::new(&spec, period_s)?,
                    last: None,
                    noise,
                }))
            }
        }
    }

    /// Sends `op_pct` as the O_P of loop slot `k` and returns the valve position V_P (%).
    pub async fn transact(&mut self, op_pct: f64, k: u64) -> Result<f64, Fault> {
        match self {
            Backend::Emulated(e) => Ok(e.step_to(op_pct, k)),
        }
    }

    /// True when the valve is a simulation, which may run on the virtual clock.
    pub fn is_simulated(&self) -> bool {
        match self {
            Backend::Emulated(_) => true,
        }
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        match self {
            Backend::Emulated(e) => format!("emulated {}", e.valve.spec().model.display_name()),
        }
    }
}

/// The emulated valve: a model, the last slot it was stepped to, and the noise generator.
#[derive(Debug)]
pub struct Emulated {
    valve: Valve,
    /// Last slot stepped and the O_P it got.
    last: Option<(u64, f64)>,
    noise: Option<(Normal<f64>, ChaCha8Rng)>,
}

impl Emulated {
    /// Steps the model through slot `k` (holding the previous O_P over skipped slots).
    fn step_to(&mut self, op_pct: f64, k: u64) -> f64 {
        match self.last {
            None => self.valve.reset(op_pct, op_pct),
            Some((last_k, held)) => {
                for _ in last_k + 1..k {
                    self.valve.step(held);
                }
            }
        }
        self.last = Some((k, op_pct));
        let vp = self.valve.step(op_pct);
        match &mut self.noise {
            Some((normal, rng)) => vp + normal.sample(rng),
            None => vp,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::daemon::config::Config;
    use crate::model::{bundled, ModelKind};
    use std::path::Path;

    fn backend(toml: &str) -> Backend {
        let cfg = Config::from_toml(toml, Path::new("t.toml")).unwrap();
        Backend::new(&cfg.valve, 0.01).unwrap()
    }

    fn run(b: &mut Backend, ops: &[(u64, f64)]) -> Vec<f64> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        ops.iter()
            .map(|&(k, op)| rt.block_on(b.transact(op, k)).unwrap())
            .collect()
    }

    #[test]
    fn emulated_matches_simulate_including_skipped_slots() {
        let mut b = backend("");
        // Slots 3 and 4 skipped: the valve holds 60 % through them.
        let got = run(
            &mut b,
            &[(0, 30.0), (1, 30.0), (2, 60.0), (5, 60.0), (6, 40.0)],
        );
        let op = [30.0, 30.0, 60.0, 60.0, 60.0, 60.0, 40.0];
        let want = Valve::new(&bundled(ModelKind::Pincart2), 0.01)
            .unwrap()
            .simulate(&op, op[0]);
        assert_eq!(got, vec![want[0], want[1], want[2], want[5], want[6]]);
    }

    #[test]
    fn noise_is_seeded_and_only_on_the_report() {
        let toml = "[valve.emulated]\nmodel = \"modelless\"\nnoise_std_pct = 0.5\nnoise_seed = 3\n";
        let ops: Vec<(u64, f64)> = (0..2000).map(|k| (k, 50.0)).collect();
        let a = run(&mut backend(toml), &ops);
        assert_eq!(a, run(&mut backend(toml), &ops));
        let mean = a.iter().sum::<f64>() / a.len() as f64;
        let sd = (a.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!((mean - 50.0).abs() < 0.05, "{mean}");
        assert!((sd - 0.5).abs() < 0.05, "{sd}");
    }
}
