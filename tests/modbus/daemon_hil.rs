//! `valve-bridge run` with the `modbus-server` source (hardware in the loop) and the Prometheus
//! endpoint, through the real binary and independent Modbus clients:
//!
//! - a pymodbus controller writes O_P steps and reads V_P back: the emulated valve follows, and
//!   the log shows the written O_P; the same with sim-device behind, over Modbus TCP (sim-device
//!   is built by `cargo test --workspace`; with `-p valve-bridge` alone build it first);
//! - mbpoll (libmodbus) writes the set-point and reads the V_P register;
//! - a set-point outside `op_min_pct..op_max_pct` gets exception 03, an unknown address 02;
//! - the watchdog fires when the controller goes quiet: `watchdog` rows with the safe O_P, the
//!   status bit, one warning per trip and per resumption, the trip counter in the metrics;
//! - `GET /metrics` answers with every metric name;
//! - bad `[source.modbus-server]` / `[metrics]` settings and a taken port fail with one line.
//!
//! Every daemon listens on port 0 and the test reads the bound addresses from the lines it prints
//! on start (`modbus-server: ADDR`, `metrics: ADDR`), so tests never race for ports. The pymodbus
//! and mbpoll tests need those tools: see `tests/common/tools.rs` for what happens without them.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::common;

use crate::common::tools::{have_mbpoll, have_pymodbus};

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

/// One row of a daemon log.
#[derive(Debug, serde::Deserialize)]
struct Row {
    op_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
}

/// A running daemon, the addresses it announced, and its output.
struct Daemon {
    child: KillOnDrop,
    stdout: BufReader<ChildStdout>,
    stderr: Option<JoinHandle<String>>,
    modbus: Option<String>,
    metrics: Option<String>,
    _dir: tempfile::TempDir,
    logs: PathBuf,
}

/// What a stopped daemon left.
struct Stopped {
    stdout: String,
    stderr: String,
    rows: Vec<Row>,
}

impl Daemon {
    /// Starts `valve-bridge run` on `toml` (no --duration) and waits for `announced` endpoint lines.
    fn start(toml: &str, announced: usize) -> Daemon {
        let dir = tempfile::tempdir().unwrap();
        let cfg = dir.path().join("hil.toml");
        std::fs::write(&cfg, toml).unwrap();
        let logs = dir.path().join("logs");
        let mut child = Command::new(BIN)
            .args(["run", "--config"])
            .arg(&cfg)
            .arg("--log-dir")
            .arg(&logs)
            .env("RUST_LOG", "info")
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = child.stderr.take().unwrap();
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            drop(err.read_to_string(&mut s));
            s
        });
        let mut daemon = Daemon {
            stdout: BufReader::new(child.stdout.take().unwrap()),
            child: KillOnDrop(child),
            stderr: Some(stderr),
            modbus: None,
            metrics: None,
            _dir: dir,
            logs,
        };
        for _ in 0..announced {
            let mut line = String::new();
            if daemon.stdout.read_line(&mut line).unwrap() == 0 {
                drop(daemon.child.0.wait());
                let err = daemon.stderr.take().unwrap().join().unwrap();
                panic!("the daemon ended before announcing its endpoints: {err}");
            }
            match line.trim().split_once(": ") {
                Some(("modbus-server", a)) => daemon.modbus = Some(a.to_string()),
                Some(("metrics", a)) => daemon.metrics = Some(a.to_string()),
                _ => panic!("unexpected line {line:?}"),
            }
        }
        daemon
    }

    /// The Modbus server's `host` and `port`.
    fn modbus(&self) -> (&str, &str) {
        self.modbus
            .as_deref()
            .and_then(|a| a.rsplit_once(':'))
            .expect("modbus-server announced")
    }

    /// SIGTERM, then the exit status must be 0; returns the output and the log rows.
    fn stop(mut self) -> Stopped {
        assert!(common::signal(&self.child.0, libc::SIGTERM));
        let status = self.child.0.wait().unwrap();
        let mut stdout = String::new();
        self.stdout.read_to_string(&mut stdout).unwrap();
        let stderr = self.stderr.take().unwrap().join().unwrap();
        assert!(status.success(), "exit {status:?}: {stderr}");
        let files: Vec<PathBuf> = std::fs::read_dir(&self.logs)
            .unwrap()
            .map(|e| e.unwrap().path())
            .collect();
        assert_eq!(files.len(), 1, "{files:?}");
        let rows = csv::Reader::from_path(&files[0])
            .unwrap()
            .deserialize()
            .map(|r| r.unwrap())
            .collect();
        Stopped {
            stdout,
            stderr,
            rows,
        }
    }
}

