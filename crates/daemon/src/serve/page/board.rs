//! The live page's board: what `GET /` shows of each valve, kept up to date by the threads that
//! already see it, never by the loop thread. Each logger puts a point of its valve's rows into
//! the valve's trace every 1/[`TRACE_HZ`] s (and at every change of status), the health thread
//! each window's figures with their baseline and limits, the diagnosis thread the count of its
//! diagnoses and where this run's lines of its history start, and a file that cannot be
//! written its log alarm ([`crate::runtime::log_file`]). The network thread reads it for `/api/live` ([`Board::live_json`]): the locks are
//! held for a copy, never across I/O.
//!
//! Not here: serving ([`crate::serve::http`]), the page itself (`live.js`), the diagnosis
//! history (read from its file, [`super::history_tail`]).

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::UNIX_EPOCH;

use serde::Serialize;

use crate::monitor::health_figures::{Figures, HealthLimits, Held, Judged};
use crate::runtime::files::history_file;
use vb_core::recording::log_format::{Sample, Status};

/// How much of each valve's trace the page shows, s.
pub(crate) const TRACE_S: f64 = 300.0;
/// Points per second of a trace.
pub(crate) const TRACE_HZ: f64 = 10.0;

/// One point of a trace.
#[derive(Debug, Clone, Copy)]
struct Point {
    t_s: f64,
    op: Option<f64>,
    vp: Option<f64>,
    status: Status,
}

/// A health window as the page shows it: what the health thread wrote in its CSV row.
#[derive(Debug, Clone, Default)]
pub(crate) struct HealthWindow {
    /// Loop time at the window's end, s.
    pub(crate) t_s: f64,
    /// None when the window had too many rows without V_P to estimate.
    pub(crate) figures: Option<Figures>,
    pub(crate) base: Option<Figures>,
    pub(crate) limits: Option<HealthLimits>,
    pub(crate) alarm: bool,
    /// The figures in alarm.
    pub(crate) held: Vec<Held>,
    /// The drifts past their limits and what the window could not measure.
    pub(crate) note: String,
}

/// One valve on the board.
#[derive(Debug)]
pub(crate) struct ValveBoard {
    name: String,
    trace: Mutex<VecDeque<Point>>,
    cap: usize,
    /// The last health window (None without `[health]`).
    health: Option<Mutex<Option<HealthWindow>>>,
    /// Diagnoses made (None without `[diagnosis]`).
    diagnoses: Option<Arc<AtomicU64>>,
    /// Loop time of the first health window and of the first diagnosis, s.
    first_t_s: (Option<f64>, Option<f64>),
    /// Where this run's lines of the diagnosis history start, bytes (the history keeps the
    /// lines of earlier runs before them, on their own loop time).
    history_from: AtomicU64,
    /// Why the valve's log cannot be written, while it cannot.
    log_alarm: Mutex<Option<String>>,
}

/// Every valve's board, and where the daemon writes its files.
#[derive(Debug)]
pub(crate) struct Board {
    /// Wall-clock time of loop time 0, Unix s (f64 bits; NaN until the first row).
    started_unix_s: AtomicU64,
    /// The log directory: the diagnosis histories and reports.
    dir: PathBuf,
    valves: Vec<Arc<ValveBoard>>,
}

/// A mutex's data, poisoned or not (a panicked writer leaves plain numbers behind).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

impl Board {
    /// A board for the valves `names` of a loop at `rate_hz`, with health windows and diagnosis
    /// counts when those run (`runs`: the loop time of the first health window and of the
    /// first diagnosis, each None when it does not run); the daemon's files are in `dir`.
    pub(crate) fn new(
        names: &[&str],
        rate_hz: f64,
        runs: (Option<f64>, Option<f64>),
        dir: &Path,
    ) -> Board {
        // Twice the points of TRACE_S: room for the points a change of status adds.
        let cap = (2.0 * TRACE_S * TRACE_HZ.min(rate_hz)).ceil() as usize;
        Board {
            started_unix_s: AtomicU64::new(f64::NAN.to_bits()),
            dir: dir.to_path_buf(),
            valves: (names.iter())
                .map(|&name| {
                    Arc::new(ValveBoard {
                        name: name.to_string(),
                        trace: Mutex::new(VecDeque::with_capacity(cap)),
                        cap,
                        health: runs.0.map(|_| Mutex::new(None)),
                        diagnoses: runs.1.map(|_| Arc::new(AtomicU64::new(0))),
                        first_t_s: runs,
                        history_from: AtomicU64::new(0),
                        log_alarm: Mutex::new(None),
                    })
                })
                .collect(),
        }
    }

