//! The daemon's TOML configuration: types, defaults, range checks and the embedded default.
//!
//! A config has the tables `[loop]`, `[valve]`, `[source]`, `[safety]`, `[log]` and `[metrics]`,
//! all optional (no `[metrics]`: no Prometheus endpoint).
//! `[valve] kind = ...` and `[source] kind = ...` pick a backend and an O_P source; the settings of
//! each kind live in their own sub-table (`[valve.emulated]`, `[source.sine]`, ...), so a file
//! can keep settings for several kinds and switch with one line, and every key keeps its exact
//! line in error messages. Every error names the file, the line and the dotted key, and says
//! what is allowed. Loading also resolves what the config points at (the model file, the
//! replayed recording), so a missing file is reported against the key that names it.
//!
//! This module does not run anything; [`crate::daemon`] builds the loop from a [`Config`].

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use super::hil;
use crate::modbus::link::{RtuLink, TcpLink};
use crate::modbus::map::{RegisterMap, StatusRegister, Table};
use crate::model::{bundled, ModelError, ModelKind, ModelSpec};
use crate::recording::{self, ColumnMap, ReadOptions, RecordingError};
/// The settings of the generated sources (`[source.random-steps]`, `[source.steps]`, ...) are
/// the parameters of the generators in [`crate::signal`].
pub use crate::signal::{
    ConstantParams as ConstantConfig, PrbsParams as PrbsConfig, RampParams as RampConfig,
    RandomStepsParams as RandomStepsConfig, SineParams as SineConfig, StepsParams as StepsConfig,
};
use crate::toml_file::{self, TomlError};

/// The default configuration, `config/emulated.toml`, embedded so default == file by construction.
pub const DEFAULT_TOML: &str = include_str!("../../config/emulated.toml");

/// The name the embedded default goes by in messages.
pub const DEFAULT_LABEL: &str = "config/emulated.toml (embedded default)";

/// A whole daemon configuration, checked and resolved.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Loop rate and clock.
    #[serde(rename = "loop", default)]
    pub loop_: LoopConfig,
    /// The valve backend.
    #[serde(default)]
    pub valve: ValveConfig,
    /// The source of O_P.
    #[serde(default)]
    pub source: SourceConfig,
    /// What to do on stop.
    #[serde(default)]
    pub safety: SafetyConfig,
    /// The CSV log.
    #[serde(default)]
    pub log: LogConfig,
    /// The Prometheus endpoint, if any.
    pub metrics: Option<MetricsConfig>,
}

/// `[loop]`: rate and clock.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Cycles per second, 1-1000.
    pub rate_hz: f64,
    /// Real (wall) clock or virtual clock (as fast as possible).
    pub clock: ClockKind,
    /// The loop sleeps until `spin_us` before each deadline, then busy-waits, 0-2000 µs.
    pub spin_us: u32,
    /// SCHED_FIFO priority of the loop thread, 1-99; 0 keeps the normal scheduler.
    pub realtime_priority: u8,
}

impl Default for LoopConfig {
    fn default() -> Self {
        LoopConfig {
            rate_hz: 100.0,
            clock: ClockKind::Real,
            spin_us: 200,
            realtime_priority: 0,
        }
    }
}

impl LoopConfig {
    /// The loop period, rounded to whole nanoseconds (the grid's unit).
    pub fn period(&self) -> std::time::Duration {
        std::time::Duration::from_nanos((1e9 / self.rate_hz).round() as u64)
    }

    /// The loop period in seconds.
    pub fn period_s(&self) -> f64 {
        self.period().as_secs_f64()
    }
}

/// Which clock drives the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockKind {
    /// Cycles start on the wall clock, on an absolute 1/rate grid.
    Real,
    /// Cycles run back to back on a simulated clock (tests, offline runs).
    Virtual,
}

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

