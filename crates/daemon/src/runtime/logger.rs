//! The sample log: CSV files in the recording format, written by their own thread.
//!
//! The loop sends each [`Sample`] down a bounded channel ([`QUEUE_ROWS`]) and never waits on
//! the disk. The logger thread writes the rows ([`LogFile`]), flushes (and syncs) at least
//! every `flush_interval_ms`, and rotates to a new file by size or by covered loop time. Each
//! file is named by the time of its first row, `vb-YYYYMMDDTHHMMSSZ.csv` (UTC; `-1`, `-2`, ...
//! added if that name is taken; `vb-NAME-...` for a named valve), and appears under that name
//! with its header already on the disk ([`files::create_with_header`], through
//! `vb-[NAME-]new.part`): a crash or a kill at any moment, a rotation included, leaves no file
//! without its header. Each valve has its own logger. A crash loses at most the last flush
//! interval, and a file cut mid-line still loads with the recording reader. With `[log]
//! compress` (the default) a file is gzipped on a thread of its own once the log has moved on to
//! the next ([`vb_core::recording::gzip`]: `NAME.csv.gz`, read as it is by every reader).
//!
//! A disk that refuses rows (full) keeps the loop running with `[log] on_error =
//! "keep-running"`: the rows are held and written later ([`crate::runtime::log_file`]), and the log
//! rotates only once the current file has taken its rows. With `"stop"`, a refused write stops
//! the loop.
//!
//! The row, its columns and their precision are the log format
//! ([`vb_core::recording::log_format`]); this module writes them.
//!
//! Rows written are passed on to the health thread when there is one ([`Forward`]), and to
//! the valve's trace on the live page when there is one ([`TraceFeed`]).
//!
//! This module does not decide what is logged; the loop does.

use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, SyncSender};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use time::OffsetDateTime;

use crate::config::{LogConfig, OnError};
use crate::error::DaemonError;
use crate::runtime::files;
use crate::runtime::log_file::{csv_line, LogAlarm, LogFile, Refused};
use crate::serve::page::board::TraceFeed;
use vb_core::recording::gzip;
use vb_core::recording::log_format::{Sample, HEADER};

/// What the logger wrote.
#[derive(Debug, Clone, Default)]
pub struct LogReport {
    /// The files, in order.
    pub files: Vec<PathBuf>,
    /// Rows written (all files).
    pub rows: u64,
    /// Rows the disk refused for a while: written late, or dropped.
    pub refused: Refused,
}

/// Where a logger passes on the rows it wrote: the health thread, with the valve's index.
pub type Forward = (usize, SyncSender<(usize, Sample)>);

/// Rows a logger's queue holds (40 s at 100 Hz). Bounded, so memory stays flat however long a
/// run and however slow the disk: on the wall clock the loop drops a row that finds the queue
/// full (and counts it) rather than wait; on the virtual clock it waits.
pub const QUEUE_ROWS: usize = 4096;

/// The running logger: the channel to send rows on, and its thread.
#[derive(Debug)]
pub struct Logger {
    /// Where the loop sends rows.
    pub tx: SyncSender<Sample>,
    /// The thread; joins when every sender is dropped.
    pub handle: JoinHandle<Result<LogReport, DaemonError>>,
}

/// Where a valve's files go and what they are named.
struct Naming {
    dir: PathBuf,
    /// `vb-`, or `vb-NAME-` for a named valve.
    prefix: String,
    started_wall: SystemTime,
    /// What a refused write does, and the valve's log alarm.
    on_error: (OnError, Arc<LogAlarm>),
}

impl Naming {
    /// A new file, its header on the disk, for a first row at loop time `t_s`.
    fn open(&self, t_s: f64) -> Result<OpenFile, DaemonError> {
        let wall = self.started_wall + Duration::from_secs_f64(t_s.max(0.0));
        let stamp = file_stamp(wall);
        let prefix = &self.prefix;
        let names = (0..).map(|n| match n {
            0 => format!("{prefix}{stamp}.csv"),
            n => format!("{prefix}{stamp}-{n}.csv"),
        });
        let mut header = Vec::new();
        csv_line(HEADER, &mut header);
        let temp = format!("{prefix}new.part");
        let (path, file) = files::create_with_header(&self.dir, &temp, names, &header)?;
        tracing::info!(file = %path.display(), "logging to");
        let size = header.len() as u64;
        Ok(OpenFile {
            log: LogFile::new(path, file, size, self.on_error.clone()),
            first_t_s: t_s,
        })
    }
}

/// One open log file.
struct OpenFile {
    log: LogFile,
    first_t_s: f64,
}

/// Writes rows into rotating files in one directory.
struct Files {
    naming: Naming,
    max_bytes: u64,
    max_span_s: f64,
    current: OpenFile,
    /// A new file could not be made: the next try waits for the next flush.
    rotation_failed: bool,
    report: LogReport,
    /// Compress each file once it is closed for a newer one (`[log] compress`).
    compress: bool,
    /// Compressions under way: the file's index in `report.files` and its thread.
    compressing: Vec<(usize, JoinHandle<io::Result<PathBuf>>)>,
    /// The row being written, as CSV.
    line: Vec<u8>,
}

