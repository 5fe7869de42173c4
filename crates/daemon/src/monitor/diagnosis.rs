//! Live diagnosis (`[diagnosis]`): every `every_s` of loop time, and on every health alarm,
//! each valve's last `window_s` of rows is diagnosed off the loop thread,
//! and the history, gauges and alarms are kept per valve. The diagnosis itself is the
//! [`DiagnoseWindow`] the daemon was handed (the analysis layer's, `valve_bridge::live`).
//!
//! The health thread feeds a [`Feed`] with the rows it gets from the loggers: a ring per
//! valve, copied into a job when a diagnosis is due. Jobs go to the diagnosis thread
//! (`vb-diagnosis`) through a queue that holds at most one job per valve, diagnosed or waiting,
//! so memory stays flat however long the run and however slow the diagnosis. A window that
//! comes due while the valve's previous diagnosis is still queued or running is, on the wall
//! clock, skipped and counted (the summary's `windows skipped`): neither the health thread nor
//! the loop ever waits for a diagnosis. On the virtual clock the health thread waits for it
//! instead (the loop then waits for the health thread), so no window is skipped and every run
//! writes the same history. The thread runs at the lowest priority (`SCHED_IDLE`, else nice 19,
//! [`vb_core::priority::lowest_priority`], which the analysis layer's diagnosis also gives the
//! threads of its parallel work): it takes only CPU time nothing else wants. Jobs are diagnosed
//! in the order they were made, each from its own copy of the rows; at the end of a run the
//! thread finishes the jobs still queued.
//!
//! A valve's windows are diagnosed from its `health_baseline_model` when it has one, else from
//! the final model of its first whole window's diagnosis once there is one (see [`history`]).
//!
//! Each diagnosis is a line of `diagnosis-<valve>.jsonl` beside the logs ([`history::Record`])
//! and, with `reports`, the full report in `diagnosis-<valve>/<stamp>/`, named by the window's
//! end in UTC (`20261122T101500Z`, `-1` added when taken). The history is appended to run
//! after run ([`files::open_history`]; loop time starts at 0 again in each run, the `utc` field
//! does not) and survives a disk that refuses it as the log does ([`LogFile`]); no report of an
//! earlier run is written over. The gauges are
//! `valve_bridge_effect_size{valve,effect,unit}` (each finding's and trace's size, in the unit
//! of its label), `valve_bridge_diagnosis_age_seconds{valve}` (loop time since the diagnosed
//! window's end) and `valve_bridge_diagnosis_alarm{valve,effect}` (1 while the effect is in
//! alarm against the valve's first diagnosis, see [`history`]).
//!
//! Not here: the diagnosis itself (`vb_analysis::diagnose`), the health figures ([`crate::monitor::health`]).

pub mod history;

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::SystemTime;

use prometheus::{Gauge, GaugeVec, Opts, Registry};

use crate::config::{ClockKind, DiagnosisConfig, OnError};
use crate::monitor::analysis::DiagnoseWindow;
use crate::runtime::files;
use crate::runtime::log_file::{LogAlarm, LogFile, Refused};
use crate::runtime::logger::file_stamp;
use crate::serve::page::board::ValveBoard;
use crate::DaemonError;
use history::{Baseline, Record};
use vb_core::model::composed::Effect;
use vb_core::model::ModelSpec;
use vb_core::recording::log_format::utc_stamp;
use vb_core::recording::RecordingView;
use vb_core::vocabulary;

/// What the live diagnosis of one valve did, for the summary.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnosisReport {
    /// Diagnoses made (failed ones included).
    pub diagnoses: u64,
    /// Every alarm raised, in order.
    pub alarms: Vec<String>,
    /// Loop time at the end of the window of the first diagnosis that raised one, s.
    pub first_alarm_t_s: Option<f64>,
    /// The history file.
    pub file: PathBuf,
    /// Windows not diagnosed because the valve's previous diagnosis was still running (on the
    /// wall clock only).
    pub skipped: u64,
    /// Lines the disk refused for a while: written late, or dropped.
    pub refused: Refused,
}