/// `[source]`: the kind of O_P source, the clamp range, and the settings of each kind.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SourceConfig {
    /// The source in use.
    pub kind: SourceKind,
    /// Lowest O_P ever sent, %.
    pub op_min_pct: f64,
    /// Highest O_P ever sent, %.
    pub op_max_pct: f64,
    /// `[source.random-steps]`.
    #[serde(rename = "random-steps")]
    pub random_steps: RandomStepsConfig,
    /// `[source.steps]`.
    pub steps: Option<StepsConfig>,
    /// `[source.ramp]`.
    pub ramp: RampConfig,
    /// `[source.sine]`.
    pub sine: SineConfig,
    /// `[source.prbs]`.
    pub prbs: PrbsConfig,
    /// `[source.replay]`.
    pub replay: Option<ReplayConfig>,
    /// `[source.constant]`.
    pub constant: Option<ConstantConfig>,
    /// `[source.modbus-server]`.
    #[serde(rename = "modbus-server")]
    pub modbus_server: ModbusServerConfig,
}

impl Default for SourceConfig {
    fn default() -> Self {
        SourceConfig {
            kind: SourceKind::RandomSteps,
            op_min_pct: 0.0,
            op_max_pct: 100.0,
            random_steps: RandomStepsConfig::default(),
            steps: None,
            ramp: RampConfig::default(),
            sine: SineConfig::default(),
            prbs: PrbsConfig::default(),
            replay: None,
            constant: None,
            modbus_server: ModbusServerConfig::default(),
        }
    }
}

/// O_P sources.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SourceKind {
    /// The paper's experiment: random levels held for random times.
    RandomSteps,
    /// A list of levels, each held for the same time.
    Steps,
    /// A linear ramp (or triangle).
    Ramp,
    /// A sine wave.
    Sine,
    /// A pseudo-random binary signal.
    Prbs,
    /// The O_P column of a recording.
    Replay,
    /// One fixed O_P.
    Constant,
    /// Whatever a process controller writes into the daemon's Modbus TCP server (HIL).
    ModbusServer,
}

impl SourceKind {
    /// The name used in config files.
    pub fn tag(self) -> &'static str {
        match self {
            SourceKind::RandomSteps => "random-steps",
            SourceKind::Steps => "steps",
            SourceKind::Ramp => "ramp",
            SourceKind::Sine => "sine",
            SourceKind::Prbs => "prbs",
            SourceKind::Replay => "replay",
            SourceKind::Constant => "constant",
            SourceKind::ModbusServer => "modbus-server",
        }
    }
}

/// `[source.replay]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplayConfig {
    /// The recording whose O_P column is replayed.
    pub file: PathBuf,
    /// Its O_P held onto the loop grid (slot k = index k), resolved at load time.
    #[serde(skip)]
    pub op_pct: Arc<Vec<f64>>,
}

/// `[source.modbus-server]`: the Modbus TCP server a process controller writes O_P into.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ModbusServerConfig {
    /// Address to serve on; loopback unless set otherwise here.
    pub listen: ListenAddr,
    /// No accepted set-point write for this long applies the `[safety]` action, s.
    pub watchdog_s: f64,
    /// O_P before the controller's first write, % (default: `[safety] go_to_pct` with
    /// `on_stop = "go-to"`, else `[source] op_min_pct`).
    pub initial_pct: Option<f64>,
    /// `[source.modbus-server.registers]`: the map served (default: per-mille set-point in
    /// holding 0, position in holding 1, status in holding 2).
    pub registers: RegisterMap,
}

impl Default for ModbusServerConfig {
    fn default() -> Self {
        ModbusServerConfig {
            listen: ListenAddr(SocketAddr::from(([127, 0, 0, 1], 5020))),
            watchdog_s: 1.0,
            initial_pct: None,
            registers: RegisterMap {
                status: Some(StatusRegister {
                    table: Table::Holding,
                    address: 2,
                    setpoint_error_bit: 0,
                }),
                ..RegisterMap::default()
            },
        }
    }
}

/// `[metrics]`: the Prometheus endpoint.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MetricsConfig {
    /// Address of the HTTP endpoint (`GET /metrics`).
    pub listen: ListenAddr,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig {
            listen: ListenAddr(SocketAddr::from(([127, 0, 0, 1], 9100))),
        }
    }
}

