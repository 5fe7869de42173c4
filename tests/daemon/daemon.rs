//! End-to-end tests of `valve-bridge run` through the real binary, with no hardware.
//!
//! - the default config (no `--config`) runs in real time and logs one row per 10 ms slot;
//! - a recording's O_P replayed on the virtual clock through the emulated pin-cart II gives, row
//!   for row, exactly the V_P of an offline simulation of the same model on the same O_P;
//! - SIGTERM mid-run stops cleanly: complete log, safe action applied and logged, exit 0;
//! - bad configs fail with one line naming the file, line and key.
//!
//! `tests/data/daemon/normal_op_30s.csv` is the first 30 s of a 100 Hz closed-loop recording
//! (backlash case of the shared test cases).

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use valve_bridge::model::{bundled, ModelKind, Valve};
use valve_bridge::recording::{self, ReadOptions};

use crate::common;

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");
const REPLAY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/tests/data/daemon/normal_op_30s.csv"
);

/// One row of a daemon log.
#[derive(Debug, serde::Deserialize)]
struct Row {
    t_s: f64,
    op_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
    lateness_us: Option<f64>,
    latency_us: Option<f64>,
    op_sent_pct: Option<f64>,
    utc: String,
    op_controller_pct: Option<f64>,
}

fn read_log(path: &Path) -> Vec<Row> {
    let mut r = csv::Reader::from_path(path).unwrap();
    let header: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(
        header,
        [
            "t_s",
            "op_pct",
            "vp_pct",
            "status",
            "lateness_us",
            "latency_us",
            "op_sent_pct",
            "utc",
            "op_controller_pct"
        ]
    );
    r.deserialize().map(|row| row.unwrap()).collect()
}

/// The only log file in `dir`.
fn only_log(dir: &Path) -> PathBuf {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    files.into_iter().next().unwrap()
}

