//! The response test's running side (`valve-bridge response-test`): its [`Plan`] (steps of
//! several sizes in both directions around a few openings, then a slow ramp out and back), the
//! [`Schedule`] that walks it as the loop's source of O_P (a hold ends once V_P has settled, or
//! after the plan's longest hold), and the checks before a valve is moved: a real valve only
//! with the user's confirmation (`--yes`, or `[test] confirm = false`), never one that does not
//! answer or reports a fault (its registers read once, nothing written), never outside the
//! source's `op_min_pct..op_max_pct`. [`Test::run`] then runs the daemon's own loop, log,
//! Modbus backends, signals and stop action, which the loop applies on every exit: the plan's
//! end, a signal, an error, a panic.
//!
//! Not here: reading the figures from the log (`vb_analysis::response`, the analysis), the report,
//! the command line.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

pub use vb_core::response_plan::{
    HoldRule, Move, Plan, Schedule, SignaturePlan, Step, QUICK, STANDARD,
};

use super::config::{Config, SourceConfig, SourceSpec, ValveChoice, ValveConfig, ValveSpec};
use super::error::DaemonError;
use super::RunOptions;
use crate::runtime::control::current_thread_runtime;
use crate::runtime::stats::Summary;
use vb_core::toml_file::TomlError;
use vb_modbus::client::{Link, ModbusValve, OpenError};
use vb_modbus::map::Format;
use vb_modbus::probe;

/// Why a response test does not start, or stopped.
#[derive(Debug, thiserror::Error)]
pub enum TestError {
    /// No valve, or not one valve, is named.
    #[error("{}: {source}", config.display())]
    Valve {
        config: PathBuf,
        #[source]
        source: ValveChoice,
    },
    /// The plan file cannot be read.
    #[error("--plan {name}: {source} (a plan is `standard`, `quick` or a TOML file)")]
    PlanFile {
        name: String,
        #[source]
        source: TomlError,
    },
    /// The plan is invalid, or leaves the valve's range.
    #[error(transparent)]
    Plan(TomlError),
    /// A real valve would be moved without the user's word.
    #[error(
        "the response test moves valve {valve} ({backend}) in steps of up to {largest_pct} % \
         within {lo}..{hi} %: make sure the process can take that, then run it again with --yes \
         (or set [test] confirm = false in {})",
        config.display()
    )]
    NotConfirmed {
        valve: String,
        backend: &'static str,
        largest_pct: f64,
        lo: f64,
        hi: f64,
        config: PathBuf,
    },
    /// The device did not answer the registers' reading before the test.
    #[error("valve {valve}: {source}")]
    Unreachable {
        valve: String,
        #[source]
        source: OpenError,
    },
    /// The device answered with a fault.
    #[error(
        "valve {valve}: {why}: the test does not start on a valve that reports a fault; clear it \
         first (`valve-bridge probe --config {}` reads its registers)",
        config.display()
    )]
    Faulted {
        valve: String,
        why: String,
        config: PathBuf,
    },
    /// The loop could not start or finish.
    #[error(transparent)]
    Daemon(#[from] DaemonError),
}

/// A response test ready to run: the daemon config that runs it and what the analysis needs.
#[derive(Debug, Clone)]
pub struct Test {
    /// The valve alone, driven by the plan, with neither compensation (the test measures the
    /// valve itself) nor the live health and diagnosis.
    pub config: Config,
    /// The plan.
    pub plan: Arc<Plan>,
    /// The valve's name.
    pub valve: String,
    /// The set-point register's resolution, % (0 when it takes any value): a step reaches the
    /// valve rounded to it.
    pub setpoint_step_pct: f64,
    /// The config file, for messages.
    path: PathBuf,
    /// Whether the test needs the user's word before it moves the valve.
    confirm: bool,
}

