//! `[source]`: the O_P source of a loop. The file's table (`SourceTable`, private to the
//! config) holds a `kind`, the clamp range and a sub-table for any kind (`[source.random-steps]`
//! ... `[source.modbus-server]`), so a file can keep the settings of several kinds and switch
//! with one line; its check turns it into a [`SourceConfig`], the clamp range and a
//! [`SourceSpec`] holding the settings of the chosen kind only, checked (a replayed recording
//! loaded onto the loop grid). A kind whose table is missing gets the table's defaults where
//! it has them and is refused where it has none (`steps`, `replay`, `constant`).
//!
//! Not here: running a source is [`crate::runtime::source`] and [`crate::serve::hil`].

use std::net::{IpAddr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use serde::Deserialize;
use toml::Spanned;

use super::{Check, ClockKind, ListenAddr, LoopConfig};
use vb_core::recording::{self, ColumnMap, ReadOptions, RecordingError};
use vb_core::response_plan::Plan;
/// The settings of the generated sources (`[source.random-steps]`, `[source.steps]`, ...) are
/// the parameters of the generators in [`vb_core::signal`].
pub use vb_core::signal::{
    ConstantParams as ConstantConfig, PrbsParams as PrbsConfig, RampParams as RampConfig,
    RandomStepsParams as RandomStepsConfig, SineParams as SineConfig, StepsParams as StepsConfig,
};
use vb_core::toml_file::TomlError;
use vb_modbus::map::{self, RegisterMap};
use vb_modbus::net::Limits;

/// A checked source of O_P: the clamp range and the settings of the kind in use.
#[derive(Debug, Clone)]
pub struct SourceConfig {
    /// Lowest O_P ever sent, %.
    pub op_min_pct: f64,
    /// Highest O_P ever sent, % (above `op_min_pct`).
    pub op_max_pct: f64,
    /// The kind in use and its settings.
    pub spec: SourceSpec,
}

impl SourceConfig {
    /// The clamp range, `(op_min_pct, op_max_pct)`.
    pub fn op_range(&self) -> (f64, f64) {
        (self.op_min_pct, self.op_max_pct)
    }

    /// The server a process controller writes into, when this is a `modbus-server` source.
    pub fn server(&self) -> Option<&ModbusServerConfig> {
        match &self.spec {
            SourceSpec::ModbusServer(s) => Some(s),
            _ => None,
        }
    }
}

/// The kind of O_P source in use, with its checked settings: one variant per `[source] kind`.
#[derive(Debug, Clone)]
pub enum SourceSpec {
    /// `random-steps`, the paper's experiment: random levels held for random times.
    RandomSteps(RandomStepsConfig),
    /// `steps`: a list of levels, each held for the same time.
    Steps(StepsConfig),
    /// `ramp`: a linear ramp (or triangle).
    Ramp(RampConfig),
    /// `sine`: a sine wave.
    Sine(SineConfig),
    /// `prbs`: a pseudo-random binary signal.
    Prbs(PrbsConfig),
    /// `replay`: the O_P column of a recording, loaded.
    Replay(ReplayConfig),
    /// `constant`: one fixed O_P.
    Constant(ConstantConfig),
    /// `modbus-server`: whatever a process controller writes into the daemon's Modbus TCP
    /// server (HIL).
    ModbusServer(ModbusServerConfig),
    /// `response-test`: a response test's plan, walked as V_P settles (`valve-bridge
    /// response-test` sets it; no config file names it).
    ResponseTest(Arc<Plan>),
}

impl SourceSpec {
    /// The name of the kind in config files.
    pub fn tag(&self) -> &'static str {
        match self {
            SourceSpec::RandomSteps(_) => "random-steps",
            SourceSpec::Steps(_) => "steps",
            SourceSpec::Ramp(_) => "ramp",
            SourceSpec::Sine(_) => "sine",
            SourceSpec::Prbs(_) => "prbs",
            SourceSpec::Replay(_) => "replay",
            SourceSpec::Constant(_) => "constant",
            SourceSpec::ModbusServer(_) => "modbus-server",
            SourceSpec::ResponseTest(_) => "response-test",
        }
    }
}

