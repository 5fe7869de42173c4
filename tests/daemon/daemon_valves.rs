//! Several valves in one daemon, through the real binary:
//! - `config/two-valves.toml` drives two emulated valves from their own sources in the same
//!   cycles, each with its own log files and summary;
//! - a valve whose device is not there logs its own rows as `disconnected` while every cycle
//!   of the other valve reads its V_P; the run exits 1 naming that valve.

use std::process::{Command, Output};

use crate::common::{log_rows, logs, LogRow};

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");
const TWO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/config/two-valves.toml");

fn run(args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .env("RUST_LOG", "info")
        .output()
        .unwrap()
}

#[test]
fn two_emulated_valves_run_in_the_same_cycles_with_their_own_logs() {
    let dir = tempfile::tempdir().unwrap();
    let log_dir = dir.path().to_str().unwrap();
    let out = run(&[
        "run",
        "--config",
        TWO,
        "--as-fast-as-possible",
        "--duration",
        "120",
        "--log-dir",
        log_dir,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for name in ["level", "cyclone"] {
        assert!(
            stdout.contains(&format!("valve {name}:\n  samples: 12000 (12000 ok")),
            "{stdout}"
        );
    }
    let level = logs(dir.path(), "vb-level-");
    let cyclone = logs(dir.path(), "vb-cyclone-");
    assert_eq!((level.len(), cyclone.len()), (1, 1), "{stdout}");
    let (a, b) = (log_rows(&level[0]), log_rows(&cyclone[0]));
    // 12000 cycles and the stop action, each.
    assert_eq!((a.len(), b.len()), (12001, 12001));
    // Each valve follows its own source: the level valve's random steps span 20-97 %, the
    // cyclone valve's stay within its 30-70 % clamp.
    let span = |r: &[LogRow]| {
        r.iter().fold((f64::MAX, f64::MIN), |(lo, hi), x| {
            (lo.min(x.op), hi.max(x.op))
        })
    };
    let (lo, hi) = span(&b);
    assert!(lo >= 30.0 && hi <= 70.0, "cyclone O_P {lo}..{hi}");
    let (lo, hi) = span(&a);
    assert!(lo < 30.0 && hi > 70.0, "level O_P {lo}..{hi}");
    assert!(a
        .iter()
        .chain(&b)
        .all(|r| r.status == "ok" || r.status == "safe-hold"));
}

#[test]
fn a_valve_without_its_device_never_stalls_the_other() {
    let dir = tempfile::tempdir().unwrap();
    // Nothing listens on a port held bound (not listening) for the whole run.
    let held = tokio::net::TcpSocket::new_v4().unwrap();
    held.bind("127.0.0.1:0".parse().unwrap()).unwrap();
    let port = held.local_addr().unwrap().port();
    let config = dir.path().join("c.toml");
    std::fs::write(
        &config,
        format!(
            "[[valve]]\nname = \"emulated\"\n\n[[valve]]\nname = \"absent\"\nkind = \"modbus-tcp\"\n\
             [valve.modbus-tcp]\naddress = \"127.0.0.1:{port}\"\n"
        ),
    )
    .unwrap();
    let out = run(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--duration",
        "2",
        "--log-dir",
        dir.path().to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    // A loaded machine may skip a slot for both valves; every cycle that ran is counted.
    assert!(
        stderr.contains("valve absent: no cycle read a V_P: all ")
            && stderr.contains(" disconnected); the last was disconnected"),
        "{stderr}"
    );
    assert!(
        stdout.contains("valve emulated:\n  samples: ")
            && stdout.contains(" ok, 0 timeout, 0 error, 0 disconnected)\n"),
        "{stdout}"
    );
    // Every cycle that ran read the emulated valve; only the absent one's rows are failures.
    let ok = log_rows(&logs(dir.path(), "vb-emulated-")[0]);
    assert!(ok
        .iter()
        .all(|r| r.status == "skipped" || (r.vp.is_some() && r.status != "disconnected")));
    assert!(ok.iter().filter(|r| r.status == "ok").count() >= 100);
    let absent = log_rows(&logs(dir.path(), "vb-absent-")[0]);
    assert!(absent[..200]
        .iter()
        .all(|r| (r.status == "disconnected" || r.status == "skipped") && r.vp.is_none()));
    drop(held);
}
