//! Live valve health (`[health]`): every `every_s` of loop time, over the last `window_s` of each
//! valve's rows, the figures a maintenance engineer watches, compared with a baseline, with an
//! alarm when one drifts past its limit.
//!
//! The figures come from the same code as `steps` and `identify`: the step analysis
//! ([`vb_core::metrics::steps::analyse`]) gives the dead time (the median delay of steps that keep
//! the direction, until V_P has moved 2 % of the step) and the reversal delay (of steps against
//! it); the identification's travel-speed
//! estimate ([`vb_core::metrics::steps::travel_speed`]) the opening and closing stroke speeds; the
//! tracking error is the RMS of O_P - V_P. A window with fewer than `min_steps` steps of a kind
//! gives no delay and says so in its note; the valve is in alarm while a figure is
//! ([`Held`]: from a window that measures it past its limit to one that measures it within it,
//! a window that cannot measure it changing nothing). The baseline is the first window with
//! enough steps, or, with `health_baseline_model`, that model's answer to each window's O_P
//! (analysed the same way).
//!
//! It runs on a thread of its own (`vb-health`), fed by the loggers with the rows they write:
//! never on the loop thread. Each window goes to `health.csv` (`health-NAME.csv` for a named
//! valve) beside the log and to the Prometheus gauges, and at the end of the run `health.svg`
//! plots each figure against its baseline and limit, drawn from the CSV by
//! the [`PlotHealth`] the daemon was handed (the windows of this run). The CSV is a history: a
//! restart appends its windows after those of the runs before ([`files::open_history`]), and a
//! disk that refuses them is survived as the log's is ([`LogFile`]); an alarm is a warning in the log, the
//! `valve_bridge_health_alarm` gauge, the summary and, for a valve a process controller drives,
//! bit [`HEALTH_ALARM_BIT`] of its status word; each window is also on the live page
//! ([`crate::serve::page`]). With `[diagnosis]`, the thread also feeds the
//! live diagnosis ([`crate::monitor::diagnosis::Feed`]) each row and each alarm it raises.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;

use crate::config::{HealthConfig, OnError};
use crate::error::DaemonError;
use crate::monitor::analysis::PlotHealth;
use crate::monitor::diagnosis::Feed;
pub use crate::monitor::health_figures::{Figures, HealthLimits, Held, Judged};
use crate::runtime::files;
use crate::runtime::log_file::{csv_line, LogAlarm, LogFile, Refused};
use crate::serve::exporter::HealthMetrics;
use crate::serve::page::board::{HealthWindow, ValveBoard};
use vb_core::model::Valve;
use vb_core::recording::health_log::{HealthRow, HEADER};
use vb_core::recording::log_format::Sample;
use vb_modbus::map::HEALTH_ALARM_BIT;
use vb_modbus::server::RegisterBank;

/// What the health check of one valve did, for the summary.
#[derive(Debug, Clone, PartialEq)]
pub struct HealthReport {
    /// Windows estimated.
    pub windows: u64,
    /// Times the alarm was raised.
    pub alarms: u64,
    /// Loop time of the first alarm, s.
    pub first_alarm_t_s: Option<f64>,
    /// The health CSV.
    pub file: PathBuf,
    /// Rows the disk refused for a while: written late, or dropped.
    pub refused: Refused,
}

/// Where a valve's baseline comes from.
enum Baseline {
    /// The first window with both delays.
    First(Option<Figures>),
    /// A model's answer to each window's O_P.
    Model(Box<Valve>),
}

/// One valve's sliding window and alarm state.
struct Monitor {
    name: String,
    op: VecDeque<f64>,
    /// NaN where the row had no V_P.
    vp: VecDeque<f64>,
    next_at_s: f64,
    baseline: Baseline,
    /// Each figure in alarm (in the order of the CSV's figures); the valve is in alarm while
    /// one is.
    held: [Option<Held>; 5],
    report: HealthReport,
    log: LogFile,
    /// The row being written, as CSV.
    line: Vec<u8>,
    metrics: Option<HealthMetrics>,
    /// The process controller's register bank of the valve, for the alarm bit.
    status: Option<Arc<RegisterBank>>,
    plot: Option<PlotHealth>,
    /// The valve on the live page.
    board: Option<Arc<ValveBoard>>,
}