/// A child process killed when dropped.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        drop(self.0.kill());
        drop(self.0.wait());
    }
}

/// A HIL config on port 0: O_P 0-80 %, safe O_P 5 %, with `extra` tables.
fn hil_config(watchdog_s: f64, extra: &str) -> String {
    format!(
        "[source]\nkind = \"modbus-server\"\nop_min_pct = 0.0\nop_max_pct = 80.0\n\
         [source.modbus-server]\nlisten = \"127.0.0.1:0\"\nwatchdog_s = {watchdog_s}\n\
         [safety]\non_stop = \"go-to\"\ngo_to_pct = 5.0\n{extra}"
    )
}

/// The process controller: `python3 -c CONTROLLER HOST PORT MODE`.
const CONTROLLER: &str = r#"
import sys, time, inspect
from pymodbus.client import ModbusTcpClient
host, port, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3]
c = ModbusTcpClient(host, port=port, timeout=1)
assert c.connect(), "connect"
kw = "device_id" if "device_id" in inspect.signature(c.read_holding_registers).parameters else "slave"
u = {kw: 1}

def write(value, address=0):
    return c.write_register(address, value, **u)

def regs():
    r = c.read_holding_registers(0, count=3, **u)
    assert not r.isError(), r
    return r.registers

def vp_pct(words):
    raw = words[1] - 65536 if words[1] >= 32768 else words[1]
    return raw / 10

if mode == "steps":
    # Each step is written every 50 ms until the valve is within 2 % of it.
    for target in (300, 150):
        deadline = time.time() + 10
        while True:
            assert not write(target).isError()
            words = regs()
            if abs(vp_pct(words) - target / 10) < 2:
                break
            assert time.time() < deadline, f"V_P {vp_pct(words)} % never reached {target / 10} %"
            time.sleep(0.05)
        print("reached", target, vp_pct(words), flush=True)
elif mode == "exceptions":
    for name, r in [
        ("above-range", write(900)),
        ("in-range", write(400)),
        ("unknown-write", write(1, address=7)),
        ("read-only", write(5, address=1)),
        ("unknown-read", c.read_holding_registers(7, count=1, **u)),
    ]:
        print(name, r.isError(), getattr(r, "exception_code", None), flush=True)
    print("set-point", regs()[0], flush=True)
elif mode == "watchdog":
    # Writes 50 % for 1 s, goes quiet for 1 s, then writes again until the loop has seen it.
    end = time.time() + 1.0
    while time.time() < end:
        assert not write(500).isError()
        time.sleep(0.05)
    time.sleep(1.0)
    print("quiet", regs(), flush=True)
    for _ in range(20):
        assert not write(500).isError()
        time.sleep(0.03)
        words = regs()
        if words[2] & 4 == 0:
            break
    print("resumed", words, flush=True)
c.close()
"#;