    /// The `i`-th valve's board (None past the last).
    pub(crate) fn valve(&self, i: usize) -> Option<Arc<ValveBoard>> {
        self.valves.get(i).cloned()
    }

    /// The logger's side of the `i`-th valve's trace, for a loop at `rate_hz`.
    pub(crate) fn feed(self: &Arc<Self>, i: usize, rate_hz: f64) -> Option<TraceFeed> {
        Some(TraceFeed {
            board: Arc::clone(self),
            valve: self.valve(i)?,
            every: ((rate_hz / TRACE_HZ).round() as u64).max(1),
            rows: 0,
            last: None,
        })
    }

    /// The diagnosis history of the valve named `valve`, when it has one, and where this
    /// run's lines start in it.
    pub(crate) fn history(&self, valve: &str) -> Option<(PathBuf, u64)> {
        let v = self.valves.iter().find(|v| v.name == valve)?;
        v.diagnoses.as_ref()?;
        let from = v.history_from.load(Ordering::Relaxed);
        Some((history_file(&self.dir, valve), from))
    }

    /// The log directory.
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// True when `valve` names one of the board's valves.
    pub(crate) fn has_valve(&self, valve: &str) -> bool {
        self.valves.iter().any(|v| v.name == valve)
    }

    /// `/api/live`: each valve's name, status, trace after loop time `since` (the last
    /// [`TRACE_S`] of it at most), last health window and diagnosis count.
    pub(crate) fn live_json(&self, since: Option<f64>) -> String {
        let started = f64::from_bits(self.started_unix_s.load(Ordering::Relaxed));
        let live = Live {
            started_unix_s: started.is_finite().then_some(started),
            trace_s: TRACE_S,
            valves: self.valves.iter().map(|v| v.view(since)).collect(),
        };
        serde_json::to_string(&live).unwrap_or_else(|_| "null".into())
    }
}

impl ValveBoard {
    /// Publishes a health window (the health thread, once per window).
    pub(crate) fn health(&self, w: HealthWindow) {
        if let Some(h) = &self.health {
            *lock(h) = Some(w);
        }
    }

    /// The counter of diagnoses made, for the diagnosis thread (None without `[diagnosis]`).
    pub(crate) fn diagnoses(&self) -> Option<Arc<AtomicU64>> {
        self.diagnoses.clone()
    }

    /// This run's lines of the diagnosis history start at byte `from` of it.
    pub(crate) fn history_starts_at(&self, from: u64) {
        self.history_from.store(from, Ordering::Relaxed);
    }

    /// Raises the log alarm with why (Some) or clears it (None).
    pub(crate) fn log_alarm(&self, why: Option<String>) {
        *lock(&self.log_alarm) = why;
    }