/// One valve to watch: its name, its health file's name, its baseline model, its metrics, the
/// register bank whose status word carries its alarm (a valve a controller drives) and its
/// place on the live page.
#[derive(Debug)]
pub struct Watched {
    pub name: String,
    pub file_name: String,
    pub baseline_model: Option<Valve>,
    pub metrics: Option<HealthMetrics>,
    pub status: Option<Arc<RegisterBank>>,
    /// Draws `health*.svg` from the CSV at the end (none: no plot).
    pub plot: Option<PlotHealth>,
    pub(crate) board: Option<Arc<ValveBoard>>,
    /// The valve's log alarm, raised while its CSV cannot be written.
    pub(crate) log_alarm: Arc<LogAlarm>,
}

/// The running health thread: where the loggers send rows (with the valve's index), and the
/// thread.
#[derive(Debug)]
pub struct Health {
    pub tx: SyncSender<(usize, Sample)>,
    pub handle: JoinHandle<Result<Vec<HealthReport>, DaemonError>>,
}

/// Opens each valve's health CSV in `dir` (appending to one there) and starts the health
/// thread for a loop of period `period_s`; it ends when every sender of rows is dropped.
/// `on_error`: what a write the disk refuses does.
pub fn start(
    cfg: &HealthConfig,
    (dir, on_error): (&Path, OnError),
    period_s: f64,
    valves: Vec<Watched>,
    diagnosis: Option<Feed>,
) -> Result<Health, DaemonError> {
    let cap = ((cfg.window_s / period_s).round() as usize).max(1);
    let mut header = Vec::new();
    csv_line(HEADER, &mut header);
    let mut monitors = Vec::with_capacity(valves.len());
    for w in valves {
        let path = dir.join(&w.file_name);
        let (file, size) = files::open_history(&path, &header)?;
        let log = LogFile::new(path.clone(), file, size, (on_error, w.log_alarm));
        monitors.push(Monitor {
            name: w.name,
            op: VecDeque::with_capacity(cap),
            vp: VecDeque::with_capacity(cap),
            next_at_s: (cap as f64 - 0.5) * period_s,
            baseline: match w.baseline_model {
                Some(v) => Baseline::Model(Box::new(v)),
                None => Baseline::First(None),
            },
            held: [None; 5],
            report: HealthReport {
                windows: 0,
                alarms: 0,
                first_alarm_t_s: None,
                file: path,
                refused: Refused::default(),
            },
            log,
            line: Vec::with_capacity(512),
            metrics: w.metrics,
            status: w.status,
            plot: w.plot,
            board: w.board,
        });
    }
    // Bounded like the loggers' queues; a logger waits for the health thread, never the loop.
    let (tx, rx) = std::sync::mpsc::sync_channel(crate::runtime::logger::QUEUE_ROWS);
    let cfg = cfg.clone();
    let handle = std::thread::Builder::new()
        .name("vb-health".into())
        .spawn(move || watch(rx, monitors, &cfg, period_s, cap, diagnosis))
        .map_err(|source| DaemonError::Thread {
            what: "health thread",
            source,
        })?;
    Ok(Health { tx, handle })
}

/// The health thread: keeps each valve's window and estimates on time.
fn watch(
    rx: Receiver<(usize, Sample)>,
    mut monitors: Vec<Monitor>,
    cfg: &HealthConfig,
    period_s: f64,
    cap: usize,
    mut diagnosis: Option<Feed>,
) -> Result<Vec<HealthReport>, DaemonError> {
    for (i, row) in rx {
        let Some(m) = monitors.get_mut(i) else {
            continue;
        };
        if m.op.len() == cap {
            m.op.pop_front();
            m.vp.pop_front();
        }
        m.op.push_back(row.op_pct.unwrap_or(f64::NAN));
        m.vp.push_back(row.vp_pct.unwrap_or(f64::NAN));
        let mut raised = false;
        if row.t_s >= m.next_at_s && m.op.len() == cap {
            m.next_at_s += cfg.every_s;
            raised = m.estimate(row.t_s, cfg, period_s)?;
        }
        if let Some(d) = &mut diagnosis {
            let (op, vp) = (m.op.back(), m.vp.back());
            d.push(
                i,
                (row.t_s, row.utc),
                *op.unwrap_or(&f64::NAN),
                *vp.unwrap_or(&f64::NAN),
                raised,
            );
        }
    }
    monitors.into_iter().map(Monitor::finish).collect()
}

