//! Run statistics: counts by status, the timing-error histogram, the live figures and the summary.
//!
//! The loop records every slot into [`Stats`] (an HDR histogram of |actual - scheduled| with 3
//! significant digits; recording never allocates) and publishes a few [`Live`] figures through
//! atomics for the progress display. At the end, [`Summary`] is what `valve-bridge run` prints.
//! Nothing here does I/O.

use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use hdrhistogram::Histogram;

use crate::monitor::diagnosis::DiagnosisReport;
use crate::monitor::health::HealthReport;
use crate::runtime::compensation::CompensationReport;
use crate::runtime::log_file::Refused;
use crate::runtime::logger::LogReport;
use crate::runtime::valve::Fault;
use vb_core::human;
use vb_core::recording::log_format::{Sample, Status};
use vb_modbus::client::LinkStats;
use vb_modbus::net::HealthView;

/// The failure statuses, in the order of [`Stats::last_faults`].
const FAILURES: [Status; 3] = [Status::Timeout, Status::Error, Status::Disconnected];

/// Counts and timing of the loop's slots.
#[derive(Debug, Clone)]
pub struct Stats {
    lateness_ns: Histogram<u64>,
    counts: [u64; Status::ALL.len()],
    /// Rows dropped because the logger's queue was full.
    dropped_log_rows: u64,
    /// The last fault of each failure kind (timeout, error, disconnected).
    last_faults: [Option<Fault>; 3],
}

impl Default for Stats {
    fn default() -> Self {
        Stats::new()
    }
}

impl Stats {
    /// Empty statistics (timing errors up to 60 s, 3 significant digits).
    pub fn new() -> Self {
        Stats {
            // Bounds are constants within the crate's limits; `new_with_bounds` only fails on bad bounds.
            lateness_ns: Histogram::new_with_bounds(1, 60_000_000_000, 3)
                .unwrap_or_else(|e| panic!("histogram bounds: {e}")),
            counts: [0; Status::ALL.len()],
            dropped_log_rows: 0,
            last_faults: [None, None, None],
        }
    }

    /// Counts a row the logger's queue had no room for.
    pub fn dropped_log_row(&mut self) {
        self.dropped_log_rows += 1;
    }

    /// Rows dropped because the logger's queue was full.
    pub fn dropped_log_rows(&self) -> u64 {
        self.dropped_log_rows
    }

    /// Keeps `fault` as the last of its kind (the summary says what went wrong).
    pub fn note_fault(&mut self, fault: Fault) {
        let i = match fault {
            Fault::Timeout(_) => 0,
            Fault::Error(_) => 1,
            Fault::Disconnected(_) => 2,
        };
        self.last_faults[i] = Some(fault);
    }

    /// The last fault of each kind that occurred, most frequent kind first.
    pub fn last_faults(&self) -> Vec<(u64, &Fault)> {
        let mut out: Vec<(u64, &Fault)> = FAILURES
            .iter()
            .zip(&self.last_faults)
            .filter_map(|(s, f)| f.as_ref().map(|f| (self.count(*s), f)))
            .collect();
        out.sort_by_key(|f| std::cmp::Reverse(f.0));
        out
    }

    /// Counts a row and, when it ran, its timing error.
    pub fn record(&mut self, sample: &Sample, lateness: Option<Duration>) {
        if let Some(i) = Status::ALL.iter().position(|s| *s == sample.status) {
            self.counts[i] += 1;
        }
        if let Some(l) = lateness {
            self.lateness_ns
                .saturating_record(l.as_nanos().max(1) as u64);
        }
    }

    /// Rows with this status.
    pub fn count(&self, status: Status) -> u64 {
        Status::ALL
            .iter()
            .position(|s| *s == status)
            .map_or(0, |i| self.counts[i])
    }

    /// The timing error at quantile `q` (0-1), µs.
    pub fn lateness_us(&self, q: f64) -> f64 {
        if self.lateness_ns.is_empty() {
            return 0.0;
        }
        self.lateness_ns.value_at_quantile(q) as f64 / 1e3
    }

    /// The largest timing error, µs.
    pub fn max_lateness_us(&self) -> f64 {
        self.lateness_ns.max() as f64 / 1e3
    }
}

/// Figures the loop publishes for the progress display (lock-free).
#[derive(Debug, Default)]
pub struct Live {
    samples: AtomicU64,
    op_bits: AtomicU64,
    vp_bits: AtomicU64,
    p99_ns: AtomicU64,
    /// A response test's moves done (high 32 bits) and in all (low 32 bits); 0 for others.
    moves: AtomicU64,
}

