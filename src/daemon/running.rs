//! Starting the daemon: checks the options, binds the listening sockets, opens the valve on the
//! loop thread, starts the logger and the network thread, and hands the loop its parts.
//! [`Running`] is the started daemon: stop it, watch it, and join it for the [`Summary`].
//!
//! Not here: what the loop does each slot ([`super::control`]), serving ([`super::net`]).

use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use super::config::{ClockKind, Config, SourceKind};
use super::control::{self, Loop, LoopEnd};
use super::exporter::LoopMetrics;
use super::logger::{LogReport, Logger, Status};
use super::net::{Listeners, Net};
use super::source::Source;
use super::stats::{Live, Stats, Summary};
use super::{DaemonError, RunOptions};
use crate::net::Health;

/// A started daemon: its threads and the stop flag.
pub struct Running {
    stop: Arc<AtomicBool>,
    live: Arc<Live>,
    rate_hz: f64,
    control: JoinHandle<Result<LoopEnd, DaemonError>>,
    logger: JoinHandle<Result<LogReport, DaemonError>>,
    net: Option<Net>,
    endpoints: Vec<(&'static str, SocketAddr)>,
    servers: Vec<(&'static str, Arc<Health>)>,
}

/// Starts the loop and logger threads; the loop runs until stopped, the duration or the source ends.
pub fn start(config: Config, opts: RunOptions) -> Result<Running, DaemonError> {
    let clock = checked_clock(&config, &opts)?;
    let rate_hz = config.loop_.rate_hz;
    let period = config.loop_.period();
    // Sockets are bound before the valve is opened, so a taken port stops the start first.
    let source = Source::new(&config.source, &config.safety, period.as_secs_f64());
    let metrics = config
        .metrics
        .as_ref()
        .map(|_| LoopMetrics::new())
        .transpose()?;
    let listeners = Listeners::bind(&config, &source, metrics.as_ref())?;
    // The backend is opened on the loop thread, inside the runtime that will drive its I/O; the
    // rest of the loop is handed over once it is open, so a valve that cannot be reached stops
    // the start before any log file is created.
    let spawned = control::spawn(
        config.valve.clone(),
        period.as_secs_f64(),
        opts.require_device,
    )?;
    let endpoints = listeners.endpoints();
    let servers = listeners.health();
    let net = Net::start(listeners)?;
    for (name, addr) in &endpoints {
        tracing::info!(%addr, "serving {name}");
    }
    let stop = Arc::new(AtomicBool::new(false));
    let live = Arc::new(Live::default());
    let dir = opts
        .log_dir
        .clone()
        .unwrap_or_else(|| config.log.dir.clone());
    let logger = Logger::start(&config.log, &dir, stop.clone())?;
    tracing::info!(
        valve = %spawned.valve,
        source = config.source.kind.tag(),
        rate_hz,
        clock = ?clock,
        "starting the loop"
    );
    let tx = logger.tx;
    let (loop_stop, loop_live) = (stop.clone(), live.clone());
    let control = spawned.run(move |backend| Loop {
        clock,
        period,
        spin: Duration::from_micros(u64::from(config.loop_.spin_us)),
        realtime_priority: config.loop_.realtime_priority,
        source,
        backend,
        metrics,
        safe_action: config.safety.on_stop,
        go_to_pct: config.safety.go_to_pct,
        max_slots: opts
            .duration_s
            .map(|d| (d * rate_hz).round().max(1.0) as u64),
        stop: loop_stop,
        live: loop_live,
        tx,
        stats: Stats::new(),
        last_op: None,
        last_status: Status::Ok,
        last_skipped_k: None,
    })?;
    Ok(Running {
        stop,
        live,
        rate_hz,
        control,
        logger: logger.handle,
        net,
        endpoints,
        servers,
    })
}

/// The clock the loop runs on, after checking that `--duration` and the clock fit the config.
fn checked_clock(config: &Config, opts: &RunOptions) -> Result<ClockKind, DaemonError> {
    if let Some(d) = opts.duration_s {
        if !(d.is_finite() && d > 0.0) {
            return Err(DaemonError::Duration(d));
        }
    }
    let clock = if opts.virtual_clock {
        ClockKind::Virtual
    } else {
        config.loop_.clock
    };
    if clock == ClockKind::Virtual && !config.valve.kind.is_simulated() {
        return Err(DaemonError::VirtualClock(config.valve.kind.tag().into()));
    }
    if clock == ClockKind::Virtual && config.source.kind == SourceKind::ModbusServer {
        return Err(DaemonError::VirtualClockController);
    }
    Ok(clock)
}

impl Running {
    /// Asks the loop to stop; it applies the safe action in its next slot.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// True once the loop thread has ended.
    pub fn is_finished(&self) -> bool {
        self.control.is_finished()
    }

    /// The loop rate, Hz.
    pub fn rate_hz(&self) -> f64 {
        self.rate_hz
    }

    /// The live figures.
    pub fn live(&self) -> &Live {
        &self.live
    }

    /// What the daemon serves, by name (`modbus-server`, `metrics`), with the bound addresses.
    pub fn endpoints(&self) -> &[(&'static str, SocketAddr)] {
        &self.endpoints
    }

    /// Waits for the loop and the logger to end and returns the summary.
    pub fn finish(self) -> Result<Summary, DaemonError> {
        let end = self
            .control
            .join()
            .map_err(|_| DaemonError::Panicked("loop"));
        // The controller and the scraper are answered until the stop action has been applied.
        let net = self.net.map(Net::stop).transpose();
        // The loop thread has dropped its sender: the logger drains, flushes and closes.
        let log = self
            .logger
            .join()
            .map_err(|_| DaemonError::Panicked("logger"))??;
        net?;
        let end = end??;
        Ok(Summary {
            stats: end.stats,
            reason: end.reason,
            slots: end.slots,
            rate_hz: self.rate_hz,
            safe: end.safe,
            reconnects: end.reconnects,
            connection_attempts: end.attempts,
            servers: (self.servers.iter())
                .map(|(name, h)| (*name, h.view()))
                .collect(),
            log,
        })
    }
}