/// The diagnosis gauges of every valve.
#[derive(Debug, Clone)]
pub struct DiagnosisMetrics {
    size: GaugeVec,
    age: GaugeVec,
    alarm: GaugeVec,
}

impl DiagnosisMetrics {
    /// Registers the gauges in `registry`.
    pub fn register(registry: &Registry) -> Result<Self, prometheus::Error> {
        let vec = |name: &str, help: &str, labels: &[&str]| {
            let g = GaugeVec::new(Opts::new(name, help), labels)?;
            registry.register(Box::new(g.clone()))?;
            Ok::<_, prometheus::Error>(g)
        };
        Ok(DiagnosisMetrics {
            size: vec(
                "valve_bridge_effect_size",
                "Size of each effect the last live diagnosis found (finding or trace), in its unit",
                &["valve", "effect", "unit"],
            )?,
            age: vec(
                "valve_bridge_diagnosis_age_seconds",
                "Loop time since the end of the window of the last live diagnosis (NaN before one)",
                &["valve"],
            )?,
            alarm: vec(
                "valve_bridge_diagnosis_alarm",
                "1 while an effect is new or past its interval against the first diagnosis",
                &["valve", "effect"],
            )?,
        })
    }

    /// The age gauge of `valve`.
    pub fn age(&self, valve: &str) -> Option<Gauge> {
        self.age.get_metric_with_label_values(&[valve]).ok()
    }

    /// Replaces the valve's sizes and alarms with those of `r`.
    /// (`before`: the valve's last record, whose sizes and alarms are taken down first).
    pub fn publish(&self, valve: &str, r: &Record, before: &Record) {
        for e in &before.effects {
            let _gone = (self.size).remove_label_values(&[valve, e.effect.name(), e.size.unit]);
        }
        for e in &r.effects {
            if let Ok(g) =
                (self.size).get_metric_with_label_values(&[valve, e.effect.name(), e.size.unit])
            {
                g.set(e.size.value);
            }
        }
        for e in Effect::ALL {
            let on = r.alarm_effects.contains(&e);
            let was = before.alarm_effects.contains(&e);
            if on || was {
                if let Ok(g) = self.alarm.get_metric_with_label_values(&[valve, e.name()]) {
                    g.set(f64::from(u8::from(on)));
                }
            }
        }
    }
}

/// One valve to diagnose: its name (label and file names), its gauges, its place on the live
/// page (the count of its diagnoses, where this run's history starts), its log alarm, and the
/// model its diagnoses start from (its `health_baseline_model`; without one, the model of its
/// first whole window's diagnosis).
#[derive(Debug)]
pub struct Watched {
    pub name: String,
    pub metrics: Option<DiagnosisMetrics>,
    pub(crate) board: Option<Arc<ValveBoard>>,
    pub(crate) log_alarm: Arc<LogAlarm>,
    pub model: Option<ModelSpec>,
}

/// A window to diagnose.
#[derive(Debug)]
struct Job {
    valve: usize,
    t_s: f64,
    /// The window's end on the wall clock (as the log's `utc`).
    utc: SystemTime,
    trigger: &'static str,
    op: Vec<f64>,
    vp: Vec<f64>,
}

/// One valve's ring of rows on the health thread.
#[derive(Debug)]
struct Ring {
    /// The valve's name, in the log's messages.
    name: String,
    op: VecDeque<f64>,
    vp: VecDeque<f64>,
    next_at_s: f64,
    /// Loop time of the window end of the last finished diagnosis (f64 bits; NaN: none yet).
    done_t_s: Arc<AtomicU64>,
    age: Option<Gauge>,
    /// A job of the valve is queued or being diagnosed.
    busy: bool,
    /// Windows skipped, read by the diagnosis thread for the summary.
    skipped: Arc<AtomicU64>,
}

