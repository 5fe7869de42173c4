//! The daemon's TOML configuration: the file's shape, its checks, and the checked [`Config`]
//! the daemon runs from; the embedded default.
//!
//! A config has the tables `[loop]`, `[valve]`, `[source]`, `[safety]`, `[log]`, `[metrics]`,
//! `[health]`, `[diagnosis]` and `[test]` (the response test's), all optional (no `[metrics]`: no Prometheus endpoint; no
//! `[health]`: no live health check; no `[diagnosis]`: no live diagnosis). Several valves are several
//! `[[valve]]` tables, each with a `name` and, optionally, a `[valve.source]` of its own.
//! `[valve] kind = ...` and `[source] kind = ...` pick a backend and an O_P source; the settings of
//! each kind live in their own sub-table (`[valve.emulated]`, `[source.sine]`, ...), so a file
//! can keep settings for several kinds and switch with one line, and every key keeps its exact
//! line in error messages.
//!
//! Two layers: serde reads the file into private types shaped as the file is (a `kind` and a
//! table for any kind); their checks turn it into [`Config`], whose [`SourceConfig`]s and
//! [`ValveConfig`]s hold the chosen kind's settings only ([`SourceSpec`], [`ValveSpec`]: one
//! variant per kind), so code downstream matches on what is there and re-checks nothing. Every error names the file, the line and the
//! dotted key, and says what is allowed. Checking also resolves what the config points at (the
//! model file, the replayed recording), so a missing file is reported against the key that
//! names it.
//!
//! Files: this one holds [`Config`], loading, and the small tables (`[loop]`, `[safety]`,
//! `[log]`, `[metrics]`); [`valve`] holds `[valve]` and [`source`] holds `[source]`, each with
//! the checks of its tables (as [`RegisterMap::check_in`] does for a register map).
//!
//! Not here: running anything; [`crate`] builds the loop from a [`Config`].
//!
//! [`RegisterMap::check_in`]: vb_modbus::map::RegisterMap::check_in

pub mod bus;
mod diagnosis;
mod health;
mod source;
mod valve;

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use vb_core::toml_file::{self, Layout, Lines, TomlError};

pub use diagnosis::DiagnosisConfig;
pub use health::HealthConfig;
pub use source::{
    ConstantConfig, ControllerAddr, ModbusServerConfig, PrbsConfig, RampConfig, RandomStepsConfig,
    ReplayConfig, SineConfig, SourceConfig, SourceSpec, StepsConfig,
};
pub use valve::{Device, EmulatedConfig, ValveConfig, ValveSpec, UNNAMED};

use source::SourceTable;
use valve::ValveTable;

/// The default configuration, `config/emulated.toml`, embedded so default == file by construction.
pub const DEFAULT_TOML: &str = include_str!("../../../../config/emulated.toml");

/// The most connections a server may be allowed (each is a file descriptor).
pub const MAX_CONNECTIONS: usize = 1000;

/// The name the embedded default goes by in messages.
pub const DEFAULT_LABEL: &str = "config/emulated.toml (embedded default)";

/// A whole daemon configuration, checked and resolved: the valves and sources hold only the
/// settings of the kinds in use.
#[derive(Debug, Clone)]
pub struct Config {
    /// Loop rate and clock.
    pub loop_: LoopConfig,
    /// The valves, in the order of the file: one `[valve]` table or several `[[valve]]` tables.
    /// The loop drives them in this order within each cycle.
    pub valves: Vec<ValveConfig>,
    /// The source of O_P of every valve that has no `source` table of its own.
    pub source: SourceConfig,
    /// What to do on stop.
    pub safety: SafetyConfig,
    /// The CSV log.
    pub log: LogConfig,
    /// The Prometheus endpoint, if any.
    pub metrics: Option<MetricsConfig>,
    /// The live health check of every valve, if any.
    pub health: Option<HealthConfig>,
    /// The live diagnosis of every valve, if any (needs `health`).
    pub diagnosis: Option<DiagnosisConfig>,
    /// The response test (`valve-bridge response-test`).
    pub test: TestConfig,
}

/// A config file as written, before its checks (field order is the order `expected one of`
/// lists the tables in).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ConfigFile {
    #[serde(rename = "loop", default)]
    loop_: LoopConfig,
    #[serde(
        rename = "valve",
        default = "valve::one_default",
        deserialize_with = "valve::one_or_many"
    )]
    valves: Vec<ValveTable>,
    #[serde(default)]
    source: SourceTable,
    #[serde(default)]
    safety: SafetyConfig,
    #[serde(default)]
    log: LogConfig,
    metrics: Option<MetricsConfig>,
    health: Option<HealthConfig>,
    diagnosis: Option<DiagnosisConfig>,
    #[serde(default)]
    test: TestConfig,
}

/// `[test]`: the response test (`valve-bridge response-test`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TestConfig {
    /// Ask for `--yes` before the test moves a real valve (false: a bench valve the test may
    /// always move).
    pub confirm: bool,
}

