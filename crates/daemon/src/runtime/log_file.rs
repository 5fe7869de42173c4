//! A file of the log directory (a log file, a health CSV, a diagnosis history) written line by
//! line so that a disk that refuses writes does not take the valve out of control.
//!
//! [`LogFile`] gathers whole lines and writes them out in batches, at each flush (then synced)
//! and when a batch is full. When the disk refuses a write (full, over a quota or a file-size
//! limit), `[log] on_error` decides:
//! - `"keep-running"` (the default): the bytes not written are kept, from the exact byte the
//!   disk stopped at, so no line is torn or doubled; later lines are held behind them, up to
//!   [`HOLD_BYTES`] (some 18 minutes of a valve's rows at 100 Hz), and the lines that find the
//!   hold full are dropped. Each flush tries again; once the disk takes everything the lines
//!   written late are counted. The valve's [`LogAlarm`] is raised meanwhile: an error in the
//!   log (stderr), the `valve_bridge_log_write_failing` gauge and a line on the live page. At
//!   the end of the run what the disk still refuses is dropped; the summary says how many lines
//!   were written late and how many dropped ([`Refused`]).
//! - `"stop"`: the error is returned at once (the logger then stops the loop, as it always did).
//!
//! Not here: what the lines say, opening files ([`crate::runtime::files`]).

use std::fs::File;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use crate::config::OnError;
use crate::error::DaemonError;
use crate::serve::exporter::ValveMetrics;
use crate::serve::page::board::ValveBoard;

/// Bytes of lines held while the disk refuses them, at most (8 MiB: 110,000 rows of the log,
/// some 76 bytes each, 18 minutes of a valve at 100 Hz).
pub const HOLD_BYTES: usize = 8 << 20;
/// Bytes gathered before they are written between two flushes.
const BATCH_BYTES: usize = 64 << 10;

/// Where a [`LogFile`] writes: a file, or in tests one that can refuse.
pub(crate) trait Disk: Write {
    /// Makes what was written durable (`fdatasync`).
    fn sync_data(&self) -> io::Result<()>;
}

impl Disk for File {
    fn sync_data(&self) -> io::Result<()> {
        File::sync_data(self)
    }
}

/// The lines a disk refused for a while: written once it took them again, or dropped.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Refused {
    /// Lines written late, after the disk had refused them.
    pub late: u64,
    /// Lines never written: the hold was full, or the run ended before the disk took them.
    pub dropped: u64,
}

impl std::ops::AddAssign for Refused {
    fn add_assign(&mut self, other: Refused) {
        self.late += other.late;
        self.dropped += other.dropped;
    }
}

/// A valve's log alarm: raised while one of its files cannot be written.
#[derive(Debug)]
pub(crate) struct LogAlarm {
    valve: String,
    /// Files of the valve failing now.
    failing: AtomicUsize,
    metrics: Option<ValveMetrics>,
    board: Option<Arc<ValveBoard>>,
}

impl LogAlarm {
    /// The alarm of the valve named `valve`, shown in its metrics and on its live page.
    pub(crate) fn new(
        valve: &str,
        metrics: Option<ValveMetrics>,
        board: Option<Arc<ValveBoard>>,
    ) -> Arc<LogAlarm> {
        Arc::new(LogAlarm {
            valve: valve.to_string(),
            failing: AtomicUsize::new(0),
            metrics,
            board,
        })
    }

    /// The file `path` cannot be written (`e`); its lines are held.
    fn raise(&self, path: &Path, e: &io::Error) {
        tracing::error!(
            valve = %self.valve,
            file = %path.display(),
            "cannot write the log: {e}; the loop runs on, and up to {} MiB of lines are held \
             to be written when the disk takes them again",
            HOLD_BYTES >> 20
        );
        if self.failing.fetch_add(1, Ordering::SeqCst) == 0 {
            if let Some(m) = &self.metrics {
                m.log_failing(true);
            }
        }
        if let Some(b) = &self.board {
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            b.log_alarm(Some(format!(
                "cannot write {name}: {e}; lines are held and written when the disk takes them again"
            )));
        }
    }