/// `x` with every NaN replaced by the last number before it (the first number for leading
/// ones); the count of NaNs replaced.
fn filled(x: &VecDeque<f64>) -> (Vec<f64>, usize) {
    let first = x.iter().copied().find(|v| !v.is_nan()).unwrap_or(0.0);
    let mut last = first;
    let mut missing = 0;
    let out = (x.iter())
        .map(|&v| {
            if v.is_nan() {
                missing += 1;
            } else {
                last = v;
            }
            last
        })
        .collect();
    (out, missing)
}

impl Monitor {
    /// Estimates the window ending at loop time `t_s`, compares, alarms, writes and publishes;
    /// true when it raised the alarm.
    fn estimate(
        &mut self,
        t_s: f64,
        cfg: &HealthConfig,
        period_s: f64,
    ) -> Result<bool, DaemonError> {
        let (op, _) = filled(&self.op);
        let (vp, missing) = filled(&self.vp);
        self.report.windows += 1;
        if missing * 10 > vp.len() {
            let note = format!(
                "{:.0} % of the rows have no V_P: no estimate",
                100.0 * missing as f64 / vp.len() as f64
            );
            return self.write(t_s, None, None, &note).map(|()| false);
        }
        let fig = Figures::of(&op, &vp, period_s, cfg.min_steps);
        let base = match &mut self.baseline {
            Baseline::Model(v) => {
                let sim = v.simulate(&op, vp.first().copied().unwrap_or(0.0));
                Some(Figures::of(&op, &sim, period_s, cfg.min_steps))
            }
            Baseline::First(b) => {
                if b.is_none() && fig.complete() {
                    *b = Some(fig);
                }
                *b
            }
        };
        let was = self.alarm();
        let mut notes = Vec::new();
        if !fig.complete() {
            notes.push(format!(
                "too few steps for the delays: {} same-direction, {} reversals (need {} each)",
                fig.same_steps, fig.reversals, cfg.min_steps
            ));
        }
        let limits = base.map(|b| (b, Figures::limits(&b, cfg)));
        let drifts = base.map(|b| fig.drifts(&b, cfg)).unwrap_or_default();
        if let Some((b, l)) = &limits {
            Held::update(&mut self.held, &fig.judged(Some(b), Some(l)), t_s);
        }
        let alarm = self.alarm();
        let raised = alarm && !was;
        if raised {
            self.report.alarms += 1;
            self.report.first_alarm_t_s.get_or_insert(t_s);
            tracing::warn!(valve = %self.name, t_s, "health alarm: {}", drifts.join("; "));
        } else if !alarm && was {
            tracing::info!(valve = %self.name, t_s, "health back within its limits");
        }
        if let Some(bank) = &self.status {
            let bit = 1 << HEALTH_ALARM_BIT;
            bank.report(None, bit, if alarm { bit } else { 0 });
        }
        notes.extend(drifts);
        let unmeasured = (self.held.iter().flatten()).filter(|h| h.measured_t_s < t_s);
        notes.extend(unmeasured.map(Held::unmeasured));
        if base.is_none() {
            notes.push("no baseline yet".into());
        }
        if let Some(m) = &self.metrics {
            m.publish(&fig, limits.as_ref().map(|l| &l.1), alarm);
        }
        self.write(t_s, Some(&fig), limits.as_ref(), &notes.join("; "))
            .map(|()| raised)
    }

    /// True while a figure is in alarm.
    fn alarm(&self) -> bool {
        self.held.iter().any(Option::is_some)
    }

