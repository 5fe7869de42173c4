//! `valve-bridge run` against `sim-device` over real Modbus, through both real binaries.
//!
//! - TCP and RTU (a pseudo-terminal): a short recording's O_P is replayed for 3 s at 100 Hz; the
//!   log has one row per slot and the logged V_P follows an offline simulation of sim-device's
//!   model (pin-cart II) on the same O_P;
//! - sim-device killed mid-run and restarted on the same port: the loop keeps its rhythm, logs
//!   `timeout`/`disconnected` rows with an empty V_P, reconnects, exits 0 and counts it all.
//!
//! sim-device is the workspace's other binary: `cargo test --workspace` builds it into the same
//! directory as `valve-bridge` (its own integration tests need it); with `cargo test -p
//! valve-bridge` alone run `cargo build -p sim-device` first.
//!
//! Tolerance of the comparison: sim-device steps its model on its own 100 Hz clock and the loop
//! reads the last stepped position, so a logged V_P lags the offline sample of the same slot by
//! one to two steps and the phase between the two clocks drifts (a few samples of jitter). A
//! logged V_P must therefore lie within the range the offline V_P covers over the slots k-4..=k,
//! widened by half a register step (positions are per-mille, 0.05 %). O_P is quantised to the
//! set-point register (0.1 %) before the offline simulation, as the device sees it.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use valve_bridge::model::{bundled, ModelKind, Valve};
use valve_bridge::recording;

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");
const RATE_HZ: f64 = 100.0;

/// Phase window of the comparison, samples (see the module documentation).
const LAG_WINDOW: usize = 4;
/// Half a per-mille position step, %.
const HALF_STEP: f64 = 0.05 + 1e-9;

#[derive(Debug, serde::Deserialize)]
struct Row {
    t_s: f64,
    op_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
}

/// The sim-device binary, next to valve-bridge.
fn sim_device_bin() -> PathBuf {
    let p = Path::new(BIN).with_file_name("sim-device");
    assert!(
        p.exists(),
        "{} not built: run `cargo test --workspace` (or `cargo build -p sim-device`)",
        p.display()
    );
    p
}

/// A running sim-device and the endpoint it printed (`tcp: ADDR` or `pty: PATH`).
struct SimDevice {
    child: Child,
    endpoint: String,
}

impl SimDevice {
    fn start(args: &[&str]) -> SimDevice {
        let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(if args.contains(&"--pty") {
            "config/sim-device-rtu.toml"
        } else {
            "config/sim-device-tcp.toml"
        });
        let mut child = Command::new(sim_device_bin())
            .args(args)
            .arg("--config")
            .arg(config)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let (_, endpoint) = line.trim().split_once(": ").expect("endpoint line");
        SimDevice {
            endpoint: endpoint.to_string(),
            child,
        }
    }

    fn kill(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }
}

impl Drop for SimDevice {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
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

/// A daemon config: the shipped sim-device config with `from` replaced by `to`, replaying `rec`.
fn config(dir: &Path, shipped: &str, from: &str, to: &str, rec: &Path) -> PathBuf {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(shipped))
        .unwrap()
        .replace(from, to);
    assert!(text.contains(to), "{shipped} has no {from}");
    let path = dir.join("daemon.toml");
    std::fs::write(
        &path,
        format!(
            "{text}\n[source]\nkind = \"replay\"\n[source.replay]\nfile = \"{}\"\n",
            rec.display()
        ),
    )
    .unwrap();
    path
}

fn run_cmd(cfg: &Path, log_dir: &Path, duration_s: f64) -> Command {
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--config"])
        .arg(cfg)
        .arg("--duration")
        .arg(duration_s.to_string())
        .arg("--log-dir")
        .arg(log_dir)
        .env("RUST_LOG", "info");
    cmd
}

fn read_log(dir: &Path) -> Vec<Row> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), 1, "{files:?}");
    let mut r = csv::Reader::from_path(&files[0]).unwrap();
    r.deserialize().map(|row| row.unwrap()).collect()
}