fn run(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .arg("run")
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Checks the cycles' slots are 0, 1, 2, ... on the 100 Hz grid, and the stop action's row on
/// the grid after them.
fn assert_on_grid(rows: &[Row]) {
    let (stop, cycles) = rows.split_last().unwrap();
    for (k, row) in cycles.iter().enumerate() {
        assert_eq!(row.t_s, k as f64 / 100.0, "row {k}");
    }
    // The stop action takes the first slot that runs after the last cycle: the next one, or a
    // later one where a stalled machine made the loop miss the slots in between (not logged,
    // the run is over).
    let slot = stop.t_s * 100.0;
    assert!(
        (slot - slot.round()).abs() < 1e-6 && slot.round() as usize >= cycles.len(),
        "stop action's row at {} s",
        stop.t_s
    );
}

#[test]
fn default_config_runs_in_real_time_with_one_row_per_slot() {
    let dir = tempfile::tempdir().unwrap();
    let started = Instant::now();
    let out = run(&["--duration", "2"], dir.path());
    let took = started.elapsed();
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(took >= Duration::from_secs(2), "real time: {took:?}");
    let stdout = text(&out.stdout);
    assert!(
        stdout.contains("run: 200 slots at 100 Hz (2.00 s), stopped: duration reached"),
        "{stdout}"
    );
    assert!(
        stdout.contains("timing error |actual - scheduled|: p50"),
        "{stdout}"
    );
    assert!(stdout.contains("stop action: safe-hold"), "{stdout}");

    // The embedded default logs to ./logs/ under the working directory.
    let log = only_log(&dir.path().join("logs"));
    let name = log.file_name().unwrap().to_string_lossy().into_owned();
    assert!(
        name.starts_with("vb-20") && name.ends_with("Z.csv"),
        "{name}"
    );
    let rows = read_log(&log);
    assert_eq!(rows.len(), 201, "200 slots and the stop action");
    // Random steps, pin-cart II: numbers at a fixed precision, no float artefacts.
    common::assert_for_people(&std::fs::read_to_string(&log).unwrap());
    common::assert_for_people(&stdout);
    assert_on_grid(&rows);
    let (cycles, safe) = rows.split_at(200);
    // Every slot ran but those a stalled machine made the loop miss, which the summary counts.
    let missed = cycles.iter().filter(|r| r.status == "skipped").count();
    // A loaded machine stalls the loop now and then; a tenth of the slots missed is not real time.
    assert!(missed <= 20, "{missed} missed cycles in 2 s");
    let ran = 200 - missed;
    for line in [
        format!("samples: {ran} ({ran} ok, 0 timeout, 0 error, 0 disconnected)"),
        format!("missed cycles: {missed}"),
    ] {
        assert!(stdout.contains(&line), "{line}\n{stdout}");
    }
    for r in cycles.iter().filter(|r| r.status == "ok") {
        let (op, vp) = (r.op_pct.unwrap(), r.vp_pct.unwrap());
        assert!((20.0..=97.0).contains(&op), "random steps in 20-97 %: {op}");
        assert!((0.0..=100.0).contains(&vp));
        assert!(r.lateness_us.unwrap() >= 0.0 && r.latency_us.unwrap() >= 0.0);
    }
    assert_eq!(safe[0].status, "safe-hold");
    let last_sent = cycles.iter().rev().find(|r| r.status == "ok").unwrap();
    assert_eq!(
        safe[0].op_pct, last_sent.op_pct,
        "hold sends the last O_P again"
    );
    // The emulated valve starts at rest at the first O_P.
    assert_eq!(rows[0].vp_pct, rows[0].op_pct);
}

#[test]
fn replayed_recording_matches_offline_simulation_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("replay.toml");
    std::fs::write(
        &config,
        format!("[loop]\nclock = \"virtual\"\n\n[source]\nkind = \"replay\"\n\n[source.replay]\nfile = \"{REPLAY}\"\n"),
    )
    .unwrap();
    let logs = dir.path().join("out");
    let out = run(
        &[
            "--config",
            config.to_str().unwrap(),
            "--log-dir",
            logs.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        text(&out.stdout).contains("stopped: source ended"),
        "{}",
        text(&out.stdout)
    );

    let mut rec = csv::Reader::from_path(REPLAY).unwrap();
    let rec_op: Vec<f64> = rec
        .records()
        .map(|r| r.unwrap()[1].parse().unwrap())
        .collect();
    let log = only_log(&logs);
    let rows = read_log(&log);
    // One row per recorded sample, then the stop action (hold: the last O_P once more).
    assert_eq!(rows.len(), rec_op.len() + 1);
    assert_on_grid(&rows);
    assert!(rows[..rec_op.len()].iter().all(|r| r.status == "ok"));
    assert_eq!(rows.last().unwrap().status, "safe-hold");
    // The emulated valve gets O_P itself (no compensation: the controller's O_P); every row
    // has its UTC time, 10 ms apart.
    for r in &rows {
        assert_eq!(r.op_sent_pct, r.op_pct);
        assert_eq!(r.op_controller_pct, r.op_pct);
    }
    let ms = |r: &Row| -> i64 {
        let t = time::PrimitiveDateTime::parse(
            r.utc.trim_end_matches('Z'),
            time::macros::format_description!(
                "[year]-[month]-[day]T[hour]:[minute]:[second].[subsecond digits:3]"
            ),
        )
        .unwrap_or_else(|e| panic!("utc {:?}: {e}", r.utc));
        (t.assume_utc().unix_timestamp_nanos() / 1_000_000) as i64
    };
    assert_eq!(ms(&rows[500]) - ms(&rows[0]), 5000, "utc follows the grid");
    // Read back with the recording reader: O_P round-trips exactly.
    let logged = recording::read(&log, &ReadOptions::default()).unwrap();
    let (op, vp) = (logged.op, logged.vp);
    assert_eq!(op.len(), rows.len());
    assert_eq!(
        &op[..rec_op.len()],
        &rec_op[..],
        "the replayed O_P is the recording's"
    );

    // Offline: the same model on the same O_P, from rest at the first O_P. Same code, same
    // inputs, so the match is exact to the log's precision (V_P is written to 0.0001 %).
    let want = Valve::new(&bundled(ModelKind::Pincart2), 0.01)
        .unwrap()
        .simulate(&op, op[0]);
    assert_eq!(vp.len(), want.len());
    for (k, (v, w)) in vp.iter().zip(&want).enumerate() {
        assert!(
            (v - w).abs() <= 0.5e-4 + 1e-12,
            "row {k}: logged {v}, offline {w}"
        );
    }
    assert!(
        vp.windows(2).filter(|w| w[0] != w[1]).count() > 100,
        "the valve moved"
    );

    // And through `valve-bridge simulate` on the log itself.
    let sim = dir.path().join("sim.csv");
    let model = concat!(env!("CARGO_MANIFEST_DIR"), "/config/models/pincart2.toml");
    let out = Command::new(BIN)
        .args(["simulate", "--model", model, "--input"])
        .arg(&log)
        .arg("--out")
        .arg(&sim)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let mut r = csv::Reader::from_path(&sim).unwrap();
    let sim_vp: Vec<f64> = r
        .records()
        .map(|r| r.unwrap()[2].parse().unwrap())
        .collect();
    // `simulate` takes its sample period from the file's timestamps (the median interval,
    // 0.01 s give or take 1e-17 s of decimal rounding), not the loop's exact 0.01 s; the model's
    // per-sample constants then differ in the last bits (observed: < 1e-13 %); the logged V_P
    // is rounded to 0.0001 %.
    assert_eq!(sim_vp.len(), vp.len());
    let worst = sim_vp
        .iter()
        .zip(&vp)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 0.5e-4 + 1e-9, "simulate differs by {worst} %");
}