/// `[source]` as the file has it: the kind in use, the clamp range, and the tables of any kind
/// (field order is the order `expected one of` lists them in).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub(super) struct SourceTable {
    /// None: `random-steps`.
    kind: Option<Spanned<SourceKind>>,
    op_min_pct: f64,
    op_max_pct: f64,
    #[serde(rename = "random-steps")]
    random_steps: RandomStepsConfig,
    steps: Option<StepsConfig>,
    ramp: RampConfig,
    sine: SineConfig,
    prbs: PrbsConfig,
    replay: Option<ReplayTable>,
    constant: Option<ConstantConfig>,
    #[serde(rename = "modbus-server")]
    modbus_server: ModbusServerConfig,
}

impl Default for SourceTable {
    fn default() -> Self {
        SourceTable {
            kind: None,
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

/// `[source] kind` as written (the names are [`SourceSpec::tag`]'s).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum SourceKind {
    RandomSteps,
    Steps,
    Ramp,
    Sine,
    Prbs,
    Replay,
    Constant,
    ModbusServer,
}

/// `[source.replay]` as written.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
struct ReplayTable {
    file: PathBuf,
}

/// A checked `[source.replay]`: the recording and its O_P.
#[derive(Debug, Clone)]
pub struct ReplayConfig {
    /// The recording whose O_P column is replayed.
    pub file: PathBuf,
    /// Its O_P held onto the loop grid (slot k = index k).
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
    /// Connections open at once; at the limit one makes room for a new one, never a
    /// controller's ([`vb_modbus::net`]).
    pub max_connections: usize,
    /// A connection without a request for this long is closed, s.
    pub idle_timeout_s: f64,
    /// The process controllers' addresses: only they may write (others get exception 01),
    /// their connections are never closed for another client's, and one slot each is kept for
    /// them. Empty (the default): anyone may write, and a connection whose write was accepted
    /// is a controller's from then on.
    pub controllers: Vec<ControllerAddr>,
    /// With several valves driven by the controller: registers per valve's block; the k-th
    /// such valve (from 0, in the order of the file) is served at the map's addresses plus
    /// k × block_size.
    pub block_size: u16,
}

impl ModbusServerConfig {
    /// The connection limits of the server.
    pub fn limits(&self) -> Limits {
        Limits {
            max_connections: self.max_connections,
            idle_timeout: Duration::from_secs_f64(self.idle_timeout_s),
            controllers: self.controllers.iter().map(|c| c.0).collect(),
        }
    }
}

/// A process controller's IP address, from a string such as `"10.0.0.5"` (no port: a client's
/// port changes with each connection; names are not resolved).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerAddr(pub IpAddr);

impl<'de> Deserialize<'de> for ControllerAddr {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        if let Ok(ip) = text.parse::<IpAddr>() {
            return Ok(ControllerAddr(ip.to_canonical()));
        }
        let fix = match text.parse::<SocketAddr>() {
            Ok(with_port) => format!("write the address without its port, \"{}\" (a client's port changes with each connection)", with_port.ip()),
            Err(_) => "write e.g. \"10.0.0.5\", the address the controller connects from (host names are not resolved)".to_string(),
        };
        Err(serde::de::Error::custom(format!(
            "`{text}` is not an IP address: {fix}"
        )))
    }
}

impl Default for ModbusServerConfig {
    fn default() -> Self {
        ModbusServerConfig {
            listen: ListenAddr(SocketAddr::from(([127, 0, 0, 1], 5020))),
            watchdog_s: 1.0,
            initial_pct: None,
            registers: RegisterMap::device_default(),
            max_connections: 8,
            idle_timeout_s: 60.0,
            controllers: Vec::new(),
            block_size: 10,
        }
    }
}
/// A range check: key, value, lowest, highest allowed, and what the value is.
type Range<'a> = (&'a str, f64, f64, f64, &'a str);

/// Runs the range checks of `table`.
fn ranges(c: &Check<'_>, table: &str, checks: &[Range<'_>]) -> Result<(), TomlError> {
    checks
        .iter()
        .try_for_each(|&(key, v, lo, hi, what)| c.range(table, key, v, lo, hi, what))
}

/// The longest hold, ramp or period accepted, s.
const DAY_S: f64 = 86_400.0;

