//! `[valve]`: which backend drives the valve and the settings of each kind (`[valve.emulated]`,
//! `[valve.modbus-tcp]`, `[valve.modbus-rtu]`, `[valve.registers]`), with their checks.
//!
//! Checking only: opening the backend is [`crate::daemon::valve`]'s job, and the link settings
//! themselves are [`crate::modbus::link`]'s types.

use std::path::PathBuf;

use serde::Deserialize;

use super::{Check, LoopConfig};
use crate::modbus::link::{RtuLink, TcpLink};
use crate::modbus::map::RegisterMap;
use crate::model::{bundled, ModelError, ModelKind, ModelSpec};
use crate::toml_file::{self, TomlError};

/// `[valve]`: which backend, and the settings of each kind.
///
/// A new backend adds a variant to [`ValveKind`] and an optional sub-table field here.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValveConfig {
    /// The backend in use.
    #[serde(default)]
    pub kind: ValveKind,
    /// `[valve.emulated]`.
    #[serde(default)]
    pub emulated: EmulatedConfig,
    /// `[valve.modbus-tcp]`.
    #[serde(rename = "modbus-tcp")]
    pub tcp: Option<TcpLink>,
    /// `[valve.modbus-rtu]`.
    #[serde(rename = "modbus-rtu")]
    pub rtu: Option<RtuLink>,
    /// `[valve.registers]`: the positioner's register map (Modbus kinds).
    #[serde(default)]
    pub registers: RegisterMap,
}

/// Valve backends.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ValveKind {
    /// A model from `config/models/` stepped once per cycle.
    #[default]
    Emulated,
    /// A positioner (or `sim-device`) over Modbus TCP, `[valve.modbus-tcp]`.
    ModbusTcp,
    /// A positioner on a serial line, Modbus RTU, `[valve.modbus-rtu]`.
    ModbusRtu,
}

impl ValveKind {
    /// True for a simulated valve, which may run on the virtual clock.
    pub fn is_simulated(self) -> bool {
        self == ValveKind::Emulated
    }

    /// The name used in config files.
    pub fn tag(self) -> &'static str {
        match self {
            ValveKind::Emulated => "emulated",
            ValveKind::ModbusTcp => "modbus-tcp",
            ValveKind::ModbusRtu => "modbus-rtu",
        }
    }
}

/// `[valve.emulated]`: the model and the measurement noise.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmulatedConfig {
    /// A bundled model by name (default `pincart2` when `model_file` is not given).
    pub model: Option<ModelKind>,
    /// A model file (instead of `model`).
    pub model_file: Option<PathBuf>,
    /// Standard deviation of Gaussian noise added to the reported V_P, % (0 = none).
    pub noise_std_pct: f64,
    /// Seed of the noise.
    pub noise_seed: u64,
}

impl EmulatedConfig {
    /// The model: `model_file` if given, else the bundled `model`, else pin-cart II.
    pub fn model_spec(&self) -> Result<ModelSpec, ModelError> {
        match &self.model_file {
            Some(file) => ModelSpec::load(file),
            None => Ok(bundled(self.model.unwrap_or(ModelKind::Pincart2))),
        }
    }
}

impl Default for EmulatedConfig {
    fn default() -> Self {
        EmulatedConfig {
            model: None,
            model_file: None,
            noise_std_pct: 0.0,
            noise_seed: 1,
        }
    }
}
impl ValveConfig {
    /// The checks of `[valve]` and its sub-tables, for a loop of `[loop]` `timing`.
    pub(super) fn check_in(&self, c: &Check<'_>, timing: &LoopConfig) -> Result<(), TomlError> {
        self.emulated.check_in(c)?;
        self.registers.check_in(c.text, c.path, "valve.registers")?;
        let (table, settings) = match self.kind {
            ValveKind::Emulated => return Ok(()),
            ValveKind::ModbusTcp => (
                "valve.modbus-tcp",
                self.tcp.as_ref().map(|t| (t.violation(), t.timeout_ms)),
            ),
            ValveKind::ModbusRtu => (
                "valve.modbus-rtu",
                self.rtu.as_ref().map(|r| (r.violation(), r.timeout_ms)),
            ),
        };
        let Some((violation, timeout_ms)) = settings else {
            return Err(TomlError::Invalid {
                path: c.path.to_path_buf(),
                line: toml_file::line_of(c.text, Some("valve"), "kind").unwrap_or(1),
                key: table.to_string(),
                message: format!(
                    "kind = \"{}\" needs this table, e.g. {}",
                    self.kind.tag(),
                    if self.kind == ValveKind::ModbusTcp {
                        "address = \"127.0.0.1:5502\""
                    } else {
                        "port = \"/dev/ttyUSB0\""
                    }
                ),
            });
        };
        if let Some((key, message)) = violation {
            return Err(c.bad(table, key, message));
        }
        // The deadline must leave the loop its rhythm: a reply may take at most one period.
        let period_ms = timing.period_s() * 1e3;
        match timeout_ms {
            Some(t) if !(t.is_finite() && t > 0.0 && t < period_ms) => Err(c.bad(
                table,
                "timeout_ms",
                format!(
                    "{t} is not allowed: a deadline in ms, above 0 and below the loop \
                     period ({period_ms:.3} ms at rate_hz = {}); leave it out for 80 % of the period",
                    timing.rate_hz
                ),
            )),
            _ => Ok(()),
        }
    }
}

impl EmulatedConfig {
    /// The checks of `[valve.emulated]`: the noise, and a model that loads.
    fn check_in(&self, c: &Check<'_>) -> Result<(), TomlError> {
        let t = "valve.emulated";
        c.range(
            t,
            "noise_std_pct",
            self.noise_std_pct,
            0.0,
            100.0,
            "a noise standard deviation in %",
        )?;
        if self.model.is_some() && self.model_file.is_some() {
            return Err(c.bad(
                t,
                "model_file",
                "give either `model` (a bundled model) or `model_file`, not both".into(),
            ));
        }
        if let Err(err) = self.model_spec() {
            let file = self.model_file.clone().unwrap_or_default();
            return Err(c.bad(
                t,
                "model_file",
                format!("cannot use model file `{}`: {err} (a model file looks like config/models/pincart2.toml)", file.display()),
            ));
        }
        Ok(())
    }
}