/// The health thread's side: the rings, and the queue to the diagnosis thread.
#[derive(Debug)]
pub struct Feed {
    cfg: DiagnosisConfig,
    cap: usize,
    rings: Vec<Ring>,
    /// The queue: room for a job per valve, so a send never waits.
    tx: SyncSender<Job>,
    /// The valves whose job has been diagnosed, from the diagnosis thread.
    done: Receiver<usize>,
    clock: ClockKind,
}

impl Feed {
    /// Takes valve `i`'s row at loop time `t_s` and wall-clock time `utc` (NaN for a missing
    /// value); `alarm_raised`: the health check raised its alarm with this row. Queues a
    /// diagnosis when one is due and the valve's previous one is done: on the virtual clock it
    /// waits for that, on the wall clock the window is skipped.
    pub fn push(
        &mut self,
        i: usize,
        (t_s, utc): (f64, SystemTime),
        op: f64,
        vp: f64,
        alarm_raised: bool,
    ) {
        let Some(r) = self.rings.get_mut(i) else {
            return;
        };
        if r.op.len() == self.cap {
            r.op.pop_front();
            r.vp.pop_front();
        }
        r.op.push_back(op);
        r.vp.push_back(vp);
        if let Some(age) = &r.age {
            age.set(t_s - f64::from_bits(r.done_t_s.load(Ordering::Relaxed)));
        }
        let full = r.op.len() == self.cap;
        let trigger = if alarm_raised && self.cfg.on_alarm {
            "health alarm"
        } else if full && t_s >= r.next_at_s {
            r.next_at_s += self.cfg.every_s;
            "every_s"
        } else {
            return;
        };
        if !self.free(i) {
            let skipped = self.rings[i].skipped.fetch_add(1, Ordering::Relaxed) + 1;
            tracing::warn!(
                valve = %self.rings[i].name,
                t_s,
                skipped,
                "live diagnosis: window skipped, the valve's previous diagnosis is still running"
            );
            return;
        }
        let r = &mut self.rings[i];
        // Leading rows before the first O_P are dropped; a missing O_P holds the last one.
        let mut op: Vec<f64> = r.op.iter().copied().collect();
        let first = op.iter().position(|v| !v.is_nan()).unwrap_or(op.len());
        let mut last = f64::NAN;
        for v in &mut op[first..] {
            if v.is_nan() {
                *v = last;
            }
            last = *v;
        }
        let job = Job {
            valve: i,
            t_s,
            utc,
            trigger,
            op: op.split_off(first),
            vp: r.vp.iter().skip(first).copied().collect(),
        };
        r.busy = true;
        // The diagnosis thread outlives the feed; a failed send means it already failed.
        let _queued = self.tx.send(job);
    }

    /// True once valve `i` has no job queued or being diagnosed: at once on the wall clock, after
    /// waiting for its job on the virtual clock (or when the diagnosis thread has gone).
    fn free(&mut self, i: usize) -> bool {
        while let Ok(v) = self.done.try_recv() {
            self.rings[v].busy = false;
        }
        while self.rings[i].busy && self.clock == ClockKind::Virtual {
            match self.done.recv() {
                Ok(v) => self.rings[v].busy = false,
                Err(_) => return true,
            }
        }
        !self.rings[i].busy
    }
}

/// The diagnosis thread, joined for each valve's report.
pub type Thread = JoinHandle<Result<Vec<DiagnosisReport>, DaemonError>>;