/// A snapshot of [`Live`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LiveView {
    /// Rows so far.
    pub samples: u64,
    /// Last O_P sent, % (NaN before the first).
    pub op_pct: f64,
    /// Last V_P read, % (NaN if the last read failed).
    pub vp_pct: f64,
    /// Timing error p99 so far, µs.
    pub p99_us: f64,
    /// A response test's moves done and in all (`None` for other sources).
    pub moves: Option<(u32, u32)>,
}

impl Live {
    /// Publishes the latest row.
    pub fn publish(&self, sample: &Sample) {
        self.samples.fetch_add(1, Ordering::Relaxed);
        if let Some(op) = sample.op_pct {
            self.op_bits.store(op.to_bits(), Ordering::Relaxed);
        }
        self.vp_bits.store(
            sample.vp_pct.unwrap_or(f64::NAN).to_bits(),
            Ordering::Relaxed,
        );
    }

    /// Publishes a response test's moves done and in all.
    pub fn publish_progress(&self, (done, all): (usize, usize)) {
        let packed = (done.min(u32::MAX as usize) as u64) << 32 | all.min(u32::MAX as usize) as u64;
        self.moves.store(packed, Ordering::Relaxed);
    }

    /// Publishes the timing p99.
    pub fn publish_p99(&self, stats: &Stats) {
        self.p99_ns
            .store((stats.lateness_us(0.99) * 1e3) as u64, Ordering::Relaxed);
    }

    /// Reads the latest figures.
    pub fn view(&self) -> LiveView {
        let samples = self.samples.load(Ordering::Relaxed);
        LiveView {
            samples,
            op_pct: if samples == 0 {
                f64::NAN
            } else {
                f64::from_bits(self.op_bits.load(Ordering::Relaxed))
            },
            vp_pct: if samples == 0 {
                f64::NAN
            } else {
                f64::from_bits(self.vp_bits.load(Ordering::Relaxed))
            },
            p99_us: self.p99_ns.load(Ordering::Relaxed) as f64 / 1e3,
            moves: match self.moves.load(Ordering::Relaxed) {
                0 => None,
                m => Some(((m >> 32) as u32, m as u32)),
            },
        }
    }
}

/// Why the loop stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// `--duration` reached.
    Duration,
    /// SIGINT or SIGTERM (or the logger failed).
    Signal,
    /// The source (a replay) ran out.
    SourceEnded,
}

impl fmt::Display for StopReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            StopReason::Duration => "duration reached",
            StopReason::Signal => "stop requested",
            StopReason::SourceEnded => "source ended",
        })
    }
}

/// The stop action as it went: its log row and, when the valve did not confirm it, why.
#[derive(Debug, Clone)]
pub struct StopAction {
    /// The row logged (status `safe-hold` or `safe-go-to`; V_P empty when not confirmed).
    pub row: Sample,
    /// Why the valve did not confirm it.
    pub fault: Option<Fault>,
}

impl fmt::Display for StopAction {
    /// `safe-hold O_P 59.90 %, V_P 59.70 %`, or what became of an action not confirmed:
    /// `safe-hold O_P 59.90 %: could not be sent (disconnected: ...)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let op = self.row.op_pct.map_or("-".into(), |v| format!("{v:.2}"));
        write!(f, "{} O_P {op} %", self.row.status.as_str())?;
        match (&self.fault, self.row.vp_pct) {
            (None, Some(vp)) => write!(f, ", V_P {vp:.2} %"),
            (None, None) => write!(f, ", V_P not read"),
            (Some(fault @ Fault::Disconnected(_)), _) => write!(f, ": could not be sent ({fault})"),
            (Some(fault @ Fault::Timeout(_)), _) => {
                write!(f, ": sent, not confirmed by the valve ({fault})")
            }
            (Some(fault @ Fault::Error(_)), _) => {
                write!(f, ": not confirmed by the valve ({fault})")
            }
        }
    }
}

