//! `valve-bridge run`: the valve loop, at 100 Hz by default, from source to valve to log.
//!
//! Every slot of an absolute time grid, the loop asks the [`source::Source`] for the wanted
//! opening O_P, sends it to the valve [`valve::Backend`] and reads V_P back in one transaction,
//! and hands a [`logger::Sample`] to the [`logger`]. Missed slots and failed transactions are
//! logged as such with an empty V_P. On stop (SIGINT, SIGTERM, `--duration`, or the end of a
//! replay) the loop applies the configured safe action in the next slot, logs it, the log is
//! flushed and closed, and a [`stats::Summary`] is returned.
//!
//! Threads: the loop runs on its own OS thread (`vb-loop`) that sleeps to absolute deadlines
//! ([`schedule`]) and runs each valve transaction on a current-thread tokio runtime it owns, so
//! async backends need no other thread and no cross-thread hop. The logger writes on its own
//! thread. The network thread (`vb-net`, only when there is something to serve) runs the
//! process controller's Modbus server ([`hil`]) and the Prometheus endpoint ([`exporter`]) on a
//! runtime of its own: the loop shares only a register bank and atomic metric handles with it and
//! never waits on a socket. The calling thread waits for signals (tokio), drives the progress
//! display and joins.
//!
//! Sample convention (as [`crate::model::Valve::simulate_into`]): in slot `k` the valve gets
//! `op_k` and the V_P it returns is sample `k`. The emulated valve starts at rest at the first
//! O_P, so a log replays exactly through `Valve::simulate(op, op[0])`.
//!
//! Not here: the Modbus protocol (a backend variant in [`valve`]), recording analysis.

pub mod config;
pub mod exporter;
pub mod hil;
pub mod logger;
pub mod schedule;
pub mod source;
pub mod stats;
pub mod valve;

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub use config::Config;
use config::{ClockKind, OnStop, SourceKind};
use exporter::LoopMetrics;
use logger::{LogReport, Logger, Sample, Status};
use schedule::{Schedule, Slot};
use source::Source;
pub use stats::Summary;
use stats::{Live, Stats, StopReason};
use valve::{Backend, BackendError, Fault};

use crate::modbus::server::RegisterBank;
use crate::toml_file::TomlError;