/// A machine that stalls the loop around the end of a run makes its stop action take a later
/// slot; the run still had the slots its duration gives, and the summary says so. The stall
/// (SIGSTOP for 60 ms) is swept across the end, so one of the runs stalls right at it.
#[test]
fn a_stall_at_the_end_of_a_run_does_not_add_slots_to_it() {
    for offset_ms in (1950..=2150).step_by(40) {
        let dir = tempfile::tempdir().unwrap();
        let child = Command::new(BIN)
            .args(["run", "--duration", "2"])
            .current_dir(dir.path())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(offset_ms));
        let stopped = common::signal(&child, libc::SIGSTOP);
        std::thread::sleep(Duration::from_millis(60));
        assert!(!stopped || common::signal(&child, libc::SIGCONT));
        let out = child.wait_with_output().unwrap();
        assert!(out.status.success(), "{}", text(&out.stderr));
        let stdout = text(&out.stdout);
        assert!(
            stdout.contains("run: 200 slots at 100 Hz (2.00 s), stopped: duration reached"),
            "stalled at {offset_ms} ms: {stdout}"
        );
        let rows = read_log(&only_log(&dir.path().join("logs")));
        assert_eq!(rows.len(), 201, "stalled at {offset_ms} ms");
        assert_on_grid(&rows);
    }
}

