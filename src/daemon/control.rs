//! The loop thread (`vb-loop`): each slot of the schedule, O_P from the source, one valve
//! transaction, a row to the logger; on stop, the safe action.
//!
//! [`spawn`] starts the thread and opens the valve on it (inside the runtime that drives the
//! valve's I/O); [`Spawned::run`] hands it the rest of the loop. Not here: starting the other
//! threads ([`super::running`]), the valve protocols ([`super::valve`]).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use super::config::{ClockKind, OnStop, ValveConfig};
use super::exporter::LoopMetrics;
use super::logger::{round_pct, Sample, Status};
use super::schedule::{self, Schedule, Slot};
use super::source::Source;
use super::stats::{Live, Stats, StopReason};
use super::valve::{Backend, Fault};
use super::DaemonError;

/// What the loop thread hands back.
pub(super) struct LoopEnd {
    pub(super) stats: Stats,
    pub(super) reason: StopReason,
    pub(super) slots: u64,
    pub(super) safe: Option<Sample>,
    pub(super) reconnects: Option<u64>,
    pub(super) attempts: Option<u64>,
}

/// Everything the loop thread owns.
pub(super) struct Loop {
    pub(super) clock: ClockKind,
    pub(super) period: Duration,
    pub(super) spin: Duration,
    pub(super) realtime_priority: u8,
    pub(super) source: Source,
    pub(super) backend: Backend,
    pub(super) metrics: Option<LoopMetrics>,
    pub(super) safe_action: OnStop,
    pub(super) go_to_pct: Option<f64>,
    pub(super) max_slots: Option<u64>,
    pub(super) stop: Arc<AtomicBool>,
    pub(super) live: Arc<Live>,
    pub(super) tx: Sender<Sample>,
    pub(super) stats: Stats,
    pub(super) last_op: Option<f64>,
    pub(super) last_status: Status,
    pub(super) last_skipped_k: Option<u64>,
}

/// Builds the loop around the opened backend.
type Build = Box<dyn FnOnce(Backend) -> Loop + Send>;

/// The loop thread, its valve open, waiting for the rest of the loop.
pub(super) struct Spawned {
    /// The valve, described for the log.
    pub valve: String,
    handle: JoinHandle<Result<LoopEnd, DaemonError>>,
    parts: Sender<Build>,
}

/// Starts the loop thread and opens the valve `[valve]` describes on it, for a loop of period
/// `period_s`; the error of a valve that cannot be opened (or, with `require_device`, reached)
/// is returned here.
pub(super) fn spawn(
    valve: ValveConfig,
    period_s: f64,
    require_device: bool,
) -> Result<Spawned, DaemonError> {
    let (ready_tx, ready_rx) = std::sync::mpsc::channel();
    let (parts, parts_rx): (Sender<Build>, Receiver<Build>) = std::sync::mpsc::channel();
    let handle = std::thread::Builder::new()
        .name("vb-loop".into())
        .spawn(move || {
            // On an error here `ready_tx` is dropped unsent and spawn() reads the error from the join.
            let rt = current_thread_runtime("loop runtime")?;
            let backend = rt.block_on(Backend::open(&valve, period_s, require_device))?;
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
    match ready_rx.recv() {
        Ok(valve) => Ok(Spawned {
            valve,
            handle,
            parts,
        }),
        Err(_) => Err(match handle.join() {
            Ok(Err(e)) => e,
            _ => DaemonError::Panicked("loop"),
        }),
    }
}

impl Spawned {
    /// Hands the loop thread the rest of the loop (`build` gets the opened backend); it runs.
    pub(super) fn run(
        self,
        build: impl FnOnce(Backend) -> Loop + Send + 'static,
    ) -> Result<JoinHandle<Result<LoopEnd, DaemonError>>, DaemonError> {
        self.parts
            .send(Box::new(build))
            .map_err(|_| DaemonError::Panicked("loop"))?;
        Ok(self.handle)
    }
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
                        op_sent_pct: None,
                        utc: schedule.wall(k),
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
            // Rounded to the log's precision: the O_P sent is the O_P logged.
            let Some(op) = self.source.op_at(t_s).map(round_pct) else {
                break (StopReason::SourceEnded, k, lateness);
            };
            let mut row = self.transact(&rt, op, (k, t_s, schedule.wall(k)), lateness, None);
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
                    (k_end, schedule.t_s(k_end), schedule.wall(k_end)),
                    lateness_end,
                    Some(status),
                );
                tracing::info!(
                    "stop action applied: {}, O_P {op:.2} %, V_P {}",
                    status.as_str(),
                    row.vp_pct
                        .map_or("not read".into(), |v| format!("{v:.2} %"))
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
            attempts: self.backend.connection_attempts(),
        })
    }

    /// One valve transaction for slot `k` at `t_s`; `safe` marks the stop action's row.
    fn transact(
        &mut self,
        rt: &tokio::runtime::Runtime,
        op: f64,
        (k, t_s, utc): (u64, f64, SystemTime),
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
        if let Err(fault) = result {
            self.stats.note_fault(fault);
        }
        Sample {
            t_s,
            op_pct: Some(op),
            vp_pct: vp,
            status: safe.unwrap_or(status),
            lateness_us: Some(micros(lateness)),
            latency_us: Some(micros(latency)),
            op_sent_pct: self.backend.sent_pct(),
            utc,
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
pub(super) fn current_thread_runtime(
    what: &'static str,
) -> Result<tokio::runtime::Runtime, DaemonError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|source| DaemonError::Thread { what, source })
}

/// A duration in µs with ns resolution (`0.021`, not `0.020999999999999998`).
fn micros(d: Duration) -> f64 {
    d.as_nanos() as f64 / 1e3
}
