//! A log disk that refuses writes does not take the valve out of control. With `[log] on_error =
//! "keep-running"` (the default) the run goes on to its duration, the rows the disk refused are
//! held and written once it takes them again, and the summary says how many were written late
//! and how many dropped; with `on_error = "stop"` the loop stops at the first refused write.
//!
//! The full disk is a file-size limit on the daemon (`prlimit --fsize`, RLIMIT_FSIZE): a write
//! past it fails (EFBIG) as one to a full disk does (ENOSPC), through the daemon's own write
//! path; raised from outside (`prlimit --pid`), the space returns.

use crate::common;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use crate::common::sim::{real_time_turn, BIN};

/// The header line of a log file, with its newline.
const HEADER: &str =
    "t_s,op_pct,vp_pct,status,lateness_us,latency_us,op_sent_pct,utc,op_controller_pct\n";

/// `valve-bridge run` with `config` in `dir`, logging to `dir/logs`, under a file-size limit
/// of `limit` bytes (soft; the hard limit stays unlimited, so it can be raised again).
fn limited(dir: &Path, config: &str, limit: u64, args: &[&str]) -> Command {
    std::fs::write(dir.join("c.toml"), config).unwrap();
    let mut cmd = Command::new("prlimit");
    cmd.arg(format!("--fsize={limit}:unlimited"))
        .arg("--")
        .arg(BIN)
        .args(["run", "--config", "c.toml", "--log-dir", "logs"])
        .args(args)
        .current_dir(dir)
        .env_remove("RUST_LOG");
    cmd
}

/// `(late, dropped)` from the summary's `log rows the disk refused: N written late, M dropped`
/// line; `(0, 0)` when it has none.
fn refused(summary: &str) -> (u64, u64) {
    let Some(rest) = (summary.lines()).find_map(|l| l.strip_prefix("log rows the disk refused: "))
    else {
        return (0, 0);
    };
    let words: Vec<&str> = rest.split([' ', ',']).filter(|w| !w.is_empty()).collect();
    (words[0].parse().unwrap(), words[3].parse().unwrap())
}

/// The only log file of `dir` and its text.
fn only_log(dir: &Path) -> (std::path::PathBuf, String) {
    let files = common::logs(dir, "vb-");
    assert_eq!(files.len(), 1, "{files:?}");
    let body = std::fs::read_to_string(&files[0]).unwrap();
    (files[0].clone(), body)
}

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_full_disk_keeps_the_loop_running_and_the_summary_counts_the_rows_dropped() {
    let dir = tempfile::tempdir().unwrap();
    // 300,000 rows: some 28 MB, past the 64 KiB the disk takes and the buffer that holds rows.
    let args = ["--as-fast-as-possible", "--duration", "3000"];
    let out = limited(dir.path(), "", 65_536, &args).output().unwrap();
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{:?}\n{stdout}\n{stderr}", out.status);
    assert!(
        stdout.starts_with("run: 300000 slots at 100 Hz (3000.00 s), stopped: duration reached"),
        "{stdout}"
    );
    assert!(
        stderr.contains("cannot write the log") && stderr.contains("the loop runs on"),
        "{stderr}"
    );
    let (path, body) = only_log(&dir.path().join("logs"));
    assert_eq!(body.len(), 65_536, "{}", path.display());
    assert!(body.starts_with(HEADER));
    // Every row the loop logged (300,000 cycles and the stop action's) is on the disk or
    // counted as dropped; none was written late (the space never came back).
    let on_disk = body.matches('\n').count() as u64 - 1;
    let (late, dropped) = refused(&stdout);
    assert_eq!((late, on_disk + dropped), (0, 300_001), "{stdout}");
    assert!(
        stdout.contains(&format!("log: {on_disk} rows in ")),
        "{stdout}"
    );
}

#[test]
fn rows_held_while_the_disk_is_full_are_written_once_it_takes_them_again() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = "[source]\nkind = \"constant\"\n[source.constant]\nop_pct = 40.0\n\
                  [log]\nflush_interval_ms = 100\n";
    // 8 KiB is some 90 rows: the disk is full after about a second of the four.
    let child = limited(dir.path(), config, 8192, &["--duration", "4"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let logs = dir.path().join("logs");
    let started = Instant::now();
    let full = loop {
        let files = if logs.exists() {
            common::logs(&logs, "vb-")
        } else {
            Vec::new()
        };
        if let Some(f) = files.first() {
            if std::fs::metadata(f).unwrap().len() == 8192 {
                break Instant::now();
            }
        }
        assert!(started.elapsed() < Duration::from_secs(3), "never full");
        std::thread::sleep(Duration::from_millis(5));
    };
    std::thread::sleep(Duration::from_millis(1500));
    let raised = Command::new("prlimit")
        .args(["--fsize=unlimited:unlimited", "--pid"])
        .arg(child.id().to_string())
        .status()
        .unwrap();
    assert!(raised.success());
    let held_s = full.elapsed().as_secs_f64();
    let out = child.wait_with_output().unwrap();
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{:?}\n{stdout}\n{stderr}", out.status);
    assert!(stdout.contains("stopped: duration reached"), "{stdout}");
    assert!(stderr.contains("the log is written again"), "{stderr}");
    // At least the rows of the 1.5 s the disk was full were held and written late; none lost.
    let (late, dropped) = refused(&stdout);
    assert!(
        late >= 140 && late as f64 <= (held_s + 0.5) * 100.0,
        "{late} late\n{stdout}"
    );
    assert_eq!(dropped, 0, "{stdout}");
    // Every row is there once, whole, on its slot of the grid (a cycle the busy machine made
    // late is there as `skipped`), the stop action's last.
    let (_, body) = only_log(&logs);
    let mut reader = csv::Reader::from_reader(body.as_bytes());
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    assert_eq!(rows.len(), 401, "{stdout}");
    for (k, row) in rows.iter().enumerate() {
        let t: f64 = row[0].parse().unwrap();
        assert!((t - k as f64 * 0.01).abs() < 1e-9, "row {k}: {row:?}");
        let fits = match k {
            400 => &row[3] == "safe-hold",
            _ => &row[3] == "ok" || &row[3] == "skipped",
        };
        assert!(fits, "row {k}: {row:?}");
    }
    assert!(stdout.contains("log: 401 rows in "), "{stdout}");
}

#[test]
fn on_error_stop_stops_the_loop_at_the_first_refused_write() {
    let dir = tempfile::tempdir().unwrap();
    let config = "[log]\non_error = \"stop\"\n";
    let args = ["--as-fast-as-possible", "--duration", "3000"];
    let out = limited(dir.path(), config, 65_536, &args).output().unwrap();
    let (stdout, stderr) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{stdout}\n{stderr}");
    let (path, _) = only_log(&dir.path().join("logs"));
    let name = path.file_name().unwrap().to_string_lossy();
    assert!(
        stderr.ends_with(&format!(
            "valve-bridge: error: cannot write log file `logs/{name}`: File too large (os error \
             27) (is the disk full?)\n"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains("INFO loop stopped reason=stop requested"),
        "{stderr}"
    );
}