/// Why the daemon could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] TomlError),
    /// The valve backend cannot start (model, Modbus settings, bus budget, connection).
    #[error(transparent)]
    Valve(#[from] BackendError),
    /// `--duration` is not a positive number.
    #[error("--duration {0}: must be a positive number of seconds")]
    Duration(f64),
    /// The virtual clock was asked for a real valve.
    #[error("the virtual clock (--as-fast-as-possible, [loop] clock = \"virtual\") needs a simulated valve, not {0}")]
    VirtualClock(String),
    /// The virtual clock was asked for a process controller.
    #[error("the virtual clock (--as-fast-as-possible) cannot serve a process controller ([source] kind = \"modbus-server\"), which runs on the wall clock: leave the option out")]
    VirtualClockController,
    /// A listening socket cannot be opened.
    #[error(
        "cannot listen on {addr} ({key}): {source} (is the port taken? set another address there)"
    )]
    Listen {
        key: &'static str,
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// The Prometheus metrics cannot be registered (a bug).
    #[error("cannot set up the metrics: {0}")]
    Metrics(#[from] prometheus::Error),
    /// The log directory cannot be created.
    #[error(
        "cannot create log directory `{dir}`: {source} (set another with --log-dir or [log] dir)"
    )]
    LogDir {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A log file cannot be created.
    #[error("cannot create log file `{path}`: {source}")]
    LogFile {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A log file cannot be written.
    #[error("cannot write log file `{path}`: {source} (is the disk full?)")]
    LogWrite {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A thread, runtime or signal handler could not be set up.
    #[error("cannot start the {what}: {source}")]
    Thread {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// A daemon thread panicked (a bug).
    #[error("the {0} thread stopped unexpectedly")]
    Panicked(&'static str),
}

/// Command-line overrides of the configuration.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this much loop time, s.
    pub duration_s: Option<f64>,
    /// Log directory instead of `[log] dir`.
    pub log_dir: Option<PathBuf>,
    /// Run on the virtual clock whatever `[loop] clock` says.
    pub virtual_clock: bool,
    /// Show the one-line progress display (only drawn on a terminal).
    pub progress: bool,
}

/// A started daemon: its threads and the stop flag.
pub struct Running {
    stop: Arc<AtomicBool>,
    live: Arc<Live>,
    rate_hz: f64,
    control: JoinHandle<Result<LoopEnd, DaemonError>>,
    logger: JoinHandle<Result<LogReport, DaemonError>>,
    net: Option<Net>,
    endpoints: Vec<(&'static str, SocketAddr)>,
}

/// What the loop thread hands back.
struct LoopEnd {
    stats: Stats,
    reason: StopReason,
    slots: u64,
    safe: Option<Sample>,
    reconnects: Option<u64>,
}

/// Everything the loop thread owns.
struct Loop {
    clock: ClockKind,
    period: Duration,
    spin: Duration,
    realtime_priority: u8,
    source: Source,
    backend: Backend,
    metrics: Option<LoopMetrics>,
    safe_action: OnStop,
    go_to_pct: Option<f64>,
    max_slots: Option<u64>,
    stop: Arc<AtomicBool>,
    live: Arc<Live>,
    tx: Sender<Sample>,
    stats: Stats,
    last_op: Option<f64>,
    last_status: Status,
    last_skipped_k: Option<u64>,
}

/// Starts the loop and logger threads; the loop runs until stopped, the duration or the source ends.
pub fn start(config: Config, opts: RunOptions) -> Result<Running, DaemonError> {
    if let Some(d) = opts.duration_s {
        if !(d.is_finite() && d > 0.0) {
            return Err(DaemonError::Duration(d));
        }
    }
    let rate_hz = config.loop_.rate_hz;
    let period = config.loop_.period();
    let period_s = period.as_secs_f64();
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
    // Sockets are bound before the valve is opened, so a taken port stops the start first.
    let source = Source::new(&config.source, &config.safety, period_s);
    let metrics = config
        .metrics
        .as_ref()
        .map(|_| LoopMetrics::new())
        .transpose()?;
    let mut endpoints = Vec::new();
    let modbus = match source.served_bank() {
        Some(bank) => {
            let key = "[source.modbus-server] listen";
            let (listener, addr) = bind(key, config.source.modbus_server.listen.0)?;
            endpoints.push(("modbus-server", addr));
            Some((listener, Arc::clone(bank)))
        }
        None => None,
    };
    let exporter = match (&config.metrics, &metrics) {
        (Some(cfg), Some(m)) => {
            let key = "[metrics] listen";
            let (listener, addr) = bind(key, cfg.listen.0)?;
            endpoints.push(("metrics", addr));
            Some((listener, m.registry().clone()))
        }
        _ => None,
    };
    // The backend is opened on the loop thread, inside the runtime that will drive its I/O; the
    // rest of the loop is handed over once it is open, so a valve that cannot be reached stops
    // the start before any log file is created.
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (parts_tx, parts_rx) =
        std::sync::mpsc::channel::<Box<dyn FnOnce(Backend) -> Loop + Send>>();
    let valve_cfg = config.valve.clone();
    let control = std::thread::Builder::new()
        .name("vb-loop".into())
        .spawn(move || {
            // On an error here `ready_tx` is dropped unsent and start() reads the error from the join.
            let rt = current_thread_runtime("loop runtime")?;
            let backend = rt.block_on(Backend::open(&valve_cfg, period_s))?;
            ready_tx
                .send(backend.describe())
                .map_err(|_| DaemonError::Panicked("calling"))?;
            // No parts: start() failed after the valve opened (the logger); nothing runs.
            let build = parts_rx
                .recv()
                .map_err(|_| DaemonError::Panicked("calling"))?;
            build(backend).run(rt)
        })
        .map_err(|source| DaemonError::Thread {
            what: "loop thread",
            source,
        })?;
    let Ok(valve) = ready_rx.recv() else {
        return Err(match control.join() {
            Ok(Err(e)) => e,
            _ => DaemonError::Panicked("loop"),
        });
    };
    let net = if modbus.is_some() || exporter.is_some() {
        Some(Net::start(modbus, exporter)?)
    } else {
        None
    };
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
        %valve,
        source = config.source.kind.tag(),
        rate_hz,
        clock = ?clock,
        "starting the loop"
    );
    let tx = logger.tx;
    let (loop_stop, loop_live) = (stop.clone(), live.clone());
    let build = move |backend| Loop {
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
    };
    parts_tx
        .send(Box::new(build))
        .map_err(|_| DaemonError::Panicked("loop"))?;
    Ok(Running {
        stop,
        live,
        rate_hz,
        control,
        logger: logger.handle,
        net,
        endpoints,
    })
}

/// A listening socket on `addr` (named by its config `key` in errors), ready for tokio, and the
/// address it is bound to (the port chosen when the config said port 0).
fn bind(
    key: &'static str,
    addr: SocketAddr,
) -> Result<(std::net::TcpListener, SocketAddr), DaemonError> {
    let (listener, bound) = std::net::TcpListener::bind(addr)
        .and_then(|l| {
            l.set_nonblocking(true)?;
            let bound = l.local_addr()?;
            Ok((l, bound))
        })
        .map_err(|source| DaemonError::Listen { key, addr, source })?;
    if !addr.ip().is_loopback() {
        tracing::warn!(
            %addr,
            "{key} is not a loopback address: other machines can reach it, and neither Modbus \
             nor the metrics endpoint has any authentication"
        );
    }
    Ok((listener, bound))
}

/// The network thread (`vb-net`): the process controller's Modbus server and the metrics
/// endpoint, on a current-thread runtime of their own. It ends when [`Net`] is stopped or dropped.
struct Net {
    stop: tokio::sync::oneshot::Sender<()>,
    handle: JoinHandle<()>,
}

impl Net {
    fn start(
        modbus: Option<(std::net::TcpListener, Arc<RegisterBank>)>,
        exporter: Option<(std::net::TcpListener, prometheus::Registry)>,
    ) -> Result<Net, DaemonError> {
        let rt = current_thread_runtime("network runtime")?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let serve = async move {
            let modbus = async {
                if let Some((listener, bank)) = modbus {
                    let serve = |l| hil::serve(l, bank);
                    serve_logged("Modbus server for the process controller", listener, serve).await;
                }
            };
            let metrics = async {
                if let Some((listener, registry)) = exporter {
                    let serve = |l| exporter::serve(l, registry);
                    serve_logged("metrics endpoint", listener, serve).await;
                }
            };
            tokio::select! {
                // Sent or dropped: either way the daemon is done.
                _ = stopped => {}
                _ = async { tokio::join!(modbus, metrics) } => {}
            }
        };
        let handle = std::thread::Builder::new()
            .name("vb-net".into())
            .spawn(move || rt.block_on(serve))
            .map_err(|source| DaemonError::Thread {
                what: "network thread",
                source,
            })?;
        Ok(Net { stop, handle })
    }

    /// Stops serving and waits for the thread.
    fn stop(self) -> Result<(), DaemonError> {
        // An error only means the thread has already ended.
        let _ = self.stop.send(());
        self.handle
            .join()
            .map_err(|_| DaemonError::Panicked("network"))
    }
}

/// Serves `listener` with `serve` (on the network thread's runtime) and logs why it stopped.
async fn serve_logged<F, Fut>(what: &str, listener: std::net::TcpListener, serve: F)
where
    F: FnOnce(tokio::net::TcpListener) -> Fut,
    Fut: std::future::Future<Output = std::io::Result<()>>,
{
    let served = match tokio::net::TcpListener::from_std(listener) {
        Ok(l) => serve(l).await,
        Err(e) => Err(e),
    };
    if let Err(e) = served {
        tracing::error!("the {what} stopped: {e}");
    }
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
            log,
        })
    }
}

