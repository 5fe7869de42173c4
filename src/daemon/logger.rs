//! The sample log: CSV files in the recording format, written by their own thread.
//!
//! The loop sends each [`Sample`] down an unbounded channel and never waits on the disk. The
//! logger thread writes the rows through a buffered CSV writer, flushes (and syncs) at least every
//! `flush_interval_ms`, and rotates to a new file by size or by covered loop time. Each file
//! starts with the header and is named by the time of its first row, `vb-YYYYMMDDTHHMMSSZ.csv`
//! (UTC; `-1`, `-2`, ... added if that name is taken; `vb-NAME-...` for a named valve). Each
//! valve has its own logger. A crash loses at most the last flush
//! interval, and a file cut mid-line still loads with the recording reader.
//!
//! Columns: `t_s,op_pct,vp_pct,status,lateness_us,latency_us,op_sent_pct,utc,op_controller_pct`
//! (the first six as they always were, then each later one added at the end, so readers of
//! older logs read these; the recording reader ignores columns it is not asked for).
//! - `t_s`: the slot's scheduled time, s from the first slot (the grid, k / rate).
//! - `op_pct`: the O_P sent in this slot (with `[valve.compensation]`, the compensated
//!   set-point: what the valve received, which identification must see); in a `skipped` row,
//!   the O_P the valve was holding.
//! - `vp_pct`: the V_P read back; empty when none was read (never repeated or invented).
//! - `status`: see [`Status`].
//! - `lateness_us`: actual start of the cycle minus `t_s`, µs (empty for `skipped`).
//! - `latency_us`: duration of the valve transaction, µs (empty for `skipped`).
//! - `op_sent_pct`: the set-point as the valve received it, % (a positioner gets O_P after its
//!   register's scaling and rounding, e.g. 45.67 % as 457 per mille = 45.7 %); empty when the
//!   write was not acknowledged.
//! - `utc`: the slot's scheduled time as UTC wall-clock time, ms (`2026-11-23T19:27:09.045Z`):
//!   the wall clock read when the loop started plus `t_s`, so it never jumps with the clock.
//! - `op_controller_pct`: the O_P the source (the process controller) asked for, before
//!   compensation; equal to `op_pct` without `[valve.compensation]` and in stop-action rows.
//!
//! Numbers are written with a fixed precision, trailing zeros dropped: times to 1 µs (`t_s`),
//! percentages to 0.0001 % ([`PCT_DECIMALS`]; the loop rounds O_P to it before sending, so the
//! logged O_P is the one sent), durations to 1 ns: never `49.400000000000006`.
//!
//! Rows written are passed on to the health thread when there is one ([`Forward`]).
//!
//! This module does not decide what is logged; the loop does.

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use time::OffsetDateTime;

use super::config::LogConfig;
use super::error::DaemonError;

/// The header of every log file.
pub const HEADER: [&str; 9] = [
    "t_s",
    "op_pct",
    "vp_pct",
    "status",
    "lateness_us",
    "latency_us",
    "op_sent_pct",
    "utc",
    "op_controller_pct",
];

/// Decimals of the percentages in the log (0.0001 %).
pub const PCT_DECIMALS: usize = 4;

/// `pct` rounded to the log's precision, so that what the loop sends is what it logs.
pub fn round_pct(pct: f64) -> f64 {
    let scale = 10f64.powi(PCT_DECIMALS as i32);
    (pct * scale).round() / scale
}

/// What happened in a slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// O_P written and V_P read.
    Ok,
    /// The valve did not answer in time; no V_P.
    Timeout,
    /// The valve answered with an error; no V_P.
    Error,
    /// The link to the valve is down; no V_P.
    Disconnected,
    /// O_P written and V_P read, but the O_P is the safe one: the process controller of the
    /// `modbus-server` source has not written a set-point for `watchdog_s`.
    Watchdog,
    /// The slot was missed because the previous cycle overran; nothing sent, no V_P.
    Skipped,
    /// The stop action `hold`: the last O_P sent once more (V_P empty if that failed).
    SafeHold,
    /// The stop action `go-to`: `go_to_pct` sent (V_P empty if that failed).
    SafeGoTo,
}