impl Files {
    /// Writes one row, rotating first if the current file is full (never for the stop action's
    /// row: a file holding only that row would be no recording; nor while the disk refuses the
    /// current file's rows, which stay in it).
    fn write(&mut self, s: &Sample) -> Result<(), DaemonError> {
        let f = &self.current;
        let full = !s.status.is_stop_action()
            && (f.log.size() >= self.max_bytes || s.t_s - f.first_t_s >= self.max_span_s);
        if full && !f.log.failing() && !self.rotation_failed {
            self.rotate(s.t_s)?;
        }
        self.line.clear();
        csv_line(s.cells(), &mut self.line);
        self.current.log.line(&self.line)?;
        Ok(())
    }

    /// Moves on to a new file for a first row at `t_s`, then closes the current one. A new file
    /// that cannot be made keeps the current one (with `on_error = "keep-running"`).
    fn rotate(&mut self, t_s: f64) -> Result<(), DaemonError> {
        let next = match self.naming.open(t_s) {
            Ok(next) => next,
            Err(e) if self.naming.on_error.0 == OnError::KeepRunning => {
                tracing::error!(
                    "{e}; the log goes on in {} and tries again at the next flush",
                    self.current.log.path().display()
                );
                self.rotation_failed = true;
                return Ok(());
            }
            Err(e) => return Err(e),
        };
        let closed = std::mem::replace(&mut self.current, next);
        let path = closed.log.path().to_path_buf();
        self.close(closed)?;
        self.compress_later(path);
        self.report
            .files
            .push(self.current.log.path().to_path_buf());
        Ok(())
    }

    /// Pushes buffered rows to the disk; the next row may try a rotation again.
    fn flush(&mut self) -> Result<(), DaemonError> {
        self.rotation_failed = false;
        self.current.log.flush()
    }

    /// Closes `file`, counting its rows.
    fn close(&mut self, file: OpenFile) -> Result<(), DaemonError> {
        let (rows, refused) = file.log.close()?;
        self.report.rows += rows;
        self.report.refused += refused;
        Ok(())
    }

    /// Compresses the closed file `path` (the last of `report.files`) on a thread of its own,
    /// so the queue keeps draining; a file that cannot be compressed is kept as it is.
    fn compress_later(&mut self, path: PathBuf) {
        if !self.compress {
            return;
        }
        let index = self.report.files.len() - 1;
        let spawned = std::thread::Builder::new()
            .name("vb-gzip".into())
            .spawn(move || gzip::compress(&path));
        match spawned {
            Ok(handle) => self.compressing.push((index, handle)),
            Err(e) => tracing::warn!("cannot start compressing a log file ({e}); it stays plain"),
        }
    }

    /// Closes the current file, waits for the compressions under way and names the files as
    /// they now are.
    fn finish(mut self) -> Result<LogReport, DaemonError> {
        let (rows, refused) = self.current.log.close()?;
        self.report.rows += rows;
        self.report.refused += refused;
        for (index, handle) in self.compressing.drain(..) {
            let plain = &mut self.report.files[index];
            match handle.join() {
                Ok(Ok(gz)) => *plain = gz,
                Ok(Err(e)) => tracing::warn!(
                    "could not compress {} ({e}); it is kept as it is",
                    plain.display()
                ),
                Err(_) => tracing::warn!(
                    "compressing {} failed; it is kept as it is",
                    plain.display()
                ),
            }
        }
        Ok(self.report)
    }
}

/// `20261122T101500Z` for a wall time (UTC).
pub(crate) fn file_stamp(t: SystemTime) -> String {
    let format = time::macros::format_description!("[year][month][day]T[hour][minute][second]Z");
    OffsetDateTime::from(t)
        .format(&format)
        .unwrap_or_else(|_| "unknown-time".into())
}

