//! `valve-bridge run` against sim-device when the link misbehaves the way field links do, through
//! both real binaries over loopback TCP and a pseudo-terminal:
//!
//! - the device is not there at start: the loop runs, logs `disconnected` rows, says so once,
//!   and picks the device up when it appears;
//! - the device freezes for 5 s (SIGSTOP) or answers every reply too late: the daemon keeps one
//!   connection (counted from sim-device's log, and from the daemon's open sockets in /proc),
//!   at most a few attempts, no flood;
//! - a lost reply (dropped, or a bad CRC on the pty) costs its own cycle only.

use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use crate::common;

use crate::common::sim::{real_time_turn, run_cmd, summary_count, SimDevice, CONSTANT};

#[derive(Debug, serde::Deserialize)]
struct Row {
    status: String,
    vp_pct: Option<f64>,
}

/// TCP sockets the process `pid` has open now: its socket descriptors (distinct inodes) that
/// /proc/PID/net/tcp lists (tokio's signal handling holds Unix sockets of its own).
fn open_sockets(pid: u32) -> usize {
    let inodes: std::collections::HashSet<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| {
            d.filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
                .filter_map(|t| {
                    let t = t.to_string_lossy().into_owned();
                    Some(t.strip_prefix("socket:[")?.strip_suffix(']')?.to_string())
                })
                .collect()
        })
        .unwrap_or_default();
    let tcp: std::collections::HashSet<String> = ["tcp", "tcp6"]
        .iter()
        .filter_map(|f| std::fs::read_to_string(format!("/proc/{pid}/net/{f}")).ok())
        .flat_map(|text| {
            // The inode is the tenth column of each socket's line.
            text.lines()
                .skip(1)
                .filter_map(|l| l.split_whitespace().nth(9).map(String::from))
                .collect::<Vec<_>>()
        })
        .collect();
    inodes.intersection(&tcp).count()
}

/// Connections sim-device accepted, from its log.
fn connections(device_log: &str) -> usize {
    device_log.matches("client connected from").count()
}

/// Waits for a started daemon and returns (exit code, stdout, stderr).
fn finish(child: Child) -> (Option<i32>, String, String) {
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn spawn(cfg: &Path, logs: &Path, duration_s: f64) -> Child {
    run_cmd(cfg, logs, duration_s)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

#[test]
fn a_device_down_at_start_is_picked_up_when_it_appears() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let (addr, cfg, port) = common::sim::nobody_listening(dir.path(), CONSTANT);
    let logs = dir.path().join("logs");
    let daemon = spawn(&cfg, &logs, 4.0);
    std::thread::sleep(Duration::from_millis(1500));
    drop(port);
    let device = SimDevice::start(&["--tcp", &addr]);
    let (code, summary, stderr) = finish(daemon);
    drop(device);
    assert_eq!(code, Some(0), "{summary}\n{stderr}");
    let rows: Vec<Row> = common::sim::read_log(&logs);
    let first_ok = rows
        .iter()
        .position(|r| r.status == "ok")
        .expect("no ok row");
    assert!(
        first_ok >= 100,
        "ok before the device started: row {first_ok}"
    );
    assert!(
        rows[..first_ok]
            .iter()
            .all(|r| r.status == "disconnected" || r.status == "skipped"),
        "{summary}"
    );
    // Once there, it is followed (a busy machine may time out a cycle now and then).
    let after = &rows[first_ok..rows.len() - 1];
    let ok = after.iter().filter(|r| r.status == "ok").count();
    assert!(ok * 10 >= after.len() * 9, "{summary}");
    // Said once, with what to do; the connection is logged when it comes.
    assert_eq!(stderr.matches("running without it").count(), 1, "{stderr}");
    assert!(
        stderr.contains(&format!(
            "cannot connect to Modbus TCP {addr}: Connection refused"
        )) && stderr.contains("--require-device stops instead"),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!("Modbus TCP {addr} unit 1: connected")),
        "{stderr}"
    );
    // The retries back off (100 ms, doubling): a handful of attempts in 1.5 s, not one a cycle.
    assert_eq!(summary_count(&summary, "reconnects: "), 1, "{summary}");
    let attempts = summary
        .lines()
        .find_map(|l| l.split_once('(')?.1.strip_suffix(" connection attempts)"))
        .and_then(|n| n.parse::<u64>().ok())
        .unwrap_or_else(|| panic!("{summary}"));
    assert!((3..=8).contains(&attempts), "{summary}");
}

/// Runs the daemon against `device` for `secs` while `during` acts on the device; samples the
/// daemon's open sockets meanwhile. Returns (summary, stderr, most sockets seen, device log).
fn watch(
    device: SimDevice,
    secs: f64,
    during: impl FnOnce(&SimDevice),
) -> (String, String, usize, String) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = device.config(dir.path(), &[], CONSTANT);
    let logs = dir.path().join("logs");
    let daemon = spawn(&cfg, &logs, secs);
    let pid = daemon.id();
    let sampling = std::thread::spawn(move || {
        let until = Instant::now() + Duration::from_secs_f64(secs);
        let mut most = 0;
        while Instant::now() < until {
            most = most.max(open_sockets(pid));
            std::thread::sleep(Duration::from_millis(20));
        }
        most
    });
    during(&device);
    let (_, summary, stderr) = finish(daemon);
    let most = sampling.join().unwrap();
    (summary, stderr, most, device.stop())
}