impl Default for TestConfig {
    fn default() -> Self {
        TestConfig { confirm: true }
    }
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

/// No valve, or more than one, fits `--valve`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}name the valve with --valve (one of {})", asked.as_ref().map_or(String::new(), |a| format!("no valve is named `{a}`: ")), names.join(", "))]
pub struct ValveChoice {
    /// The name asked for, if any.
    pub asked: Option<String>,
    /// The valves' names.
    pub names: Vec<String>,
}

/// `[metrics]`: the Prometheus endpoint.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MetricsConfig {
    /// Address of the HTTP endpoint (`GET /metrics`).
    pub listen: ListenAddr,
    /// Connections open at once; at the limit one makes room for a new one (first from the host
    /// holding the most; a scraper's after the others of its host).
    pub max_connections: usize,
}

impl Default for MetricsConfig {
    fn default() -> Self {
        MetricsConfig {
            listen: ListenAddr(SocketAddr::from(([127, 0, 0, 1], 9100))),
            max_connections: 8,
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
    /// Gzip each file once the log has rotated to the next (`NAME.csv.gz`); the file being
    /// written stays plain CSV.
    pub compress: bool,
    /// What a write the disk refuses does to the loop.
    pub on_error: OnError,
}

/// `[log] on_error`: what a write the disk refuses (full, quota, file-size limit) does.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnError {
    /// The loop runs on; the log holds its lines and writes them when the disk takes them
    /// again (see `crate::runtime::log_file`).
    #[default]
    KeepRunning,
    /// The loop stops at the first refused write, with its stop action.
    Stop,
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            dir: PathBuf::from("./logs"),
            rotate_size_mb: 100.0,
            rotate_after_s: 3600.0,
            flush_interval_ms: 1000,
            compress: true,
            on_error: OnError::KeepRunning,
        }
    }
}
/// Where the checks of one config point their messages: the lines of its tables (in one
/// `[[valve]]` table and its sub-tables, for that valve's checks), its file, and the prefix of
/// the tables looked up (`valve.` for a valve's own `[valve.source]`).
pub(super) struct Check<'a> {
    lines: Lines<'a>,
    /// The whole file's text, which the spans serde gives index.
    file: &'a str,
    path: &'a Path,
    prefix: &'static str,
}

impl<'a> Check<'a> {
    /// The checks of a whole file, `text` laid out in `layout`.
    fn whole(text: &'a str, layout: &'a Layout<'a>, path: &'a Path) -> Self {
        Check {
            lines: layout.lines(),
            file: text,
            path,
            prefix: "",
        }
    }

    /// The checks of the `nth` (0-based) `[[valve]]` table and its sub-tables.
    fn valve(&self, nth: usize) -> Check<'a> {
        Check {
            lines: self.lines.nth(nth),
            ..self.under("")
        }
    }

    /// The same part of the file, with every table looked up under `prefix`.
    fn under(&self, prefix: &'static str) -> Check<'a> {
        Check { prefix, ..*self }
    }

    /// The line (1-based, in the file) of a value whose span serde gave ([`toml::Spanned`]).
    fn line_at(&self, span: std::ops::Range<usize>) -> usize {
        toml_file::line_at(self.file, span.start)
    }

    /// An error about `table.key`, at the line that sets it.
    fn bad(&self, table: &str, key: &str, message: String) -> TomlError {
        let prefixed = format!("{}{table}", self.prefix);
        let line = self.lines.of(Some(&prefixed), key).unwrap_or(1);
        self.bad_on(line, table, key, message)
    }

    /// An error about `table.key` at `line` of the file.
    fn bad_on(&self, line: usize, table: &str, key: &str, message: String) -> TomlError {
        let table = format!("{}{table}", self.prefix);
        let dotted = if key.is_empty() {
            table
        } else {
            format!("{table}.{key}")
        };
        TomlError::Invalid {
            path: self.path.to_path_buf(),
            line,
            key: dotted,
            message,
        }
    }

    /// `max_connections` of `table`: 1 to [`MAX_CONNECTIONS`].
    fn max_connections(&self, table: &str, n: usize) -> Result<(), TomlError> {
        self.range(
            table,
            "max_connections",
            n as f64,
            1.0,
            MAX_CONNECTIONS as f64,
            "connections open at once",
        )
    }

    /// `value` of `table.key` must be finite and within `lo..=hi`; `what` says what it is.
    fn range(
        &self,
        table: &str,
        key: &str,
        value: f64,
        lo: f64,
        hi: f64,
        what: &str,
    ) -> Result<(), TomlError> {
        if value.is_finite() && (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(self.bad(
                table,
                key,
                format!(
                    "{} is out of range: {what}, {lo} to {hi}",
                    vb_core::human::num(value)
                ),
            ))
        }
    }
}