    fn view(&self, since: Option<f64>) -> ValveJson<'_> {
        let round = |v: f64, scale: f64| (v * scale).round() / scale;
        let mut trace = TraceJson::default();
        let (mut status, mut t_s) = (None, None);
        {
            let points = lock(&self.trace);
            if let Some(last) = points.back() {
                status = Some(last.status.as_str());
                t_s = Some(last.t_s);
                let from = since.unwrap_or(f64::NEG_INFINITY).max(last.t_s - TRACE_S);
                let first = points.partition_point(|p| p.t_s <= from);
                for p in points.range(first..) {
                    trace.t.push(round(p.t_s, 100.0));
                    trace.op.push(p.op.map(|v| round(v, 1000.0)));
                    trace.vp.push(p.vp.map(|v| round(v, 1000.0)));
                }
            }
        }
        let health = self.health.as_ref().map(|h| {
            let w = lock(h).clone();
            let judged = w.as_ref().and_then(|w| {
                let f = w.figures?;
                Some(f.judged(w.base.as_ref(), w.limits.as_ref()).to_vec())
            });
            let (t_s, alarm) = (
                w.as_ref().map(|w| w.t_s),
                w.as_ref().is_some_and(|w| w.alarm),
            );
            let (note, held) = w.map(|w| (w.note, w.held)).unwrap_or_default();
            HealthJson {
                t_s,
                alarm,
                note,
                figures: judged.unwrap_or_default(),
                alarms: held,
                first_t_s: self.first_t_s.0,
            }
        });
        ValveJson {
            name: &self.name,
            status,
            t_s,
            trace,
            health,
            diagnoses: (self.diagnoses.as_ref()).map(|d| d.load(Ordering::Relaxed)),
            first_diagnosis_t_s: self.first_t_s.1,
            log_alarm: lock(&self.log_alarm).clone(),
        }
    }
}

/// A logger's side of its valve's trace: takes a row every 1/[`TRACE_HZ`] s and each row whose
/// status differs from the row before.
#[derive(Debug)]
pub(crate) struct TraceFeed {
    board: Arc<Board>,
    valve: Arc<ValveBoard>,
    /// Rows per point.
    every: u64,
    rows: u64,
    last: Option<Status>,
}

impl TraceFeed {
    /// Takes a row the logger wrote.
    pub(crate) fn row(&mut self, s: &Sample) {
        if self.last.is_none() {
            let t0 = s.utc.duration_since(UNIX_EPOCH).unwrap_or_default();
            let bits = (t0.as_secs_f64() - s.t_s).to_bits();
            let nan = f64::NAN.to_bits();
            // Only the first row of any valve sets it.
            let _set = (self.board.started_unix_s).compare_exchange(
                nan,
                bits,
                Ordering::Relaxed,
                Ordering::Relaxed,
            );
        }
        let changed = self.last != Some(s.status);
        self.last = Some(s.status);
        self.rows += 1;
        if !changed && !self.rows.is_multiple_of(self.every) {
            return;
        }
        let p = Point {
            t_s: s.t_s,
            op: s.op_pct,
            vp: s.vp_pct,
            status: s.status,
        };
        let mut trace = lock(&self.valve.trace);
        if trace.len() == self.valve.cap {
            trace.pop_front();
        }
        trace.push_back(p);
    }
}

/// `/api/live`.
#[derive(Serialize)]
struct Live<'a> {
    /// Wall-clock time of loop time 0, Unix s (null before the first row).
    started_unix_s: Option<f64>,
    /// The stretch of trace the page keeps, s.
    trace_s: f64,
    valves: Vec<ValveJson<'a>>,
}

#[derive(Serialize)]
struct ValveJson<'a> {
    name: &'a str,
    /// The status of the last row taken (null before the first).
    status: Option<&'static str>,
    /// Its loop time, s.
    t_s: Option<f64>,
    trace: TraceJson,
    /// Null without `[health]`.
    health: Option<HealthJson>,
    /// Diagnoses made; null without `[diagnosis]`.
    diagnoses: Option<u64>,
    /// Loop time of the first diagnosis, s (null without `[diagnosis]`).
    first_diagnosis_t_s: Option<f64>,
    /// Why the valve's log cannot be written; null while it can.
    log_alarm: Option<String>,
}

/// Columns of a trace: loop time (s), O_P and V_P (%, null where missing).
#[derive(Serialize, Default)]
struct TraceJson {
    t: Vec<f64>,
    op: Vec<Option<f64>>,
    vp: Vec<Option<f64>>,
}