#[test]
fn a_frozen_device_gets_no_flood_of_connections() {
    let _turn = real_time_turn();
    let device = SimDevice::start(&["--tcp", "127.0.0.1:0"]);
    let (summary, stderr, sockets, device_log) = watch(device, 8.0, |d| {
        std::thread::sleep(Duration::from_millis(1500));
        d.signal(libc::SIGSTOP);
        std::thread::sleep(Duration::from_secs(5));
        d.signal(libc::SIGCONT);
    });
    let accepted = connections(&device_log);
    println!(
        "5 s freeze: {accepted} connections accepted by the device, at most {sockets} TCP socket(s) \
         open in the daemon; {}",
        summary.lines().find(|l| l.starts_with("reconnects")).unwrap_or("")
    );
    // One connection at a time; during the freeze at most one reopening after 3 s of silence.
    assert_eq!(sockets, 1, "{summary}");
    assert!(
        (1..=3).contains(&accepted),
        "{accepted} connections\n{device_log}"
    );
    assert!(summary_count(&summary, "samples: ") > 0, "{summary}");
    assert!(
        stderr.contains("valve transactions succeed again"),
        "{stderr}"
    );
}

#[test]
fn replies_always_too_late_keep_one_connection() {
    let _turn = real_time_turn();
    let device = SimDevice::start(&["--tcp", "127.0.0.1:0", "--delay-ms", "12"]);
    let (summary, _, sockets, device_log) = watch(device, 5.0, |_| {});
    assert_eq!(summary_count(&summary, "reconnects: "), 0, "{summary}");
    let accepted = connections(&device_log);
    println!(
        "replies 12 ms late, 8 ms deadline, 5 s: {accepted} connection(s), at most {sockets} \
         TCP socket(s) open"
    );
    assert_eq!(sockets, 1, "{summary}");
    // The device answers, only late: the one connection is kept throughout.
    assert_eq!(accepted, 1, "{device_log}");
    assert!(
        summary.contains("came after their deadline; a longer timeout_ms may fit"),
        "{summary}"
    );
}

/// Share of the run's cycles that failed, and how many failures there were in a row at most.
fn lost(summary: &str, rows: &[Row]) -> (f64, usize) {
    let cycles = summary_count(summary, "samples: ") as f64;
    let failed = rows
        .iter()
        .filter(|r| r.status == "timeout" || r.status == "error")
        .count();
    let ran: Vec<&Row> = rows.iter().filter(|r| r.status != "skipped").collect();
    let mut run = 0;
    let mut longest = 0;
    for r in ran {
        run = if r.vp_pct.is_none() && r.status != "safe-hold" {
            run + 1
        } else {
            0
        };
        longest = longest.max(run);
    }
    (failed as f64 / cycles, longest)
}

fn lost_cycles(device_args: &[&str]) -> (f64, usize, String) {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let device = SimDevice::start(device_args);
    let cfg = device.config(dir.path(), &[], CONSTANT);
    let logs = dir.path().join("logs");
    let out = run_cmd(&cfg, &logs, 3.0).output().unwrap();
    let summary = common::sim::stdout(&out);
    let rows: Vec<Row> = common::sim::read_log(&logs);
    let (share, longest) = lost(&summary, &rows);
    println!(
        "{device_args:?}: {:.1} % of the cycles lost, at most {longest} in a row",
        share * 100.0
    );
    (share, longest, summary)
}

#[test]
fn a_lost_reply_costs_one_cycle() {
    // One reply in 10 dropped (TCP): 10 % of the cycles, never two in a row.
    let (share, longest, summary) = lost_cycles(&["--tcp", "127.0.0.1:0", "--drop-every", "10"]);
    assert!(
        share <= 0.11 && longest == 1,
        "{share} {longest}\n{summary}"
    );
    // One reply in 7 with a bad CRC (RTU on a pty): a seventh of the cycles. A loaded machine
    // can stall a cycle past its deadline beside one (a `timeout` next to an `error`), so two
    // in a row are allowed only when the summary counts such a timeout. A machine that stalls
    // the device or the pty for longer than `late_reply_ms` (a reply arriving after it, which
    // no bad CRC makes) holds the line for that long: such a run measures the machine, not
    // what a bad CRC costs, and is run once more.
    let crc = ["--pty", "--corrupt-crc-every", "7"];
    let (mut share, mut longest, mut summary) = lost_cycles(&crc);
    if summary.contains("replies no request waited for: ") {
        (share, longest, summary) = lost_cycles(&crc);
    }
    let stalled = !summary.contains(" 0 timeout,");
    assert!(
        share <= 0.16 && (longest == 1 || (stalled && longest == 2)),
        "{share} {longest}\n{summary}"
    );
}

#[test]
fn a_device_that_closes_after_each_answer_gets_few_connections() {
    let _turn = real_time_turn();
    // Each connection's first request is answered, its second closes it.
    let device = SimDevice::start(&["--tcp", "127.0.0.1:0", "--disconnect-after", "2"]);
    let (summary, stderr, sockets, device_log) = watch(device, 5.0, |_| {});
    let accepted = connections(&device_log);
    let reconnects = summary_count(&summary, "reconnects: ");
    println!(
        "a device closing each connection after one answer, 5 s: {accepted} connections \
         accepted, at most {sockets} TCP socket(s) open in the daemon"
    );
    assert!(
        (3..=12).contains(&accepted),
        "{accepted} connections\n{summary}\n{stderr}"
    );
    // Never two at once. Each connection lives for one answer (a few ms of every reconnect
    // wait), so the 20 ms sampling may see none open at all: the device's count above shows
    // they were made.
    assert!(sockets <= 1, "{sockets} sockets at once\n{summary}");
    assert!(reconnects >= 2, "{summary}");
}
