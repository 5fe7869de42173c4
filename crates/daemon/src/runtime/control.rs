//! The loop thread (`vb-loop`): each slot of the schedule, for every valve in the order of the
//! config, O_P from its source, its compensation ([`crate::runtime::compensation`], with
//! `[valve.compensation]`), one valve transaction, a row to its logger; on stop, the safe
//! action (never compensated). A valve whose transaction fails logs its own row as failed; the
//! others run on.
//!
//! [`spawn`] starts the thread and opens the valves on it (inside the runtime that drives the
//! valve's I/O); [`Spawned::run`] hands it the rest of the loop. Not here: starting the other
//! threads ([`crate::running`]), the valve protocols ([`crate::runtime::valve`]).

use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender, TrySendError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use crate::config::{ClockKind, OnStop, ValveConfig};
use crate::error::DaemonError;
use crate::runtime::compensation::{Compensation, CompensationReport};
use crate::runtime::schedule::{Schedule, Slot};
use crate::runtime::source::Source;
use crate::runtime::stats::{Live, Stats, StopAction, StopReason};
use crate::runtime::valve::{Backend, Fault};
use crate::serve::exporter::{LoopMetrics, ValveMetrics};
use vb_core::recording::log_format::{round_pct, Sample, Status};
use vb_modbus::client::LinkStats;

/// What the loop thread hands back.
pub(crate) struct LoopEnd {
    pub(crate) reason: StopReason,
    pub(crate) slots: u64,
    /// Each valve's end, in the order of the config.
    pub(crate) valves: Vec<LaneEnd>,
}

/// What one valve's lane hands back.
pub(crate) struct LaneEnd {
    pub(crate) stats: Stats,
    pub(crate) safe: Option<StopAction>,
    pub(crate) link: Option<LinkStats>,
    pub(crate) compensation: Option<CompensationReport>,
}

/// Everything the loop thread owns.
pub(crate) struct Loop {
    pub(crate) clock: ClockKind,
    pub(crate) period: Duration,
    pub(crate) spin: Duration,
    pub(crate) realtime_priority: u8,
    /// The valves, driven in this order within each cycle.
    pub(crate) lanes: Vec<Lane>,
    pub(crate) metrics: Option<LoopMetrics>,
    pub(crate) safe_action: OnStop,
    pub(crate) go_to_pct: Option<f64>,
    pub(crate) max_slots: Option<u64>,
    pub(crate) stop: Arc<AtomicBool>,
    /// The first valve's figures, for the progress display and the service watchdog.
    pub(crate) live: Arc<Live>,
}

/// One valve of the loop: its source, backend, log channel and figures.
pub(crate) struct Lane {
    /// The valve's name, in the log's messages.
    pub(crate) name: String,
    pub(crate) source: Source,
    /// The compensation of its O_P, with `[valve.compensation]`.
    pub(crate) compensation: Option<Compensation>,
    pub(crate) backend: Backend,
    pub(crate) metrics: Option<ValveMetrics>,
    pub(crate) tx: SyncSender<Sample>,
    pub(crate) stats: Stats,
    /// The O_P this cycle's source asked for (taken before any valve transacts).
    pub(crate) op: f64,
    /// The last O_P sent (compensated), and the last the source asked for.
    pub(crate) last_op: Option<f64>,
    pub(crate) last_op_controller: Option<f64>,
    pub(crate) last_status: Status,
    pub(crate) last_skipped_k: Option<u64>,
}

impl Lane {
    /// A lane for `backend`, fed by `source` through `compensation`, logging to `tx`.
    pub(crate) fn new(
        name: String,
        (source, compensation): (Source, Option<Compensation>),
        backend: Backend,
        metrics: Option<ValveMetrics>,
        tx: SyncSender<Sample>,
    ) -> Self {
        Lane {
            name,
            source,
            compensation,
            backend,
            metrics,
            tx,
            stats: Stats::new(),
            op: 0.0,
            last_op: None,
            last_op_controller: None,
            last_status: Status::Ok,
            last_skipped_k: None,
        }
    }
}

