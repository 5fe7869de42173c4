//! One process controller driving two valves through one daemon (`[source] kind =
//! "modbus-server"` with two `[[valve]]` tables), through the real binary and a real Modbus TCP
//! client (tokio-modbus here, mbpoll too when installed):
//! - each valve has its own register block (valve `a` at 0-2, valve `b` at 10-12 with
//!   `block_size = 10`): set-point, position, status word; a read across blocks gets 02;
//! - each valve has its own watchdog: `b`'s controller goes quiet and only `b` trips (status
//!   bit 2, `watchdog` rows), `a` keeps following its set-points;
//! - with `[health]`, a valve in health alarm shows it in bit 3 of its own status word: `a`,
//!   measured against a baseline model with no delay and no speed limit, is in alarm after its
//!   first window; `b` is not.

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::tools::have_mbpoll;
use tokio_modbus::client::{Reader, Writer};
use tokio_modbus::{ExceptionCode, Slave};

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

fn config(dir: &Path) -> std::path::PathBuf {
    let baseline = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/models/modelless.toml");
    let text = format!(
        "[source]\nkind = \"modbus-server\"\n\
         [source.modbus-server]\nlisten = \"127.0.0.1:0\"\nwatchdog_s = 1.0\nblock_size = 10\n\
         [[valve]]\nname = \"a\"\nhealth_baseline_model = {:?}\n\
         [[valve]]\nname = \"b\"\n\
         [health]\nwindow_s = 10.0\nevery_s = 1.0\nmin_steps = 2\n",
        baseline.display().to_string()
    );
    let path = dir.join("hil.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// The status word's bits: valve fault 1, watchdog 2, health alarm 3.
const WATCHDOG: u16 = 1 << 2;
const ALARM: u16 = 1 << 3;

#[test]
fn a_controller_drives_two_valves_each_with_its_block_watchdog_and_alarm_bit() {
    let _turn = common::sim::real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let mut child = Command::new(BIN)
        .args(["run", "--duration", "13", "--config"])
        .arg(config(dir.path()))
        .arg("--log-dir")
        .arg(dir.path())
        .env("RUST_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    // Kept open until the daemon exits: it prints its summary there.
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    stdout.read_line(&mut line).unwrap();
    let addr = line
        .trim()
        .strip_prefix("modbus-server: ")
        .unwrap_or_else(|| panic!("no modbus-server line: {line:?}"));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let mut ctx = tokio_modbus::client::tcp::connect_slave(addr.parse().unwrap(), Slave(1))
            .await
            .unwrap();
        // Valve a: steps of 1.2 s (same-direction steps and reversals) for the health check;
        // valve b: 60 % for 3 s, then nothing.
        let levels = [300u16, 400, 500, 400, 300, 400, 500, 400, 300, 400, 500];
        let start = Instant::now();
        while start.elapsed() < Duration::from_millis(12_500) {
            let t = start.elapsed().as_secs_f64();
            let a = levels[((t / 1.2) as usize).min(levels.len() - 1)];
            ctx.write_single_register(0, a).await.unwrap().unwrap();
            if t < 3.0 {
                ctx.write_single_register(10, 600).await.unwrap().unwrap();
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        let a = ctx.read_holding_registers(0, 3).await.unwrap().unwrap();
        let b = ctx.read_holding_registers(10, 3).await.unwrap().unwrap();
        assert_eq!(a[0], 500, "a's last set-point: {a:?}");
        assert!(a[2] & ALARM != 0 && a[2] & WATCHDOG == 0, "a: {a:?}");
        assert_eq!(b[0], 600, "b's set-point: {b:?}");
        assert!((595..=605).contains(&b[1]), "b held at 60 %: {b:?}");
        assert!(b[2] & WATCHDOG != 0 && b[2] & ALARM == 0, "b: {b:?}");
        assert_eq!(
            ctx.read_holding_registers(0, 13).await.unwrap(),
            Err(ExceptionCode::IllegalDataAddress),
            "a read across blocks"
        );
    });
    if have_mbpoll() {
        let (host, port) = addr.rsplit_once(':').unwrap();
        let out = Command::new("mbpoll")
            .args(["-m", "tcp", "-p", port, "-a", "1", "-t", "4", "-1", "-q"])
            .args(["-r", "11", "-c", "3", host])
            .output()
            .expect("mbpoll runs");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(out.status.success(), "{text}");
        assert!(
            text.contains("[11]: \t600"),
            "b's set-point via mbpoll: {text}"
        );
        assert!(text.contains("[13]: \t4"), "b's status via mbpoll: {text}");
    }
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let mut summary = String::new();
    std::io::Read::read_to_string(&mut stdout, &mut summary).unwrap();
    assert!(summary.contains("valve b:"), "{summary}");
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("WARN")).collect();
    assert!(
        (warnings.iter()).any(|l| l.contains("health alarm: ") && l.contains("valve=a")),
        "{stderr}"
    );
    assert!(!(warnings.iter()).any(|l| l.contains("health alarm") && l.contains("valve=b")));
    let tripped: Vec<&&str> = (warnings.iter())
        .filter(|l| l.contains("watchdog: no set-point"))
        .collect();
    assert_eq!(tripped.len(), 1, "one watchdog trips: {stderr}");
    assert!(tripped[0].contains("valve=b"), "b's: {stderr}");
    for (name, want) in [("a", false), ("b", true)] {
        let log = &common::logs(dir.path(), &format!("vb-{name}-"))[0];
        let text = std::fs::read_to_string(log).unwrap();
        assert_eq!(text.contains(",watchdog,"), want, "{name}'s watchdog rows");
    }
}