    /// The file `path` is written again, after `late` lines held.
    fn clear(&self, path: &Path, late: u64) {
        tracing::warn!(
            valve = %self.valve,
            file = %path.display(),
            "the log is written again: {late} lines written late"
        );
        self.release();
    }

    /// One file fewer failing; the alarm falls with the last.
    fn release(&self) {
        if self.failing.fetch_sub(1, Ordering::SeqCst) == 1 {
            if let Some(m) = &self.metrics {
                m.log_failing(false);
            }
            if let Some(b) = &self.board {
                b.log_alarm(None);
            }
        }
    }

    /// Counts lines of `path` that will never be written (`first`: the first of them).
    fn dropped(&self, path: &Path, lines: u64, first: bool) {
        if let Some(m) = &self.metrics {
            m.log_rows_refused(0, lines);
        }
        if let (Some(b), true) = (&self.board, first) {
            let name = path.file_name().unwrap_or_default().to_string_lossy();
            b.log_alarm(Some(format!(
                "cannot write {name}: the lines held fill {} MiB; later lines are dropped",
                HOLD_BYTES >> 20
            )));
        }
    }
}

/// Appends `record` to `out` as one CSV line (csv's quoting, `\n` at the end).
pub(crate) fn csv_line<I, T>(record: I, out: &mut Vec<u8>)
where
    I: IntoIterator<Item = T>,
    T: AsRef<[u8]>,
{
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .buffer_capacity(256)
        .from_writer(out);
    // Writing into memory cannot fail; a record csv could not encode would lose its line only.
    if let Err(e) = w.write_record(record).and_then(|()| Ok(w.flush()?)) {
        tracing::warn!("a line of the log could not be encoded: {e}");
    }
}

/// The number of lines (newlines) in `bytes`.
fn lines(bytes: &[u8]) -> u64 {
    bytes.iter().filter(|&&b| b == b'\n').count() as u64
}

/// One file of the log directory, written line by line (see the module's documentation).
#[derive(Debug)]
pub(crate) struct LogFile<D: Disk = File> {
    path: PathBuf,
    disk: D,
    /// Whole lines not written yet; the first may be written in part (up to the byte the disk
    /// refused).
    pending: Vec<u8>,
    /// Bytes in the file.
    on_disk: u64,
    on_error: OnError,
    alarm: Arc<LogAlarm>,
    /// The disk refused the last write; lines are held.
    failing: bool,
    /// Lines written late in the current outage.
    late_now: u64,
    /// Whole lines taken in.
    taken: u64,
    refused: Refused,
}

impl<D: Disk> LogFile<D> {
    /// The file at `path`, `on_disk` bytes long, written to `disk`.
    pub(crate) fn new(
        path: PathBuf,
        disk: D,
        on_disk: u64,
        (on_error, alarm): (OnError, Arc<LogAlarm>),
    ) -> Self {
        LogFile {
            path,
            disk,
            pending: Vec::with_capacity(BATCH_BYTES),
            on_disk,
            on_error,
            alarm,
            failing: false,
            late_now: 0,
            taken: 0,
            refused: Refused::default(),
        }
    }

    /// The file's path.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes in the file and held for it.
    pub(crate) fn size(&self) -> u64 {
        self.on_disk + self.pending.len() as u64
    }

    /// The disk refused the last write.
    pub(crate) fn failing(&self) -> bool {
        self.failing
    }

    /// Takes one whole line (ending in `\n`); writes the batch when it is full.
    pub(crate) fn line(&mut self, line: &[u8]) -> Result<(), DaemonError> {
        if self.on_error == OnError::KeepRunning && self.pending.len() + line.len() > HOLD_BYTES {
            if self.refused.dropped == 0 {
                tracing::error!(
                    file = %self.path.display(),
                    "the log's held lines fill {} MiB: later lines are dropped until the disk \
                     takes them again",
                    HOLD_BYTES >> 20
                );
            }
            self.refused.dropped += 1;
            self.alarm.dropped(&self.path, 1, self.refused.dropped == 1);
            return Ok(());
        }
        self.pending.extend_from_slice(line);
        self.taken += 1;
        if self.failing || self.pending.len() < BATCH_BYTES {
            return Ok(());
        }
        let written = self.write_out();
        self.outcome(written)
    }