#[test]
fn sigterm_stops_cleanly_with_the_safe_action_logged() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("goto.toml");
    std::fs::write(
        &config,
        "[safety]\non_stop = \"go-to\"\ngo_to_pct = 5.0\n\n[log]\nflush_interval_ms = 100\n",
    )
    .unwrap();
    let logs = dir.path().join("logs");
    let child = Command::new(BIN)
        .args([
            "run",
            "--config",
            config.to_str().unwrap(),
            "--log-dir",
            logs.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until at least 50 rows are on disk.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let rows = std::fs::read_dir(&logs)
            .ok()
            .and_then(|mut d| d.next())
            .and_then(|e| std::fs::read_to_string(e.ok()?.path()).ok())
            .map_or(0, |t| t.lines().count());
        if rows > 50 {
            break;
        }
        assert!(Instant::now() < deadline, "no log rows after 20 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(common::signal(&child, libc::SIGTERM));
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status,
        text(&out.stderr)
    );
    let stdout = text(&out.stdout);
    assert!(stdout.contains("stopped: stop requested"), "{stdout}");
    assert!(
        stdout.contains("stop action: safe-go-to O_P 5.00 %"),
        "{stdout}"
    );
    assert!(
        text(&out.stderr).contains("SIGTERM"),
        "{}",
        text(&out.stderr)
    );

    let log = only_log(&logs);
    let rows = read_log(&log);
    assert!(rows.len() > 50);
    assert_on_grid(&rows);
    let (last, cycles) = rows.split_last().unwrap();
    assert_eq!(last.status, "safe-go-to");
    assert_eq!(last.op_pct, Some(5.0));
    assert!(last.vp_pct.is_some());
    assert!(cycles
        .iter()
        .all(|r| r.status == "ok" || r.status == "skipped"));

    // The recording reader loads the log on its grid: every row, without V_P where none was read.
    let opts = ReadOptions::default();
    let rec = recording::read(&log, &opts).unwrap();
    let with_vp = rows.iter().filter(|r| r.vp_pct.is_some()).count();
    assert_eq!(rec.len(), rows.len());
    assert_eq!(rec.vp.iter().filter(|v| v.is_finite()).count(), with_vp);
    assert_eq!(rec.vp.last(), last.vp_pct.as_ref());
    assert!((rec.sample_period - 0.01).abs() < 1e-12);

    // A log cut mid-line by a crash still loads, without the cut row.
    let text = std::fs::read_to_string(&log).unwrap();
    let cut = text.len() - last_line_len(&text) / 2 - 1;
    let cut_log = dir.path().join("cut.csv");
    std::fs::write(&cut_log, &text[..cut]).unwrap();
    let rec = recording::read(&cut_log, &opts).unwrap();
    assert_eq!(rec.len(), rows.len() - 1);
    assert!(
        rec.warnings.iter().any(|w| w.contains("cut off")),
        "{:?}",
        rec.warnings
    );
}

/// Length of the last line of `text`, without its newline.
fn last_line_len(text: &str) -> usize {
    text.trim_end_matches('\n')
        .rsplit('\n')
        .next()
        .map_or(0, str::len)
}

#[test]
fn bad_configs_fail_with_one_line_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "[loop]\nrate_hz = 100.0\nrate = 5\n",
            "bad.toml:3: loop.rate: unknown field `rate`",
        ),
        (
            "[loop]\nrate_hz = \"fast\"\n",
            "bad.toml:2: loop.rate_hz: invalid type: string \"fast\", expected f64",
        ),
        (
            "[loop]\nrate_hz = 20000.0\n",
            "bad.toml:2: loop.rate_hz: 20000 is out of range: a loop rate in Hz, 1 to 1000",
        ),
        (
            "[valve]\nkind = \"emulated\"\n\n[valve.emulated]\nmodel_file = \"missing.toml\"\n",
            "bad.toml:5: valve.emulated.model_file: cannot use model file `missing.toml`",
        ),
    ];
    for (toml, want) in cases {
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, toml).unwrap();
        let out = run(&["--config", "bad.toml", "--duration", "1"], dir.path());
        assert_eq!(out.status.code(), Some(1), "{toml}");
        let stderr = text(&out.stderr);
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            stderr.starts_with(&format!("valve-bridge: error: {want}")),
            "{stderr}"
        );
        assert!(
            !dir.path().join("logs").exists(),
            "nothing runs on a bad config"
        );
    }
}

#[test]
fn a_missing_config_file_names_each_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["--config", "no-such.toml", "--duration", "1"], dir.path());
    assert_eq!(out.status.code(), Some(1));
    let stderr = text(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("valve-bridge: error: no-such.toml: cannot read: No such file"),
        "{stderr}"
    );
    assert_eq!(stderr.matches("os error 2").count(), 1, "{stderr}");
}

#[test]
fn a_closed_stdout_loses_only_the_printed_summary() {
    // Whoever reads stdout goes away before the summary comes: the run still ends cleanly
    // (exit 0, no panic) and puts the summary in its log on stderr instead.
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(BIN)
        .args([
            "run",
            "--as-fast-as-possible",
            "--duration",
            "2",
            "--log-dir",
        ])
        .arg(dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("summary not printed on stdout"), "{stderr}");
}

/// The peak resident memory of `valve-bridge run ARGS` (in `cwd`), KiB.
fn peak_rss_kib(args: &[&str], cwd: &Path) -> i64 {
    let mut cmd = Command::new(BIN);
    cmd.arg("run").args(args).current_dir(cwd);
    let run = common::run_watched(&mut cmd, i64::MAX, Duration::from_secs(3600));
    assert_eq!(run.code, Some(0), "{}", run.stderr);
    run.peak_kib
}

#[test]
fn memory_stays_flat_on_the_virtual_clock_however_long_the_run() {
    // The loop produces rows far faster than the logger writes them: its queue is bounded, so
    // ten times the run takes no more memory (it was 37 MB more per simulated hour).
    let dir = tempfile::tempdir().unwrap();
    let run = |secs: &str, sub: &str| {
        let logs = dir.path().join(sub);
        let logs = logs.to_str().unwrap();
        let args = [
            "--as-fast-as-possible",
            "--duration",
            secs,
            "--log-dir",
            logs,
        ];
        peak_rss_kib(&args, dir.path())
    };
    let short = run("600", "short");
    let long = run("6000", "long");
    assert!(
        long < short + 4096,
        "{short} KiB for 600 s, {long} KiB for 6000 s"
    );
}