impl SourceTable {
    /// The checks of `[source]` and of the sub-table its `kind` uses, for a loop of `[loop]`
    /// `timing`: the chosen kind's settings, with a replayed recording loaded.
    pub(super) fn check(
        self,
        c: &Check<'_>,
        timing: &LoopConfig,
    ) -> Result<SourceConfig, TomlError> {
        let opening = "an opening in %";
        ranges(
            c,
            "source",
            &[
                ("op_min_pct", self.op_min_pct, 0.0, 100.0, opening),
                ("op_max_pct", self.op_max_pct, 0.0, 100.0, opening),
            ],
        )?;
        if self.op_min_pct >= self.op_max_pct {
            return Err(c.bad(
                "source",
                "op_max_pct",
                format!("must be above op_min_pct = {}", self.op_min_pct),
            ));
        }
        // The line of `kind`; only a kind written out can lack its table.
        let (kind, line) = match &self.kind {
            Some(k) => (*k.get_ref(), c.line_at(k.span())),
            None => (SourceKind::RandomSteps, 1),
        };
        // The kinds without defaults, whose names are their tables'.
        let missing = |kind: &str, example: &str| {
            c.bad_on(
                line,
                "source",
                "kind",
                format!("kind = \"{kind}\" needs a [source.{kind}] table, e.g. {example}"),
            )
        };
        let spec = match kind {
            SourceKind::RandomSteps => {
                check_random_steps(&self.random_steps, c)?;
                SourceSpec::RandomSteps(self.random_steps)
            }
            SourceKind::Steps => {
                let steps = self
                    .steps
                    .ok_or_else(|| missing("steps", "levels_pct = [30.0, 60.0], hold_s = 5.0"))?;
                check_steps(&steps, c)?;
                SourceSpec::Steps(steps)
            }
            SourceKind::Ramp => {
                check_ramp(&self.ramp, c)?;
                SourceSpec::Ramp(self.ramp)
            }
            SourceKind::Sine => {
                check_sine(&self.sine, c)?;
                SourceSpec::Sine(self.sine)
            }
            SourceKind::Prbs => {
                check_prbs(&self.prbs, c, timing.rate_hz)?;
                SourceSpec::Prbs(self.prbs)
            }
            SourceKind::Replay => SourceSpec::Replay(
                self.replay
                    .ok_or_else(|| missing("replay", "file = \"recording.csv\""))?
                    .load(c, timing.period_s())?,
            ),
            SourceKind::Constant => {
                let k = self
                    .constant
                    .ok_or_else(|| missing("constant", "op_pct = 50.0"))?;
                ranges(
                    c,
                    "source.constant",
                    &[("op_pct", k.op_pct, 0.0, 100.0, opening)],
                )?;
                SourceSpec::Constant(k)
            }
            SourceKind::ModbusServer => {
                self.modbus_server.check_in(c, timing.clock)?;
                SourceSpec::ModbusServer(self.modbus_server)
            }
        };
        Ok(SourceConfig {
            op_min_pct: self.op_min_pct,
            op_max_pct: self.op_max_pct,
            spec,
        })
    }
}

/// The checks of `[source.random-steps]`.
fn check_random_steps(p: &RandomStepsConfig, c: &Check<'_>) -> Result<(), TomlError> {
    ranges(
        c,
        "source.random-steps",
        &[
            ("min_pct", p.min_pct, 0.0, 100.0, "a level in %"),
            (
                "max_pct",
                p.max_pct,
                p.min_pct,
                100.0,
                "a level in %, at least min_pct",
            ),
            ("hold_min_s", p.hold_min_s, 0.0, DAY_S, "a hold time in s"),
            (
                "hold_max_s",
                p.hold_max_s,
                p.hold_min_s.max(1e-3),
                DAY_S,
                "a hold time in s, above hold_min_s",
            ),
        ],
    )
}

/// The checks of `[source.ramp]`.
fn check_ramp(p: &RampConfig, c: &Check<'_>) -> Result<(), TomlError> {
    ranges(
        c,
        "source.ramp",
        &[
            ("from_pct", p.from_pct, 0.0, 100.0, "a level in %"),
            ("to_pct", p.to_pct, 0.0, 100.0, "a level in %"),
            ("duration_s", p.duration_s, 1e-3, DAY_S, "a ramp time in s"),
        ],
    )
}

/// The checks of `[source.sine]`.
fn check_sine(p: &SineConfig, c: &Check<'_>) -> Result<(), TomlError> {
    ranges(
        c,
        "source.sine",
        &[
            ("mean_pct", p.mean_pct, 0.0, 100.0, "a level in %"),
            (
                "amplitude_pct",
                p.amplitude_pct,
                0.0,
                100.0,
                "an amplitude in %",
            ),
            ("period_s", p.period_s, 1e-3, DAY_S, "a period in s"),
        ],
    )
}

