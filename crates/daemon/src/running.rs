//! Starting the daemon: checks the options, binds the listening sockets, opens the valves on
//! the loop thread, starts a logger per valve and the network thread, and hands the loop its
//! parts.
//! [`Running`] is the started daemon: stop it, watch it, and join it for the [`Summary`].
//!
//! Not here: what the loop does each slot ([`crate::runtime::control`]), serving ([`crate::serve`]).

use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use crate::config::{ClockKind, Config, DiagnosisConfig};
use crate::error::DaemonError;
use crate::monitor::analysis::{DiagnoseWindow, PlotHealth};
use crate::monitor::diagnosis::{self, DiagnosisMetrics};
use crate::monitor::health::{self, HealthReport};
use crate::runtime::compensation::Compensation;
use crate::runtime::control::{self, Lane, Loop, LoopEnd};
use crate::runtime::files;
use crate::runtime::log_file::LogAlarm;
use crate::runtime::logger::{LogReport, Logger};
use crate::runtime::source::Source;
use crate::runtime::stats::{Live, Summary, ValveSummary};
use crate::runtime::valve::BackendError;
use crate::serve::exporter::LoopMetrics;
use crate::serve::page::board::Board;
use crate::serve::{Listeners, Net};
use crate::RunOptions;
use vb_core::model::{ModelSpec, Valve};
use vb_modbus::net::Health;

