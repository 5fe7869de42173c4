//! The valve backend seam: one transaction per cycle, "write O_P, read V_P".
//!
//! [`Backend`] is an enum with one variant per `[valve] kind`. Each variant implements
//! `transact(op_pct, k)`: send the wanted opening for loop slot `k`, return the measured position,
//! or a [`Fault`] that the log records as `timeout`, `error` or `disconnected`. A transaction
//! runs on the loop thread's current-thread tokio runtime, so a network backend can `await` its
//! I/O (with its own timeout, well inside one period) without any other thread.
//!
//! Adding a backend: add its `kind`, its `[valve.<kind>]` table and a [`ValveSpec`] variant in
//! [`crate::config`], a variant here, and its arm in [`Backend::open`], [`Backend::transact`] and
//! [`Backend::describe`]. Nothing else in the daemon changes. [`Backend::open`] runs on the loop
//! thread's runtime, so a network backend's sockets belong to the runtime that drives them.
//!
//! The `modbus-tcp` / `modbus-rtu` backends are [`ModbusValve`]: one cycle writes O_P and reads
//! V_P under the link's deadline; its faults are logged as they come (`timeout`, `error`,
//! `disconnected`), the link is reopened in the background of later cycles (also when the
//! device was not there at start, unless `--require-device`), and the number of reconnections
//! goes into the summary. A real device runs on its own clock, so slots the loop
//! skipped are simply not sent. Valves on one serial bus ([`Backend::open_all`]) share one link:
//! the port is opened once, each valve addresses its slave id, the bus budget is checked (and
//! logged) once for their sum, and each valve's cycle deadline is its share of the period
//! ([`vb_modbus::budget::BusBudget::deadlines`]), so a device that does not answer costs
//! its own share and its own rows only.
//!
//! The `emulated` backend steps a [`vb_core::model::Valve`] once per slot, in real time: slots the
//! loop skipped are stepped with the O_P the valve was holding, so the emulated valve never falls
//! behind the clock, and the log (which shows that held O_P in skipped rows) replays through
//! [`vb_core::model::Valve::simulate`] to the log's precision. It starts at rest at its first O_P
//! (`reset(op0, op0)`). Optional Gaussian measurement noise is added to the reported V_P only.
//! A drift ([`vb_core::model::drift`]: `dead_time_drift_s_per_h`, `friction_band_drift_pct_per_h`)
//! wears the model with loop time, slot by slot: a valve wearing over hours, for the live health
//! check to notice.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use std::time::Duration;

use crate::config::{bus, ValveConfig, ValveSpec};
use vb_core::model::{Drift, ModelError, Valve};
use vb_modbus::client::{Link, LinkStats, ModbusValve, OpenError, MAX_BACKOFF};
use vb_modbus::map::RegisterMap;

/// Why a transaction gave no V_P: the Modbus client's fault kinds, shared by every backend.
pub use vb_modbus::client::{Cycle, Fault};