/// The checks of `[source.steps]`.
fn check_steps(p: &StepsConfig, c: &Check<'_>) -> Result<(), TomlError> {
    let t = "source.steps";
    if p.levels_pct.is_empty() {
        return Err(c.bad(
            t,
            "levels_pct",
            "give at least one level, e.g. [30.0, 60.0]".into(),
        ));
    }
    for &v in &p.levels_pct {
        c.range(t, "levels_pct", v, 0.0, 100.0, "each level in %")?;
    }
    c.range(t, "hold_s", p.hold_s, 1e-3, DAY_S, "a hold time in s")
}

/// The checks of `[source.prbs]` for a loop at `rate_hz`.
fn check_prbs(p: &PrbsConfig, c: &Check<'_>, rate_hz: f64) -> Result<(), TomlError> {
    ranges(
        c,
        "source.prbs",
        &[
            ("mean_pct", p.mean_pct, 0.0, 100.0, "a level in %"),
            (
                "amplitude_pct",
                p.amplitude_pct,
                0.0,
                100.0,
                "an amplitude in %",
            ),
            (
                "band_hz",
                p.band_hz,
                1e-4,
                rate_hz / 2.0,
                "a frequency in Hz up to half the loop rate",
            ),
        ],
    )
}

impl ReplayTable {
    /// Loads the recording of `[source.replay]` onto the loop grid of `period_s`.
    fn load(self, c: &Check<'_>, period_s: f64) -> Result<ReplayConfig, TomlError> {
        let op = load_replay(&self.file, period_s).map_err(|m| {
            c.bad(
                "source.replay",
                "file",
                format!("cannot replay `{}`: {m}", self.file.display()),
            )
        })?;
        Ok(ReplayConfig {
            file: self.file,
            op_pct: Arc::new(op),
        })
    }
}

impl ModbusServerConfig {
    /// The checks of `[source.modbus-server]`, when it is the source (`clock` is `[loop] clock`).
    fn check_in(&self, c: &Check<'_>, clock: ClockKind) -> Result<(), TomlError> {
        let t = "source.modbus-server";
        if clock == ClockKind::Virtual {
            return Err(c.bad(
                "loop",
                "clock",
                "\"virtual\" cannot serve a process controller, which runs on the wall clock: \
                 use clock = \"real\" with [source] kind = \"modbus-server\""
                    .into(),
            ));
        }
        if !(self.watchdog_s.is_finite() && self.watchdog_s > 0.0 && self.watchdog_s <= 3600.0) {
            return Err(c.bad(
                t,
                "watchdog_s",
                format!(
                    "{} is not allowed: the time without a set-point write after which the \
                     [safety] action applies, above 0 and at most 3600 s, e.g. 1.0",
                    self.watchdog_s
                ),
            ));
        }
        if let Some(v) = self.initial_pct {
            if !(v.is_finite() && (0.0..=100.0).contains(&v)) {
                return Err(c.bad(
                    t,
                    "initial_pct",
                    format!("{} is out of range: the O_P before the first write, an opening in %, 0 to 100", vb_core::human::num(v)),
                ));
            }
        }
        c.max_connections(t, self.max_connections)?;
        self.check_controllers(c)?;
        c.range(
            t,
            "idle_timeout_s",
            self.idle_timeout_s,
            0.1,
            DAY_S,
            "the time after which a connection without requests is closed, in s",
        )?;
        let section = "source.modbus-server.registers";
        self.registers.check_in(c.lines, c.path, section)?;
        if let Some(st) = self.registers.status {
            let bit = st.setpoint_error_bit;
            if [
                map::VALVE_FAULT_BIT,
                map::WATCHDOG_BIT,
                map::HEALTH_ALARM_BIT,
            ]
            .contains(&bit)
            {
                return Err(TomlError::Invalid {
                    path: c.path.to_path_buf(),
                    line: (c.lines.of(Some(section), "status"))
                        .or_else(|| c.lines.of(Some(section), ""))
                        .unwrap_or(1),
                    key: format!("{section}.status.setpoint_error_bit"),
                    message: format!(
                        "{bit} is taken: the daemon reports a valve fault in bit {}, the \
                         watchdog in bit {} and a health alarm in bit {} of the status \
                         register; use 0 or 4-15",
                        map::VALVE_FAULT_BIT,
                        map::WATCHDOG_BIT,
                        map::HEALTH_ALARM_BIT
                    ),
                });
            }
        }
        Ok(())
    }