    /// Writes out every line taken and syncs; on a disk that refused, tries again.
    pub(crate) fn flush(&mut self) -> Result<(), DaemonError> {
        let written = self.write_out().and_then(|()| self.disk.sync_data());
        self.outcome(written)
    }

    /// Flushes a last time and closes: the lines written, and those the disk refused (what it
    /// still refuses is dropped).
    pub(crate) fn close(mut self) -> Result<(u64, Refused), DaemonError> {
        let flushed = self.flush();
        let left = lines(&self.pending);
        if left > 0 {
            tracing::error!(
                file = %self.path.display(),
                "{left} lines held for the log are dropped: the disk still refuses them at the end of the run"
            );
            self.refused.dropped += left;
            self.alarm.dropped(&self.path, left, false);
        }
        if self.failing {
            // Lines written in part of an outage that lasts to the end were still written late.
            self.refused.late += self.late_now;
            if let Some(m) = &self.alarm.metrics {
                m.log_rows_refused(self.late_now, 0);
            }
            self.failing = false;
            self.alarm.release();
        }
        flushed.map(|()| (self.taken - left, self.refused))
    }

    /// Writes the pending bytes, as far as the disk takes them.
    fn write_out(&mut self) -> io::Result<()> {
        while !self.pending.is_empty() {
            match self.disk.write(&self.pending) {
                Ok(0) => return Err(io::ErrorKind::WriteZero.into()),
                Ok(n) => {
                    if self.failing {
                        self.late_now += lines(&self.pending[..n]);
                    }
                    self.pending.drain(..n);
                    self.on_disk += n as u64;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// What a write or flush that gave `written` means for the file and the alarm.
    fn outcome(&mut self, written: io::Result<()>) -> Result<(), DaemonError> {
        match written {
            Ok(()) if self.failing && self.pending.is_empty() => {
                self.failing = false;
                self.refused.late += self.late_now;
                if let Some(m) = &self.alarm.metrics {
                    m.log_rows_refused(self.late_now, 0);
                }
                self.alarm.clear(&self.path, self.late_now);
                self.late_now = 0;
                Ok(())
            }
            Ok(()) => Ok(()),
            Err(source) if self.on_error == OnError::Stop => Err(DaemonError::LogWrite {
                path: self.path.clone(),
                source,
            }),
            Err(e) => {
                if !self.failing {
                    self.failing = true;
                    self.alarm.raise(&self.path, &e);
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A disk that takes `room` bytes, then refuses with ENOSPC until given more.
    #[derive(Debug, Default)]
    struct Small {
        bytes: Vec<u8>,
        room: usize,
    }

    impl Write for Small {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let n = buf.len().min(self.room - self.bytes.len());
            if n == 0 {
                return Err(io::Error::from_raw_os_error(libc::ENOSPC));
            }
            self.bytes.extend_from_slice(&buf[..n]);
            Ok(n)
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Disk for Small {
        fn sync_data(&self) -> io::Result<()> {
            Ok(())
        }
    }

    fn file(room: usize, on_error: OnError) -> LogFile<Small> {
        let disk = Small {
            room,
            ..Small::default()
        };
        let alarm = LogAlarm::new("v", None, None);
        LogFile::new("v.csv".into(), disk, 0, (on_error, alarm))
    }

    fn row(k: usize) -> Vec<u8> {
        format!("{k},{}\n", "x".repeat(k % 7)).into_bytes()
    }

    #[test]
    fn lines_refused_are_held_and_written_whole_and_once_when_space_returns() {
        let mut f = file(100, OnError::KeepRunning);
        for k in 0..40 {
            f.line(&row(k)).unwrap();
        }
        f.flush().unwrap();
        assert!(f.failing() && f.alarm.failing.load(Ordering::SeqCst) == 1);
        assert_eq!(f.disk.bytes.len(), 100, "cut mid-line at the disk's limit");
        for k in 40..60 {
            f.line(&row(k)).unwrap();
        }
        f.flush().unwrap();
        assert!(f.failing());
        f.disk.room = usize::MAX;
        f.flush().unwrap();
        assert!(!f.failing() && f.alarm.failing.load(Ordering::SeqCst) == 0);
        let want: Vec<u8> = (0..60).flat_map(row).collect();
        assert_eq!(f.disk.bytes, want);
        // The lines whose end was past the 100 bytes the disk took at first: written late.
        let on_time = lines(&want[..100]);
        assert_eq!(
            f.refused,
            Refused {
                late: 60 - on_time,
                dropped: 0
            }
        );
        let (written, refused) = f.close().unwrap();
        assert_eq!((written, refused.late), (60, 60 - on_time));
    }

    #[test]
    fn the_alarm_shows_in_the_metrics_and_on_the_live_page_while_the_disk_refuses() {
        use crate::serve::exporter::LoopMetrics;
        use crate::serve::page::board::Board;
        let metrics = LoopMetrics::new(&["v"], false).unwrap();
        let board = Board::new(&["v"], 100.0, (None, None), Path::new("/logs"));
        let alarm = LogAlarm::new("v", metrics.valve(0), board.valve(0));
        let disk = Small {
            room: 10,
            ..Small::default()
        };
        let mut f = LogFile::new("/logs/v.csv".into(), disk, 0, (OnError::KeepRunning, alarm));
        let shown = |board: &Board| {
            let live: serde_json::Value = serde_json::from_str(&board.live_json(None)).unwrap();
            live["valves"][0]["log_alarm"].as_str().map(String::from)
        };
        let gauge = |m: &LoopMetrics| {
            let text = m.text().unwrap();
            let line = (text.lines())
                .find(|l| l.starts_with("valve_bridge_log_write_failing{"))
                .unwrap()
                .to_string();
            let late = (text.lines())
                .find(|l| l.starts_with("valve_bridge_log_rows_late_total{"))
                .unwrap()
                .to_string();
            (line, late)
        };
        for k in 0..5 {
            f.line(&row(k)).unwrap();
        }
        f.flush().unwrap();
        let why = shown(&board).unwrap();
        assert!(
            why.starts_with("cannot write v.csv: No space left on device"),
            "{why}"
        );
        let (failing, _) = gauge(&metrics);
        assert_eq!(failing, "valve_bridge_log_write_failing{valve=\"v\"} 1");
        f.disk.room = usize::MAX;
        f.flush().unwrap();
        assert_eq!(shown(&board), None);
        let (failing, late) = gauge(&metrics);
        assert_eq!(failing, "valve_bridge_log_write_failing{valve=\"v\"} 0");
        assert_eq!(
            late,
            format!(
                "valve_bridge_log_rows_late_total{{valve=\"v\"}} {}",
                f.refused.late
            )
        );
        assert!(f.refused.late > 0);
    }

    #[test]
    fn a_full_hold_drops_lines_and_the_end_of_the_run_drops_what_is_left() {
        let mut f = file(10, OnError::KeepRunning);
        let line = vec![b'y'; 1023]
            .into_iter()
            .chain([b'\n'])
            .collect::<Vec<u8>>();
        let n = HOLD_BYTES / line.len() + 100;
        for _ in 0..n {
            f.line(&line).unwrap();
        }
        assert_eq!(f.refused.dropped, 100);
        assert!(f.pending.len() <= HOLD_BYTES);
        let (written, refused) = f.close().unwrap();
        // Every line the file took is held (the first in part), none written whole.
        assert_eq!((written, refused.late), (0, 0));
        assert_eq!(refused.dropped, n as u64);
    }

    #[test]
    fn on_error_stop_returns_the_first_refused_write() {
        let mut f = file(100, OnError::Stop);
        f.line(b"1,2\n").unwrap();
        f.flush().unwrap();
        assert_eq!(f.disk.bytes, b"1,2\n");
        for k in 0..40 {
            f.line(&row(k)).unwrap();
        }
        let e = f.flush().unwrap_err();
        assert!(
            e.to_string()
                .starts_with("cannot write log file `v.csv`: No space left"),
            "{e}"
        );
    }

    #[test]
    fn a_line_is_csv() {
        let mut out = b"t\n".to_vec();
        csv_line(["1.5", "a,b", ""], &mut out);
        assert_eq!(out, b"t\n1.5,\"a,b\",\n");
    }
}
