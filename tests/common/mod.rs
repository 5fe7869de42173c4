//! Helpers shared by the integration tests of `valve-bridge` (each test file uses a part).
#![allow(dead_code)]

pub(crate) mod diagnosis;
pub(crate) mod servers;
pub(crate) mod sim;
pub(crate) mod tools;

use std::path::{Path, PathBuf};
use std::process::Child;

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
