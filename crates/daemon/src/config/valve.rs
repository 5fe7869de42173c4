//! `[valve]`: which backend drives the valve and the settings of each kind (`[valve.emulated]`,
//! `[valve.modbus-tcp]`, `[valve.modbus-rtu]`, `[valve.registers]` over a `profile`), with their
//! checks; several valves are `[[valve]]` tables, each named, each with these sub-tables and
//! optionally a `[valve.source]` and a `[valve.compensation]` of its own.
//!
//! The file's table (`ValveTable`, private to the config) holds a `kind` and the tables of any
//! kind; its check turns it into a [`ValveConfig`] whose [`ValveSpec`] holds the chosen
//! backend's settings only: the emulated model, or a Modbus link with its [`Device`] (register
//! map resolved over the profile). A Modbus kind without its link table is refused there.
//!
//! Not here: opening the backend is [`crate::runtime::valve`]'s job, and the link settings
//! themselves are [`vb_modbus::link`]'s types.

use std::path::PathBuf;

use serde::Deserialize;
use toml::Spanned;

use super::source::SourceTable;
use super::{Check, LoopConfig, SourceConfig};
use vb_core::compensate::{CompensateError, CompensationConfig, Compensator};
use vb_core::model::{bundled, DriftSpec, ModelError, ModelKind, ModelSpec};
use vb_core::toml_file::TomlError;
use vb_modbus::link::{RtuLink, TcpLink};
use vb_modbus::map::{RegisterKeys, RegisterMap};
use vb_modbus::profile;

/// A checked valve: its name, its own source if any, and its backend with the settings of
/// that backend only.
#[derive(Debug, Clone)]
pub struct ValveConfig {
    /// The valve's name in logs, file names, metrics (label `valve`) and the summary; required
    /// with several valves.
    pub name: Option<String>,
    /// `[valve.source]`: this valve's source of O_P (default: `[source]`).
    pub source: Option<SourceConfig>,
    /// The backend in use and its settings.
    pub backend: ValveSpec,
    /// A model file whose answer to each window's O_P is the health baseline (default: the
    /// first window with enough steps).
    pub health_baseline_model: Option<PathBuf>,
    /// `[valve.compensation]`: the O_P compensated for the identified valve before it is sent.
    pub compensation: Option<CompensationConfig>,
}

/// The backend of a checked valve: one variant per `[valve] kind`, with that kind's settings.
#[derive(Debug, Clone)]
pub enum ValveSpec {
    /// `emulated`: a model from `config/models/` stepped once per cycle, `[valve.emulated]`.
    Emulated(EmulatedConfig),
    /// `modbus-tcp`: a positioner (or `sim-device`) over Modbus TCP, `[valve.modbus-tcp]`.
    ModbusTcp(TcpLink, Device),
    /// `modbus-rtu`: a positioner on a serial line, Modbus RTU, `[valve.modbus-rtu]`.
    ModbusRtu(RtuLink, Device),
}

impl ValveSpec {
    /// True for a simulated valve, which may run on the virtual clock.
    pub fn is_simulated(&self) -> bool {
        matches!(self, ValveSpec::Emulated(_))
    }

    /// The name of the kind in config files.
    pub fn tag(&self) -> &'static str {
        match self {
            ValveSpec::Emulated(_) => "emulated",
            ValveSpec::ModbusTcp(..) => "modbus-tcp",
            ValveSpec::ModbusRtu(..) => "modbus-rtu",
        }
    }
}

/// The positioner behind a Modbus link: the shipped profile the config names, if any, and the
/// register map in use (`[valve.registers]` over the profile's map, or over the default one).
#[derive(Debug, Clone)]
pub struct Device {
    /// A shipped register profile of a real device (`config/profiles/NAME.toml`).
    pub profile: Option<String>,
    /// The positioner's register map.
    pub registers: RegisterMap,
}

/// `[valve]` (or one `[[valve]]`) as the file has it: the backend in use and the tables of any
/// kind (field order is the order `expected one of` lists them in).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ValveTable {
    #[serde(default)]
    name: Option<String>,
    #[serde(default)]
    source: Option<SourceTable>,
    /// None: `emulated`.
    #[serde(default)]
    kind: Option<Spanned<ValveKind>>,
    #[serde(default)]
    emulated: EmulatedConfig,
    #[serde(rename = "modbus-tcp")]
    tcp: Option<TcpLink>,
    #[serde(rename = "modbus-rtu")]
    rtu: Option<RtuLink>,
    #[serde(default)]
    profile: Option<String>,
    /// `[valve.registers]` as written: each key given replaces the profile's (or the default).
    #[serde(default, rename = "registers")]
    register_keys: RegisterKeys,
    #[serde(default)]
    health_baseline_model: Option<PathBuf>,
    #[serde(default)]
    compensation: Option<CompensationConfig>,
}

