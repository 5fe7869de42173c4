//! sim-device: a fake valve positioner (Bürkert-style, or a device profile's) that speaks real
//! Modbus TCP and RTU.
//!
//! It serves the register map of `valve-bridge`'s `[valve.registers]` table (`--config`, over the
//! config's `profile` if it names one), of a shipped device profile (`--profile NAME`: its map,
//! its further registers read as 0, and only its function codes, others answered with exception
//! 01), or without either the map of the shipped `config/sim-device-*.toml` (per-mille `u16`
//! set-point in holding register 0, `i16` position in 1, status word in 2), from a
//! [`RegisterBank`], over Modbus TCP
//! (`--tcp ADDR`), on a pseudo-terminal it opens itself (`--pty`) or on a serial device
//! (`--serial PATH`). Its valve is a model from `config/models/` (pin-cart II by default) stepped
//! at 100 Hz in real time from the last accepted set-point, optionally wearing over hours (a
//! growing dead time or friction band, the daemon's [`vb_core::model::drift`]). Repeated
//! `--unit ID=MODEL[,KEY=VALUE...]` serve several valves at their own addresses on the same
//! port, each with its own model and registers ([`units`]): on RTU a request to an address no
//! unit has gets no reply, as on a real bus; on TCP, with several units, a request to a unit id
//! none has gets exception 0B (gateway target device failed to respond), and with one unit any
//! unit id is answered. A set-point outside 0-100 % keeps the last value and raises the status
//! error bit, as Bürkert positioners do. Faults can be injected for tests (on every unit's
//! requests, numbered across the device): response delay, dropped responses, corrupted CRC
//! (RTU), exception responses, a byte too many, broken MBAP frames (TCP) and TCP disconnects;
//! `--baud-emulation` makes a pty answer as
//! slowly as a real line would.
//!
//! On start it prints one line per endpoint on stdout, `tcp: 127.0.0.1:5502` and
//! `pty: /dev/pts/5`, for a client (or a test) to connect to. The TCP server survives accept
//! errors, keeps at most `--max-connections` (at the limit one makes room for a new one, chosen
//! as in the daemon's servers) and closes connections idle for
//! `--idle-timeout-s`; each connection is logged (`client connected from ...`), and SIGINT or
//! SIGTERM logs what the server went through before exiting. It is a test instrument: no
//! persistence, no device identification, no coils.

mod faults;
mod rtu;
mod tcp;
mod units;

use std::io::Write;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context as _};
use clap::Parser;
use serde::Deserialize;
use tokio::net::TcpListener;
use tokio_serial::{SerialPort, SerialStream};
use vb_core::model::DriftSpec;
use vb_core::toml_file;
use vb_modbus::link::{Parity, RtuLink};
use vb_modbus::map::{RegisterKeys, RegisterMap};
use vb_modbus::net::{Health, Limits};
use vb_modbus::profile::{self, Profile};
use vb_modbus::serial;

use faults::{FaultConfig, Faults};
use rtu::{LineSpeed, RtuDevice};
use units::{Banks, Defaults, Served, Unit, UnitArg};