/// What `valve-bridge run` reports at the end.
#[derive(Debug, Clone)]
pub struct Summary {
    /// Each valve's figures, in the order of the config.
    pub valves: Vec<ValveSummary>,
    /// Why the loop stopped.
    pub reason: StopReason,
    /// Slots covered, including skipped ones (not the stop action).
    pub slots: u64,
    /// Loop rate, Hz.
    pub rate_hz: f64,
    /// What each server (`modbus-server`, `metrics`) went through.
    pub servers: Vec<(&'static str, HealthView)>,
}

/// One valve's part of the [`Summary`].
#[derive(Debug, Clone)]
pub struct ValveSummary {
    /// The valve's name.
    pub name: String,
    /// Loop statistics (cycle rows and the stop-action row).
    pub stats: Stats,
    /// The stop action, if one was sent.
    pub safe: Option<StopAction>,
    /// What a Modbus link went through: reconnects, attempts, late replies (None: not a
    /// Modbus valve).
    pub link: Option<LinkStats>,
    /// What the logger wrote.
    pub log: LogReport,
    /// What the live health check did, with `[health]`.
    pub health: Option<HealthReport>,
    /// What the live diagnosis did, with `[diagnosis]`.
    pub diagnosis: Option<DiagnosisReport>,
    /// What compensation did, with `[valve.compensation]`.
    pub compensation: Option<CompensationReport>,
}

/// A run in which a valve never gave a V_P: it did not do its job, whatever stopped it.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{valve}no cycle read a V_P: all {cycles} failed ({counts}); the last {last}")]
pub struct NothingRead {
    /// `valve NAME: ` with several valves, else empty.
    pub valve: String,
    /// Cycles that ran a transaction.
    pub cycles: u64,
    /// The failures by kind, e.g. `200 error`.
    pub counts: String,
    /// The last fault of the most frequent kind, e.g. `error: device answered FC 23 with ...`.
    pub last: String,
}

impl Summary {
    /// Err when cycles ran but a valve read no V_P (every one of its transactions failed): the
    /// cause is the last fault of the most frequent kind.
    pub fn check(&self) -> Result<(), NothingRead> {
        let several = self.valves.len() > 1;
        for v in &self.valves {
            let s = &v.stats;
            let cycles = v.samples();
            if cycles == 0 || s.count(Status::Ok) + s.count(Status::Watchdog) > 0 {
                continue;
            }
            let counts: Vec<String> = FAILURES
                .iter()
                .filter(|st| s.count(**st) > 0)
                .map(|st| format!("{} {}", s.count(*st), st.as_str()))
                .collect();
            let last = s
                .last_faults()
                .first()
                .map_or("fault is unknown".into(), |(_, f)| format!("was {f}"));
            return Err(NothingRead {
                valve: if several {
                    format!("valve {}: ", v.name)
                } else {
                    String::new()
                },
                cycles,
                counts: counts.join(", "),
                last,
            });
        }
        Ok(())
    }
}

impl ValveSummary {
    /// Slots that ran a transaction (ok or failed), not counting skipped slots or the stop action.
    pub fn samples(&self) -> u64 {
        [
            Status::Ok,
            Status::Watchdog,
            Status::Timeout,
            Status::Error,
            Status::Disconnected,
        ]
        .iter()
        .map(|s| self.stats.count(*s))
        .sum()
    }

    /// Slots missed because a cycle overran.
    pub fn missed(&self) -> u64 {
        self.stats.count(Status::Skipped)
    }