/// An `IP:port` to listen on, from a string such as `"127.0.0.1:5020"` (names are not resolved).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ListenAddr(pub SocketAddr);

impl<'de> Deserialize<'de> for ListenAddr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        text.parse().map(ListenAddr).map_err(|_| {
            serde::de::Error::custom(format!(
                "`{text}` is not an IP address and port: write e.g. \"127.0.0.1:5020\" \
                 (host names are not resolved; \"0.0.0.0:5020\" serves every interface)"
            ))
        })
    }
}

/// `[safety]`.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyConfig {
    /// What the valve gets when the loop stops.
    #[serde(default)]
    pub on_stop: OnStop,
    /// The O_P sent on stop with `on_stop = "go-to"`, %.
    #[serde(default)]
    pub go_to_pct: Option<f64>,
}

/// The safe action applied when the loop stops.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnStop {
    /// Send the last O_P once more.
    #[default]
    Hold,
    /// Send `go_to_pct`.
    GoTo,
}

/// `[log]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogConfig {
    /// Directory of the CSV files (created if missing).
    pub dir: PathBuf,
    /// Rotate when a file reaches this size, MB.
    pub rotate_size_mb: f64,
    /// Rotate when a file has covered this much loop time, s.
    pub rotate_after_s: f64,
    /// Flush at least this often, ms (10-1000).
    pub flush_interval_ms: u64,
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            dir: PathBuf::from("./logs"),
            rotate_size_mb: 100.0,
            rotate_after_s: 3600.0,
            flush_interval_ms: 1000,
        }
    }
}

impl Config {
    /// Loads `path`, or the embedded default when `path` is None; checked and resolved.
    pub fn load(path: Option<&Path>) -> Result<Config, TomlError> {
        match path {
            Some(p) => {
                let (config, text): (Config, String) = toml_file::load(p)?;
                config.resolve(&text, p)
            }
            None => Config::from_toml(DEFAULT_TOML, Path::new(DEFAULT_LABEL)),
        }
    }

    /// The embedded default configuration.
    pub fn embedded_default() -> Result<Config, TomlError> {
        Config::load(None)
    }

    /// Parses, checks and resolves TOML `text` (`label` names it in messages).
    pub fn from_toml(text: &str, label: &Path) -> Result<Config, TomlError> {
        let config: Config = toml_file::parse(text, label)?;
        config.resolve(text, label)
    }