impl Config {
    /// Loads `path`, or the embedded default when `path` is None; checked and resolved.
    pub fn load(path: Option<&Path>) -> Result<Config, TomlError> {
        match path {
            Some(p) => {
                let (file, text): (ConfigFile, String) = toml_file::load(p)?;
                file.check(&text, p)
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
        let file: ConfigFile = toml_file::parse(text, label)?;
        file.check(text, label)
    }
}

impl ConfigFile {
    /// The checks of every table in file order, then those across tables; loads the model and
    /// the replayed recording. `text` is the file's text, `path` names it.
    fn check(self, text: &str, path: &Path) -> Result<Config, TomlError> {
        let layout = Layout::parse(text);
        let c = Check::whole(text, &layout, path);
        self.loop_.check_in(&c)?;
        let source = self.source.check(&c, &self.loop_)?;
        let valves = valve::check_all(self.valves, &c, &self.loop_)?;
        let config = Config {
            loop_: self.loop_,
            valves,
            source,
            safety: self.safety,
            log: self.log,
            metrics: self.metrics,
            health: self.health,
            diagnosis: self.diagnosis,
            test: self.test,
        };
        if let Some(s) = config.controller_server() {
            let driven = config.valves.iter().filter(|v| v.source.is_none()).count();
            s.check_blocks(&c, driven)?;
        }
        config.safety.check_in(&c)?;
        config.log.check_in(&c)?;
        let period_s = config.loop_.period_s();
        if let Some(h) = &config.health {
            h.check_in(&c, period_s)?;
        }
        if let Some(d) = &config.diagnosis {
            d.check_in(&c, period_s, config.health.is_some())?;
        }
        if let Some(m) = &config.metrics {
            c.max_connections("metrics", m.max_connections)?;
        }
        if let (Some(m), Some(server)) = (&config.metrics, config.controller_server()) {
            let hil = server.listen.0;
            if m.listen.0 == hil && hil.port() != 0 {
                return Err(c.bad(
                    "metrics",
                    "listen",
                    format!("{hil} is also [source.modbus-server] listen: give the endpoint its own port, e.g. \"127.0.0.1:9100\""),
                ));
            }
        }
        Ok(config)
    }
}

impl Config {
    /// The source of O_P of `valve`: its own `source` table, else `[source]`.
    pub fn source_of<'a>(&'a self, valve: &'a ValveConfig) -> &'a SourceConfig {
        valve.source.as_ref().unwrap_or(&self.source)
    }

    /// The valve `name` names, or the only one when `name` is None (`--valve` of `probe` and
    /// `response-test`).
    pub fn valve(&self, name: Option<&str>) -> Result<&ValveConfig, ValveChoice> {
        let picked = match name {
            Some(name) => self.valves.iter().find(|v| v.label() == name),
            None if self.valves.len() == 1 => self.valves.first(),
            None => None,
        };
        picked.ok_or_else(|| ValveChoice {
            asked: name.map(str::to_string),
            names: self.valves.iter().map(|v| v.label().to_string()).collect(),
        })
    }

    /// The server of the process controller (`[source.modbus-server]`), when it drives a valve.
    pub fn controller_server(&self) -> Option<&ModbusServerConfig> {
        (self.valves.iter()).find_map(|v| self.source_of(v).server())
    }
}

impl LoopConfig {
    /// The checks of `[loop]`.
    fn check_in(&self, c: &Check<'_>) -> Result<(), TomlError> {
        c.range(
            "loop",
            "rate_hz",
            self.rate_hz,
            1.0,
            1000.0,
            "a loop rate in Hz",
        )?;
        c.range(
            "loop",
            "spin_us",
            f64::from(self.spin_us),
            0.0,
            2000.0,
            "a busy-wait margin in µs",
        )?;
        c.range(
            "loop",
            "realtime_priority",
            f64::from(self.realtime_priority),
            0.0,
            99.0,
            "a SCHED_FIFO priority (0 = normal scheduling)",
        )
    }
}

impl SafetyConfig {
    /// The checks of `[safety]`.
    fn check_in(&self, c: &Check<'_>) -> Result<(), TomlError> {
        if self.on_stop != OnStop::GoTo {
            return Ok(());
        }
        match self.go_to_pct {
            None => Err(c.bad(
                "safety",
                "on_stop",
                "on_stop = \"go-to\" needs go_to_pct = <an opening in %>".into(),
            )),
            Some(v) => c.range("safety", "go_to_pct", v, 0.0, 100.0, "an opening in %"),
        }
    }
}

impl LogConfig {
    /// The checks of `[log]`.
    fn check_in(&self, c: &Check<'_>) -> Result<(), TomlError> {
        c.range(
            "log",
            "rotate_size_mb",
            self.rotate_size_mb,
            0.001,
            1e6,
            "a file size in MB",
        )?;
        c.range(
            "log",
            "rotate_after_s",
            self.rotate_after_s,
            1.0,
            1e7,
            "a file duration in s",
        )?;
        c.range(
            "log",
            "flush_interval_ms",
            self.flush_interval_ms as f64,
            10.0,
            1000.0,
            "a flush interval in ms",
        )
    }
}

#[cfg(test)]
mod tests;