/// Starts the diagnosis thread for `valves` with their histories in `dir` (appended to; a
/// link where a history or a valve's report directory goes is refused), for a loop of period
/// `period_s` on `clock`; `on_error`: what a write the disk refuses does.
pub fn start(
    cfg: &DiagnosisConfig,
    (dir, on_error): (&Path, OnError),
    (period_s, clock): (f64, ClockKind),
    valves: Vec<Watched>,
    diagnose: DiagnoseWindow,
) -> Result<(Feed, Thread), DaemonError> {
    let cap = ((cfg.window_s / period_s).round() as usize).max(1);
    let (tx, rx) = std::sync::mpsc::sync_channel(valves.len());
    let (done_tx, done) = std::sync::mpsc::channel();
    let mut rings = Vec::with_capacity(valves.len());
    let mut histories = Vec::with_capacity(valves.len());
    for w in valves {
        let done = Arc::new(AtomicU64::new(f64::NAN.to_bits()));
        let skipped = Arc::new(AtomicU64::new(0));
        let path = files::history_file(dir, &w.name);
        let (file, size) = files::open_history(&path, b"")?;
        files::refuse_link(&dir.join(format!("diagnosis-{}", w.name)))?;
        if let Some(b) = &w.board {
            b.history_starts_at(size);
        }
        rings.push(Ring {
            name: w.name.clone(),
            op: VecDeque::with_capacity(cap),
            vp: VecDeque::with_capacity(cap),
            next_at_s: (cap as f64 - 0.5) * period_s,
            done_t_s: done.clone(),
            age: w.metrics.as_ref().and_then(|m| m.age(&w.name)),
            busy: false,
            skipped: skipped.clone(),
        });
        histories.push(History {
            log: LogFile::new(path.clone(), file, size, (on_error, w.log_alarm)),
            name: w.name,
            dir: dir.to_path_buf(),
            baseline: Baseline::default(),
            model: w.model,
            last: None,
            metrics: w.metrics,
            board: w.board,
            diagnose,
            done_t_s: done,
            skipped,
            report: DiagnosisReport {
                diagnoses: 0,
                alarms: Vec::new(),
                first_alarm_t_s: None,
                file: path,
                skipped: 0,
                refused: Refused::default(),
            },
        });
    }
    let (cfg2, thread_err) = (cfg.clone(), |source| DaemonError::Thread {
        what: "diagnosis thread",
        source,
    });
    let handle = std::thread::Builder::new()
        .name("vb-diagnosis".into())
        .spawn(move || work((rx, done_tx), histories, &cfg2, period_s))
        .map_err(thread_err)?;
    let feed = Feed {
        cfg: cfg.clone(),
        cap,
        rings,
        tx,
        done,
        clock,
    };
    Ok((feed, handle))
}

/// One valve's history on the diagnosis thread.
struct History {
    name: String,
    log: LogFile,
    dir: PathBuf,
    baseline: Baseline,
    /// The model every window's diagnosis starts from: the valve's health baseline model, or
    /// the baseline diagnosis's final model once there is one.
    model: Option<ModelSpec>,
    last: Option<Record>,
    metrics: Option<DiagnosisMetrics>,
    board: Option<Arc<ValveBoard>>,
    diagnose: DiagnoseWindow,
    done_t_s: Arc<AtomicU64>,
    /// Windows the feed skipped.
    skipped: Arc<AtomicU64>,
    report: DiagnosisReport,
}

/// The diagnosis thread: diagnoses each job in order, at the lowest priority, and tells the
/// feed of each valve whose job is done.
fn work(
    (rx, done): (Receiver<Job>, Sender<usize>),
    mut histories: Vec<History>,
    cfg: &DiagnosisConfig,
    period_s: f64,
) -> Result<Vec<DiagnosisReport>, DaemonError> {
    vb_core::priority::lowest_priority();
    for job in rx {
        let Some(h) = histories.get_mut(job.valve) else {
            continue;
        };
        let record = h.diagnose(&job, cfg, period_s);
        h.write(record)?;
        // The feed has gone at the end of the run; nobody waits then.
        let _told = done.send(job.valve);
    }
    (histories.into_iter())
        .map(|mut h| {
            let (_, refused) = h.log.close()?;
            h.report.refused = refused;
            h.report.skipped = h.skipped.load(Ordering::Relaxed);
            Ok(h.report)
        })
        .collect()
}