impl Logger {
    /// Creates the directory and the first file, then starts the logger thread. The files of a
    /// valve named `name` are `vb-NAME-YYYYMMDDTHHMMSSZ.csv`, those of an unnamed one
    /// `vb-YYYYMMDDTHHMMSSZ.csv`; `alarm` is the valve's log alarm.
    ///
    /// On a write error with `on_error = "stop"` the thread logs it, sets `stop` (the loop then
    /// ends cleanly) and keeps draining the channel so the loop never blocks; the error is
    /// returned by the join.
    pub(crate) fn start(
        cfg: &LogConfig,
        (dir, name): (&Path, Option<&str>),
        (forward, trace): (Option<Forward>, Option<TraceFeed>),
        alarm: Arc<LogAlarm>,
        stop: Arc<AtomicBool>,
    ) -> Result<Logger, DaemonError> {
        std::fs::create_dir_all(dir).map_err(|source| DaemonError::LogDir {
            dir: dir.to_path_buf(),
            source,
        })?;
        let naming = Naming {
            dir: dir.to_path_buf(),
            prefix: name.map_or("vb-".into(), |n| format!("vb-{n}-")),
            started_wall: SystemTime::now(),
            on_error: (cfg.on_error, alarm),
        };
        let current = naming.open(0.0)?;
        let files = Files {
            max_bytes: (cfg.rotate_size_mb * 1e6) as u64,
            max_span_s: cfg.rotate_after_s,
            rotation_failed: false,
            report: LogReport {
                files: vec![current.log.path().to_path_buf()],
                ..LogReport::default()
            },
            current,
            naming,
            compress: cfg.compress,
            compressing: Vec::new(),
            line: Vec::with_capacity(256),
        };
        let flush_every = Duration::from_millis(cfg.flush_interval_ms);
        let (tx, rx) = mpsc::sync_channel(QUEUE_ROWS);
        let handle = std::thread::Builder::new()
            .name("vb-logger".into())
            .spawn(move || write_all(rx, files, flush_every, (forward, trace), &stop))
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
    (forward, mut trace): (Option<Forward>, Option<TraceFeed>),
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
                    if let Some(t) = &mut trace {
                        t.row(sample);
                    }
                }
                if !done && Instant::now() >= next_flush {
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
            let report = files.finish();
            return match failed {
                Some(e) => Err(e),
                None => report,
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::recording::log_format::Status;

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

    /// A logger of the valve `name` into `dir`.
    fn start(cfg: &LogConfig, dir: &Path, name: Option<&str>) -> Logger {
        let alarm = LogAlarm::new(name.unwrap_or("valve"), None, None);
        let stop = Arc::new(AtomicBool::new(false));
        Logger::start(cfg, (dir, name), (None, None), alarm, stop).unwrap()
    }

    #[test]
    fn a_file_made_at_a_rotation_holds_its_header_before_any_row_is_flushed() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            rotate_after_s: 1.0,
            compress: false,
            ..LogConfig::default()
        };
        let logger = start(&cfg, dir.path(), None);
        // A second of rows, and the first of the next file: no flush for a second.
        for k in 0..=100u32 {
            let vp = Some(f64::from(k) / 10.0);
            let row = sample(f64::from(k) / 100.0, Status::Ok, vp);
            logger.tx.send(row).unwrap();
        }
        let started = Instant::now();
        let second = loop {
            let mut names: Vec<PathBuf> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "csv"))
                .collect();
            names.sort();
            if names.len() == 2 {
                break names[1].clone();
            }
            assert!(started.elapsed() < Duration::from_millis(500), "{names:?}");
            std::thread::yield_now();
        };
        let text = std::fs::read_to_string(&second).unwrap();
        assert_eq!(text, format!("{}\n", HEADER.join(",")));
        drop(logger.tx);
        let report = logger.handle.join().unwrap().unwrap();
        assert_eq!((report.rows, report.files.len()), (101, 2));
    }

    #[test]
    fn rows_rotate_by_span_and_keep_empty_vp() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            dir: dir.path().to_path_buf(),
            rotate_size_mb: 100.0,
            rotate_after_s: 1.0,
            flush_interval_ms: 10,
            compress: false,
            on_error: OnError::KeepRunning,
        };
        let logger = start(&cfg, dir.path(), None);
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
    fn rotated_files_are_compressed_and_read_back_as_one_recording() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            rotate_after_s: 1.0,
            ..LogConfig::default()
        };
        let logger = start(&cfg, dir.path(), Some("level"));
        for k in 0..250u32 {
            let vp = Some(f64::from(k) / 10.0);
            let row = sample(f64::from(k) / 100.0, Status::Ok, vp);
            logger.tx.send(row).unwrap();
        }
        drop(logger.tx);
        let report = logger.handle.join().unwrap().unwrap();
        let names: Vec<String> = report
            .files
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), 3, "{names:?}");
        assert!(names[0].ends_with(".csv.gz") && names[1].ends_with(".csv.gz"));
        assert!(
            names[2].ends_with(".csv"),
            "the file being written stays plain"
        );
        for f in &report.files {
            assert!(f.exists(), "{}", f.display());
        }
        let mut on_disk: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(on_disk.len(), 3, "no plain twin or part left: {on_disk:?}");
        on_disk.clear();
        let opts = vb_core::recording::ReadOptions::default();
        let rec = vb_core::recording::read_all(&[dir.path().to_path_buf()], &opts).unwrap();
        assert_eq!(rec.vp.len(), 250);
        assert_eq!(rec.vp[123], 12.3);
    }

    #[test]
    fn rows_reach_the_disk_within_the_flush_interval() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            dir: dir.path().to_path_buf(),
            flush_interval_ms: 50,
            ..LogConfig::default()
        };
        let logger = start(&cfg, dir.path(), None);
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