/// A fake valve positioner speaking Modbus TCP and RTU.
#[derive(Parser, Debug)]
#[command(name = "sim-device", version, about)]
struct Args {
    /// Serve Modbus TCP on this address (port 0: any free port; the line `tcp: ADDR` tells which).
    #[arg(long, value_name = "ADDR")]
    tcp: Option<SocketAddr>,
    /// Serve Modbus RTU on a new pseudo-terminal; prints `pty: PATH` for the client.
    #[arg(long)]
    pty: bool,
    /// With --pty: also make PATH a symbolic link to the client end (a stable name for configs).
    #[arg(long, value_name = "PATH", requires = "pty")]
    pty_link: Option<PathBuf>,
    /// Serve Modbus RTU on this serial device.
    #[arg(long, value_name = "PATH", conflicts_with = "pty")]
    serial: Option<PathBuf>,
    /// Serial baud rate (--serial).
    #[arg(long, default_value_t = 19200)]
    baud: u32,
    /// Serial parity: none, even or odd (--serial; also the character size of --baud-emulation).
    #[arg(long, default_value = "even", value_parser = parse_parity)]
    parity: Parity,
    /// Serial stop bits, 1 or 2.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=2))]
    stop_bits: u8,
    /// A valve-bridge config file: its [valve.registers] table is the map served, and
    /// [valve.modbus-rtu] slave_id / [valve.modbus-tcp] unit_id the RTU address.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// A shipped register profile of a real device (config/profiles/NAME.toml) to serve: its
    /// map, its further registers and only its function codes.
    #[arg(long, value_name = "NAME", conflicts_with = "config")]
    profile: Option<String>,
    /// A unit served: its RTU slave address / TCP unit id, `ID`, or with a model and settings
    /// of its own, `ID=MODEL[,KEY=VALUE...]` (keys: noise_pct and the drift options' names
    /// with `_`, e.g. `2=pincart2,friction_band_drift_pct_per_h=2`). Repeat for several valves
    /// on one port (default: one unit, from --config, else 1).
    #[arg(long, value_name = "ID[=MODEL,...]", value_parser = units::parse_unit)]
    unit: Vec<UnitArg>,
    /// The valve of every unit without a model of its own: a bundled model name (pincart2,
    /// fopdt, ...) or a model file.
    #[arg(long, default_value = "pincart2")]
    model: String,
    /// Standard deviation of Gaussian noise on the reported position, %.
    #[arg(long, default_value_t = 0.0)]
    noise_pct: f64,
    /// Dead time added per hour of running, s/h (a wearing valve; 0 = none).
    #[arg(long, default_value_t = 0.0)]
    dead_time_drift_s_per_h: f64,
    /// The most dead time the drift adds, s.
    #[arg(long, default_value_t = DriftSpec::default().dead_time_drift_max_s)]
    dead_time_drift_max_s: f64,
    /// Friction band widening per hour of running, % of travel per hour (pin-cart models;
    /// 0 = none).
    #[arg(long, default_value_t = 0.0)]
    friction_band_drift_pct_per_h: f64,
    /// The most the friction band widens, %.
    #[arg(long, default_value_t = DriftSpec::default().friction_band_drift_max_pct)]
    friction_band_drift_max_pct: f64,
    /// Seed of the noise and of --drop-prob.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Extra delay before every response, ms (with --delay-every: before those responses only).
    #[arg(long, default_value_t = 0)]
    delay_ms: u64,
    /// Delay only every N-th response by --delay-ms (a device that is late now and then).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..), requires = "delay_ms")]
    delay_every: Option<u64>,
    /// Leave every N-th request unanswered.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    drop_every: Option<u64>,
    /// Leave requests unanswered with this probability.
    #[arg(
        long,
        value_name = "P",
        default_value_t = 0.0,
        conflicts_with = "drop_every"
    )]
    drop_prob: f64,
    /// Corrupt the CRC of every N-th response (RTU).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    corrupt_crc_every: Option<u64>,
    /// Answer every N-th request with one byte too many (a read's byte count off by one).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    bad_byte_count_every: Option<u64>,
    /// Answer every N-th request with an MBAP length of 0, which puts the stream out of step
    /// (TCP).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    broken_frame_every: Option<u64>,
    /// Answer every N-th request with exception 04 (server device failure).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    exception_every: Option<u64>,
    /// Close a TCP connection on its N-th request, unanswered (the client must reconnect).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    disconnect_after: Option<u64>,
    /// TCP connections open at once; at the limit one makes room for a new one (first from the
    /// host holding the most, one silent for 100 ms since it opened, then the longest idle).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u64).range(1..=1000))]
    max_connections: u64,
    /// Close a TCP connection that sends no request for this long, s.
    #[arg(long, default_value_t = 60.0)]
    idle_timeout_s: f64,
    /// RTU: answer as late as a line at this baud rate would (characters of request and reply,
    /// at the --parity/--stop-bits character size, plus --turnaround-ms).
    #[arg(long, value_name = "BAUD", value_parser = clap::value_parser!(u32).range(300..))]
    baud_emulation: Option<u32>,
    /// Device response time added by --baud-emulation, ms.
    #[arg(long, default_value_t = 1.0)]
    turnaround_ms: f64,
}