/// Runs until SIGINT/SIGTERM, `--duration` or the end of the source, showing progress.
pub fn run(config: Config, opts: RunOptions) -> Result<Summary, DaemonError> {
    let thread_err = |what| move |source| DaemonError::Thread { what, source };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(thread_err("signal runtime"))?;
    let progress = opts.progress;
    let running = rt.block_on(async {
        use tokio::signal::unix::{signal, SignalKind};
        // Handlers first, so a signal during start-up already stops cleanly.
        let mut sigint = signal(SignalKind::interrupt()).map_err(thread_err("SIGINT handler"))?;
        let mut sigterm = signal(SignalKind::terminate()).map_err(thread_err("SIGTERM handler"))?;
        let running = start(config, opts)?;
        announce(running.endpoints());
        let bar = progress_bar(progress);
        let mut tick = tokio::time::interval(Duration::from_millis(50));
        while !running.is_finished() {
            tokio::select! {
                _ = sigint.recv() => {
                    tracing::info!("SIGINT: stopping");
                    running.stop();
                }
                _ = sigterm.recv() => {
                    tracing::info!("SIGTERM: stopping");
                    running.stop();
                }
                _ = tick.tick() => show(&bar, &running),
            }
        }
        bar.finish_and_clear();
        Ok::<_, DaemonError>(running)
    })?;
    running.finish()
}

