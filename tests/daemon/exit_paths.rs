//! Every way out of `valve-bridge run` applies the stop action and logs its row, whatever happens
//! to standard error; and no command panics when its output cannot be written.
//!
//! - stderr on `/dev/full` with `RUST_LOG=info` (the shipped systemd unit's level): the run
//!   ends normally, its log closes with the `safe-hold` row, the summary is printed;
//! - stderr a pipe whose reader has gone, while the device is killed mid-run (the loop warns on
//!   every fault) and the daemon is then stopped with SIGTERM: the same;
//! - sim-device with stderr on `/dev/full` serves;
//! - a stop action sent to a device nobody listens for is told as not sent;
//! - an analysis command writing to `/dev/full` fails with one line; into a closed pipe it ends
//!   quietly.

use crate::common;

use std::io::Read;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use crate::common::sim::{
    nobody_listening, read_log, real_time_turn, run_cmd, SimDevice, BIN, CONSTANT,
};

/// The rows of a daemon log, as far as these tests look.
#[derive(Debug, serde::Deserialize)]
struct Row {
    op_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
}

fn dev_full() -> std::fs::File {
    std::fs::OpenOptions::new()
        .write(true)
        .open("/dev/full")
        .expect("/dev/full")
}

/// Panics unless the log in `dir` ends with the stop action's `safe-hold` row at O_P `op`.
fn ends_with_safe_hold(dir: &Path, op: f64) -> Vec<Row> {
    let rows: Vec<Row> = read_log(dir);
    let last = rows.last().expect("a log row");
    assert_eq!(last.status, "safe-hold", "{:?}", &rows[rows.len() - 3..]);
    assert_eq!(last.op_pct, Some(op));
    rows
}

#[test]
fn a_full_stderr_does_not_skip_the_stop_action() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("const.toml");
    std::fs::write(&cfg, CONSTANT).unwrap();
    let logs = dir.path().join("logs");
    let out = run_cmd(&cfg, &logs, 0.5)
        .arg("--as-fast-as-possible")
        .env("RUST_LOG", "info")
        .stderr(dev_full())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{:?}\n{stdout}", out.status);
    assert!(
        stdout.contains("stop action: safe-hold O_P 40.00 %, V_P "),
        "{stdout}"
    );
    let rows = ends_with_safe_hold(&logs, 40.0);
    assert_eq!(rows.len(), 51);
}

#[test]
fn a_closed_stderr_pipe_mid_run_does_not_skip_the_stop_action() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let mut dev = SimDevice::start(&["--tcp", "127.0.0.1:0"]);
    let cfg = dev.config(dir.path(), &[], CONSTANT);
    let logs = dir.path().join("logs");
    let mut daemon = run_cmd(&cfg, &logs, 30.0)
        .env("RUST_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Read one byte of the log, then hang up: every later line meets a closed pipe.
    let mut stderr = daemon.stderr.take().unwrap();
    let mut first = [0u8; 1];
    stderr.read_exact(&mut first).unwrap();
    drop(stderr);
    std::thread::sleep(Duration::from_millis(500));
    // The loop now warns of every failed cycle, into the closed pipe.
    dev.kill();
    std::thread::sleep(Duration::from_millis(500));
    assert!(common::signal(&daemon, libc::SIGTERM));
    let out = daemon.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{:?}\n{stdout}", out.status);
    assert!(stdout.contains("stopped: stop requested"), "{stdout}");
    // The device is gone: the stop action is logged, and told as not sent.
    assert!(
        stdout.contains("stop action: safe-hold O_P 40.00 %: could not be sent (disconnected: "),
        "{stdout}"
    );
    let rows = ends_with_safe_hold(&logs, 40.0);
    assert!(rows.iter().any(|r| r.status == "ok" && r.vp_pct.is_some()));
    assert!(rows
        .iter()
        .any(|r| r.status == "disconnected" || r.status == "timeout"));
}

#[test]
fn sim_device_serves_with_a_full_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let mut sim = Command::new(common::sim::sim_device_bin())
        .args(["--tcp", "127.0.0.1:0"])
        .env("RUST_LOG", "debug")
        .stdout(Stdio::piped())
        .stderr(dev_full())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(sim.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let addr = line.trim().trim_start_matches("tcp: ").to_string();
    let cfg = common::sim::config(
        dir.path(),
        common::sim::TCP_CONFIG.0,
        &[(common::sim::TCP_CONFIG.1, &addr)],
        CONSTANT,
    );
    let logs = dir.path().join("logs");
    let out = {
        let _turn = real_time_turn();
        run_cmd(&cfg, &logs, 0.5).output().unwrap()
    };
    drop(sim.kill());
    drop(sim.wait());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let rows: Vec<Row> = read_log(&logs);
    let ok = rows.iter().filter(|r| r.status == "ok").count();
    assert!(ok >= 40, "{ok} ok rows of {}", rows.len());
}

#[test]
fn a_stop_action_to_nobody_is_told_as_not_sent() {
    let dir = tempfile::tempdir().unwrap();
    let (_addr, cfg, _guard) = nobody_listening(dir.path(), CONSTANT);
    let logs = dir.path().join("logs");
    let out = {
        let _turn = real_time_turn();
        run_cmd(&cfg, &logs, 0.3).output().unwrap()
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains("stop action: safe-hold O_P 40.00 %: could not be sent (disconnected: "),
        "{stdout}"
    );
    assert!(!stdout.contains("applied"), "{stdout}");
}

const RECORDING: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/cases/pub_backlash_rs.csv"
);

#[test]
fn analysis_output_that_cannot_be_written_is_one_line_or_quiet() {
    let out = Command::new(BIN)
        .args(["steps", RECORDING])
        .stdout(dev_full())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("valve-bridge: error: cannot write to standard output: "),
        "{stderr}"
    );
    // A reader that has gone, as after `| head -c 1`: the pipe's read end is closed before the
    // command writes.
    let mut fds = [0 as libc::c_int; 2];
    // SAFETY: pipe(2) fills the two descriptors; the read end is closed at once and the write
    // end handed to a File that owns it.
    #[allow(unsafe_code)]
    let stdout = unsafe {
        assert_eq!(libc::pipe(fds.as_mut_ptr()), 0);
        libc::close(fds[0]);
        <std::fs::File as std::os::fd::FromRawFd>::from_raw_fd(fds[1])
    };
    let out = Command::new(BIN)
        .args(["steps", RECORDING])
        .stdout(stdout)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {stderr}", out.status);
    assert!(stderr.is_empty(), "{stderr}");
}