    /// Range checks, then loads the model and the replayed recording.
    fn resolve(mut self, text: &str, path: &Path) -> Result<Config, TomlError> {
        let bad = |table: &str, key: &str, message: String| {
            toml_file::invalid(text, path, Some(table), key, message)
        };
        let range = |table: &str, key: &str, value: f64, lo: f64, hi: f64, what: &str| {
            if value.is_finite() && (lo..=hi).contains(&value) {
                Ok(())
            } else {
                Err(bad(
                    table,
                    key,
                    format!("{value} is out of range: {what}, {lo} to {hi}"),
                ))
            }
        };

        let l = &self.loop_;
        range(
            "loop",
            "rate_hz",
            l.rate_hz,
            1.0,
            1000.0,
            "a loop rate in Hz",
        )?;
        range(
            "loop",
            "spin_us",
            f64::from(l.spin_us),
            0.0,
            2000.0,
            "a busy-wait margin in µs",
        )?;
        range(
            "loop",
            "realtime_priority",
            f64::from(l.realtime_priority),
            0.0,
            99.0,
            "a SCHED_FIFO priority (0 = normal scheduling)",
        )?;

        let e = &self.valve.emulated;
        range(
            "valve.emulated",
            "noise_std_pct",
            e.noise_std_pct,
            0.0,
            100.0,
            "a noise standard deviation in %",
        )?;
        if e.model.is_some() && e.model_file.is_some() {
            return Err(bad(
                "valve.emulated",
                "model_file",
                "give either `model` (a bundled model) or `model_file`, not both".into(),
            ));
        }
        if let Err(err) = e.model_spec() {
            let file = e.model_file.clone().unwrap_or_default();
            return Err(bad(
                "valve.emulated",
                "model_file",
                format!("cannot use model file `{}`: {err} (a model file looks like config/models/pincart2.toml)", file.display()),
            ));
        }

        self.valve
            .registers
            .check_in(text, path, "valve.registers")?;
        let link = match self.valve.kind {
            ValveKind::Emulated => None,
            ValveKind::ModbusTcp => Some((
                "valve.modbus-tcp",
                self.valve
                    .tcp
                    .as_ref()
                    .map(|t| (t.violation(), t.timeout_ms)),
            )),
            ValveKind::ModbusRtu => Some((
                "valve.modbus-rtu",
                self.valve
                    .rtu
                    .as_ref()
                    .map(|r| (r.violation(), r.timeout_ms)),
            )),
        };
        if let Some((table, settings)) = link {
            let Some((violation, timeout_ms)) = settings else {
                return Err(TomlError::Invalid {
                    path: path.to_path_buf(),
                    line: toml_file::line_of(text, Some("valve"), "kind").unwrap_or(1),
                    key: table.to_string(),
                    message: format!(
                        "kind = \"{}\" needs this table, e.g. {}",
                        self.valve.kind.tag(),
                        if self.valve.kind == ValveKind::ModbusTcp {
                            "address = \"127.0.0.1:5502\""
                        } else {
                            "port = \"/dev/ttyUSB0\""
                        }
                    ),
                });
            };
            if let Some((key, message)) = violation {
                return Err(bad(table, key, message));
            }
            // The deadline must leave the loop its rhythm: a reply may take at most one period.
            let period_ms = l.period_s() * 1e3;
            if let Some(t) = timeout_ms {
                if !(t.is_finite() && t > 0.0 && t < period_ms) {
                    return Err(bad(
                        table,
                        "timeout_ms",
                        format!(
                            "{t} is not allowed: a deadline in ms, above 0 and below the loop \
                             period ({period_ms} ms at rate_hz = {}); leave it out for 80 % of the period",
                            l.rate_hz
                        ),
                    ));
                }
            }
        }

        let s = &self.source;
        range(
            "source",
            "op_min_pct",
            s.op_min_pct,
            0.0,
            100.0,
            "an opening in %",
        )?;
        range(
            "source",
            "op_max_pct",
            s.op_max_pct,
            0.0,
            100.0,
            "an opening in %",
        )?;
        if s.op_min_pct >= s.op_max_pct {
            return Err(bad(
                "source",
                "op_max_pct",
                format!("must be above op_min_pct = {}", s.op_min_pct),
            ));
        }
        let missing = |table: &str, example: &str| {
            bad(
                "source",
                "kind",
                format!(
                    "kind = \"{}\" needs a [source.{table}] table, e.g. {example}",
                    s.kind.tag()
                ),
            )
        };
        match s.kind {
            SourceKind::RandomSteps => {
                let r = &s.random_steps;
                let t = "source.random-steps";
                range(t, "min_pct", r.min_pct, 0.0, 100.0, "a level in %")?;
                range(
                    t,
                    "max_pct",
                    r.max_pct,
                    r.min_pct,
                    100.0,
                    "a level in %, at least min_pct",
                )?;
                range(
                    t,
                    "hold_min_s",
                    r.hold_min_s,
                    0.0,
                    86_400.0,
                    "a hold time in s",
                )?;
                range(
                    t,
                    "hold_max_s",
                    r.hold_max_s,
                    r.hold_min_s.max(1e-3),
                    86_400.0,
                    "a hold time in s, above hold_min_s",
                )?;
            }
            SourceKind::Steps => {
                let st = s
                    .steps
                    .as_ref()
                    .ok_or_else(|| missing("steps", "levels_pct = [30.0, 60.0], hold_s = 5.0"))?;
                if st.levels_pct.is_empty() {
                    return Err(bad(
                        "source.steps",
                        "levels_pct",
                        "give at least one level, e.g. [30.0, 60.0]".into(),
                    ));
                }
                for &v in &st.levels_pct {
                    range(
                        "source.steps",
                        "levels_pct",
                        v,
                        0.0,
                        100.0,
                        "each level in %",
                    )?;
                }
                range(
                    "source.steps",
                    "hold_s",
                    st.hold_s,
                    1e-3,
                    86_400.0,
                    "a hold time in s",
                )?;
            }
            SourceKind::Ramp => {
                let r = &s.ramp;
                range(
                    "source.ramp",
                    "from_pct",
                    r.from_pct,
                    0.0,
                    100.0,
                    "a level in %",
                )?;
                range(
                    "source.ramp",
                    "to_pct",
                    r.to_pct,
                    0.0,
                    100.0,
                    "a level in %",
                )?;
                range(
                    "source.ramp",
                    "duration_s",
                    r.duration_s,
                    1e-3,
                    86_400.0,
                    "a ramp time in s",
                )?;
            }
            SourceKind::Sine => {
                let w = &s.sine;
                range(
                    "source.sine",
                    "mean_pct",
                    w.mean_pct,
                    0.0,
                    100.0,
                    "a level in %",
                )?;
                range(
                    "source.sine",
                    "amplitude_pct",
                    w.amplitude_pct,
                    0.0,
                    100.0,
                    "an amplitude in %",
                )?;
                range(
                    "source.sine",
                    "period_s",
                    w.period_s,
                    1e-3,
                    86_400.0,
                    "a period in s",
                )?;
            }
            SourceKind::Prbs => {
                let p = &s.prbs;
                range(
                    "source.prbs",
                    "mean_pct",
                    p.mean_pct,
                    0.0,
                    100.0,
                    "a level in %",
                )?;
                range(
                    "source.prbs",
                    "amplitude_pct",
                    p.amplitude_pct,
                    0.0,
                    100.0,
                    "an amplitude in %",
                )?;
                let nyquist = l.rate_hz / 2.0;
                range(
                    "source.prbs",
                    "band_hz",
                    p.band_hz,
                    1e-4,
                    nyquist,
                    "a frequency in Hz up to half the loop rate",
                )?;
            }
            SourceKind::Replay => {
                let r = s
                    .replay
                    .as_ref()
                    .ok_or_else(|| missing("replay", "file = \"recording.csv\""))?;
                let op = load_replay(&r.file, self.loop_.period_s()).map_err(|m| {
                    bad(
                        "source.replay",
                        "file",
                        format!("cannot replay `{}`: {m}", r.file.display()),
                    )
                })?;
                if let Some(r) = self.source.replay.as_mut() {
                    r.op_pct = Arc::new(op);
                }
            }
            SourceKind::Constant => {
                let c = s
                    .constant
                    .as_ref()
                    .ok_or_else(|| missing("constant", "op_pct = 50.0"))?;
                range(
                    "source.constant",
                    "op_pct",
                    c.op_pct,
                    0.0,
                    100.0,
                    "an opening in %",
                )?;
            }
            SourceKind::ModbusServer => self.check_modbus_server(text, path)?,
        }

        if self.safety.on_stop == OnStop::GoTo {
            match self.safety.go_to_pct {
                None => {
                    return Err(bad(
                        "safety",
                        "on_stop",
                        "on_stop = \"go-to\" needs go_to_pct = <an opening in %>".into(),
                    ))
                }
                Some(v) => range("safety", "go_to_pct", v, 0.0, 100.0, "an opening in %")?,
            }
        }

        let g = &self.log;
        range(
            "log",
            "rotate_size_mb",
            g.rotate_size_mb,
            0.001,
            1e6,
            "a file size in MB",
        )?;
        range(
            "log",
            "rotate_after_s",
            g.rotate_after_s,
            1.0,
            1e7,
            "a file duration in s",
        )?;
        range(
            "log",
            "flush_interval_ms",
            g.flush_interval_ms as f64,
            10.0,
            1000.0,
            "a flush interval in ms",
        )?;
        if let (Some(m), SourceKind::ModbusServer) = (&self.metrics, self.source.kind) {
            let hil = self.source.modbus_server.listen.0;
            if m.listen.0 == hil && hil.port() != 0 {
                return Err(bad(
                    "metrics",
                    "listen",
                    format!("{hil} is also [source.modbus-server] listen: give the endpoint its own port, e.g. \"127.0.0.1:9100\""),
                ));
            }
        }
        Ok(self)
    }