/// Prints one `name: ADDR` line per endpoint on stdout, at once (a client may be waiting for it).
fn announce(endpoints: &[(&'static str, SocketAddr)]) {
    let mut out = std::io::stdout().lock();
    for (name, addr) in endpoints {
        // A closed stdout only loses the announcement; the daemon runs on.
        let _ = writeln!(out, "{name}: {addr}");
    }
    let _ = out.flush();
}

fn progress_bar(enabled: bool) -> ProgressBar {
    if !enabled {
        return ProgressBar::hidden();
    }
    // Drawn on stderr only when it is a terminal; otherwise indicatif stays quiet.
    let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg}") {
        bar.set_style(style);
    }
    bar
}

fn show(bar: &ProgressBar, running: &Running) {
    if bar.is_hidden() {
        return;
    }
    let v = running.live().view();
    bar.set_message(format!(
        "t {:.1} s  samples {}  O_P {:.2} %  V_P {:.2} %  timing p99 {:.0} us",
        v.samples as f64 / running.rate_hz,
        v.samples,
        v.op_pct,
        v.vp_pct,
        v.p99_us
    ));
    bar.tick();
}

impl Loop {
    /// The loop thread's body.
    fn run(mut self, rt: tokio::runtime::Runtime) -> Result<LoopEnd, DaemonError> {
        schedule::tighten_timer_slack();
        if self.realtime_priority > 0 && self.clock == ClockKind::Real {
            match schedule::realtime_priority(self.realtime_priority) {
                Ok(()) => tracing::info!(
                    priority = self.realtime_priority,
                    "loop thread runs under SCHED_FIFO"
                ),
                Err(e) => tracing::warn!(
                    "cannot give the loop thread SCHED_FIFO priority {} ({e}): needs root or \
                     CAP_SYS_NICE; running at normal priority",
                    self.realtime_priority
                ),
            }
        }
        // The grid starts once the thread is ready, so slot 0 is not late by the set-up.
        let mut schedule = match self.clock {
            ClockKind::Real => Schedule::real(self.period, self.spin),
            ClockKind::Virtual => Schedule::virtual_clock(self.period),
        };
        let (reason, k_end, lateness_end) = loop {
            let slot = schedule.next_slot();
            let k = slot.k();
            let ending = self.max_slots.is_some_and(|m| k >= m) || self.stop.load(Ordering::SeqCst);
            let lateness = match slot {
                // Past the end, a missed slot is not logged: the stop action takes the next one.
                Slot::Skipped { .. } if ending => continue,
                Slot::Skipped { .. } => {
                    let row = Sample {
                        t_s: schedule.t_s(k),
                        op_pct: self.last_op,
                        vp_pct: None,
                        status: Status::Skipped,
                        lateness_us: None,
                        latency_us: None,
                    };
                    // One warning per run of consecutive missed slots, not one per slot.
                    if self.last_skipped_k.is_none_or(|last| last + 1 != k) {
                        tracing::warn!(k, "cycle missed: the previous one overran");
                    }
                    self.last_skipped_k = Some(k);
                    self.emit(row, None)?;
                    continue;
                }
                Slot::Run { lateness, .. } => lateness,
            };
            if ending {
                let reason = if self.stop.load(Ordering::SeqCst) {
                    StopReason::Signal
                } else {
                    StopReason::Duration
                };
                break (reason, k, lateness);
            }
            let t_s = schedule.t_s(k);
            let Some(op) = self.source.op_at(t_s) else {
                break (StopReason::SourceEnded, k, lateness);
            };
            let mut row = self.transact(&rt, op, (k, t_s), lateness, None);
            // A failed transaction keeps its failure status; the O_P column shows the safe O_P.
            if row.status == Status::Ok && self.source.watchdog_tripped() {
                row.status = Status::Watchdog;
            }
            self.source.feedback(&row);
            self.emit(row, Some(lateness))?;
            if k.is_multiple_of(100) {
                self.live.publish_p99(&self.stats);
            }
        };
        let safe_op = match self.safe_action {
            OnStop::Hold => self.last_op.map(|op| (op, Status::SafeHold)),
            OnStop::GoTo => self.go_to_pct.map(|op| (op, Status::SafeGoTo)),
        };
        let safe = match safe_op {
            Some((op, status)) => {
                let row = self.transact(
                    &rt,
                    op,
                    (k_end, schedule.t_s(k_end)),
                    lateness_end,
                    Some(status),
                );
                tracing::info!(
                    action = status.as_str(),
                    op_pct = op,
                    vp_pct = row.vp_pct,
                    "stop action applied"
                );
                self.source.feedback(&row);
                self.emit(row, Some(lateness_end))?;
                Some(row)
            }
            None => None,
        };
        tracing::info!(%reason, slots = k_end, "loop stopped");
        Ok(LoopEnd {
            stats: self.stats,
            reason,
            slots: k_end,
            safe,
            reconnects: self.backend.reconnects(),
        })
    }