fn parse_parity(s: &str) -> Result<Parity, String> {
    match s {
        "none" => Ok(Parity::None),
        "even" => Ok(Parity::Even),
        "odd" => Ok(Parity::Odd),
        _ => Err(format!("`{s}`: one of none, even, odd")),
    }
}

/// The parts of a valve-bridge config file sim-device uses; other tables are ignored.
#[derive(Debug, Default, Deserialize)]
struct ConfigFile {
    #[serde(default)]
    valve: ValveSection,
}

#[derive(Debug, Default, Deserialize)]
struct ValveSection {
    #[serde(default)]
    profile: Option<String>,
    #[serde(default)]
    registers: RegisterKeys,
    #[serde(default, rename = "modbus-rtu")]
    rtu: LinkIds,
    #[serde(default, rename = "modbus-tcp")]
    tcp: LinkIds,
}

#[derive(Debug, Default, Deserialize)]
struct LinkIds {
    slave_id: Option<u8>,
    unit_id: Option<u8>,
}

/// The registers and the RTU address from `--config` (its `[valve.registers]` over its
/// `profile`, if any), checked with errors naming file, line and key.
fn load_config(path: &Path) -> anyhow::Result<(Served, Option<u8>)> {
    let (file, text): (ConfigFile, String) = toml_file::load(path)?;
    let v = file.valve;
    let section = "valve.registers";
    let layout = toml_file::Layout::parse(&text);
    let served = match &v.profile {
        None => {
            let map = RegisterMap::from(v.registers);
            map.check_in(layout.lines(), path, section)?;
            Served::map(map)
        }
        Some(name) => {
            let p = shipped_profile(name)?;
            Served::profile(p.under(&v.registers, layout.lines(), path, section)?, &p)
        }
    };
    Ok((served, v.rtu.slave_id.or(v.tcp.unit_id)))
}

/// The shipped profile `name`, or what the shipped ones are.
fn shipped_profile(name: &str) -> anyhow::Result<Profile> {
    match profile::find(name) {
        Some(found) => Ok(found?),
        None => bail!("{}", profile::unknown(name)),
    }
}

fn main() -> std::process::ExitCode {
    vb_core::logging::init_tracing();
    let result = tokio::runtime::Runtime::new()
        .context("cannot start the async runtime")
        .and_then(|rt| rt.block_on(run(Args::parse())));
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // Told if stderr can take it; the exit code says it anyway.
            let _lost = writeln!(
                std::io::stderr(),
                "sim-device: error: {}",
                vb_core::logging::error_line(&e)
            );
            std::process::ExitCode::FAILURE
        }
    }
}

/// Prints an endpoint line and flushes it at once (a test may be waiting for it).
fn announce(line: &str) {
    let mut out = std::io::stdout().lock();
    // A closed stdout only loses the announcement; serving goes on.
    if let Err(e) = writeln!(out, "{line}").and_then(|()| out.flush()) {
        tracing::debug!("{line:?} not announced on stdout: {e}");
    }
}

/// Refuses option combinations that cannot work, with the option to change.
fn check(args: &Args) -> anyhow::Result<()> {
    if args.tcp.is_none() && !args.pty && args.serial.is_none() {
        bail!("nothing to serve: give --tcp ADDR, --pty or --serial PATH");
    }
    let rtu = args.pty || args.serial.is_some();
    if args.corrupt_crc_every.is_some() && !rtu {
        bail!("--corrupt-crc-every needs --pty or --serial: Modbus TCP has no CRC");
    }
    if args.broken_frame_every.is_some() && args.tcp.is_none() {
        bail!("--broken-frame-every needs --tcp: it breaks Modbus TCP's MBAP framing");
    }
    if args.baud_emulation.is_some() && !rtu {
        bail!("--baud-emulation needs --pty or --serial");
    }
    if args.disconnect_after.is_some() && args.tcp.is_none() {
        bail!("--disconnect-after needs --tcp: a serial line has no connection to close (use --drop-every)");
    }
    if !(0.0..=1.0).contains(&args.drop_prob) {
        bail!("--drop-prob {}: a probability, 0-1", args.drop_prob);
    }
    if !(args.noise_pct.is_finite() && args.noise_pct >= 0.0) {
        bail!(
            "--noise-pct {}: a standard deviation in %, >= 0",
            args.noise_pct
        );
    }
    if !(args.idle_timeout_s.is_finite() && (0.1..=86_400.0).contains(&args.idle_timeout_s)) {
        bail!(
            "--idle-timeout-s {}: a time in s, 0.1-86400",
            args.idle_timeout_s
        );
    }
    if !(args.turnaround_ms.is_finite() && (0.0..=1000.0).contains(&args.turnaround_ms)) {
        bail!(
            "--turnaround-ms {}: a response time in ms, 0-1000",
            args.turnaround_ms
        );
    }
    Ok(())
}

