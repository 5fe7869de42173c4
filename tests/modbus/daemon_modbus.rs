//! `valve-bridge run` against `sim-device` over real Modbus, through both real binaries.
//!
//! - TCP and RTU (a pseudo-terminal): a short recording's O_P is replayed for 3 s at 100 Hz; the
//!   log has one row per slot and the logged V_P follows an offline simulation of sim-device's
//!   model (pin-cart II) on the same O_P;
//! - sim-device killed mid-run and restarted on the same port: the loop keeps its rhythm, logs
//!   `timeout`/`disconnected` rows with an empty V_P, reconnects, exits 0 and counts it all;
//! - injected faults (corrupted CRC on the pty, dropped replies, replies later than the deadline,
//!   exception replies): each fault is a row of its kind with an empty V_P, one row per slot,
//!   the summary counts exactly the rows of each status, and the log on stderr names the fault.
//!
//! Start-up errors are in [`super::daemon_startup`].
//!
//! The daemon runs with `RUST_LOG` unset, as a user starts it: its stderr is the default log.
//!
//! sim-device is the workspace's other binary: `cargo test --workspace` builds it into the same
//! directory as `valve-bridge` (its own integration tests need it); with `cargo test -p
//! valve-bridge` alone run `cargo build -p sim-device` first.
//!
//! Tolerance of the comparison: sim-device steps its model on its own 100 Hz clock and the loop
//! reads the last stepped position, so a logged V_P lags the offline sample of the same slot by
//! one to two steps, and the phase between the two clocks drifts: on a loaded machine either
//! clock can stall, the device's without a trace in the loop's log (its model task late, then
//! catching up in a burst). The check is therefore an alignment in time, not a range: each row's
//! V_P must equal an offline sample of the same slot or of one up to [`MAX_LAG`] slots earlier
//! (300 ms), and the samples matched must run forward in time as the rows do, never back. A
//! match allows half a register step (positions are per-mille, 0.05 %) and what the valve
//! strokes in one slot at its speed limit (0.2 % at 20 %/s: steps the device runs in a burst
//! with the newest set-point instead of the one written during its stall). O_P is quantised to
//! the set-point register (0.1 %) before the offline simulation, as the device sees it. A valve
//! that does not follow the model (V_P equal to O_P, a wrong scale, the wrong model), or a V_P
//! stale by more than 300 ms, or one that goes back in time, misses by far more.

use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::Duration;

use valve_bridge::model::composed::{self, Knob};
use valve_bridge::model::{bundled, ModelKind, Valve};
use valve_bridge::recording;

use crate::common;

use crate::common::sim::{
    real_time_turn, run_cmd, stdout, summary_count, SimDevice, CONSTANT, TCP_CONFIG,
};

const RATE_HZ: f64 = 100.0;

/// Most a logged V_P may lag the offline sample it matches, slots (see the module
/// documentation).
const MAX_LAG: usize = 30;
/// Half a per-mille position step, %.
const HALF_STEP: f64 = 0.05 + 1e-9;

#[derive(Debug, serde::Deserialize)]
struct Row {
    t_s: f64,
    op_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
    latency_us: Option<f64>,
}

/// A 3 s recording: 40 %, 60 %, 30 %, one second each (the device starts at rest at 0 %).
fn write_recording(dir: &Path) -> PathBuf {
    let t: Vec<f64> = (0..300).map(|k| k as f64 / RATE_HZ).collect();
    let op: Vec<f64> = t
        .iter()
        .map(|&t| match t {
            t if t < 1.0 => 40.0,
            t if t < 2.0 => 60.0,
            _ => 30.0,
        })
        .collect();
    let path = dir.join("steps.csv");
    recording::write_columns(&path, &["t_s", "op_pct"], &[&t, &op]).unwrap();
    path
}

/// The `[source]` tables that replay `rec`.
fn replay(rec: &Path) -> String {
    format!(
        "[source]\nkind = \"replay\"\n[source.replay]\nfile = \"{}\"\n",
        rec.display()
    )
}