/// Why the valve backend cannot start.
#[derive(Debug, thiserror::Error)]
pub enum BackendError {
    /// The emulated valve's model cannot be built.
    #[error("valve model: {0}")]
    Model(#[from] ModelError),
    /// The Modbus valve cannot be opened.
    #[error(transparent)]
    Modbus(#[from] OpenError),
}

/// A valve the loop can drive. Both variants are large and boxed once at start-up, so moving the
/// backend into the loop thread copies a pointer.
#[derive(Debug)]
pub enum Backend {
    /// A model advanced in real time.
    Emulated(Box<Emulated>),
    /// A positioner over Modbus TCP or RTU.
    Modbus(Box<ModbusValve>),
}

impl Backend {
    /// Opens the backend `[valve]` selects, for a loop of period `period_s`; to be awaited on
    /// the runtime that will run its transactions. A Modbus device that cannot be reached is an
    /// error with `require_device`; otherwise the backend starts disconnected, says so once, and
    /// its cycles retry the link with backoff (logged as `disconnected`) until the device answers.
    pub async fn open(
        cfg: &ValveConfig,
        period_s: f64,
        require_device: bool,
    ) -> Result<Backend, BackendError> {
        match &cfg.backend {
            ValveSpec::ModbusTcp(link, device) => {
                let link = Link::Tcp(link.clone());
                open_modbus(link, device.registers, period_s, require_device).await
            }
            ValveSpec::ModbusRtu(link, device) => {
                let link = Link::Rtu(link.clone());
                open_modbus(link, device.registers, period_s, require_device).await
            }
            ValveSpec::Emulated(e) => {
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
                let valve = Valve::new(&spec, period_s)?;
                let drift = Drift::new(&e.drift(), &valve)?;
                Ok(Backend::Emulated(Box::new(Emulated {
                    valve,
                    last: None,
                    noise,
                    drift,
                })))
            }
        }
    }

    /// Opens every valve of `cfgs`, in order (see [`Backend::open`]); valves that share a
    /// serial port share one link, opened once, with the bus budget checked for all of them and
    /// the cycle deadline split between them.
    pub async fn open_all(
        cfgs: &[ValveConfig],
        period_s: f64,
        require_device: bool,
    ) -> Result<Vec<Backend>, BackendError> {
        let buses = bus::buses(cfgs);
        let mut backends: Vec<Backend> = Vec::with_capacity(cfgs.len());
        for (i, cfg) in cfgs.iter().enumerate() {
            let on_bus = buses.iter().find(|(_, m)| m.contains(&i));
            let (Some((port, members)), ValveSpec::ModbusRtu(rtu, device)) = (on_bus, &cfg.backend)
            else {
                backends.push(Backend::open(cfg, period_s, require_device).await?);
                continue;
            };
            let budget = bus::budget(cfgs, port, members, period_s);
            let timeouts = bus::timeouts(cfgs, members);
            let deadlines = budget.deadlines(&timeouts).map_err(|message| {
                BackendError::Modbus(OpenError::Setting {
                    section: "valve.modbus-rtu",
                    key: "timeout_ms",
                    message,
                })
            })?;
            let at = members.iter().position(|&j| j == i).unwrap_or(0);
            let link = Link::Rtu(rtu.clone());
            let first = match backends.get(members[0]) {
                Some(Backend::Modbus(m)) if at > 0 => Some(m),
                _ => None,
            };
            let mut valve = match first {
                Some(first) => first.sharing(link, device.registers, period_s)?,
                None => {
                    budget.check().map_err(OpenError::from)?;
                    let mut valve = ModbusValve::new(link, device.registers, period_s)?;
                    connect(&mut valve, require_device).await?;
                    valve
                }
            };
            valve.set_timeout(Duration::from_secs_f64(deadlines[at]));
            backends.push(Backend::Modbus(Box::new(valve)));
        }
        Ok(backends)
    }

    /// Sends `op_pct` as the O_P of loop slot `k`: the valve position V_P (%) or the fault, and
    /// the set-point the valve received (the O_P after the register's scaling and rounding; the
    /// O_P itself for the emulated valve; None when no write was acknowledged).
    pub async fn transact(&mut self, op_pct: f64, k: u64) -> Cycle {
        match self {
            Backend::Emulated(e) => Cycle {
                vp_pct: Ok(e.step_to(op_pct, k)),
                sent_pct: Some(op_pct),
                status: None,
            },
            Backend::Modbus(m) => m.cycle(op_pct).await,
        }
    }

    /// What a Modbus link went through: reconnects, attempts, late replies (None: not a
    /// Modbus valve).
    pub fn link_stats(&self) -> Option<LinkStats> {
        match self {
            Backend::Emulated(_) => None,
            Backend::Modbus(m) => Some(m.link_stats()),
        }
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        match self {
            Backend::Emulated(e) => format!("emulated {}", e.valve.spec().model.display_name()),
            Backend::Modbus(m) => m.describe(),
        }
    }
}

/// Opens the Modbus valve on `link` with the map `registers` (see [`Backend::open`]).
async fn open_modbus(
    link: Link,
    registers: RegisterMap,
    period_s: f64,
    require_device: bool,
) -> Result<Backend, BackendError> {
    let mut valve = ModbusValve::new(link, registers, period_s)?;
    // The bus budget is logged by its own check, once.
    valve.check_budget()?;
    connect(&mut valve, require_device).await?;
    Ok(Backend::Modbus(Box::new(valve)))
}

/// Connects `valve` now; a device that is not there is an error with `require_device`,
/// otherwise the valve starts disconnected and its cycles retry the link.
async fn connect(valve: &mut ModbusValve, require_device: bool) -> Result<(), BackendError> {
    match valve.connect_now().await {
        Ok(()) => Ok(()),
        Err(e) if require_device => Err(e.into()),
        Err(e) => {
            tracing::warn!(
                "{e}; running without it: cycles are logged as `disconnected` and the link is \
                 retried (every {} s at most) until the device answers (--require-device stops \
                 instead)",
                MAX_BACKOFF.as_secs()
            );
            Ok(())
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
    drift: Option<Drift>,
}

impl Emulated {
    /// Steps the model through slot `k` (holding the previous O_P over skipped slots).
    fn step_to(&mut self, op_pct: f64, k: u64) -> f64 {
        match self.last {
            None => {
                self.valve.reset(op_pct, op_pct);
                if let Some(d) = &mut self.drift {
                    d.reset(op_pct);
                }
            }
            Some((last_k, held)) => {
                for j in last_k + 1..k {
                    self.step_model(held, j);
                }
            }
        }
        self.last = Some((k, op_pct));
        let vp = self.step_model(op_pct, k);
        match &mut self.noise {
            Some((normal, rng)) => vp + normal.sample(rng),
            None => vp,
        }
    }

    /// One step of the model in slot `k`, worn by the drift when there is one.
    fn step_model(&mut self, op_pct: f64, k: u64) -> f64 {
        match &mut self.drift {
            Some(d) => d.step(&mut self.valve, op_pct, k),
            None => self.valve.step(op_pct),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use std::path::Path;
    use vb_core::model::{bundled, ModelKind};

    fn backend(toml: &str) -> Backend {
        let cfg = Config::from_toml(toml, Path::new("t.toml")).unwrap();
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        rt.block_on(Backend::open(&cfg.valves[0], 0.01, true))
            .unwrap()
    }

    fn run(b: &mut Backend, ops: &[(u64, f64)]) -> Vec<f64> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .build()
            .unwrap();
        ops.iter()
            .map(|&(k, op)| rt.block_on(b.transact(op, k)).vp_pct.unwrap())
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
    fn drift_adds_a_dead_time_growing_with_loop_time() {
        // Modelless: V_P is O_P delayed by the drift alone, 360 s/h = 1 ms more per 10 ms slot.
        let toml = "[valve.emulated]\nmodel = \"modelless\"\ndead_time_drift_s_per_h = 360.0\ndead_time_drift_max_s = 0.5\n";
        let mut b = backend(toml);
        // A step at slot 300 shows when k - floor(k / 10) reaches 300 (the delay grows
        // meanwhile, by whole slots).
        let mut ops: Vec<(u64, f64)> = (0..300).map(|k| (k, 10.0)).collect();
        ops.extend((300..400).map(|k| (k, 20.0)));
        let vp = run(&mut b, &ops);
        let first = vp.iter().position(|&v| v > 10.0).unwrap();
        assert_eq!(first, 333);
        // The growth stops at the most the drift adds (0.5 s, reached at 5 s).
        let mut ops: Vec<(u64, f64)> = (400..2000).map(|k| (k, 20.0)).collect();
        ops.extend((2000..2100).map(|k| (k, 30.0)));
        let vp = run(&mut b, &ops);
        let first = vp.iter().position(|&v| v > 20.0).unwrap();
        assert_eq!(first, 1600 + 50);
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