#[derive(Serialize)]
struct HealthJson {
    /// Loop time at the end of the last window (null before the first).
    t_s: Option<f64>,
    alarm: bool,
    note: String,
    /// Each figure with its baseline and limit (empty when the window gave none).
    figures: Vec<Judged>,
    /// The figures in alarm, each with its last measured value, limit and since when.
    alarms: Vec<Held>,
    /// Loop time of the first window, s.
    first_t_s: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn row(k: u64, status: Status) -> Sample {
        let t_s = k as f64 * 0.01;
        Sample {
            t_s,
            op_pct: Some(40.0 + k as f64 * 1e-3),
            vp_pct: (status == Status::Ok).then_some(39.5),
            status,
            lateness_us: None,
            latency_us: None,
            op_sent_pct: None,
            utc: UNIX_EPOCH + Duration::from_secs(1_700_000_000) + Duration::from_secs_f64(t_s),
            op_controller_pct: None,
        }
    }

    fn parse(board: &Board, since: Option<f64>) -> serde_json::Value {
        serde_json::from_str(&board.live_json(since)).unwrap()
    }

    #[test]
    fn a_trace_keeps_ten_points_a_second_and_every_change_of_status() {
        let board = Arc::new(Board::new(
            &["a", "b"],
            100.0,
            (Some(600.0), None),
            Path::new("/x"),
        ));
        let v = parse(&board, None);
        assert_eq!(v["started_unix_s"], serde_json::Value::Null);
        assert_eq!(v["valves"][1]["status"], serde_json::Value::Null);
        let mut feed = board.feed(0, 100.0).unwrap();
        assert!(board.feed(2, 100.0).is_none());
        for k in 0..100 {
            let status = if k == 55 { Status::Timeout } else { Status::Ok };
            feed.row(&row(k, status));
        }
        let v = parse(&board, None);
        assert_eq!(v["started_unix_s"].as_f64(), Some(1_700_000_000.0));
        let a = &v["valves"][0];
        assert_eq!(
            (a["name"].as_str(), a["status"].as_str()),
            (Some("a"), Some("ok"))
        );
        // The first row, every tenth, and the timeout and the row after it.
        let t: Vec<f64> = serde_json::from_value(a["trace"]["t"].clone()).unwrap();
        assert_eq!(
            t,
            [0.0, 0.09, 0.19, 0.29, 0.39, 0.49, 0.55, 0.56, 0.59, 0.69, 0.79, 0.89, 0.99]
        );
        assert_eq!(a["trace"]["vp"][6], serde_json::Value::Null);
        assert_eq!(a["trace"]["op"][1].as_f64(), Some(40.009));
        // After a time: only what came since.
        let later = parse(&board, Some(0.79));
        assert_eq!(
            later["valves"][0]["trace"]["t"],
            serde_json::json!([0.89, 0.99])
        );
        // [health] without a window yet; no [diagnosis].
        assert_eq!(a["health"]["t_s"], serde_json::Value::Null);
        assert_eq!(a["diagnoses"], serde_json::Value::Null);
        assert!(board.history("a").is_none());
    }

    #[test]
    fn a_trace_shows_the_last_minutes_only() {
        let board = Arc::new(Board::new(
            &["a"],
            100.0,
            (None, Some(1200.0)),
            Path::new("/logs"),
        ));
        let mut feed = board.feed(0, 100.0).unwrap();
        // Ten minutes, twice the page's stretch.
        for k in 0..60_000 {
            feed.row(&row(k, Status::Ok));
        }
        let v = parse(&board, None);
        let t = v["valves"][0]["trace"]["t"].as_array().unwrap().clone();
        assert_eq!(t.len(), 3000);
        assert_eq!(t.last().unwrap().as_f64(), Some(599.99));
        assert_eq!(v["valves"][0]["health"], serde_json::Value::Null);
        board
            .valve(0)
            .unwrap()
            .diagnoses()
            .unwrap()
            .fetch_add(2, Ordering::Relaxed);
        assert_eq!(parse(&board, None)["valves"][0]["diagnoses"], 2);
        assert_eq!(
            board.history("a"),
            Some((PathBuf::from("/logs/diagnosis-a.jsonl"), 0))
        );
        let v = board.valve(0).unwrap();
        v.history_starts_at(120);
        assert_eq!(board.history("a").unwrap().1, 120);
        assert_eq!(
            parse(&board, None)["valves"][0]["log_alarm"],
            serde_json::Value::Null
        );
        v.log_alarm(Some("cannot write vb-a.csv".into()));
        let live = parse(&board, None);
        assert_eq!(live["valves"][0]["log_alarm"], "cannot write vb-a.csv");
        assert!(board.history("../a").is_none() && !board.has_valve("b"));
    }