/// One row per slot on the 10 ms grid, plus the stop action's row. The stop action takes the
/// first slot that runs after the last: `slots` itself, or a later one where a stalled machine
/// made the loop miss the slots at the end (those are not logged, the run is over).
fn assert_grid(rows: &[Row], slots: usize) {
    assert_eq!(
        rows.len(),
        slots + 1,
        "one row per slot and the stop action"
    );
    for (k, r) in rows[..slots].iter().enumerate() {
        assert!(
            (r.t_s - k as f64 / RATE_HZ).abs() < 1e-6,
            "row {k} at {}",
            r.t_s
        );
    }
    let stop = &rows[slots];
    let stop_slot = stop.t_s * RATE_HZ;
    assert!(
        (stop_slot - stop_slot.round()).abs() < 1e-4 && stop_slot.round() as usize >= slots,
        "stop action's row at {} s",
        stop.t_s
    );
    assert_eq!(stop.status, "safe-hold");
}

/// [`assert_grid`], and the rhythm kept: every slot ran but those the summary counts as missed,
/// which a machine stalled for longer than a period may cost (`skipped` rows: O_P kept, no V_P)
/// and which stay rare. Timing figures themselves are measured by the loop bench, not here.
fn assert_rhythm(rows: &[Row], slots: usize, summary: &str) -> Counts {
    assert_grid(rows, slots);
    let n = counts(rows, slots, summary);
    assert!(
        n.skipped * 20 <= slots,
        "{} of {slots} slots missed: the loop lost its rhythm\n{summary}",
        n.skipped
    );
    for (k, r) in rows[..slots].iter().enumerate() {
        assert!(r.op_pct.is_some(), "row {k} has no O_P");
        if r.status == "skipped" {
            assert_eq!(r.vp_pct, None, "row {k}: a missed slot with a V_P");
        }
    }
    n
}

/// The rows whose logged V_P matches no offline sample of slots k-MAX_LAG..=k at or after the
/// sample the previous row matched, with the smallest distance to those samples, % (see the
/// module documentation).
fn misses(rows: &[Row]) -> Vec<(usize, f64)> {
    let op: Vec<f64> = rows
        .iter()
        .map(|r| (r.op_pct.unwrap() * 10.0).round() / 10.0)
        .collect();
    let spec = bundled(ModelKind::Pincart2);
    let tolerance_pct = HALF_STEP + composed::get(&spec, Knob::Slew) / RATE_HZ;
    let mut valve = Valve::new(&spec, 1.0 / RATE_HZ).unwrap();
    // sim-device's valve rests at 0 % with a 0 % set-point until the first write: the offline
    // series starts with that rest so that slot k's sample is `offline[k + MAX_LAG]`.
    valve.reset(0.0, 0.0);
    let offline: Vec<f64> = std::iter::repeat_n(0.0, MAX_LAG)
        .chain(op.iter().map(|&o| valve.step(o)))
        .collect();
    // The earliest sample that still matches keeps every later row the most samples to match
    // (the allowed samples of each row form an interval), so matching greedily finds an
    // alignment whenever one exists.
    let mut matched = 0;
    let mut out = Vec::new();
    for (k, r) in rows.iter().enumerate() {
        // A missed slot or a timeout read nothing; every other row holds a V_P.
        let Some(vp) = r.vp_pct else {
            assert!(
                r.status == "skipped" || r.status == "timeout",
                "row {k} has no V_P"
            );
            continue;
        };
        let first = matched.max(k);
        let distance = |j: usize| (offline[j] - vp).abs();
        match (first..=k + MAX_LAG).find(|&j| distance(j) <= tolerance_pct) {
            Some(j) => matched = j,
            None => {
                let nearest = (first..=k + MAX_LAG)
                    .map(distance)
                    .fold(f64::INFINITY, f64::min);
                out.push((k, nearest));
            }
        }
    }
    out
}

fn replay_follows_model(device_args: &[&str]) {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let rec = write_recording(dir.path());
    let dev = SimDevice::start(device_args);
    let cfg = dev.config(dir.path(), &[], &replay(&rec));
    let logs = dir.path().join("logs");
    let out = run_cmd(&cfg, &logs, 3.0).output().unwrap();
    let summary = stdout(&out);
    assert!(summary.contains("reconnects: 0"), "{summary}");
    let rows: Vec<Row> = common::sim::read_log(&logs);
    let n = assert_rhythm(&rows, 300, &summary);
    // A machine stalled for longer than the 8 ms deadline costs a cycle its reply (a timeout
    // row, no V_P); the deadline itself is tested below. Every other slot that ran read a V_P.
    assert!(
        n.ok + n.skipped + n.timeout == 300 && n.timeout * 50 <= 300,
        "every slot that ran read a V_P but a rare timeout\n{summary}"
    );
    // The valve really moved: up at its 20 %/s slew rate past 30 %, then back down after the
    // last step's reversal.
    let vp: Vec<f64> = rows[..300].iter().filter_map(|r| r.vp_pct).collect();
    let peak = vp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(peak > 30.0 && vp[vp.len() - 1] < peak - 1.0, "{summary}");
    let missed = misses(&rows);
    assert!(
        missed.is_empty(),
        "V_P matching no offline sample of the last 300 ms in time order (row, nearest %): \
         {missed:?}"
    );
}