impl History {
    /// Diagnoses a job's window: its record, with the alarms against the baseline, and its
    /// report files written.
    fn diagnose(&mut self, job: &Job, cfg: &DiagnosisConfig, period_s: f64) -> Record {
        // Loop time of each row, the last at the job's time.
        let n = job.op.len();
        let t: Vec<f64> = (0..n)
            .map(|k| job.t_s - (n - 1 - k) as f64 * period_s)
            .collect();
        let rec = RecordingView {
            t: &t,
            op: &job.op,
            vp: &job.vp,
            restarts: &[],
            dt: period_s,
        };
        let mut record = Record {
            t_s: job.t_s,
            utc: utc_stamp(job.utc),
            window_s: job.op.len() as f64 * period_s,
            trigger: job.trigger,
            verdict: String::new(),
            compared: self.model.is_some(),
            reference: false,
            effects: Vec::new(),
            advice: Vec::new(),
            alarms: Vec::new(),
            alarm_effects: Vec::new(),
            report: None,
            error: None,
        };
        let title = format!("valve {}: live diagnosis at {:.0} s", self.name, job.t_s);
        let base = self.model.as_ref();
        let d = match (self.diagnose)(&rec, base, cfg.reports.then_some(title.as_str())) {
            Ok(d) => d,
            Err(e) => {
                tracing::warn!(valve = %self.name, t_s = job.t_s, "live diagnosis failed: {e}");
                record.error = Some(e);
                return record;
            }
        };
        record.verdict = d.verdict;
        record.effects = d.effects;
        let findings = record.effects.iter().filter(|e| e.finding);
        record.advice = vocabulary::advice(findings.map(|e| (e.effect, &e.size)));
        let whole = job.trigger == "every_s";
        let had = self.baseline.is_set();
        let (standing, raised) = self.baseline.compare(job.t_s, whole, &record.effects);
        record.reference = !had && self.baseline.is_set();
        if self.model.is_none() && self.baseline.is_set() {
            self.model = Some(d.model);
        }
        for (_, a) in &raised {
            tracing::warn!(valve = %self.name, t_s = job.t_s, "diagnosis alarm: {a}");
            self.report.first_alarm_t_s.get_or_insert(job.t_s);
        }
        self.report.alarms.extend(raised.into_iter().map(|a| a.1));
        (record.alarm_effects, record.alarms) = standing.into_iter().unzip();
        if !d.report.is_empty() {
            record.report = self.write_report(job.utc, &d.report);
        }
        record
    }

    /// Writes a report's files (as `diagnose --out` would) in a new directory
    /// `diagnosis-<valve>/<stamp>/`, named by `utc`, the window's end; the report's path
    /// relative to the history's directory (None when it could not be written: said in the
    /// log).
    fn write_report(&self, utc: SystemTime, report: &[(&str, String)]) -> Option<String> {
        let valve = format!("diagnosis-{}", self.name);
        let parent = self.dir.join(&valve);
        let written = files::real_dir(&parent)
            .map_err(|e| e.to_string())
            .and_then(|()| files::new_dir(&parent, &file_stamp(utc)).map_err(|e| e.to_string()))
            .and_then(|dir| {
                for (name, text) in report {
                    files::write_new(&dir.join(name), text.as_bytes())
                        .map_err(|e| format!("{}: {e}", dir.join(name).display()))?;
                }
                Ok(dir)
            });
        match written {
            Ok(dir) => {
                let stamp = dir.file_name().unwrap_or_default().to_string_lossy();
                Some(format!("{valve}/{stamp}/report.html"))
            }
            Err(e) => {
                tracing::warn!(valve = %self.name, "cannot write the diagnosis report: {e}");
                None
            }
        }
    }