impl Status {
    /// Every status, in the order of the summary.
    pub const ALL: [Status; 8] = [
        Status::Ok,
        Status::Timeout,
        Status::Error,
        Status::Disconnected,
        Status::Watchdog,
        Status::Skipped,
        Status::SafeHold,
        Status::SafeGoTo,
    ];

    /// The word written in the `status` column.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Timeout => "timeout",
            Status::Error => "error",
            Status::Disconnected => "disconnected",
            Status::Watchdog => "watchdog",
            Status::Skipped => "skipped",
            Status::SafeHold => "safe-hold",
            Status::SafeGoTo => "safe-go-to",
        }
    }

    /// True for the stop action's row.
    pub fn is_stop_action(self) -> bool {
        matches!(self, Status::SafeHold | Status::SafeGoTo)
    }
}

/// One row of the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Scheduled time, s from the first slot.
    pub t_s: f64,
    /// O_P, % (empty only if no O_P was ever sent before a skipped slot).
    pub op_pct: Option<f64>,
    /// V_P, % (empty when not read).
    pub vp_pct: Option<f64>,
    /// What happened.
    pub status: Status,
    /// Start of the cycle minus `t_s`, µs.
    pub lateness_us: Option<f64>,
    /// Valve transaction time, µs.
    pub latency_us: Option<f64>,
    /// The set-point as the valve received it, % (empty when no write was acknowledged).
    pub op_sent_pct: Option<f64>,
    /// The scheduled time as wall-clock time.
    pub utc: SystemTime,
    /// The O_P the source asked for, before compensation, %.
    pub op_controller_pct: Option<f64>,
}

impl Sample {
    /// The row's cells, as written.
    fn cells(&self) -> [String; HEADER.len()] {
        let opt = |v: Option<f64>, decimals| v.map_or(String::new(), |v| fixed(v, decimals));
        [
            fixed(self.t_s, 6),
            opt(self.op_pct, PCT_DECIMALS),
            opt(self.vp_pct, PCT_DECIMALS),
            self.status.as_str().to_string(),
            opt(self.lateness_us, 3),
            opt(self.latency_us, 3),
            opt(self.op_sent_pct, PCT_DECIMALS),
            utc_stamp(self.utc),
            opt(self.op_controller_pct, PCT_DECIMALS),
        ]
    }
}

/// `v` with `decimals` decimals, trailing zeros dropped but one kept (`50.0`, `0.07`, `12.5`).
pub fn fixed(v: f64, decimals: usize) -> String {
    let text = format!("{v:.decimals$}");
    let text = match text.find('.') {
        Some(dot) => {
            let trimmed = text.trim_end_matches('0');
            if trimmed.len() == dot + 1 {
                format!("{trimmed}0")
            } else {
                trimmed.to_string()
            }
        }
        None => text,
    };
    // -0.0 after rounding reads as 0.0.
    if text
        .trim_start_matches('-')
        .trim_matches(['0', '.'])
        .is_empty()
    {
        "0.0".to_string()
    } else {
        text
    }
}

/// `2026-11-23T19:27:09.045Z` (UTC, ms).
fn utc_stamp(t: SystemTime) -> String {
    let format = time::macros::format_description!(
        "[year]-[month]-[day]T[hour]:[minute]:[second].[subsecond digits:3]Z"
    );
    OffsetDateTime::from(t)
        .format(&format)
        .unwrap_or_else(|_| "unknown-time".into())
}

/// What the logger wrote.
#[derive(Debug, Clone, Default)]
pub struct LogReport {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// Rows written (all files).
    pub rows: u64,
}