    /// Closes the CSV and draws `health*.svg` beside it, from it (nothing when no window was
    /// estimated; a plot that cannot be drawn or written is said in the log, the run is not
    /// failed for it); the report.
    fn finish(mut self) -> Result<HealthReport, DaemonError> {
        let (_, refused) = self.log.close()?;
        self.report.refused = refused;
        let file = &self.report.file;
        let Some(plot) = self.plot else {
            return Ok(self.report);
        };
        let svg = file.with_extension("svg");
        let drawn = plot(&self.name, file).map_err(|e| format!("cannot draw it: {e}"));
        let written = drawn.and_then(|text| match text.is_empty() {
            true => Ok(()),
            false => files::write_over(&svg, text.as_bytes()).map_err(|e| e.to_string()),
        });
        if let Err(e) = written {
            tracing::warn!(valve = %self.name, plot = %svg.display(), "no health plot: {e}");
        }
        Ok(self.report)
    }

    /// One row of the health CSV, flushed, and the window on the live page.
    fn write(
        &mut self,
        t_s: f64,
        fig: Option<&Figures>,
        base: Option<&(Figures, HealthLimits)>,
        note: &str,
    ) -> Result<(), DaemonError> {
        let row = HealthRow {
            t_s,
            steps: fig.map(|f| (f.same_steps, f.reversals)),
            figures: fig.map_or([None; 5], Figures::in_log_order),
            alarm: self.alarm(),
            base: base.map_or([None; 5], |b| b.0.in_log_order()),
            limits: base.map_or([None; 5], |b| b.1.in_log_order()),
            note: note.to_string(),
        };
        if let Some(b) = &self.board {
            b.health(HealthWindow {
                t_s,
                figures: fig.copied(),
                base: base.map(|b| b.0),
                limits: base.map(|b| b.1),
                alarm: self.alarm(),
                held: self.held.iter().flatten().copied().collect(),
                note: note.to_string(),
            });
        }
        self.line.clear();
        csv_line(row.cells(), &mut self.line);
        self.log.line(&self.line)?;
        self.log.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, ModelKind};
    use vb_core::signal::{RandomSteps, RandomStepsParams};

    /// 10 min of the paper's random steps through pin-cart II with `extra_dead_time_s`.
    fn window(extra_dead_time_s: f64) -> (Vec<f64>, Vec<f64>) {
        let mut spec = bundled(ModelKind::Pincart2);
        spec.dead_time_s += extra_dead_time_s;
        let mut sig = RandomSteps::new(&RandomStepsParams::default());
        let op: Vec<f64> = (0..60_000).map(|k| sig.op_at(k as f64 * 0.01)).collect();
        let vp = Valve::new(&spec, 0.01).unwrap().simulate(&op, op[0]);
        (op, vp)
    }

    #[test]
    fn a_longer_dead_time_drifts_past_the_limit_and_the_same_valve_does_not() {
        let cfg = HealthConfig::default();
        let (op, vp) = window(0.0);
        let base = Figures::of(&op, &vp, 0.01, cfg.min_steps);
        assert!(base.complete(), "{base:?}");
        // The paper's valve: about 0.45 s for a step that keeps the direction, 1 s reversing.
        let dead = base.dead_time_s.unwrap();
        assert!((0.3..0.6).contains(&dead), "{base:?}");
        assert!(base.reversal_delay_s.unwrap() > dead + 0.2, "{base:?}");
        assert!(base.drifts(&base, &cfg).is_empty());
        // Past both limits by more than a sample: a rise of exactly a limit does not alarm.
        let (op, vp) = window(0.4);
        let worn = Figures::of(&op, &vp, 0.01, cfg.min_steps);
        let drifts = worn.drifts(&base, &cfg);
        assert!(
            drifts.iter().any(|d| d.starts_with("dead time")),
            "{drifts:?}"
        );
        assert!(
            drifts.iter().any(|d| d.starts_with("reversal delay")),
            "{drifts:?}"
        );
    }

    #[test]
    fn a_window_without_steps_gives_no_delays() {
        let op = vec![50.0; 6000];
        let f = Figures::of(&op, &op, 0.01, 5);
        assert_eq!((f.dead_time_s, f.reversal_delay_s), (None, None));
        assert_eq!(f.tracking_rms_pct, 0.0);
    }

    #[test]
    fn missing_positions_are_held_and_counted() {
        let x: VecDeque<f64> = [f64::NAN, 1.0, f64::NAN, 3.0].into();
        assert_eq!(filled(&x), (vec![1.0, 1.0, 1.0, 3.0], 2));
    }
}