fn controller(daemon: &Daemon, mode: &str) -> String {
    let (host, port) = daemon.modbus();
    let out = Command::new("python3")
        .args(["-c", CONTROLLER, host, port, mode])
        .output()
        .expect("python3 runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "controller {mode} failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

#[test]
fn pymodbus_controller_drives_the_emulated_valve_and_the_log_shows_its_o_p() {
    if !have_pymodbus() {
        return;
    }
    let daemon = Daemon::start(&hil_config(2.0, "[valve.emulated]\nmodel = \"fopdt\"\n"), 1);
    let text = controller(&daemon, "steps");
    assert!(
        text.contains("reached 300") && text.contains("reached 150"),
        "{text}"
    );
    let out = daemon.stop();
    assert!(
        out.stdout.contains("stop action: safe-go-to O_P 5.00 %"),
        "{}",
        out.stdout
    );
    let ran: Vec<&Row> = out.rows.iter().filter(|r| r.status != "skipped").collect();
    // Only the initial/safe O_P and what the controller wrote ever reach the valve.
    for r in &ran {
        let op = r.op_pct.unwrap();
        assert!([5.0, 30.0, 15.0].contains(&op), "{r:?}");
        assert!(r.vp_pct.is_some(), "{r:?}");
    }
    // The written steps are logged in order, and V_P got to each while it was held.
    let first_30 = ran.iter().position(|r| r.op_pct == Some(30.0)).unwrap();
    let first_15 = ran.iter().position(|r| r.op_pct == Some(15.0)).unwrap();
    assert!(first_30 < first_15);
    assert!(ran[first_30..first_15]
        .iter()
        .any(|r| (r.vp_pct.unwrap() - 30.0).abs() < 2.0));
    assert!(ran[first_15..]
        .iter()
        .any(|r| r.op_pct == Some(15.0) && (r.vp_pct.unwrap() - 15.0).abs() < 2.0));
    assert!(
        ran[first_15..first_15 + 10]
            .iter()
            .all(|r| r.status == "ok"),
        "the controller was writing"
    );
}

#[test]
fn pymodbus_controller_drives_sim_device_through_the_loop() {
    if !have_pymodbus() {
        return;
    }
    let sim = Path::new(BIN).with_file_name("sim-device");
    assert!(
        sim.exists(),
        "{} not built: run `cargo test --workspace`",
        sim.display()
    );
    let mut device = KillOnDrop(
        Command::new(sim)
            .args(["--tcp", "127.0.0.1:0", "--model", "modelless"])
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let mut line = String::new();
    BufReader::new(device.0.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let device_addr = line
        .trim()
        .strip_prefix("tcp: ")
        .expect("tcp: ADDR")
        .to_string();
    let daemon = Daemon::start(
        &hil_config(
            2.0,
            &format!(
                "[valve]\nkind = \"modbus-tcp\"\n[valve.modbus-tcp]\naddress = \"{device_addr}\"\n"
            ),
        ),
        1,
    );
    let text = controller(&daemon, "steps");
    assert!(
        text.contains("reached 300") && text.contains("reached 150"),
        "{text}"
    );
    let out = daemon.stop();
    drop(device);
    assert!(out.stdout.contains("reconnects: 0"), "{}", out.stdout);
    // The device follows at once (modelless): logged V_P equals the O_P of a few cycles before.
    for step in [30.0, 15.0] {
        assert!(
            out.rows
                .iter()
                .any(|r| r.op_pct == Some(step) && r.vp_pct == Some(step)),
            "{step}"
        );
    }
}

#[test]
fn mbpoll_writes_the_set_point_and_reads_v_p() {
    if !have_mbpoll() {
        return;
    }
    // The emulated valve starts at rest at its first O_P, 40 %; hold keeps it there.
    let daemon = Daemon::start(
        "[source]\nkind = \"modbus-server\"\n[source.modbus-server]\nlisten = \"127.0.0.1:0\"\n\
         initial_pct = 40.0\nwatchdog_s = 60.0\n",
        1,
    );
    let (host, port) = daemon.modbus();
    let mbpoll = |opts: &[&str], values: &[&str]| {
        let out = Command::new("mbpoll")
            .args(["-m", "tcp", "-p", port, "-a", "1", "-t", "4", "-1", "-q"])
            .args(opts)
            .arg(host)
            .args(values)
            .output()
            .expect("mbpoll runs");
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "mbpoll {opts:?} {values:?}: {text}");
        text
    };
    std::thread::sleep(Duration::from_millis(200));
    let read = mbpoll(&["-r", "1", "-c", "3"], &[]);
    assert!(read.contains("[1]: \t400"), "the initial O_P: {read}");
    let vp: i32 = read
        .lines()
        .find_map(|l| l.strip_prefix("[2]: \t"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no V_P in {read}"));
    assert!(
        (395..=405).contains(&vp),
        "V_P {vp} per mille at rest at 40 %: {read}"
    );
    assert!(
        read.contains("[3]: \t0"),
        "status: no fault, no watchdog: {read}"
    );
    // What mbpoll writes is the next O_P.
    mbpoll(&["-r", "1"], &["250"]);
    std::thread::sleep(Duration::from_millis(100));
    let read = mbpoll(&["-r", "1"], &[]);
    assert!(read.contains("[1]: \t250"), "{read}");
    let out = daemon.stop();
    assert!(out
        .rows
        .iter()
        .any(|r| r.op_pct == Some(25.0) && r.status == "ok"));
}

#[test]
fn out_of_range_writes_get_03_and_unknown_addresses_02() {
    if !have_pymodbus() {
        return;
    }
    let daemon = Daemon::start(&hil_config(60.0, ""), 1);
    let text = controller(&daemon, "exceptions");
    for line in [
        "above-range True 3",
        "in-range False",
        "unknown-write True 2",
        "read-only True 2",
        "unknown-read True 2",
        "set-point 400",
    ] {
        assert!(text.lines().any(|l| l.starts_with(line)), "{line}: {text}");
    }
    let out = daemon.stop();
    // The refused 90 % never reached the valve.
    assert!(out.rows.iter().all(|r| r.op_pct != Some(90.0)));
    assert!(out.rows.iter().any(|r| r.op_pct == Some(40.0)));
}

#[test]
fn watchdog_sends_the_safe_o_p_while_the_controller_is_quiet() {
    if !have_pymodbus() {
        return;
    }
    let daemon = Daemon::start(&hil_config(0.3, "[metrics]\nlisten = \"127.0.0.1:0\"\n"), 2);
    let text = controller(&daemon, "watchdog");
    let status = |tag: &str| -> u16 {
        let line = text
            .lines()
            .find(|l| l.starts_with(tag))
            .unwrap_or_else(|| panic!("{text}"));
        let words = line[tag.len()..].trim().trim_matches(['[', ']']);
        words.split(',').nth(2).unwrap().trim().parse().unwrap()
    };
    assert_eq!(
        status("quiet") & 0b100,
        0b100,
        "watchdog bit while quiet: {text}"
    );
    assert_eq!(
        status("resumed") & 0b100,
        0,
        "cleared after a write: {text}"
    );
    let metrics = http_get(daemon.metrics.as_deref().unwrap(), "/metrics");
    let trips: u64 = metrics
        .lines()
        .find_map(|l| l.strip_prefix("valve_bridge_watchdog_trips_total{valve=\"valve\"} "))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{metrics}"));
    assert!(trips >= 1, "{metrics}");
    let out = daemon.stop();

    // Cycles (skipped slots aside): 50 % from the controller, then the safe 5 % in `watchdog`
    // rows, then 50 % again.
    let ran: Vec<&Row> = out
        .rows
        .iter()
        .filter(|r| r.status == "ok" || r.status == "watchdog")
        .collect();
    for r in ran.iter().filter(|r| r.status == "watchdog") {
        assert_eq!(r.op_pct, Some(5.0), "{r:?}");
    }
    let first_50 = ran.iter().position(|r| r.op_pct == Some(50.0)).unwrap();
    let held = first_50
        + ran[first_50..]
            .iter()
            .position(|r| r.status == "watchdog")
            .unwrap();
    assert!(ran[held..]
        .iter()
        .any(|r| r.op_pct == Some(50.0) && r.status == "ok"));
    // One warning when it fires and one when writes resume, per trip.
    let runs = ran
        .windows(2)
        .filter(|w| w[0].status == "ok" && w[1].status == "watchdog")
        .count();
    let resumed = ran
        .windows(2)
        .filter(|w| w[0].status == "watchdog" && w[1].status == "ok")
        .count();
    assert!(runs >= 1 && resumed >= 1);
    assert_eq!(
        out.stderr.matches("watchdog: no set-point").count(),
        runs,
        "{}",
        out.stderr
    );
    assert_eq!(
        out.stderr
            .matches("watchdog: set-point writes resumed")
            .count(),
        resumed
    );
    assert!(out.stdout.contains("watchdog: "), "{}", out.stdout);
    // The watchdog's and the stop action's messages carry rounded numbers.
    common::assert_for_people(&out.stderr);
    common::assert_for_people(&out.stdout);
}

/// The body of an HTTP GET on `addr`, asserting status 200.
fn http_get(addr: &str, path: &str) -> String {
    let (status, body) = http(addr, path);
    assert!(status.starts_with("HTTP/1.1 200 OK"), "{status}");
    body
}

/// Status line and body of an HTTP GET (read to the end: the request asks the server to close).
fn http(addr: &str, path: &str) -> (String, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    let (head, body) = reply.split_once("\r\n\r\n").unwrap_or((&reply, ""));
    (
        head.lines().next().unwrap_or("").to_string(),
        body.to_string(),
    )
}

#[test]
fn metrics_endpoint_answers_get_metrics() {
    // The default source and valve: the endpoint needs no Modbus server.
    let daemon = Daemon::start("[metrics]\nlisten = \"127.0.0.1:0\"\n", 1);
    let addr = daemon.metrics.clone().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let body = http_get(&addr, "/metrics");
    for name in [
        "valve_bridge_timing_error_seconds_bucket",
        "valve_bridge_timing_error_seconds_count",
        "valve_bridge_cycles_total{valve=\"valve\"}",
        "valve_bridge_cycle_failures_total{kind=\"timeout\",valve=\"valve\"}",
        "valve_bridge_cycle_failures_total{kind=\"error\",valve=\"valve\"}",
        "valve_bridge_cycle_failures_total{kind=\"disconnected\",valve=\"valve\"}",
        "valve_bridge_missed_cycles_total",
        "valve_bridge_op_ratio",
        "valve_bridge_vp_ratio",
        "valve_bridge_reconnects_total",
        "valve_bridge_watchdog_trips_total",
        "valve_bridge_server_up{server=\"metrics\"} 1",
        "valve_bridge_server_connections{server=\"metrics\"} 1",
        "valve_bridge_server_connections_accepted_total{server=\"metrics\"}",
        "valve_bridge_server_connections_evicted_total{server=\"metrics\"} 0",
        "valve_bridge_server_accept_errors_total{server=\"metrics\"} 0",
    ] {
        assert!(body.lines().any(|l| l.starts_with(name)), "{name}: {body}");
    }
    let cycles: u64 = body
        .lines()
        .find_map(|l| l.strip_prefix("valve_bridge_cycles_total{valve=\"valve\"} "))
        .and_then(|v| v.parse().ok())
        .unwrap();
    assert!(cycles > 0, "{body}");
    // The live page beside the metrics; other paths are not found.
    let (status, page) = http(&addr, "/");
    assert!(status.starts_with("HTTP/1.1 200"), "{status}");
    assert!(page.contains("valve-bridge: live"), "{page}");
    assert!(http(&addr, "/nothing").0.starts_with("HTTP/1.1 404"));
    let out = daemon.stop();
    assert!(
        out.stdout.contains("stopped: stop requested"),
        "{}",
        out.stdout
    );
}

#[test]
fn bad_settings_fail_with_one_line_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let hil = "[source]\nkind = \"modbus-server\"\n";
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let cases = [
        (
            format!("{hil}[source.modbus-server]\nlisten = \"localhost:5020\"\n"),
            "bad.toml:4: source.modbus-server.listen: `localhost:5020` is not an IP address and port: write e.g. \"127.0.0.1:5020\"".to_string(),
        ),
        (
            format!("{hil}[source.modbus-server]\nwatchdog_s = -1.0\n"),
            "bad.toml:4: source.modbus-server.watchdog_s: -1 is not allowed".to_string(),
        ),
        (
            format!("{hil}op_min_pct = 60.0\nop_max_pct = 20.0\n"),
            "bad.toml:4: source.op_max_pct: must be above op_min_pct = 60".to_string(),
        ),
        (
            "[metrics]\nlisten = \"127.0.0.1\"\n".to_string(),
            "bad.toml:2: metrics.listen: `127.0.0.1` is not an IP address and port".to_string(),
        ),
        (
            "[metrics]\nport = 9100\n".to_string(),
            "bad.toml:2: metrics.port: unknown field `port`".to_string(),
        ),
        (
            format!("{hil}[source.modbus-server]\nlisten = \"127.0.0.1:{port}\"\n"),
            format!("cannot listen on 127.0.0.1:{port} ([source.modbus-server] listen)"),
        ),
    ];
    for (toml, want) in cases {
        std::fs::write(dir.path().join("bad.toml"), &toml).unwrap();
        let out = Command::new(BIN)
            .args(["run", "--config", "bad.toml", "--duration", "1"])
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{toml}");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(stderr.lines().count(), 1, "{stderr}");
        assert!(
            stderr.starts_with(&format!("valve-bridge: error: {want}")),
            "{stderr}"
        );
        assert!(
            !Path::new(&dir.path().join("logs")).exists(),
            "nothing ran: {toml}"
        );
    }
    drop(taken);
}