/// Where a logger passes on the rows it wrote: the health thread, with the valve's index.
pub type Forward = (usize, SyncSender<(usize, Sample)>);

/// Rows a logger's queue holds (40 s at 100 Hz). Bounded, so memory stays flat however long a
/// run and however slow the disk: on the wall clock the loop drops a row that finds the queue
/// full (and counts it) rather than wait; on the virtual clock it waits.
pub const QUEUE_ROWS: usize = 4096;

/// The running logger: the channel to send rows on, and its thread.
pub struct Logger {
    /// Where the loop sends rows.
    pub tx: SyncSender<Sample>,
    /// The thread; joins when every sender is dropped.
    pub handle: JoinHandle<Result<LogReport, DaemonError>>,
}

/// A file writer that counts the bytes it passes on (for rotation by size).
struct Counting {
    file: File,
    bytes: u64,
}

impl Write for Counting {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.file.write(buf)?;
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.file.flush()
    }
}

/// One open log file.
struct OpenFile {
    path: PathBuf,
    csv: csv::Writer<Counting>,
    first_t_s: f64,
}

/// Writes rows into rotating files in one directory.
struct Files {
    dir: PathBuf,
    /// `vb-`, or `vb-NAME-` for a named valve.
    prefix: String,
    started_wall: SystemTime,
    max_bytes: u64,
    max_span_s: f64,
    current: Option<OpenFile>,
    report: LogReport,
}