impl Test {
    /// The test of `plan` (`standard`, `quick` or a file) on the valve `valve` names (the only
    /// one when None) of `config`, read from `path`.
    pub fn new(
        mut config: Config,
        path: &Path,
        valve: Option<&str>,
        plan: &str,
    ) -> Result<Test, TestError> {
        let picked = config.valve(valve).map_err(|source| TestError::Valve {
            config: path.to_path_buf(),
            source,
        })?;
        let range = config.source_of(picked).op_range();
        let plan = Arc::new(Plan::load(plan, range).map_err(|e| match e {
            TomlError::Read { .. } => TestError::PlanFile {
                name: plan.to_string(),
                source: e,
            },
            invalid => TestError::Plan(invalid),
        })?);
        let mut valve = picked.clone();
        if valve.compensation.take().is_some() {
            tracing::info!(
                valve = valve.label(),
                "the response test measures the valve itself: [valve.compensation] is left out"
            );
        }
        valve.source = None;
        let setpoint_step_pct = setpoint_step(&valve);
        config.source = SourceConfig {
            op_min_pct: range.0,
            op_max_pct: range.1,
            spec: SourceSpec::ResponseTest(plan.clone()),
        };
        config.valves = vec![valve];
        config.health = None;
        config.diagnosis = None;
        Ok(Test {
            valve: config.valves[0].label().to_string(),
            confirm: config.test.confirm,
            config,
            plan,
            setpoint_step_pct,
            path: path.to_path_buf(),
        })
    }

    /// Runs the test: with the user's word (`yes`) for a real valve, after reading its registers
    /// once; returns the loop's summary (its logs are [`Summary`]'s).
    pub fn run(self, yes: bool, opts: RunOptions) -> Result<Summary, TestError> {
        let valve = &self.config.valves[0];
        if !valve.backend.is_simulated() && self.confirm && !yes {
            let range = self.config.source.op_range();
            return Err(TestError::NotConfirmed {
                valve: self.valve.clone(),
                backend: valve.backend.tag(),
                largest_pct: self.plan.largest_step_pct(),
                lo: range.0,
                hi: range.1,
                config: self.path.clone(),
            });
        }
        self.check_device()?;
        Ok(super::run(self.config, opts)?)
    }

    /// Reads the Modbus valve's registers once, writing nothing: refused when it does not
    /// answer, a register cannot be read, or its status word has the error bit set.
    fn check_device(&self) -> Result<(), TestError> {
        let valve = &self.config.valves[0];
        let (link, device) = match &valve.backend {
            ValveSpec::ModbusTcp(l, d) => (Link::Tcp(l.clone()), d),
            ValveSpec::ModbusRtu(l, d) => (Link::Rtu(l.clone()), d),
            ValveSpec::Emulated(_) => return Ok(()),
        };
        let unreachable = |source| TestError::Unreachable {
            valve: self.valve.clone(),
            source,
        };
        let rt = current_thread_runtime("device check runtime")?;
        let report = rt.block_on(async {
            let mut v = ModbusValve::new(link, device.registers, self.config.loop_.period_s())?;
            v.set_timeout(CHECK_TIMEOUT);
            v.connect_now().await?;
            Ok(probe::probe(&mut v, None, None).await)
        });
        let report = report.map_err(unreachable)?;
        let faulted = |why| TestError::Faulted {
            valve: self.valve.clone(),
            why,
            config: self.path.clone(),
        };
        for row in &report.before {
            let value = row.result.as_ref().map_err(|e| {
                faulted(format!(
                    "its {} register ({}) cannot be read: {e}",
                    row.name, row.address
                ))
            })?;
            if let (Some(status), Some(&word)) = (device.registers.status, value.words.first()) {
                if row.name == "status" && word & status.error_mask() != 0 {
                    return Err(faulted(format!(
                        "its status word {word:#06x} has the error bit {} set (a set-point was refused)",
                        status.setpoint_error_bit
                    )));
                }
            }
        }
        tracing::info!(valve = %self.valve, "registers read, no fault: starting the test");
        Ok(())
    }
}

/// How long the check before the test waits for each register.
const CHECK_TIMEOUT: Duration = Duration::from_secs(1);

/// The resolution of `valve`'s set-point register, % (0 for an emulated valve or a float).
fn setpoint_step(valve: &ValveConfig) -> f64 {
    match &valve.backend {
        ValveSpec::ModbusTcp(_, d) | ValveSpec::ModbusRtu(_, d) => {
            match d.registers.setpoint.format {
                Format::F32 => 0.0,
                _ => d.registers.setpoint.scale.abs(),
            }
        }
        ValveSpec::Emulated(_) => 0.0,
    }
}
