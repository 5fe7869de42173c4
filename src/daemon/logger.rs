//! The sample log: CSV files in the recording format, written by their own thread.
//!
//! The loop sends each [`Sample`] down a bounded channel ([`QUEUE_ROWS`]) and never waits on
//! the disk. The logger thread writes the rows through a buffered CSV writer, flushes (and
//! syncs) at least every `flush_interval_ms`, and rotates to a new file by size or by covered
//! loop time. Each file starts with the header and is named by the time of its first row,
//! `vb-YYYYMMDDTHHMMSSZ.csv` (UTC; `-1`, `-2`, ... added if that name is taken; `vb-NAME-...`
//! for a named valve). Each valve has its own logger. A crash loses at most the last flush
//! interval, and a file cut mid-line still loads with the recording reader. With `[log]
//! compress` (the default) a file is gzipped on a thread of its own once the log has moved on to
//! the next ([`crate::recording::gzip`]: `NAME.csv.gz`, read as it is by every reader).
//!
//! The row, its columns and their precision are the log format
//! ([`crate::recording::log_format`]); this module writes them.
//!
//! Rows written are passed on to the health thread when there is one ([`Forward`]), and to
//! the valve's trace on the live page when there is one ([`TraceFeed`]).
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
use super::page::board::TraceFeed;
use crate::recording::gzip;
use crate::recording::log_format::{Sample, HEADER};

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
#[derive(Debug)]
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
    /// Compress each file once it is closed for a newer one (`[log] compress`).
    compress: bool,
    /// Compressions under way: the file's index in `report.files` and its thread.
    compressing: Vec<(usize, JoinHandle<io::Result<PathBuf>>)>,
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
            let closed = self.current.as_ref().map(|f| f.path.clone());
            self.close()?;
            if let Some(path) = closed {
                self.compress_later(path);
            }
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

    /// Waits for the compressions under way and names the files as they now are.
    fn finish_compressing(&mut self) {
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
    pub(crate) fn start(
        cfg: &LogConfig,
        dir: &Path,
        name: Option<&str>,
        (forward, trace): (Option<Forward>, Option<TraceFeed>),
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
            compress: cfg.compress,
            compressing: Vec::new(),
        };
        files.open(0.0)?;
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
            files.finish_compressing();
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
    use crate::recording::log_format::Status;

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
            compress: false,
        };
        let logger = Logger::start(
            &cfg,
            dir.path(),
            None,
            (None, None),
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
    fn rotated_files_are_compressed_and_read_back_as_one_recording() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            rotate_after_s: 1.0,
            ..LogConfig::default()
        };
        let stop = Arc::new(AtomicBool::new(false));
        let logger = Logger::start(&cfg, dir.path(), Some("level"), (None, None), stop).unwrap();
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
        let opts = crate::recording::ReadOptions::default();
        let rec = crate::recording::read_all(&[dir.path().to_path_buf()], &opts).unwrap();
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
        let logger = Logger::start(
            &cfg,
            dir.path(),
            None,
            (None, None),
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