/// The serial line settings of the command line (the port is set where it is opened).
fn line(args: &Args, port: &str) -> RtuLink {
    RtuLink {
        baud: args.baud,
        parity: args.parity,
        stop_bits: args.stop_bits,
        ..RtuLink::new(port)
    }
}

async fn run(args: Args) -> anyhow::Result<()> {
    check(&args)?;
    let (served, config_unit) = match (&args.config, &args.profile) {
        (Some(path), _) => load_config(path)?,
        (None, Some(name)) => {
            let p = shipped_profile(name)?;
            tracing::info!("sim-device: profile {name}: {}", p.about.device);
            (Served::profile(p.map, &p), None)
        }
        (None, None) => (Served::map(RegisterMap::device_default()), None),
    };
    let map = served.map;
    let units = units_of(&args, &served, config_unit)?;
    let banks = Banks::of(&units);
    let faults = Arc::new(Faults::new(FaultConfig {
        delay: Duration::from_millis(args.delay_ms),
        delay_every: args.delay_every,
        drop_every: args.drop_every,
        drop_prob: args.drop_prob,
        corrupt_crc_every: args.corrupt_crc_every,
        exception_every: args.exception_every,
        bad_byte_count_every: args.bad_byte_count_every,
        broken_frame_every: args.broken_frame_every,
        disconnect_after: args.disconnect_after,
        seed: args.seed,
    }));
    tracing::info!(
        "sim-device: set-point at {} {}, position at {} {}",
        map.setpoint.table,
        map.setpoint.address,
        map.position.table,
        map.position.address
    );
    let mut stepping = tokio::task::JoinSet::new();
    for unit in units {
        tracing::info!("{}", unit.describe());
        stepping.spawn(unit.step());
    }

    let mut servers: tokio::task::JoinSet<anyhow::Result<()>> = tokio::task::JoinSet::new();
    // Removed when serving ends, however it ends.
    let mut link: Option<PtyLink> = None;
    let health = Arc::new(Health::default());
    if let Some(addr) = args.tcp {
        let listener = TcpListener::bind(addr)
            .await
            .with_context(|| format!("cannot listen on {addr} (--tcp)"))?;
        announce(&format!("tcp: {}", listener.local_addr()?));
        let limits = Limits {
            max_connections: args.max_connections as usize,
            idle_timeout: Duration::from_secs_f64(args.idle_timeout_s),
            controllers: Arc::default(),
        };
        let serving = tcp::serve(
            listener,
            banks.clone(),
            Arc::clone(&faults),
            limits,
            Arc::clone(&health),
        );
        servers.spawn(async move {
            serving.await;
            Ok(())
        });
    }
    if args.pty || args.serial.is_some() {
        let device = RtuDevice {
            banks,
            faults: Arc::clone(&faults),
            line: args.baud_emulation.map(|baud| LineSpeed {
                baud,
                bits_per_char: line(&args, "").bits_per_char(),
                turnaround: Duration::from_secs_f64(args.turnaround_ms / 1000.0),
            }),
        };
        link = spawn_rtu(&mut servers, &args, device)?;
    }
    // Serve until a signal, or until the first server ends (a serial port that closed).
    let result = tokio::select! {
        signal = stop_signal() => {
            let signal = signal?;
            if args.tcp.is_some() {
                tracing::info!("{signal}: stopping; Modbus TCP served {}", health.view());
            } else {
                tracing::info!("{signal}: stopping");
            }
            Ok(())
        }
        ended = servers.join_next() => match ended {
            Some(Ok(r)) => r,
            Some(Err(e)) => Err(anyhow::anyhow!("server task failed: {e}")),
            None => Ok(()),
        },
    };
    stepping.abort_all();
    drop(link);
    result
}