    /// `controllers`: each listed once, reachable on `listen`, and fewer than `max_connections`
    /// (a slot is kept for each).
    fn check_controllers(&self, c: &Check<'_>) -> Result<(), TomlError> {
        let t = "source.modbus-server";
        let (n, max) = (self.controllers.len(), self.max_connections);
        for (i, ControllerAddr(ip)) in self.controllers.iter().enumerate() {
            if self.controllers[..i].contains(&ControllerAddr(*ip)) {
                return Err(c.bad(t, "controllers", format!("{ip} is listed twice")));
            }
            let listen = self.listen.0;
            if listen.ip().is_loopback() && !ip.is_loopback() {
                return Err(c.bad(
                    t,
                    "controllers",
                    format!("{ip} cannot connect: listen = \"{listen}\" serves this machine only; set listen to the interface the controller reaches (e.g. \"0.0.0.0:{}\")", listen.port()),
                ));
            }
        }
        if n >= max {
            return Err(c.bad(
                t,
                "controllers",
                format!("{n} controllers keep {n} of the max_connections = {max} slots, leaving none for other clients: raise max_connections above {n}"),
            ));
        }
        Ok(())
    }

    /// The checks of the blocks of `valves` valves driven by the controller: every register of
    /// the map inside one block, and every block inside the 65536 addresses.
    pub(super) fn check_blocks(&self, c: &Check<'_>, valves: usize) -> Result<(), TomlError> {
        if valves < 2 {
            return Ok(());
        }
        let m = &self.registers;
        let status = m.status.map(|s| u32::from(s.address) + 1).unwrap_or(0);
        let top = m.setpoint.span().end.max(m.position.span().end).max(status);
        let size = u32::from(self.block_size);
        if top > size {
            return Err(c.bad(
                "source.modbus-server",
                "block_size",
                format!("{size} registers per valve cannot hold the map of [source.modbus-server.registers], which reaches address {}: set block_size = {top} or more, or move the registers down", top - 1),
            ));
        }
        if size * valves as u32 > 1 << 16 {
            return Err(c.bad(
                "source.modbus-server",
                "block_size",
                format!("{valves} blocks of {size} registers do not fit the 65536 register addresses: lower block_size"),
            ));
        }
        Ok(())
    }
}

/// Most grid slots a replay holds in memory (80 MB; 27.8 h at 10 ms).
const MAX_REPLAY_SLOTS: f64 = 1e7;
/// Most rows of the replayed file (as many as slots): a source that never ends, such as a pipe
/// or a device, is refused once it has given these.
const MAX_REPLAY_ROWS: usize = MAX_REPLAY_SLOTS as usize;

/// The O_P column of a recording (V_P is not read, so a log with failed reads replays too),
/// held onto a grid of `period_s` from its first row; refused when it holds more than
/// [`MAX_REPLAY_ROWS`] rows or that grid would exceed [`MAX_REPLAY_SLOTS`].
fn load_replay(file: &Path, period_s: f64) -> Result<Vec<f64>, RecordingError> {
    let opts = ReadOptions {
        columns: ColumnMap {
            vp: None,
            ..ColumnMap::default()
        },
        max_rows: MAX_REPLAY_ROWS,
        ..ReadOptions::default()
    };
    let rec = recording::read(file, &opts)?;
    let slots = rec.duration() / period_s;
    if slots > MAX_REPLAY_SLOTS {
        return Err(RecordingError::Invalid {
            file: file.display().to_string(),
            detail: format!(
                "spans {} h, {} slots of {} s; a replay holds at most {MAX_REPLAY_SLOTS:e} slots ({} h): cut the file or lengthen [loop] period",
                vb_core::human::num(rec.duration() / 3600.0),
                vb_core::human::num(slots),
                vb_core::human::num(period_s),
                vb_core::human::num(MAX_REPLAY_SLOTS * period_s / 3600.0)
            ),
        });
    }
    Ok(recording::resample_zoh(&rec.t, &rec.op, period_s))
}