/// `[valve] kind` as written (the names are [`ValveSpec::tag`]'s).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum ValveKind {
    /// A model from `config/models/` stepped once per cycle.
    Emulated,
    /// A positioner (or `sim-device`) over Modbus TCP, `[valve.modbus-tcp]`.
    ModbusTcp,
    /// A positioner on a serial line, Modbus RTU, `[valve.modbus-rtu]`.
    ModbusRtu,
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
    /// Dead time added to the model's, growing by this much per hour of loop time, s/h (a
    /// wearing valve; 0 = none).
    pub dead_time_drift_s_per_h: f64,
    /// The most dead time the drift adds, s.
    pub dead_time_drift_max_s: f64,
    /// The friction band (pin-cart models) widening by this much per hour of loop time, % of
    /// travel per hour (0 = none).
    pub friction_band_drift_pct_per_h: f64,
    /// The most the friction band widens, %.
    pub friction_band_drift_max_pct: f64,
}

impl EmulatedConfig {
    /// The model: `model_file` if given, else the bundled `model`, else pin-cart II.
    pub fn model_spec(&self) -> Result<ModelSpec, ModelError> {
        match &self.model_file {
            Some(file) => ModelSpec::load(file),
            None => Ok(bundled(self.model.unwrap_or(ModelKind::Pincart2))),
        }
    }

    /// The valve's wear ([`vb_core::model::drift`]).
    pub fn drift(&self) -> DriftSpec {
        DriftSpec {
            dead_time_drift_s_per_h: self.dead_time_drift_s_per_h,
            dead_time_drift_max_s: self.dead_time_drift_max_s,
            friction_band_drift_pct_per_h: self.friction_band_drift_pct_per_h,
            friction_band_drift_max_pct: self.friction_band_drift_max_pct,
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
            dead_time_drift_s_per_h: DriftSpec::default().dead_time_drift_s_per_h,
            dead_time_drift_max_s: DriftSpec::default().dead_time_drift_max_s,
            friction_band_drift_pct_per_h: DriftSpec::default().friction_band_drift_pct_per_h,
            friction_band_drift_max_pct: DriftSpec::default().friction_band_drift_max_pct,
        }
    }
}
/// The name a valve without `name` goes by.
pub const UNNAMED: &str = "valve";

/// One default valve, for a config without any `[valve]` table.
pub(super) fn one_default() -> Vec<ValveTable> {
    vec![ValveTable::default()]
}

/// Reads `valve` as one `[valve]` table or as `[[valve]]` tables, keeping the errors (and
/// their lines) of either form.
pub(super) fn one_or_many<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Vec<ValveTable>, D::Error> {
    struct OneOrMany;
    impl<'de> serde::de::Visitor<'de> for OneOrMany {
        type Value = Vec<ValveTable>;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a [valve] table or [[valve]] tables")
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
            let one = ValveTable::deserialize(serde::de::value::MapAccessDeserializer::new(map))?;
            Ok(vec![one])
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
            Vec::deserialize(serde::de::value::SeqAccessDeserializer::new(seq))
        }
    }
    d.deserialize_any(OneOrMany)
}

/// The checks of every valve: names (required, distinct and fit for file names with several
/// valves), then each valve's tables and its own source (never the controller's server, which
/// is the top `[source]`), at their lines; the checked valves.
pub(super) fn check_all(
    valves: Vec<ValveTable>,
    c: &Check<'_>,
    timing: &LoopConfig,
) -> Result<Vec<ValveConfig>, TomlError> {
    let several = valves.len() > 1;
    let check_of = |i: usize| c.valve(i);
    let mut seen: Vec<String> = Vec::new();
    let count = valves.len();
    let mut checked = Vec::with_capacity(count);
    for (i, v) in valves.into_iter().enumerate() {
        let vc = check_of(i);
        match &v.name {
            None if several => {
                return Err(vc.bad(
                    "valve",
                    "",
                    format!("valve {} of {count} has no name: with several [[valve]] tables each needs name = \"...\" (e.g. \"level\")", i + 1),
                ))
            }
            None => {}
            Some(name) => {
                let fit = !name.is_empty()
                    && name.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '-' || ch == '_');
                if !fit {
                    return Err(vc.bad("valve", "name", format!("`{name}`: a name is letters, digits, `-` and `_` (it names the log files and the metrics' `valve` label)")));
                }
                if seen.contains(name) {
                    return Err(vc.bad("valve", "name", format!("`{name}` names two valves: give each its own name")));
                }
                seen.push(name.clone());
            }
        }
        let valve = v.check(&vc, timing)?;
        if (valve.source.as_ref()).is_some_and(|s| s.server().is_some()) {
            return Err(vc.bad(
                "valve.source",
                "kind",
                format!("valve `{}`: the process controller's server is the [source] table (kind = \"modbus-server\"), one for every valve it drives: leave this valve's [valve.source] out to have the controller drive it", valve.label()),
            ));
        }
        checked.push(valve);
    }
    super::bus::check(&checked, check_of, timing)?;
    Ok(checked)
}

impl ValveConfig {
    /// The name the valve goes by (`valve` when it has none).
    pub fn label(&self) -> &str {
        self.name.as_deref().unwrap_or(UNNAMED)
    }
}