/// The units of the command line (`--unit`, else one at the address of `--config`, else 1),
/// each serving `served`; two units at one address are refused.
fn units_of(args: &Args, served: &Served, config_unit: Option<u8>) -> anyhow::Result<Vec<Unit>> {
    let defaults = Defaults {
        model: args.model.clone(),
        noise_pct: args.noise_pct,
        drift: DriftSpec {
            dead_time_drift_s_per_h: args.dead_time_drift_s_per_h,
            dead_time_drift_max_s: args.dead_time_drift_max_s,
            friction_band_drift_pct_per_h: args.friction_band_drift_pct_per_h,
            friction_band_drift_max_pct: args.friction_band_drift_max_pct,
        },
        seed: args.seed,
    };
    let one = [UnitArg {
        id: config_unit.unwrap_or(1),
        model: None,
        settings: Vec::new(),
    }];
    let args_units = if args.unit.is_empty() {
        &one[..]
    } else {
        &args.unit[..]
    };
    let mut units: Vec<Unit> = Vec::with_capacity(args_units.len());
    for a in args_units {
        if units.iter().any(|u| u.id == a.id) {
            bail!(
                "--unit {}: two units at one address; give each its own id",
                a.id
            );
        }
        units.push(Unit::new(a, &defaults, served)?);
    }
    Ok(units)
}

/// Waits for SIGINT or SIGTERM and names it.
async fn stop_signal() -> anyhow::Result<&'static str> {
    use tokio::signal::unix::{signal, SignalKind};
    let mut int = signal(SignalKind::interrupt()).context("cannot handle SIGINT")?;
    let mut term = signal(SignalKind::terminate()).context("cannot handle SIGTERM")?;
    Ok(tokio::select! {
        _ = int.recv() => "SIGINT",
        _ = term.recv() => "SIGTERM",
    })
}

/// The `--pty-link` made for this run's pseudo-terminal: removed on drop, if it still points
/// there (a later run may have taken the name).
struct PtyLink {
    link: PathBuf,
    target: PathBuf,
}

impl Drop for PtyLink {
    fn drop(&mut self) {
        if std::fs::read_link(&self.link).is_ok_and(|t| t == self.target) {
            if let Err(e) = std::fs::remove_file(&self.link) {
                tracing::warn!("cannot remove {}: {e}", self.link.display());
            }
        }
    }
}

/// Opens the pseudo-terminal (`--pty`) or the serial device (`--serial`), announces it and
/// serves `device` on it; the `--pty-link` made, if any.
fn spawn_rtu(
    servers: &mut tokio::task::JoinSet<anyhow::Result<()>>,
    args: &Args,
    device: RtuDevice,
) -> anyhow::Result<Option<PtyLink>> {
    if args.pty {
        let (server_end, client_end) =
            SerialStream::pair().context("cannot open a pseudo-terminal (--pty)")?;
        let path = client_end
            .name()
            .context("the pseudo-terminal has no path")?;
        let made = match &args.pty_link {
            Some(link) => {
                // Replace a link left by an earlier run; a missing one is fine.
                let _gone = std::fs::remove_file(link);
                std::os::unix::fs::symlink(&path, link).with_context(|| {
                    format!("cannot create the link {} (--pty-link)", link.display())
                })?;
                Some(PtyLink {
                    link: link.clone(),
                    target: PathBuf::from(&path),
                })
            }
            None => None,
        };
        announce(&format!("pty: {path}"));
        servers.spawn(async move {
            // The client end stays open for the device's life: without it, the server end
            // reads EIO whenever a client closes its handle.
            let _client_end = client_end;
            device.serve(server_end).await.context("pseudo-terminal")
        });
        return Ok(made);
    } else if let Some(path) = &args.serial {
        let name = path.display().to_string();
        let port = serial::open(&line(args, &name))
            .with_context(|| format!("cannot open serial port {name} (--serial)"))?;
        announce(&format!("serial: {name}"));
        servers.spawn(async move { device.serve(port).await.with_context(|| name) });
    }
    Ok(None)
}
