//! Helpers shared by the integration tests of `valve-bridge` (each test crate, a folder of
//! tests/ whose main.rs includes this one with `#[path]`, uses a part).
#![allow(dead_code)]

pub(crate) mod diagnosis;
pub(crate) mod servers;
pub(crate) mod sim;
pub(crate) mod tools;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Sends `sig` to `child`; true if kill(2) took it.
pub(crate) fn signal(child: &Child, sig: libc::c_int) -> bool {
    kill(child.id() as libc::pid_t, sig)
}

/// Sends `sig` to the process group `child` leads; true if kill(2) took it.
pub(crate) fn signal_group(child: &Child, sig: libc::c_int) -> bool {
    kill(-(child.id() as libc::pid_t), sig)
}

/// kill(2): `sig` to `pid` (a process group when negative).
#[allow(unsafe_code)]
fn kill(pid: libc::pid_t, sig: libc::c_int) -> bool {
    // SAFETY: kill(2) takes two integers and touches no memory of this process.
    unsafe { libc::kill(pid, sig) == 0 }
}

/// The log files of `dir` whose names start with `prefix` (`vb-NAME-`), oldest first.
pub(crate) fn logs(dir: &Path, prefix: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            let name = p.file_name().unwrap().to_string_lossy().into_owned();
            name.starts_with(prefix) && name.ends_with(".csv")
        })
        .collect();
    files.sort();
    files
}

/// How a child run by [`run_watched`] ended.
#[derive(Debug)]
pub(crate) struct Watched {
    /// Its exit code; `None` when a signal ended it.
    pub code: Option<i32>,
    /// Its peak resident memory, KiB (wait4(2)'s accounting of that one child).
    pub peak_kib: i64,
    /// What it wrote to stderr.
    pub stderr: String,
    /// Why it was killed: its memory or its time passed the bound.
    pub killed: Option<String>,
}

/// Runs `cmd` (stdout discarded) to its end, killing it once its resident memory passes
/// `max_kib` (`VmHWM`, polled every 10 ms) or it has run for `timeout`; its peak memory is
/// measured either way.
// The child is reaped by wait4, not by `Child::wait`, which would not return its rusage.
#[allow(clippy::zombie_processes)]
pub(crate) fn run_watched(cmd: &mut Command, max_kib: i64, timeout: Duration) -> Watched {
    let mut child = cmd
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut pipe = child.stderr.take().unwrap();
    let stderr = std::thread::spawn(move || {
        let mut text = String::new();
        pipe.read_to_string(&mut text).map(|_| text)
    });
    let pid = child.id() as libc::pid_t;
    let start = Instant::now();
    let mut killed = None;
    let (status, usage) = loop {
        if let Some(done) = wait4(pid, libc::WNOHANG) {
            break done;
        }
        if killed.is_none() {
            let hwm = vm_hwm_kib(pid);
            if hwm > max_kib || start.elapsed() > timeout {
                killed = Some(format!(
                    "killed after {:?} at a peak of {hwm} KiB (bounds {max_kib} KiB, {timeout:?})",
                    start.elapsed()
                ));
                kill(pid, libc::SIGKILL);
            }
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Watched {
        code: libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status)),
        peak_kib: usage.ru_maxrss,
        stderr: stderr.join().unwrap().unwrap(),
        killed,
    }
}

/// wait4(2) on the child `pid`: its status and rusage once it has ended (`None` while it runs,
/// with `WNOHANG`).
#[allow(unsafe_code)]
fn wait4(pid: libc::pid_t, options: libc::c_int) -> Option<(libc::c_int, libc::rusage)> {
    let mut status = 0;
    // SAFETY: wait4 on our own child's pid, with valid pointers to a status and an rusage.
    unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        let got = libc::wait4(pid, &mut status, options, &mut usage);
        assert!(got >= 0, "wait4: {}", std::io::Error::last_os_error());
        (got == pid).then_some((status, usage))
    }
}

/// The peak resident memory of the running process `pid`, KiB (0 once it is gone).
fn vm_hwm_kib(pid: libc::pid_t) -> i64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// One row of a daemon log as the tests read it (the columns they check).
#[derive(Debug)]
pub(crate) struct LogRow {
    pub op: f64,
    pub vp: Option<f64>,
    pub status: String,
    pub latency_us: Option<f64>,
}

/// Every row of the daemon log at `path`.
pub(crate) fn log_rows(path: &Path) -> Vec<LogRow> {
    let mut r = csv::Reader::from_path(path).unwrap();
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            LogRow {
                op: rec[1].parse().unwrap(),
                vp: rec[2].parse().ok(),
                status: rec[3].to_string(),
                latency_us: rec[5].parse().ok(),
            }
        })
        .collect()
}

/// Panics if `text`, meant for people, holds a number with a float artefact: seven or more
/// decimals (`0.09999999999999999`, `49.400000000000006`).
pub(crate) fn assert_for_people(text: &str) {
    let bytes = text.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'.' && i > 0 && bytes[i - 1].is_ascii_digit() {
            let decimals = bytes[i + 1..]
                .iter()
                .take_while(|b| b.is_ascii_digit())
                .count();
            let start = text[..i]
                .rfind(|c: char| !c.is_ascii_digit())
                .map_or(0, |s| s + 1);
            assert!(
                decimals < 7,
                "a number for people with {decimals} decimals: `{}` in\n{text}",
                &text[start..i + 1 + decimals]
            );
            i += decimals;
        }
        i += 1;
    }
}