impl ValveTable {
    /// The checks of `[valve]` and its sub-tables (its own `[valve.source]` last), for a loop
    /// of `[loop]` `timing`: the checked valve, its register map resolved.
    fn check(self, c: &Check<'_>, timing: &LoopConfig) -> Result<ValveConfig, TomlError> {
        self.emulated.check_in(c)?;
        if let Some(file) = &self.health_baseline_model {
            if let Err(err) = ModelSpec::load(file) {
                return Err(c.bad(
                    "valve",
                    "health_baseline_model",
                    format!("cannot use model file `{}`: {err} (a model file looks like config/models/pincart2.toml; `identify --out` writes them)", file.display()),
                ));
            }
        }
        if let Some(comp) = &self.compensation {
            check_compensation(comp, c, timing)?;
        }
        let device = Device {
            registers: self.register_map(c)?,
            profile: self.profile,
        };
        // The line of `kind`; only a kind written out can lack its table.
        let (kind, line) = match &self.kind {
            Some(k) => (*k.get_ref(), c.line_at(k.span())),
            None => (ValveKind::Emulated, 1),
        };
        let backend = match kind {
            ValveKind::Emulated => ValveSpec::Emulated(self.emulated),
            ValveKind::ModbusTcp => {
                let example = "address = \"127.0.0.1:5502\"";
                let link = self
                    .tcp
                    .ok_or_else(|| no_link(c, line, "modbus-tcp", example))?;
                check_link(
                    c,
                    "valve.modbus-tcp",
                    link.violation(),
                    link.timeout_ms,
                    timing,
                )?;
                ValveSpec::ModbusTcp(link, device)
            }
            ValveKind::ModbusRtu => {
                let example = "port = \"/dev/ttyUSB0\"";
                let link = self
                    .rtu
                    .ok_or_else(|| no_link(c, line, "modbus-rtu", example))?;
                check_link(
                    c,
                    "valve.modbus-rtu",
                    link.violation(),
                    link.timeout_ms,
                    timing,
                )?;
                ValveSpec::ModbusRtu(link, device)
            }
        };
        let source = match self.source {
            Some(s) => Some(s.check(&c.under("valve."), timing)?),
            None => None,
        };
        Ok(ValveConfig {
            name: self.name,
            source,
            backend,
            health_baseline_model: self.health_baseline_model,
            compensation: self.compensation,
        })
    }
}

/// The refusal of `kind = "<tag>"` (at `line`) without its `[valve.<tag>]` table; `example`
/// is a key of it.
fn no_link(c: &Check<'_>, line: usize, tag: &str, example: &str) -> TomlError {
    let message = format!("kind = \"{tag}\" needs this table, e.g. {example}");
    c.bad_on(line, "valve", tag, message)
}

/// The checks of the link table `table`: its settings' `violation`, and a deadline
/// `timeout_ms` that leaves a loop of `[loop]` `timing` its rhythm.
fn check_link(
    c: &Check<'_>,
    table: &str,
    violation: Option<(&'static str, String)>,
    timeout_ms: Option<f64>,
    timing: &LoopConfig,
) -> Result<(), TomlError> {
    if let Some((key, message)) = violation {
        return Err(c.bad(table, key, message));
    }
    // A reply may take at most one period.
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

impl ValveTable {
    /// `[valve.registers]` over the profile's map (or the default map), checked.
    fn register_map(&self, c: &Check<'_>) -> Result<RegisterMap, TomlError> {
        let section = "valve.registers";
        let Some(name) = &self.profile else {
            let map = RegisterMap::from(self.register_keys);
            map.check_in(c.lines, c.path, section)?;
            return Ok(map);
        };
        match profile::find(name) {
            None => Err(c.bad("valve", "profile", profile::unknown(name))),
            Some(found) => found?.under(&self.register_keys, c.lines, c.path, section),
        }
    }
}

/// The checks of `[valve.compensation]`: its settings, and a model a compensator can use.
fn check_compensation(
    comp: &CompensationConfig,
    c: &Check<'_>,
    timing: &LoopConfig,
) -> Result<(), TomlError> {
    let t = "valve.compensation";
    if let Some((key, message)) = comp.violation() {
        return Err(c.bad(t, key, message));
    }
    let file = comp.model_file.clone().unwrap_or_default();
    let built = ModelSpec::load(&file)
        .map_err(CompensateError::from)
        .and_then(|m| Compensator::new(comp, &m, timing.period_s(), (0.0, 100.0)));
    match built {
        Ok(_) => Ok(()),
        Err(err) => Err(c.bad(
            t,
            "model_file",
            format!("cannot use model file `{}`: {err}", file.display()),
        )),
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
        let model = self
            .model_spec()
            .map(|s| s.model)
            .unwrap_or(ModelKind::Pincart2);
        match self.drift().violation(model) {
            Some(v) => Err(c.bad(
                t,
                v.key,
                format!(
                    "{} is not allowed: {}",
                    vb_core::human::num(v.value),
                    v.allowed
                ),
            )),
            None => Ok(()),
        }
    }
}