#[test]
fn tcp_replay_follows_the_model() {
    replay_follows_model(&["--tcp", "127.0.0.1:0"]);
}

#[test]
fn rtu_over_a_pty_replay_follows_the_model() {
    replay_follows_model(&["--pty"]);
}

#[test]
fn device_killed_and_restarted_keeps_the_rhythm_and_reconnects() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let rec = write_recording(dir.path());
    let mut dev = SimDevice::start(&["--tcp", "127.0.0.1:0"]);
    let addr = dev.endpoint.clone();
    let cfg = dev.config(dir.path(), &[], &replay(&rec));
    let logs = dir.path().join("logs");
    let daemon = run_cmd(&cfg, &logs, 3.0)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1000));
    dev.kill();
    // The daemon retries at once, then after 0.1, 0.2, 0.4 and 0.8 s (its backoff doubles): a
    // device back 0.5 s after the kill is 0.2 s clear of the attempts at 0.3 and 0.7 s, so the
    // link is back at 0.7 s however long the device takes to start (within 0.2 s). Back at
    // 0.7 s, it raced the attempt then and lost it on a loaded machine (next one at 1.5 s).
    std::thread::sleep(Duration::from_millis(500));
    let _restarted = SimDevice::start(&["--tcp", &addr]);
    let summary = stdout(&daemon.wait_with_output().unwrap());
    let rows: Vec<Row> = common::sim::read_log(&logs);
    let n = assert_rhythm(&rows, 300, &summary);
    assert_eq!(n.error, 0, "{summary}");
    let failed: Vec<&Row> = rows
        .iter()
        .filter(|r| r.status == "timeout" || r.status == "disconnected")
        .collect();
    assert!(
        failed.len() >= 50,
        "{} failed rows\n{summary}",
        failed.len()
    );
    assert!(failed
        .iter()
        .all(|r| r.vp_pct.is_none() && r.op_pct.is_some()));
    // Ok before the kill, and ok again at the end, after the reconnection: never disconnected,
    // a timeout only where a stalled machine kept a reply past its deadline (rare), and slots
    // a stalled machine missed aside.
    let ran_ok = |rows: &[Row]| {
        let timeouts = rows.iter().filter(|r| r.status == "timeout").count();
        timeouts * 25 <= rows.len()
            && rows
                .iter()
                .all(|r| matches!(r.status.as_str(), "ok" | "skipped" | "timeout"))
    };
    assert!(ran_ok(&rows[..90]), "{summary}");
    assert!(ran_ok(&rows[250..300]), "{summary}");
    assert!(reconnects(&summary) >= 1, "{summary}");
}

/// Cycle rows per status.
#[derive(Debug)]
struct Counts {
    ok: usize,
    timeout: usize,
    error: usize,
    disconnected: usize,
    skipped: usize,
}

impl Counts {
    /// Cycles that sent a request: all but the missed slots.
    fn sent(&self) -> usize {
        self.ok + self.timeout + self.error + self.disconnected
    }
}

/// The statuses of the first `slots` rows, checked against the summary's `samples:` and
/// `missed cycles:` lines: the summary counts exactly the rows the log holds.
fn counts(rows: &[Row], slots: usize, summary: &str) -> Counts {
    let n = |s: &str| rows[..slots].iter().filter(|r| r.status == s).count();
    let c = Counts {
        ok: n("ok"),
        timeout: n("timeout"),
        error: n("error"),
        disconnected: n("disconnected"),
        skipped: n("skipped"),
    };
    assert_eq!(
        c.ok + c.timeout + c.error + c.disconnected + c.skipped,
        slots,
        "unknown statuses in the log"
    );
    for line in [
        format!(
            "samples: {} ({} ok, {} timeout, {} error, {} disconnected)",
            slots - c.skipped,
            c.ok,
            c.timeout,
            c.error,
            c.disconnected
        ),
        format!("missed cycles: {}", c.skipped),
    ] {
        assert!(
            summary.lines().any(|l| l == line),
            "the log rows give `{line}`; summary:\n{summary}"
        );
    }
    c
}