impl Files {
    /// Opens a new file for a first row at loop time `t_s`.
    fn open(&mut self, t_s: f64) -> Result<(), DaemonError> {
        let wall = self.started_wall + Duration::from_secs_f64(t_s.max(0.0));
        let stamp = file_stamp(wall);
        let mut n = 0;
        loop {
            let name = if n == 0 {
                format!("{}{stamp}.csv", self.prefix)
            } else {
                format!("{}{stamp}-{n}.csv", self.prefix)
            };
            let path = self.dir.join(name);
            match File::options().write(true).create_new(true).open(&path) {
                Ok(file) => {
                    let mut csv = csv::WriterBuilder::new()
                        .has_headers(false)
                        .buffer_capacity(64 * 1024)
                        .from_writer(Counting { file, bytes: 0 });
                    csv.write_record(HEADER)
                        .map_err(|e| write_error(&path, e))?;
                    tracing::info!(file = %path.display(), "logging to");
                    self.report.files.push(path.clone());
                    self.current = Some(OpenFile {
                        path,
                        csv,
                        first_t_s: t_s,
                    });
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists && n < 1000 => n += 1,
                Err(source) => return Err(DaemonError::LogFile { path, source }),
            }
        }
    }

    /// Writes one row, rotating first if the current file is full (never for the stop action's
    /// row: a file holding only that row would be no recording).
    fn write(&mut self, s: &Sample) -> Result<(), DaemonError> {
        let full = match &self.current {
            None => true,
            Some(_) if s.status.is_stop_action() => false,
            Some(f) => {
                f.csv.get_ref().bytes >= self.max_bytes || s.t_s - f.first_t_s >= self.max_span_s
            }
        };
        if full {
            self.close()?;
            self.open(s.t_s)?;
        }
        if let Some(f) = &mut self.current {
            f.csv
                .write_record(s.cells())
                .map_err(|e| write_error(&f.path, e))?;
            self.report.rows += 1;
        }
        Ok(())
    }

    /// Pushes buffered rows to the disk.
    fn flush(&mut self) -> Result<(), DaemonError> {
        if let Some(f) = &mut self.current {
            let io = |source| DaemonError::LogWrite {
                path: f.path.clone(),
                source,
            };
            f.csv.flush().map_err(io)?;
            f.csv
                .get_ref()
                .file
                .sync_data()
                .map_err(|source| DaemonError::LogWrite {
                    path: f.path.clone(),
                    source,
                })?;
        }
        Ok(())
    }

    fn close(&mut self) -> Result<(), DaemonError> {
        self.flush()?;
        self.current = None;
        Ok(())
    }
}

fn write_error(path: &Path, e: csv::Error) -> DaemonError {
    DaemonError::LogWrite {
        path: path.to_path_buf(),
        source: io::Error::other(e),
    }
}

/// `20261122T101500Z` for a wall time (UTC).
fn file_stamp(t: SystemTime) -> String {
    let format = time::macros::format_description!("[year][month][day]T[hour][minute][second]Z");
    OffsetDateTime::from(t)
        .format(&format)
        .unwrap_or_else(|_| "unknown-time".into())
}

impl Logger {
    /// Creates the directory and the first file, then starts the logger thread. The files of a
    /// valve named `name` are `vb-NAME-YYYYMMDDTHHMMSSZ.csv`, those of an unnamed one
    /// `vb-YYYYMMDDTHHMMSSZ.csv`.
    ///
    /// On a write error the thread logs it, sets `stop` (the loop then ends cleanly) and keeps
    /// draining the channel so the loop never blocks; the error is returned by the join.
    pub fn start(
        cfg: &LogConfig,
        dir: &Path,
        name: Option<&str>,
        forward: Option<Forward>,
        stop: Arc<AtomicBool>,
    ) -> Result<Logger, DaemonError> {
        std::fs::create_dir_all(dir).map_err(|source| DaemonError::LogDir {
            dir: dir.to_path_buf(),
            source,
        })?;
        let mut files = Files {
            dir: dir.to_path_buf(),
            prefix: name.map_or("vb-".into(), |n| format!("vb-{n}-")),
            started_wall: SystemTime::now(),
            max_bytes: (cfg.rotate_size_mb * 1e6) as u64,
            max_span_s: cfg.rotate_after_s,
            current: None,
            report: LogReport::default(),
        };
        files.open(0.0)?;
        let flush_every = Duration::from_millis(cfg.flush_interval_ms);
        let (tx, rx) = mpsc::sync_channel(QUEUE_ROWS);
        let handle = std::thread::Builder::new()
            .name("vb-logger".into())
            .spawn(move || write_all(rx, files, flush_every, forward, &stop))
            .map_err(|source| DaemonError::Thread {
                what: "logger",
                source,
            })?;
        Ok(Logger { tx, handle })
    }
}

/// The logger thread: write, flush on time, close when the loop hangs up.
fn write_all(
    rx: Receiver<Sample>,
    mut files: Files,
    flush_every: Duration,
    forward: Option<Forward>,
    stop: &AtomicBool,
) -> Result<LogReport, DaemonError> {
    let mut next_flush = Instant::now() + flush_every;
    let mut failed: Option<DaemonError> = None;
    loop {
        let wait = next_flush.saturating_duration_since(Instant::now());
        let received = rx.recv_timeout(wait);
        let done = matches!(received, Err(RecvTimeoutError::Disconnected));
        if failed.is_none() {
            let mut step = || -> Result<(), DaemonError> {
                if let Ok(sample) = &received {
                    files.write(sample)?;
                    if let Some((i, tx)) = &forward {
                        // The health thread only hangs up by failing; its join says why.
                        let _ = tx.send((*i, *sample));
                    }
                }
                if done {
                    files.close()?;
                } else if Instant::now() >= next_flush {
                    files.flush()?;
                    next_flush = Instant::now() + flush_every;
                }
                Ok(())
            };
            if let Err(e) = step() {
                tracing::error!("{e}; stopping the loop");
                stop.store(true, Ordering::SeqCst);
                failed = Some(e);
            }
        }
        if done {
            return match failed {
                Some(e) => Err(e),
                None => Ok(files.report),
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_s: f64, status: Status, vp: Option<f64>) -> Sample {
        Sample {
            t_s,
            op_pct: Some(50.0),
            vp_pct: vp,
            status,
            lateness_us: Some(12.5),
            latency_us: Some(3.0),
            op_sent_pct: vp.map(|_| 50.0),
            utc: SystemTime::UNIX_EPOCH
                + Duration::from_secs(1_800_000_000)
                + Duration::from_micros((t_s * 1e6).round() as u64),
            op_controller_pct: Some(49.5),
        }
    }

    #[test]
    fn rows_rotate_by_span_and_keep_empty_vp() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            dir: dir.path().to_path_buf(),
            rotate_size_mb: 100.0,
            rotate_after_s: 1.0,
            flush_interval_ms: 10,
        };
        let logger = Logger::start(
            &cfg,
            dir.path(),
            None,
            None,
            Arc::new(AtomicBool::new(false)),
        )
        .unwrap();
        for k in 0..250u32 {
            let status = if k == 7 { Status::Timeout } else { Status::Ok };
            let vp = (status == Status::Ok).then_some(f64::from(k) / 10.0);
            logger
                .tx
                .send(sample(f64::from(k) / 100.0, status, vp))
                .unwrap();
        }
        drop(logger.tx);
        let report = logger.handle.join().unwrap().unwrap();
        assert_eq!(report.rows, 250);
        assert_eq!(report.files.len(), 3, "{:?}", report.files);
        let first = std::fs::read_to_string(&report.files[0]).unwrap();
        let lines: Vec<&str> = first.lines().collect();
        assert_eq!(
            lines[0],
            "t_s,op_pct,vp_pct,status,lateness_us,latency_us,op_sent_pct,utc,op_controller_pct"
        );
        assert_eq!(lines.len(), 101);
        assert_eq!(
            lines[8],
            "0.07,50.0,,timeout,12.5,3.0,,2027-01-15T08:00:00.070Z,49.5"
        );
        assert_eq!(
            lines[9],
            "0.08,50.0,0.8,ok,12.5,3.0,50.0,2027-01-15T08:00:00.080Z,49.5"
        );
        let name = report.files[0]
            .file_name()
            .unwrap()
            .to_string_lossy()
            .into_owned();
        assert!(
            name.starts_with("vb-")
                && name.ends_with("Z.csv")
                && name.len() == "vb-20261122T101500Z.csv".len(),
            "{name}"
        );
    }

    #[test]
    fn numbers_have_a_fixed_precision_without_artefacts() {
        assert_eq!(fixed(49.400000000000006, PCT_DECIMALS), "49.4");
        assert_eq!(fixed(0.1 + 0.2, 6), "0.3");
        assert_eq!(fixed(50.9913961021933, PCT_DECIMALS), "50.9914");
        assert_eq!(fixed(40.0, PCT_DECIMALS), "40.0");
        assert_eq!(fixed(-0.00001, PCT_DECIMALS), "0.0");
        assert_eq!(fixed(-0.3, PCT_DECIMALS), "-0.3");
        assert_eq!(fixed(1234.5678, 3), "1234.568");
        // What the loop sends is what the log shows, to the last digit.
        let op = round_pct(50.9913961021933);
        assert_eq!(fixed(op, PCT_DECIMALS).parse::<f64>().unwrap(), op);
    }

    #[test]
    fn rows_reach_the_disk_within_the_flush_interval() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            dir: dir.path().to_path_buf(),
            flush_interval_ms: 50,
            ..LogConfig::default()
        };
        let logger = Logger::start(
            &cfg,
            dir.path(),
            None,
            None,
            Arc::new(AtomicBool::new(false)),
        )
        .unwrap();
        logger.tx.send(sample(0.0, Status::Ok, Some(1.0))).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        let path = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let text = std::fs::read_to_string(path).unwrap();
        assert_eq!(text.lines().count(), 2, "{text:?}");
        drop(logger.tx);
        logger.handle.join().unwrap().unwrap();
    }
}