    /// Appends `record` to the history, publishes it and marks its time as done.
    fn write(&mut self, record: Record) -> Result<(), DaemonError> {
        self.report.diagnoses += 1;
        match serde_json::to_vec(&record) {
            Ok(mut line) => {
                line.push(b'\n');
                self.log.line(&line)?;
                self.log.flush()?;
            }
            Err(e) => tracing::warn!(valve = %self.name, "a diagnosis could not be encoded: {e}"),
        }
        if let Some(m) = &self.metrics {
            let empty = Record {
                effects: Vec::new(),
                alarms: Vec::new(),
                alarm_effects: Vec::new(),
                ..record.clone()
            };
            m.publish(&self.name, &record, self.last.as_ref().unwrap_or(&empty));
        }
        if record.error.is_none() {
            self.done_t_s.store(record.t_s.to_bits(), Ordering::Relaxed);
        }
        if let Some(c) = self.board.as_ref().and_then(|b| b.diagnoses()) {
            c.fetch_add(1, Ordering::Relaxed);
        }
        self.last = Some(record);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;
    use crate::monitor::analysis::WindowDiagnosis;

    /// Held by a test that keeps a diagnosis running.
    static RUNNING: Mutex<()> = Mutex::new(());

    /// A diagnosis that runs while [`RUNNING`] is held, then finds the window cannot be judged.
    fn held(
        _: &RecordingView,
        _: Option<&ModelSpec>,
        _: Option<&str>,
    ) -> Result<WindowDiagnosis, String> {
        drop(RUNNING.lock());
        Err("nothing to judge".into())
    }

    /// Pushes 300 s of rows of one valve at 10 Hz (a 60 s window due every 60 s: five of them)
    /// on `clock`; the valve's report and its history's lines.
    fn five_windows(clock: ClockKind, keep_running: bool) -> (DiagnosisReport, Vec<String>) {
        let dir = tempfile::tempdir().unwrap();
        let cfg = DiagnosisConfig {
            every_s: 60.0,
            window_s: 60.0,
            on_alarm: false,
            reports: false,
        };
        let valves = vec![Watched {
            name: "a".into(),
            metrics: None,
            board: None,
            log_alarm: LogAlarm::new("a", None, None),
            model: None,
        }];
        let on_error = (dir.path(), OnError::KeepRunning);
        let (mut feed, thread) = start(&cfg, on_error, (0.1, clock), valves, held).unwrap();
        let running = keep_running.then(|| RUNNING.lock().unwrap_or_else(|p| p.into_inner()));
        let t0 = SystemTime::UNIX_EPOCH;
        for k in 0..=3000u32 {
            let t_s = f64::from(k) * 0.1;
            let utc = t0 + std::time::Duration::from_millis(u64::from(k) * 100);
            feed.push(0, (t_s, utc), 50.0, 49.0, false);
        }
        drop(running);
        drop(feed);
        let report = thread.join().unwrap().unwrap().remove(0);
        let text = std::fs::read_to_string(files::history_file(dir.path(), "a")).unwrap();
        (report, text.lines().map(String::from).collect())
    }

    #[test]
    fn on_the_wall_clock_a_window_due_while_the_last_is_diagnosed_is_skipped() {
        let (report, lines) = five_windows(ClockKind::Real, true);
        assert_eq!((report.diagnoses, report.skipped), (1, 4));
        assert_eq!(lines.len(), 1);
        assert!(
            lines[0].contains(r#""t_s":60.0,"utc":"1970-01-01T00:01:00.000Z""#),
            "{}",
            lines[0]
        );
    }

    #[test]
    fn on_the_virtual_clock_every_window_is_diagnosed_in_turn() {
        let (report, lines) = five_windows(ClockKind::Virtual, false);
        assert_eq!((report.diagnoses, report.skipped), (5, 0));
        let times: Vec<f64> = (lines.iter())
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
            .map(|v| v["t_s"].as_f64().unwrap())
            .collect();
        assert_eq!(times, [60.0, 120.0, 180.0, 240.0, 300.0]);
    }
}