    /// One valve transaction for slot `k` at `t_s`; `safe` marks the stop action's row.
    fn transact(
        &mut self,
        rt: &tokio::runtime::Runtime,
        op: f64,
        (k, t_s): (u64, f64),
        lateness: Duration,
        safe: Option<Status>,
    ) -> Sample {
        let started = Instant::now();
        let result = rt.block_on(self.backend.transact(op, k));
        let latency = started.elapsed();
        self.last_op = Some(op);
        let (status, vp) = match result {
            Ok(vp) => (Status::Ok, Some(vp)),
            Err(ref fault) => (
                match fault {
                    Fault::Timeout(_) => Status::Timeout,
                    Fault::Error(_) => Status::Error,
                    Fault::Disconnected(_) => Status::Disconnected,
                },
                None,
            ),
        };
        if status != self.last_status {
            match &result {
                Err(fault) => tracing::warn!(k, "valve transaction failed: {fault}"),
                Ok(_) => tracing::info!(k, "valve transactions succeed again"),
            }
            self.last_status = status;
        }
        Sample {
            t_s,
            op_pct: Some(op),
            vp_pct: vp,
            status: safe.unwrap_or(status),
            lateness_us: Some(micros(lateness)),
            latency_us: Some(micros(latency)),
        }
    }

    /// Counts, publishes and logs a row.
    fn emit(&mut self, row: Sample, lateness: Option<Duration>) -> Result<(), DaemonError> {
        self.stats.record(&row, lateness);
        self.live.publish(&row);
        if let Some(m) = &self.metrics {
            m.record(&row, lateness);
            m.totals(
                self.backend.reconnects().unwrap_or(0),
                self.source.watchdog_trips(),
            );
        }
        // The logger only hangs up by panicking; its join reports that.
        self.tx
            .send(row)
            .map_err(|_| DaemonError::Panicked("logger"))
    }
}

/// A current-thread runtime: the loop thread's (every valve transaction) or the network thread's.
fn current_thread_runtime(what: &'static str) -> Result<tokio::runtime::Runtime, DaemonError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|source| DaemonError::Thread { what, source })
}

/// A duration in µs with ns resolution (`0.021`, not `0.020999999999999998`).
fn micros(d: Duration) -> f64 {
    d.as_nanos() as f64 / 1e3
}