/// Builds the loop around the opened backends.
type Build = Box<dyn FnOnce(Vec<Backend>) -> Loop + Send>;

/// The loop thread, its valves open, waiting for the rest of the loop.
pub(crate) struct Spawned {
    /// The valves, described for the log.
    pub valves: Vec<String>,
    handle: JoinHandle<Result<LoopEnd, DaemonError>>,
    parts: Sender<Build>,
}

/// Starts the loop thread and opens the valves `valves` describe on it, in order, for a loop of
/// period `period_s`; the error of a valve that cannot be opened (or, with `require_device`,
/// reached) is returned here.
pub(crate) fn spawn(
    valves: Vec<ValveConfig>,
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
            let backends = rt.block_on(Backend::open_all(&valves, period_s, require_device))?;
            ready_tx
                .send(backends.iter().map(Backend::describe).collect())
                .map_err(|_| DaemonError::Panicked("calling"))?;
            // No parts: start() failed after the valves opened (the logger); nothing runs.
            let build = parts_rx
                .recv()
                .map_err(|_| DaemonError::Panicked("calling"))?;
            build(backends).run(rt)
        })
        .map_err(|source| DaemonError::Thread {
            what: "loop thread",
            source,
        })?;
    match ready_rx.recv() {
        Ok(valves) => Ok(Spawned {
            valves,
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
    /// Hands the loop thread the rest of the loop (`build` gets the opened backends); it runs.
    pub(crate) fn run(
        self,
        build: impl FnOnce(Vec<Backend>) -> Loop + Send + 'static,
    ) -> Result<JoinHandle<Result<LoopEnd, DaemonError>>, DaemonError> {
        self.parts
            .send(Box::new(build))
            .map_err(|_| DaemonError::Panicked("loop"))?;
        Ok(self.handle)
    }
}

impl Loop {
    /// The loop thread's body: the cycles, then each valve's stop action, also when a cycle
    /// failed (the logger gone) or panicked.
    fn run(mut self, rt: tokio::runtime::Runtime) -> Result<LoopEnd, DaemonError> {
        vb_core::priority::tighten_timer_slack();
        if self.realtime_priority > 0 && self.clock == ClockKind::Real {
            match vb_core::priority::realtime_priority(self.realtime_priority) {
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
        let mut at = (0, Duration::ZERO);
        // A panic in a cycle must not skip the stop action: it is caught here, the stop action
        // applied, and the panic reported as the loop's error (its message went to stderr).
        let cycles = std::panic::catch_unwind(AssertUnwindSafe(|| {
            self.cycles(&rt, &mut schedule, &mut at)
        }));
        // `slots`: the slots the run had, before it ended; `k_end`: the slot its stop action
        // takes, later than that where a stalled machine made the loop miss the slots between.
        let (ended, slots, k_end, lateness_end) = match cycles {
            Ok(Ok((reason, slots, k, lateness))) => (Ok(reason), slots, k, lateness),
            Ok(Err(e)) => (Err(e), at.0 + 1, at.0 + 1, at.1),
            Err(_) => (Err(DaemonError::Panicked("loop")), at.0 + 1, at.0 + 1, at.1),
        };
        let mut safe = Vec::with_capacity(self.lanes.len());
        let mut ended = ended;
        for i in 0..self.lanes.len() {
            let (action, logged) = self.stop_action(i, &rt, (k_end, &schedule), lateness_end);
            if let (Err(e), Ok(_)) = (logged, &ended) {
                ended = Err(e);
            }
            safe.push(action);
        }
        let reason = ended.inspect_err(|e| {
            tracing::error!("the loop stopped on an error, after its stop action: {e}")
        })?;
        tracing::info!(%reason, slots, stop_slot = k_end, "loop stopped");
        Ok(LoopEnd {
            reason,
            slots,
            valves: (self.lanes.into_iter().zip(safe))
                .map(|(lane, safe)| LaneEnd {
                    link: lane.backend.link_stats(),
                    compensation: lane.compensation.map(Compensation::report),
                    stats: lane.stats,
                    safe,
                })
                .collect(),
        })
    }

    /// The cycles until the loop is asked to stop, the duration is reached or a source ends:
    /// why it ended, the slots the run had, the slot the stop action takes and how late that
    /// slot was. `at` follows the last slot run, for the stop action after a failure.
    fn cycles(
        &mut self,
        rt: &tokio::runtime::Runtime,
        schedule: &mut Schedule,
        at: &mut (u64, Duration),
    ) -> Result<(StopReason, u64, u64, Duration), DaemonError> {
        // The first slot found past the end; slots missed after it are not the run's.
        let mut end: Option<u64> = None;
        loop {
            let slot = schedule.next_slot();
            let k = slot.k();
            let ending = self.max_slots.is_some_and(|m| k >= m) || self.stop.load(Ordering::SeqCst);
            if ending && end.is_none() {
                end = Some(k);
            }
            let lateness = match slot {
                // Past the end, a missed slot is not logged: the stop action takes the next one.
                Slot::Skipped { .. } if ending => continue,
                Slot::Skipped { .. } => {
                    self.skipped(k, schedule.t_s(k), schedule.wall(k))?;
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
                return Ok((reason, end.unwrap_or(k), k, lateness));
            }
            *at = (k, lateness);
            let t_s = schedule.t_s(k);
            // Every valve's O_P first: a source that ends stops the loop before any is sent.
            // Rounded to the log's precision: the O_P sent is the O_P logged.
            let mut ended = false;
            for lane in &mut self.lanes {
                match lane.source.op_at(t_s) {
                    Some(op) => lane.op = round_pct(op),
                    None => ended = true,
                }
            }
            if ended {
                return Ok((StopReason::SourceEnded, k, k, lateness));
            }
            if let Some(m) = &self.metrics {
                m.timing(lateness);
            }
            for i in 0..self.lanes.len() {
                let lane = &mut self.lanes[i];
                let sent = match &mut lane.compensation {
                    Some(c) => c.setpoint(lane.op, t_s),
                    None => lane.op,
                };
                let (mut row, _) = lane.transact(
                    rt,
                    (sent, lane.op),
                    (k, t_s, schedule.wall(k)),
                    lateness,
                    None,
                );
                lane.last_op_controller = Some(lane.op);
                if let Some(c) = &mut lane.compensation {
                    c.observe(&row);
                }
                // A failed transaction keeps its failure status; the O_P column shows the safe O_P.
                if row.status == Status::Ok && lane.source.watchdog_tripped() {
                    row.status = Status::Watchdog;
                }
                lane.source.feedback(&row);
                self.emit(i, row, Some(lateness))?;
            }
            if k.is_multiple_of(100) {
                if let Some(lane) = self.lanes.first() {
                    self.live.publish_p99(&lane.stats);
                }
            }
        }
    }

    /// Logs slot `k` as missed for every valve (the O_P column shows the O_P it holds).
    fn skipped(&mut self, k: u64, t_s: f64, utc: SystemTime) -> Result<(), DaemonError> {
        for i in 0..self.lanes.len() {
            let lane = &mut self.lanes[i];
            let row = Sample {
                t_s,
                op_pct: lane.last_op,
                vp_pct: None,
                status: Status::Skipped,
                lateness_us: None,
                latency_us: None,
                op_sent_pct: None,
                utc,
                op_controller_pct: lane.last_op_controller,
            };
            // One warning per run of consecutive missed slots, not one per slot.
            if i == 0 && lane.last_skipped_k.is_none_or(|last| last + 1 != k) {
                tracing::warn!(k, "cycle missed: the previous one overran");
            }
            lane.last_skipped_k = Some(k);
            self.emit(i, row, None)?;
        }
        Ok(())
    }

    /// Applies the stop action to valve `i` in slot `k_end`: the action as it went, and
    /// whether its row reached the logger.
    fn stop_action(
        &mut self,
        i: usize,
        rt: &tokio::runtime::Runtime,
        (k_end, schedule): (u64, &Schedule),
        lateness_end: Duration,
    ) -> (Option<StopAction>, Result<(), DaemonError>) {
        let lane = &mut self.lanes[i];
        let safe_op = match self.safe_action {
            OnStop::Hold => lane.last_op.map(|op| (op, Status::SafeHold)),
            OnStop::GoTo => self.go_to_pct.map(|op| (op, Status::SafeGoTo)),
        };
        let Some((op, status)) = safe_op else {
            return (None, Ok(()));
        };
        let (row, fault) = lane.transact(
            rt,
            (op, op),
            (k_end, schedule.t_s(k_end), schedule.wall(k_end)),
            lateness_end,
            Some(status),
        );
        let action = StopAction { row, fault };
        match &action.fault {
            None => tracing::info!(valve = %lane.name, "stop action applied: {action}"),
            Some(_) => tracing::error!(valve = %lane.name, "stop action: {action}"),
        }
        self.lanes[i].source.feedback(&row);
        let logged = self.emit(i, row, Some(lateness_end));
        (Some(action), logged)
    }

    /// Counts, publishes and logs a row of valve `i`.
    fn emit(
        &mut self,
        i: usize,
        row: Sample,
        lateness: Option<Duration>,
    ) -> Result<(), DaemonError> {
        let lane = &mut self.lanes[i];
        lane.stats.record(&row, lateness);
        if i == 0 {
            self.live.publish(&row);
            if let Some(moves) = lane.source.progress() {
                self.live.publish_progress(moves);
            }
        }
        if let Some(m) = &lane.metrics {
            m.record(&row);
            m.totals(
                lane.backend.link_stats().unwrap_or_default(),
                lane.source.watchdog_trips(),
            );
        }
        // The logger only hangs up by panicking; its join reports that. On the wall clock a
        // cycle never waits for it: a row that finds its queue full is dropped and counted (the
        // stop action's row excepted, the loop is over then).
        let hung_up = |_| DaemonError::Panicked("logger");
        if self.clock == ClockKind::Virtual || row.status.is_stop_action() {
            return lane.tx.send(row).map_err(hung_up);
        }
        match lane.tx.try_send(row) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(_)) => {
                lane.stats.dropped_log_row();
                if let Some(m) = &lane.metrics {
                    m.dropped_log_row();
                }
                Ok(())
            }
            Err(TrySendError::Disconnected(_)) => Err(DaemonError::Panicked("logger")),
        }
    }
}

impl Lane {
    /// One valve transaction for slot `k` at `t_s`: `(op, op_controller)` is the O_P sent and
    /// the one the source asked for (before compensation). Returns its row and, for the stop
    /// action's row (marked by `safe`), the fault that kept the valve from confirming it.
    fn transact(
        &mut self,
        rt: &tokio::runtime::Runtime,
        (op, op_controller): (f64, f64),
        (k, t_s, utc): (u64, f64, SystemTime),
        lateness: Duration,
        safe: Option<Status>,
    ) -> (Sample, Option<Fault>) {
        let started = Instant::now();
        let cycle = rt.block_on(self.backend.transact(op, k));
        let latency = started.elapsed();
        self.last_op = Some(op);
        let result = cycle.vp_pct;
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
                Err(fault) => {
                    tracing::warn!(k, valve = %self.name, "valve transaction failed: {fault}")
                }
                Ok(_) => tracing::info!(k, valve = %self.name, "valve transactions succeed again"),
            }
            self.last_status = status;
        }
        // The stop action's caller needs the fault; a cycle's goes to the statistics only.
        let fault = match result {
            Err(f) if safe.is_some() => {
                self.stats.note_fault(f.clone());
                Some(f)
            }
            Err(f) => {
                self.stats.note_fault(f);
                None
            }
            Ok(_) => None,
        };
        let row = Sample {
            t_s,
            op_pct: Some(op),
            vp_pct: vp,
            status: safe.unwrap_or(status),
            lateness_us: Some(micros(lateness)),
            latency_us: Some(micros(latency)),
            op_sent_pct: cycle.sent_pct,
            utc,
            op_controller_pct: Some(op_controller),
        };
        (row, fault)
    }
}

/// A current-thread runtime: the loop thread's (every valve transaction) or the network thread's.
pub(crate) fn current_thread_runtime(
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