    /// The valve's lines of the summary, each starting with `indent`.
    fn write(&self, f: &mut fmt::Formatter<'_>, indent: &str) -> fmt::Result {
        let s = &self.stats;
        writeln!(
            f,
            "{indent}samples: {} ({} ok, {} timeout, {} error, {} disconnected)",
            self.samples(),
            s.count(Status::Ok),
            s.count(Status::Timeout),
            s.count(Status::Error),
            s.count(Status::Disconnected)
        )?;
        let held = s.count(Status::Watchdog);
        if held > 0 {
            writeln!(
                f,
                "{indent}watchdog: {held} cycles sent the safe O_P (no set-point from the controller)"
            )?;
        }
        for (_, fault) in s.last_faults() {
            writeln!(f, "{indent}last {fault}")?;
        }
        writeln!(f, "{indent}missed cycles: {}", self.missed())?;
        if s.dropped_log_rows() > 0 {
            writeln!(
                f,
                "{indent}log rows dropped: {} (the logger fell behind the loop: a slow or full disk?)",
                s.dropped_log_rows()
            )?;
        }
        if let Some(l) = self.link {
            writeln!(
                f,
                "{indent}reconnects: {} ({})",
                l.reconnects,
                human::count(l.attempts, "connection attempt")
            )?;
            if l.late_replies > 0 {
                writeln!(
                    f,
                    "{indent}late replies discarded: {} (answers to earlier requests, after their deadline: timeout_ms may be shorter than the device's slowest answer)",
                    l.late_replies
                )?;
            }
            if l.noise_bytes > 0 {
                writeln!(
                    f,
                    "{indent}line noise: {} that formed no frame, dropped (check the RS-485 wiring, termination and earthing)",
                    human::count(l.noise_bytes, "byte")
                )?;
            }
            if l.unexpected_replies > 0 {
                writeln!(
                    f,
                    "{indent}replies no request waited for: {} (a reply came later than late_reply_ms, now {} ms: one before it may have been taken for a later request's)",
                    l.unexpected_replies,
                    l.late_reply_ms.unwrap_or_default()
                )?;
            }
        }
        match &self.safe {
            Some(action) => writeln!(f, "{indent}stop action: {action}")?,
            None => writeln!(f, "{indent}stop action: none (no O_P was ever sent)")?,
        }
        if let Some(h) = &self.health {
            writeln!(
                f,
                "{indent}health: {} windows, {} alarms{}, in {}",
                h.windows,
                h.alarms,
                h.first_alarm_t_s
                    .map_or(String::new(), |t| format!(" (first at {t:.0} s)")),
                h.file.display()
            )?;
            write_refused(f, indent, "health rows", h.refused)?;
        }
        if let Some(d) = &self.diagnosis {
            writeln!(
                f,
                "{indent}diagnosis: {} diagnoses, {} alarms, in {}",
                d.diagnoses,
                d.alarms.len(),
                d.file.display()
            )?;
            for a in &d.alarms {
                writeln!(f, "{indent}  alarm: {a}")?;
            }
            if d.skipped > 0 {
                writeln!(
                    f,
                    "{indent}diagnosis: {} windows skipped (each came while the valve's diagnosis before it was still running)",
                    d.skipped
                )?;
            }
            write_refused(f, indent, "diagnosis lines", d.refused)?;
        }
        if let Some(c) = &self.compensation {
            write_compensation(f, indent, c)?;
        }
        write_refused(f, indent, "log rows", self.log.refused)?;
        let files: Vec<String> = self
            .log
            .files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        write!(
            f,
            "{indent}log: {} rows in {}",
            self.log.rows,
            files.join(", ")
        )
    }
}

/// The line `WHAT the disk refused: N written late, M dropped`, when it refused any.
fn write_refused(f: &mut fmt::Formatter<'_>, indent: &str, what: &str, r: Refused) -> fmt::Result {
    if r == Refused::default() {
        return Ok(());
    }
    writeln!(
        f,
        "{indent}{what} the disk refused: {} written late, {} dropped (a full disk? they were held, up to {} MiB)",
        r.late,
        r.dropped,
        crate::runtime::log_file::HOLD_BYTES >> 20
    )
}

/// The summary's compensation line.
fn write_compensation(
    f: &mut fmt::Formatter<'_>,
    indent: &str,
    c: &CompensationReport,
) -> fmt::Result {
    let state = match (c.switched_off_s, &c.tripping) {
        (Some(t), Some(w)) => format!(
            "switched off by its guard at {t:.1} s ({})",
            crate::runtime::compensation::tripped(w)
        ),
        (Some(t), None) => format!("switched off by its guard at {t:.1} s"),
        (None, _) => "on".into(),
    };
    let last = c.last.map_or(String::new(), |w| {
        format!(
            "; last window: O_P - V_P {:.3} % RMS with it, {:.3} % the model's without",
            w.with_pct, w.without_pct
        )
    });
    writeln!(
        f,
        "{indent}compensation: {state}, {} windows judged{last} ({})",
        c.windows, c.described
    )
}

impl fmt::Display for Summary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "run: {} slots at {} Hz ({:.2} s), stopped: {}",
            self.slots,
            self.rate_hz,
            self.slots as f64 / self.rate_hz,
            self.reason
        )?;
        for (name, health) in &self.servers {
            writeln!(f, "{name}: {health}")?;
        }
        // Every valve of a cycle starts in the same slot: the timing is the loop's.
        if let Some(s) = self.valves.first().map(|v| &v.stats) {
            writeln!(
                f,
                "timing error |actual - scheduled|: p50 {:.2} us, p99 {:.2} us, max {:.2} us",
                s.lateness_us(0.5),
                s.lateness_us(0.99),
                s.max_lateness_us()
            )?;
        }
        let several = self.valves.len() > 1;
        for (i, v) in self.valves.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            if several {
                writeln!(f, "valve {}:", v.name)?;
            }
            v.write(f, if several { "  " } else { "" })?;
        }
        Ok(())
    }
}