/// The summary's reconnection count.
fn reconnects(summary: &str) -> u64 {
    summary_count(summary, "reconnects: ")
}

/// Slots of a fault run (2 s at 100 Hz).
const FAULT_SLOTS: usize = 200;

/// What a daemon run against a faulty device left: its log rows, its summary and its stderr.
struct FaultRun {
    rows: Vec<Row>,
    summary: String,
    stderr: String,
}

/// Runs the daemon for [`FAULT_SLOTS`] at a constant O_P against sim-device started with
/// `device_args`, its shipped config changed by `edits`. Checks what holds whatever the fault:
/// exit 0 (some cycle read a V_P), one row per slot, O_P in every row, a V_P in exactly the
/// `ok` rows, a plain-text log. A slot missed because the machine is busy is a row too
/// (`skipped`), so the checks on the faults tolerate those; the counts still have to match the
/// summary.
fn fault_run(device_args: &[&str], edits: &[(&str, &str)]) -> FaultRun {
    fault_run_ending(device_args, edits, true)
}

/// [`fault_run`] of a run that succeeds or, with `succeeds` false, must exit 1 because no
/// cycle read a V_P (its summary is printed all the same).
fn fault_run_ending(device_args: &[&str], edits: &[(&str, &str)], succeeds: bool) -> FaultRun {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let dev = SimDevice::start(device_args);
    let cfg = dev.config(dir.path(), edits, CONSTANT);
    let logs = dir.path().join("logs");
    let out = run_cmd(&cfg, &logs, FAULT_SLOTS as f64 / RATE_HZ)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let summary = if succeeds {
        stdout(&out)
    } else {
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let rows: Vec<Row> = common::sim::read_log(&logs);
    assert_grid(&rows, FAULT_SLOTS);
    for (k, r) in rows[..FAULT_SLOTS].iter().enumerate() {
        assert_eq!(r.op_pct, Some(40.0), "row {k}");
        assert_eq!(
            r.vp_pct.is_some(),
            r.status == "ok",
            "row {k}: {} with V_P {:?}",
            r.status,
            r.vp_pct
        );
    }
    assert!(
        !stderr.contains('\u{1b}'),
        "colour codes in a log that is not a terminal:\n{stderr}"
    );
    common::assert_for_people(&stderr);
    common::assert_for_people(&summary);
    FaultRun {
        rows,
        summary,
        stderr,
    }
}

/// True if every failed cycle costs only itself: the next cycle that runs (a slot missed on a
/// busy machine aside) is `ok`.
fn costs_one_cycle(rows: &[Row]) -> bool {
    let ran: Vec<&Row> = rows[..FAULT_SLOTS]
        .iter()
        .filter(|r| r.status != "skipped")
        .collect();
    ran.windows(2)
        .all(|w| w[0].status == "ok" || w[1].status == "ok")
}

#[test]
fn corrupted_crc_on_the_pty_gives_error_rows_and_keeps_the_port() {
    let f = fault_run(&["--pty", "--corrupt-crc-every", "10"], &[]);
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    // Every 10th reply is corrupted, one request per cycle that ran: a bad reply costs its own
    // cycle, so one cycle in 10 is an error (or a timeout, when a busy machine let the
    // corrupted reply arrive late) and the others are ok.
    let tenth = n.sent() / 10;
    assert!(
        n.error <= tenth + 1 && n.error + n.timeout + 1 >= tenth,
        "{}",
        f.summary
    );
    assert!(
        n.ok + n.error + n.skipped + n.timeout == FAULT_SLOTS,
        "{}",
        f.summary
    );
    assert!(n.ok >= FAULT_SLOTS * 3 / 4, "{}", f.summary);
    // The port stays open: its input is emptied before each request.
    assert_eq!(reconnects(&f.summary), 0, "{}", f.summary);
    assert!(costs_one_cycle(&f.rows), "{}", f.summary);
    assert!(
        f.stderr
            .contains("valve transaction failed: error: CRC error in reply to FC 23"),
        "{}",
        f.stderr
    );
    assert!(
        !f.stderr.contains("Failed to decode response frame"),
        "tokio-modbus's per-frame warnings are off by default:\n{}",
        f.stderr
    );
    assert_eq!(
        f.stderr.matches("bus budget: ").count(),
        1,
        "the bus budget is logged once:\n{}",
        f.stderr
    );
}

#[test]
fn dropped_replies_time_out_and_keep_the_link() {
    let f = fault_run(&["--tcp", "127.0.0.1:0", "--drop-every", "25"], &[]);
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    let dropped = n.sent() / 25;
    assert!(
        (dropped - 1..=dropped + 1).contains(&n.timeout),
        "{}",
        f.summary
    );
    assert_eq!(n.error, 0, "{}", f.summary);
    assert_eq!(reconnects(&f.summary), 0, "{}", f.summary);
    // A lost reply costs its own cycle: the next one is ok.
    assert!(costs_one_cycle(&f.rows), "{}", f.summary);
    for want in [
        "valve transaction failed: timeout: no reply to FC 23 within 8 ms",
        "valve transactions succeed again",
    ] {
        assert!(f.stderr.contains(want), "no `{want}` in\n{}", f.stderr);
    }
}

#[test]
fn replies_later_than_the_deadline_time_out_and_the_run_fails() {
    // 20 ms late against the 8 ms deadline: no cycle succeeds, none waits past its deadline by
    // much, the one connection is kept (the late replies are dropped by transaction id), and
    // the run exits 1 saying why.
    let f = fault_run_ending(&["--tcp", "127.0.0.1:0", "--delay-ms", "20"], &[], false);
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    assert_eq!((n.ok, n.error, n.disconnected), (0, 0, 0), "{}", f.summary);
    assert!(n.timeout >= FAULT_SLOTS * 9 / 10, "{}", f.summary);
    for r in f.rows.iter().filter(|r| r.status == "timeout") {
        assert!(r.latency_us.unwrap() >= 8000.0, "{:?}", r.latency_us);
    }
    assert_eq!(reconnects(&f.summary), 0, "{}", f.summary);
    assert!(
        f.summary
            .contains("stop action: safe-hold O_P 40.00 %: sent, not confirmed by the valve (timeout: no reply to FC 23 within 8 ms"),
        "{}",
        f.summary
    );
    assert!(
        f.summary
            .contains("last timeout: no reply to FC 23 within 8 ms"),
        "{}",
        f.summary
    );
    let last = f.stderr.lines().last().unwrap_or("");
    assert!(
        last.starts_with(&format!(
            "valve-bridge: error: no cycle read a V_P: all {} failed ({} timeout); the last was \
             timeout: no reply to FC 23 within 8 ms",
            n.timeout, n.timeout
        )),
        "{}",
        f.stderr
    );
}

#[test]
fn replies_within_the_deadline_are_ok() {
    // 2 ms late against a 9.5 ms deadline: the cycles succeed (a busy machine may still delay a
    // few past the deadline), and each took at least the delay.
    let f = fault_run(
        &["--tcp", "127.0.0.1:0", "--delay-ms", "2"],
        &[("timeout_ms = 8.0", "timeout_ms = 9.5")],
    );
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    assert!(n.ok >= FAULT_SLOTS * 9 / 10, "{}", f.summary);
    assert_eq!(n.error, 0, "{}", f.summary);
    for r in f.rows.iter().filter(|r| r.status == "ok") {
        assert!(r.latency_us.unwrap() >= 2000.0, "{:?}", r.latency_us);
    }
}

#[test]
fn a_byte_too_many_costs_its_own_cycle_and_keeps_the_link() {
    let f = fault_run(
        &["--tcp", "127.0.0.1:0", "--bad-byte-count-every", "2"],
        &[],
    );
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    // Every second reply is malformed: half the cycles fail, each on its own.
    assert!((90..=110).contains(&n.error), "{}", f.summary);
    assert_eq!(n.disconnected, 0, "{}", f.summary);
    assert_eq!(reconnects(&f.summary), 0, "{}", f.summary);
    assert!(
        f.summary.contains("(1 connection attempt)"),
        "{}",
        f.summary
    );
    assert!(costs_one_cycle(&f.rows), "{}", f.summary);
    assert!(
        f.summary
            .contains("last error: malformed reply to FC 23: byte count 5, 4 expected"),
        "{}",
        f.summary
    );
}

#[test]
fn broken_frames_back_off_by_their_rate() {
    // Every second reply breaks the MBAP framing: the stream is out of step and reopened, but
    // not at once each time (the device answers well between): about 10 connections in 2 s,
    // not one per two cycles.
    let f = fault_run(&["--tcp", "127.0.0.1:0", "--broken-frame-every", "2"], &[]);
    let reopened = reconnects(&f.summary);
    assert!((1..=11).contains(&reopened), "{}", f.summary);
    assert!(
        f.stderr
            .contains("times in the last 5 s (the last time: FC 23: ")
            && f.stderr.contains("next connection in"),
        "{}",
        f.stderr
    );
}

#[test]
fn exception_replies_are_error_rows_and_keep_the_link() {
    let f = fault_run(&["--tcp", "127.0.0.1:0", "--exception-every", "10"], &[]);
    let n = counts(&f.rows, FAULT_SLOTS, &f.summary);
    assert!(n.error >= FAULT_SLOTS / 20, "{}", f.summary);
    // One request per cycle, and an exception keeps the link: exactly the cycles of requests
    // 10, 20, ... fail. A slot a busy machine missed sent no request; after a timeout the
    // device may or may not have counted the request, so the count picks up again at the next
    // exception.
    let (mut request, mut checked) = (None, 0);
    for (k, r) in f.rows[..FAULT_SLOTS].iter().enumerate() {
        match (r.status.as_str(), request) {
            ("skipped", _) => {}
            ("ok" | "error", Some(q)) => {
                let q: u32 = q + 1;
                let want = if q.is_multiple_of(10) { "error" } else { "ok" };
                assert_eq!(r.status, want, "row {k}\n{}", f.summary);
                request = Some(q);
                checked += 1;
            }
            ("error", None) => request = Some(0),
            ("ok", None) => {}
            _ => request = None,
        }
    }
    assert!(
        checked >= FAULT_SLOTS / 2,
        "only {checked} cycles in step with the device's count\n{}",
        f.summary
    );
    // Only a timeout (a busy machine) drops the link, never an exception.
    assert!(reconnects(&f.summary) <= n.timeout as u64, "{}", f.summary);
    for k in 0..FAULT_SLOTS - 1 {
        if f.rows[k].status == "error" {
            assert_ne!(f.rows[k + 1].status, "disconnected", "row {}", k + 1);
        }
    }
    assert!(
        f.stderr.contains(
            "valve transaction failed: error: device answered FC 23 with exception 04 (server \
             device failure"
        ),
        "{}",
        f.stderr
    );
}

#[test]
fn runs_where_no_cycle_reads_a_v_p_fail_naming_the_cause() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    // The map asks for a status register the device does not have: every cycle an exception.
    let dev = SimDevice::start_bare(&["--tcp", "127.0.0.1:0"], TCP_CONFIG);
    let cfg = dev.config(
        dir.path(),
        &[(
            "address = 2, setpoint_error_bit",
            "address = 9, setpoint_error_bit",
        )],
        CONSTANT,
    );
    let out = run_cmd(&cfg, &dir.path().join("logs"), 0.5)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let last = stderr.lines().last().unwrap_or("");
    assert!(
        last.starts_with("valve-bridge: error: no cycle read a V_P: all ")
            && last.contains(
                " error); the last was error: device answered FC 23 with exception 02 (illegal \
                 data address: the device has no such register; check the addresses and tables \
                 in [valve.registers]"
            ),
        "{stderr}"
    );
    assert!(
        String::from_utf8_lossy(&out.stdout).contains(" (0 ok, 0 timeout, "),
        "the summary is printed first"
    );
    // Nobody listening: every cycle disconnected, the refused connection named.
    let (addr, cfg, _port) = common::sim::nobody_listening(dir.path(), CONSTANT);
    let out = run_cmd(&cfg, &dir.path().join("logs2"), 0.5)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    let last = stderr.lines().last().unwrap_or("");
    assert!(
        last.starts_with(
            "valve-bridge: error: no cycle read a V_P: all 50 failed (50 disconnected)"
        ) && last.contains(&format!(
            "Modbus TCP {addr} unit 1: cannot connect: Connection refused"
        )),
        "{stderr}"
    );
}