/// A started daemon: its threads and the stop flag.
#[derive(Debug)]
pub struct Running {
    stop: Arc<AtomicBool>,
    live: Arc<Live>,
    rate_hz: f64,
    /// The loop and the loggers, stopped and joined however `Running` goes.
    threads: LoopThreads,
    /// The health thread, with `[health]`.
    health: Option<JoinHandle<Result<Vec<HealthReport>, DaemonError>>>,
    /// The diagnosis thread, with `[diagnosis]`.
    diagnosis: Option<diagnosis::Thread>,
    net: Option<Net>,
    endpoints: Vec<(&'static str, SocketAddr)>,
    servers: Vec<(&'static str, Arc<Health>)>,
}

/// Starts the loop and logger threads; the loop runs until stopped, the duration or a source ends.
pub fn start(config: Config, opts: RunOptions) -> Result<Running, DaemonError> {
    files::ignore_file_size_signal();
    let clock = checked_clock(&config, &opts)?;
    let diagnose = checked_diagnosis(&config, &opts)?;
    let rate_hz = config.loop_.rate_hz;
    let period = config.loop_.period();
    // Sockets are bound before the valves are opened, so a taken port stops the start first.
    let mut sources: Vec<Source> = (config.valves.iter())
        .map(|v| {
            Source::new(config.source_of(v), &config.safety, period.as_secs_f64()).named(v.label())
        })
        .collect();
    let dir = opts
        .log_dir
        .clone()
        .unwrap_or_else(|| config.log.dir.clone());
    let (metrics, board, listeners) = bind(&config, &sources, &dir)?;
    // The backends are opened on the loop thread, inside the runtime that will drive their I/O;
    // the rest of the loop is handed over once they are open, so a valve that cannot be reached
    // stops the start before any log file is created.
    let spawned = control::spawn(
        config.valves.clone(),
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
    let alarms: Vec<Arc<LogAlarm>> = (config.valves.iter().enumerate())
        .map(|(i, v)| {
            let m = metrics.as_ref().and_then(|m| m.valve(i));
            LogAlarm::new(v.label(), m, board.as_ref().and_then(|b| b.valve(i)))
        })
        .collect();
    let (health, diagnosis) = start_health(
        (&config, clock),
        (&dir, &alarms),
        (metrics.as_ref(), board.as_deref()),
        &sources,
        (diagnose, opts.analysis.plot_health),
    )?;
    let mut lanes = Vec::with_capacity(config.valves.len());
    let mut loggers = Vec::with_capacity(config.valves.len());
    for (i, (valve, described)) in config.valves.iter().zip(&spawned.valves).enumerate() {
        let forward = health.as_ref().map(|h| (i, h.tx.clone()));
        let trace = board.as_ref().and_then(|b| b.feed(i, rate_hz));
        let logger = Logger::start(
            &config.log,
            (&dir, valve.name.as_deref()),
            (forward, trace),
            alarms[i].clone(),
            stop.clone(),
        )?;
        tracing::info!(
            valve = valve.label(),
            described = %described,
            source = config.source_of(valve).spec.tag(),
            "valve"
        );
        loggers.push((valve.label().to_string(), logger.handle));
        let source = sources.remove(0);
        let m = metrics.as_ref().and_then(|m| m.valve(i));
        let comp_metrics = match (&metrics, &valve.compensation) {
            (Some(m), Some(_)) => Some(m.compensation(valve.label())?),
            _ => None,
        };
        let compensation = Compensation::new(
            valve,
            period.as_secs_f64(),
            config.source_of(valve).op_range(),
            comp_metrics,
        )?;
        lanes.push((
            valve.label().to_string(),
            (source, compensation),
            m,
            logger.tx,
        ));
    }
    tracing::info!(valves = lanes.len(), rate_hz, clock = ?clock, "starting the loop");
    let (loop_stop, loop_live) = (stop.clone(), live.clone());
    let control = spawned.run(move |backends| Loop {
        clock,
        period,
        spin: Duration::from_micros(u64::from(config.loop_.spin_us)),
        realtime_priority: config.loop_.realtime_priority,
        lanes: (lanes.into_iter().zip(backends))
            .map(|((name, source, m, tx), backend)| Lane::new(name, source, backend, m, tx))
            .collect(),
        metrics,
        safe_action: config.safety.on_stop,
        go_to_pct: config.safety.go_to_pct,
        max_slots: opts
            .duration_s
            .map(|d| (d * rate_hz).round().max(1.0) as u64),
        stop: loop_stop,
        live: loop_live,
    })?;
    Ok(Running {
        threads: LoopThreads {
            stop: stop.clone(),
            control: Some(control),
            loggers,
        },
        stop,
        live,
        rate_hz,
        health: health.map(|h| h.handle),
        diagnosis,
        net,
        endpoints,
        servers,
    })
}

/// The metrics and the live page's board (with `[metrics]`), and the servers' sockets, bound.
type Bound = (Option<LoopMetrics>, Option<Arc<Board>>, Listeners);

/// What [`Bound`] holds for `config` (the daemon's files in `dir`).
fn bind(config: &Config, sources: &[Source], dir: &Path) -> Result<Bound, DaemonError> {
    let names: Vec<&str> = config.valves.iter().map(|v| v.label()).collect();
    let metrics = config
        .metrics
        .as_ref()
        .map(|_| LoopMetrics::new(&names, config.health.is_some()))
        .transpose()?;
    // The loop time of the first health window and of the first diagnosis, for the page.
    let runs = (
        config.health.as_ref().map(|h| h.window_s),
        config.diagnosis.as_ref().map(|d| d.window_s),
    );
    let board = (config.metrics.as_ref())
        .map(|_| Arc::new(Board::new(&names, config.loop_.rate_hz, runs, dir)));
    let listeners = Listeners::bind(config, sources, (metrics.as_ref(), board.as_ref()))?;
    Ok((metrics, board, listeners))
}

/// The loop thread and the loggers. Dropped before [`Running::finish`] took them (the calling
/// thread panicked, or gave up on the daemon), it stops the loop and waits for it and the
/// loggers: the stop action is applied and its row written whatever happens to the caller.
#[derive(Debug)]
struct LoopThreads {
    stop: Arc<AtomicBool>,
    control: Option<JoinHandle<Result<LoopEnd, DaemonError>>>,
    /// Each valve's name and logger, in the order of the config.
    loggers: Vec<(String, JoinHandle<Result<LogReport, DaemonError>>)>,
}

impl LoopThreads {
    /// Waits for the loop thread (after the stop action) and returns how it ended.
    fn join_loop(&mut self) -> Result<Result<LoopEnd, DaemonError>, DaemonError> {
        match self.control.take() {
            Some(handle) => handle.join().map_err(|_| DaemonError::Panicked("loop")),
            None => Err(DaemonError::Panicked("loop")),
        }
    }
}

impl Drop for LoopThreads {
    fn drop(&mut self) {
        if self.control.is_some() {
            self.stop.store(true, Ordering::SeqCst);
            tracing::warn!("stopping the loop: the daemon's caller ended before it");
        }
        // Errors were told where they happened; what matters here is that the threads end.
        let _ended = self.join_loop();
        for (_, logger) in self.loggers.drain(..) {
            let _ended = logger.join();
        }
    }
}

/// Starts the health thread when `[health]` asks for it: a CSV per valve in `dir`, the gauges,
/// the live page's `board`, and the alarm bit in the status word of each valve a process
/// controller drives (`sources`); and with `[diagnosis]`, the diagnosis thread it feeds, for a
/// loop on `clock`. `alarms`: each valve's log alarm.
fn start_health(
    (config, clock): (&Config, ClockKind),
    (dir, alarms): (&Path, &[Arc<LogAlarm>]),
    (metrics, board): (Option<&LoopMetrics>, Option<&Board>),
    sources: &[Source],
    (diagnose, plot): (Option<Diagnose<'_>>, Option<PlotHealth>),
) -> Result<(Option<health::Health>, Option<diagnosis::Thread>), DaemonError> {
    let Some(cfg) = &config.health else {
        return Ok((None, None));
    };
    std::fs::create_dir_all(dir).map_err(|source| DaemonError::LogDir {
        dir: dir.to_path_buf(),
        source,
    })?;
    let period_s = config.loop_.period_s();
    let mut watched = Vec::with_capacity(config.valves.len());
    // Each valve's health baseline model: its answer is the health baseline, and the live
    // diagnosis starts from it.
    let models = (config.valves.iter())
        .map(|v| {
            v.health_baseline_model
                .as_deref()
                .map(ModelSpec::load)
                .transpose()
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(BackendError::from)?;
    for (i, v) in config.valves.iter().enumerate() {
        let baseline_model = match &models[i] {
            Some(spec) => Some(Valve::new(spec, period_s).map_err(BackendError::from)?),
            None => None,
        };
        watched.push(health::Watched {
            name: v.label().to_string(),
            file_name: v
                .name
                .as_ref()
                .map_or("health.csv".into(), |n| format!("health-{n}.csv")),
            baseline_model,
            metrics: metrics.and_then(|m| m.health(i)),
            status: sources.get(i).and_then(Source::served_bank).cloned(),
            plot,
            board: board.and_then(|b| b.valve(i)),
            log_alarm: alarms[i].clone(),
        });
    }
    let (feed, diagnosis) = match diagnose {
        Some((d, diagnose)) => {
            let m = metrics
                .map(|m| DiagnosisMetrics::register(m.registry()))
                .transpose()?;
            let valves = (config.valves.iter())
                .enumerate()
                .map(|(i, v)| diagnosis::Watched {
                    name: v.label().to_string(),
                    metrics: m.clone(),
                    board: board.and_then(|b| b.valve(i)),
                    log_alarm: alarms[i].clone(),
                    model: models[i].clone(),
                })
                .collect();
            let files_in = (dir, config.log.on_error);
            let (feed, handle) =
                diagnosis::start(d, files_in, (period_s, clock), valves, diagnose)?;
            (Some(feed), Some(handle))
        }
        None => (None, None),
    };
    let health = health::start(cfg, (dir, config.log.on_error), period_s, watched, feed)?;
    Ok((Some(health), diagnosis))
}

/// `[diagnosis]` with the function that diagnoses a window.
type Diagnose<'a> = (&'a DiagnosisConfig, DiagnoseWindow);

/// The diagnosis `[diagnosis]` asks for; refused before anything is opened when the daemon was
/// handed none.
fn checked_diagnosis<'a>(
    config: &'a Config,
    opts: &RunOptions,
) -> Result<Option<Diagnose<'a>>, DaemonError> {
    match &config.diagnosis {
        Some(d) => Ok(Some((
            d,
            opts.analysis.diagnose.ok_or(DaemonError::NoDiagnosis)?,
        ))),
        None => Ok(None),
    }
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
    let real = config.valves.iter().find(|v| !v.backend.is_simulated());
    if let (ClockKind::Virtual, Some(v)) = (clock, real) {
        return Err(DaemonError::VirtualClock(v.backend.tag().into()));
    }
    if clock == ClockKind::Virtual && config.controller_server().is_some() {
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
        self.threads
            .control
            .as_ref()
            .is_none_or(|c| c.is_finished())
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

    /// Waits for the loop and the loggers to end and returns the summary.
    pub fn finish(self) -> Result<Summary, DaemonError> {
        let mut threads = self.threads;
        let end = threads.join_loop();
        // The controller and the scraper are answered until the stop action has been applied.
        let net = self.net.map(Net::stop).transpose();
        // The loop thread has dropped its senders: each logger drains, flushes and closes.
        let loggers = std::mem::take(&mut threads.loggers);
        let mut logs = Vec::with_capacity(loggers.len());
        for (name, handle) in loggers {
            let log = handle
                .join()
                .map_err(|_| DaemonError::Panicked("logger"))??;
            logs.push((name, log));
        }
        // The loggers have dropped theirs: the health thread finishes its rows.
        let mut health = match self.health {
            Some(h) => h.join().map_err(|_| DaemonError::Panicked("health"))??,
            None => Vec::new(),
        }
        .into_iter();
        // The health thread has dropped the feed: the diagnosis thread finishes its jobs.
        let mut diagnosis = match self.diagnosis {
            Some(h) => h.join().map_err(|_| DaemonError::Panicked("diagnosis"))??,
            None => Vec::new(),
        }
        .into_iter();
        net?;
        let end = end??;
        Ok(Summary {
            valves: (end.valves.into_iter().zip(logs))
                .map(|(lane, (name, log))| ValveSummary {
                    name,
                    stats: lane.stats,
                    safe: lane.safe,
                    link: lane.link,
                    log,
                    health: health.next(),
                    diagnosis: diagnosis.next(),
                    compensation: lane.compensation,
                })
                .collect(),
            reason: end.reason,
            slots: end.slots,
            rate_hz: self.rate_hz,
            servers: (self.servers.iter())
                .map(|(name, h)| (*name, h.view()))
                .collect(),
        })
    }
}