    /// The checks of `[source.modbus-server]`, when it is the source.
    fn check_modbus_server(&self, text: &str, path: &Path) -> Result<(), TomlError> {
        let t = "source.modbus-server";
        let bad = |table: &str, key: &str, message: String| {
            toml_file::invalid(text, path, Some(table), key, message)
        };
        let m = &self.source.modbus_server;
        if self.loop_.clock == ClockKind::Virtual {
            return Err(bad(
                "loop",
                "clock",
                "\"virtual\" cannot serve a process controller, which runs on the wall clock: \
                 use clock = \"real\" with [source] kind = \"modbus-server\""
                    .into(),
            ));
        }
        if !(m.watchdog_s.is_finite() && m.watchdog_s > 0.0 && m.watchdog_s <= 3600.0) {
            return Err(bad(
                t,
                "watchdog_s",
                format!(
                    "{} is not allowed: the time without a set-point write after which the \
                     [safety] action applies, above 0 and at most 3600 s, e.g. 1.0",
                    m.watchdog_s
                ),
            ));
        }
        if let Some(v) = m.initial_pct {
            if !(v.is_finite() && (0.0..=100.0).contains(&v)) {
                return Err(bad(
                    t,
                    "initial_pct",
                    format!("{v} is out of range: the O_P before the first write, an opening in %, 0 to 100"),
                ));
            }
        }
        let section = "source.modbus-server.registers";
        m.registers.check_in(text, path, section)?;
        if let Some(st) = m.registers.status {
            let bit = st.setpoint_error_bit;
            if bit == hil::VALVE_FAULT_BIT || bit == hil::WATCHDOG_BIT {
                return Err(TomlError::Invalid {
                    path: path.to_path_buf(),
                    line: toml_file::line_of(text, Some(section), "status")
                        .or_else(|| toml_file::line_of(text, Some(section), ""))
                        .unwrap_or(1),
                    key: format!("{section}.status.setpoint_error_bit"),
                    message: format!(
                        "{bit} is taken: the daemon reports a valve fault in bit {} and the \
                         watchdog in bit {} of the status register; use 0 or 3-15",
                        hil::VALVE_FAULT_BIT,
                        hil::WATCHDOG_BIT
                    ),
                });
            }
        }
        Ok(())
    }
}