    #[test]
    fn a_health_window_shows_its_figures_against_their_limits() {
        let board = Board::new(&["a"], 100.0, (Some(600.0), None), Path::new("/x"));
        let f = Figures {
            same_steps: 9,
            reversals: 6,
            dead_time_s: Some(0.9),
            reversal_delay_s: None,
            opening_speed_pct_per_s: 20.0,
            closing_speed_pct_per_s: 10.0,
            tracking_rms_pct: 1.0,
        };
        let base = Figures {
            dead_time_s: Some(0.45),
            ..f
        };
        let cfg = crate::config::HealthConfig::default();
        let limits = Figures::limits(&base, &cfg);
        // Past its limit at 600 s, then a window that cannot measure it: still in alarm, as
        // last measured, since 600 s.
        let mut held = [None; 5];
        Held::update(&mut held, &f.judged(Some(&base), Some(&limits)), 600.0);
        let unmeasured = Figures {
            dead_time_s: None,
            ..f
        };
        Held::update(
            &mut held,
            &unmeasured.judged(Some(&base), Some(&limits)),
            630.0,
        );
        board.valve(0).unwrap().health(HealthWindow {
            t_s: 630.0,
            figures: Some(unmeasured),
            base: Some(base),
            limits: Some(limits),
            alarm: true,
            held: held.iter().flatten().copied().collect(),
            note: String::new(),
        });
        let h = &parse(&board, None)["valves"][0]["health"];
        let a = &h["alarms"][0];
        assert_eq!(
            (a["name"].as_str(), a["now"].as_f64()),
            (Some("dead time"), Some(0.9))
        );
        assert_eq!(
            (a["limit"].as_f64(), a["since_t_s"].as_f64()),
            (Some(0.65), Some(600.0))
        );
        assert_eq!(
            (a["measured_t_s"].as_f64(), h["first_t_s"].as_f64()),
            (Some(600.0), Some(600.0))
        );
        assert_eq!(h["alarms"].as_array().map(Vec::len), Some(1));
        assert!(held[0].is_some_and(|d| d.unmeasured().starts_with(
            "dead time not measured in this window (too few steps): in alarm since 600.0 s, last 0.900 s"
        )));
        // Measured within its limit, it leaves the alarm.
        let well = Figures {
            dead_time_s: Some(0.5),
            ..f
        };
        Held::update(&mut held, &well.judged(Some(&base), Some(&limits)), 660.0);
        assert!(held.iter().all(Option::is_none), "{held:?}");
        board.valve(0).unwrap().health(HealthWindow {
            t_s: 660.0,
            figures: Some(f),
            base: Some(base),
            limits: Some(limits),
            alarm: true,
            held: Vec::new(),
            note: f.drifts(&base, &cfg).join("; "),
        });
        let h = &parse(&board, None)["valves"][0]["health"];
        assert_eq!(
            (h["t_s"].as_f64(), h["alarm"].as_bool()),
            (Some(660.0), Some(true))
        );
        assert_eq!(
            h["note"],
            "dead time 0.900 s against 0.450 s (limit +0.2 s)"
        );
        let dead = &h["figures"][0];
        assert_eq!(dead["name"], "dead time");
        assert_eq!(
            (dead["now"].as_f64(), dead["limit"].as_f64()),
            (Some(0.9), Some(0.65))
        );
        assert_eq!(
            (dead["past"].as_bool(), dead["highest"].as_bool()),
            (Some(true), Some(true))
        );
        assert_eq!(h["figures"][1]["now"], serde_json::Value::Null);
        assert_eq!(h["figures"][2]["past"], false);
    }
}