fn stdout(out: &Output) -> String {
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "exit {:?}\nstdout:\n{text}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

/// One row per slot on the 10 ms grid, plus the stop action's row.
fn assert_rhythm(rows: &[Row], slots: usize) {
    assert_eq!(
        rows.len(),
        slots + 1,
        "one row per slot and the stop action"
    );
    for (k, r) in rows.iter().enumerate() {
        assert!(
            (r.t_s - k as f64 / RATE_HZ).abs() < 1e-6,
            "row {k} at {}",
            r.t_s
        );
        assert_ne!(r.status, "skipped", "row {k}: a cycle overran");
    }
    assert_eq!(rows[slots].status, "safe-hold");
}

/// Largest distance of a logged V_P from the offline range over slots k-LAG_WINDOW..=k.
fn worst_miss(rows: &[Row]) -> (f64, usize) {
    let op: Vec<f64> = rows
        .iter()
        .map(|r| (r.op_pct.unwrap() * 10.0).round() / 10.0)
        .collect();
    let mut valve = Valve::new(&bundled(ModelKind::Pincart2), 1.0 / RATE_HZ).unwrap();
    // sim-device's valve rests at 0 % with a 0 % set-point until the first write: the offline
    // series starts with that rest so that slot k's window is `offline[k..=k + LAG_WINDOW]`.
    valve.reset(0.0, 0.0);
    let offline: Vec<f64> = std::iter::repeat_n(0.0, LAG_WINDOW)
        .chain(op.iter().map(|&o| valve.step(o)))
        .collect();
    let mut worst = (0.0, 0);
    for (k, r) in rows.iter().enumerate() {
        let vp = r.vp_pct.unwrap();
        let window = &offline[k..=k + LAG_WINDOW];
        let lo = window.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = window.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let miss = (lo - HALF_STEP - vp).max(vp - hi - HALF_STEP).max(0.0);
        if miss > worst.0 {
            worst = (miss, k);
        }
    }
    worst
}

fn replay_follows_model(shipped: &str, from: &str, device_args: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let rec = write_recording(dir.path());
    let dev = SimDevice::start(device_args);
    let cfg = config(dir.path(), shipped, from, &dev.endpoint, &rec);
    let logs = dir.path().join("logs");
    let out = run_cmd(&cfg, &logs, 3.0).output().unwrap();
    let summary = stdout(&out);
    assert!(
        summary.contains("samples: 300 (300 ok, 0 timeout, 0 error, 0 disconnected)"),
        "{summary}"
    );
    assert!(summary.contains("reconnects: 0"), "{summary}");
    let rows = read_log(&logs);
    assert_rhythm(&rows, 300);
    assert!(rows.iter().all(|r| r.vp_pct.is_some()));
    // The valve really moved: up at its 20 %/s slew rate past 30 %, then back down after the
    // last step's reversal.
    let vp: Vec<f64> = rows[..300].iter().map(|r| r.vp_pct.unwrap()).collect();
    let peak = vp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    assert!(peak > 30.0 && vp[299] < peak - 1.0, "{summary}");
    let (miss, k) = worst_miss(&rows);
    assert!(
        miss == 0.0,
        "row {k}: V_P {:?} is {miss:.3} % outside the offline range of slots {}..={k}",
        rows[k].vp_pct,
        k.saturating_sub(LAG_WINDOW)
    );
}

#[test]
fn tcp_replay_follows_the_model() {
    replay_follows_model(
        "config/sim-device-tcp.toml",
        "127.0.0.1:5502",
        &["--tcp", "127.0.0.1:0"],
    );
}

#[test]
fn rtu_over_a_pty_replay_follows_the_model() {
    replay_follows_model(
        "config/sim-device-rtu.toml",
        "/tmp/vb-sim-device",
        &["--pty"],
    );
}

#[test]
fn device_killed_and_restarted_keeps_the_rhythm_and_reconnects() {
    let dir = tempfile::tempdir().unwrap();
    let rec = write_recording(dir.path());
    let mut dev = SimDevice::start(&["--tcp", "127.0.0.1:0"]);
    let addr = dev.endpoint.clone();
    let cfg = config(
        dir.path(),
        "config/sim-device-tcp.toml",
        "127.0.0.1:5502",
        &addr,
        &rec,
    );
    let logs = dir.path().join("logs");
    let daemon = run_cmd(&cfg, &logs, 3.0)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(1000));
    dev.kill();
    std::thread::sleep(Duration::from_millis(700));
    let _restarted = SimDevice::start(&["--tcp", &addr]);
    let summary = stdout(&daemon.wait_with_output().unwrap());
    let rows = read_log(&logs);
    assert_rhythm(&rows, 300);
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
    assert!(rows.iter().all(|r| r.status != "error"), "{summary}");
    // Ok before the kill, and ok again at the end, after the reconnection.
    assert!(rows[..90].iter().all(|r| r.status == "ok"), "{summary}");
    assert!(rows[250..300].iter().all(|r| r.status == "ok"), "{summary}");
    let count = |s: &str| rows[..300].iter().filter(|r| r.status == s).count();
    assert!(
        summary.contains(&format!(
            "samples: 300 ({} ok, {} timeout, 0 error, {} disconnected)",
            count("ok"),
            count("timeout"),
            count("disconnected")
        )),
        "{summary}"
    );
    let reconnects: u64 = summary
        .lines()
        .find_map(|l| l.strip_prefix("reconnects: "))
        .expect("reconnects line")
        .parse()
        .unwrap();
    assert!(reconnects >= 1, "{summary}");
}