/// The O_P column of a recording (V_P is not read, so a log with failed reads replays too),
/// held onto a grid of `period_s` from its first row.
fn load_replay(file: &Path, period_s: f64) -> Result<Vec<f64>, RecordingError> {
    let opts = ReadOptions {
        columns: ColumnMap {
            vp: None,
            ..ColumnMap::default()
        },
        ..ReadOptions::default()
    };
    let rec = recording::read(file, &opts)?;
    Ok(recording::resample_zoh(&rec.t, &rec.op, period_s))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(text: &str) -> String {
        Config::from_toml(text, Path::new("c.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn shipped_file_is_the_embedded_default_and_states_the_defaults() {
        let on_disk =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/config/emulated.toml"))
                .unwrap();
        assert_eq!(on_disk, DEFAULT_TOML);
        // Every value the file shows is the value an empty config gets.
        let shipped = Config::embedded_default().unwrap();
        let mut empty = Config::from_toml("", Path::new("empty.toml")).unwrap();
        // No `model` means pin-cart II; the file says so explicitly.
        empty.valve.emulated.model = Some(ModelKind::Pincart2);
        assert_eq!(format!("{shipped:?}"), format!("{empty:?}"));
        assert_eq!(shipped.loop_.rate_hz, 100.0);
        assert_eq!(shipped.source.kind, SourceKind::RandomSteps);
        assert_eq!(
            shipped.valve.emulated.model_spec().unwrap().model,
            ModelKind::Pincart2
        );
        assert_eq!(shipped.log.dir, PathBuf::from("./logs"));
    }

    #[test]
    fn commented_examples_in_the_shipped_file_are_valid() {
        // Uncomment the example tables of the other sources and use each in turn.
        let start = DEFAULT_TOML.find("# [source.steps]").unwrap();
        let end = DEFAULT_TOML.find("[safety]").unwrap();
        let examples: String = DEFAULT_TOML[start..end]
            .lines()
            .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
            .collect::<Vec<_>>()
            .join("\n");
        let text = format!(
            "{}{examples}\n{}",
            &DEFAULT_TOML[..start],
            &DEFAULT_TOML[end..]
        );
        for kind in ["random-steps", "steps", "ramp", "sine", "prbs", "constant"] {
            let t = text.replace("kind = \"random-steps\"", &format!("kind = \"{kind}\""));
            let c = Config::from_toml(&t, Path::new("examples.toml")).unwrap();
            assert_eq!(c.source.kind.tag(), kind);
        }
        let t = text.replace("kind = \"random-steps\"", "kind = \"replay\"");
        let e = Config::from_toml(&t, Path::new("examples.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("source.replay.file: cannot replay `recording.csv`"),
            "{e}"
        );
    }

    #[test]
    fn errors_name_file_line_key_and_what_is_allowed() {
        let e = err("[loop]\nrate_hz = 5000.0\n");
        assert!(
            e.starts_with("c.toml:2: loop.rate_hz: 5000 is out of range"),
            "{e}"
        );
        assert!(e.contains("1 to 1000"), "{e}");
        let e = err("[loop]\nrate_hz = 100.0\nrat = 1\n");
        assert!(
            e.starts_with("c.toml:3: loop.rat: unknown field `rat`"),
            "{e}"
        );
        let e = err("[source.sine]\nperiod_s = \"long\"\n");
        assert!(
            e.starts_with("c.toml:2: source.sine.period_s: invalid type"),
            "{e}"
        );
        let e = err("[valve.emulated]\nmodel_file = \"no/such/model.toml\"\n");
        assert!(
            e.starts_with(
                "c.toml:2: valve.emulated.model_file: cannot use model file `no/such/model.toml`"
            ),
            "{e}"
        );
        let e = err("[source]\nkind = \"steps\"\n");
        assert!(
            e.starts_with("c.toml:2: source.kind: kind = \"steps\" needs a [source.steps] table"),
            "{e}"
        );
        let e = err("[safety]\non_stop = \"go-to\"\n");
        assert!(
            e.starts_with("c.toml:2: safety.on_stop: on_stop = \"go-to\" needs go_to_pct"),
            "{e}"
        );
        let e = err("[source]\nkind = \"noise\"\n");
        assert!(
            e.contains("source.kind: unknown variant `noise`, expected one of"),
            "{e}"
        );
        let e = err("[source]\nop_min_pct = 60.0\nop_max_pct = 50.0\n");
        assert!(
            e.starts_with("c.toml:3: source.op_max_pct: must be above op_min_pct"),
            "{e}"
        );
        let e = err("[source]\nkind = \"prbs\"\n[source.prbs]\nband_hz = 80.0\n");
        assert!(
            e.starts_with("c.toml:4: source.prbs.band_hz: 80 is out of range"),
            "{e}"
        );
        assert!(!e.contains('\n'), "{e}");
    }

    #[test]
    fn modbus_server_and_metrics_errors_name_their_key() {
        let hil = "[source]\nkind = \"modbus-server\"\n";
        let cases = [
            (
                format!("{hil}[source.modbus-server]\nlisten = \"localhost:5020\"\n"),
                "c.toml:4: source.modbus-server.listen: `localhost:5020` is not an IP address and port",
            ),
            (
                format!("{hil}[source.modbus-server]\nwatchdog_s = 0.0\n"),
                "c.toml:4: source.modbus-server.watchdog_s: 0 is not allowed",
            ),
            (
                format!("{hil}[source.modbus-server]\ninitial_pct = 120.0\n"),
                "c.toml:4: source.modbus-server.initial_pct: 120 is out of range",
            ),
            (
                format!("{hil}op_min_pct = 50.0\nop_max_pct = 50.0\n"),
                "c.toml:4: source.op_max_pct: must be above op_min_pct",
            ),
            (
                format!("{hil}[source.modbus-server.registers]\nstatus = {{ address = 2, setpoint_error_bit = 2 }}\n"),
                "c.toml:4: source.modbus-server.registers.status.setpoint_error_bit: 2 is taken",
            ),
            (
                format!("{hil}[source.modbus-server.registers]\nposition = {{ address = 0, format = \"i16\" }}\n"),
                "c.toml:4: source.modbus-server.registers.position.address: 0 overlaps setpoint",
            ),
            (
                format!("[loop]\nclock = \"virtual\"\n{hil}"),
                "c.toml:2: loop.clock: \"virtual\" cannot serve a process controller",
            ),
            (
                "[metrics]\nlisten = \"9100\"\n".to_string(),
                "c.toml:2: metrics.listen: `9100` is not an IP address and port",
            ),
            (
                format!("{hil}[metrics]\nlisten = \"127.0.0.1:5020\"\n"),
                "c.toml:4: metrics.listen: 127.0.0.1:5020 is also [source.modbus-server] listen",
            ),
        ];
        for (text, want) in cases {
            let e = err(&text);
            assert!(e.starts_with(want), "{text}: {e}");
            assert!(!e.contains('\n'), "{e}");
        }
        // Defaults: loopback 5020, 1 s watchdog, per-mille map with a status register; no metrics.
        let c = Config::from_toml(hil, Path::new("c.toml")).unwrap();
        let m = &c.source.modbus_server;
        assert_eq!(m.listen.0.to_string(), "127.0.0.1:5020");
        assert_eq!(m.watchdog_s, 1.0);
        assert_eq!(m.registers.status.map(|s| s.address), Some(2));
        assert!(c.metrics.is_none());
        let c = Config::from_toml("[metrics]\n", Path::new("c.toml")).unwrap();
        assert_eq!(c.metrics.unwrap().listen.0.to_string(), "127.0.0.1:9100");
    }

    #[test]
    fn shipped_hil_config_serves_loopback_with_metrics() {
        let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/config/hil.toml"));
        let c = Config::load(Some(path)).unwrap();
        assert_eq!(c.source.kind, SourceKind::ModbusServer);
        assert_eq!(c.valve.kind, ValveKind::Emulated);
        let m = &c.source.modbus_server;
        assert!(m.listen.0.ip().is_loopback());
        // The map written out in the file is the default one.
        assert_eq!(m.registers, ModbusServerConfig::default().registers);
        assert_eq!(c.safety.on_stop, OnStop::GoTo);
        assert_eq!(
            c.metrics.map(|x| x.listen.0.to_string()).as_deref(),
            Some("127.0.0.1:9100")
        );
    }

    #[test]
    fn model_file_loads_any_model() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/models/stiction.toml");
        let c = Config::from_toml(
            &format!("[valve.emulated]\nmodel_file = \"{path}\"\n"),
            Path::new("c.toml"),
        )
        .unwrap();
        assert_eq!(
            c.valve.emulated.model_spec().unwrap().model,
            ModelKind::Stiction
        );
        let e = err(&format!(
            "[valve.emulated]\nmodel = \"fopdt\"\nmodel_file = \"{path}\"\n"
        ));
        assert!(e.contains("not both"), "{e}");
    }
}
