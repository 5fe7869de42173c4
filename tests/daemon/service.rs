//! Running as a systemd service: `valve-bridge run` speaks systemd's notification protocol
//! (a Unix datagram socket named by NOTIFY_SOCKET, here the test's): READY=1 once the loop runs,
//! WATCHDOG=1 at half of WATCHDOG_USEC while it makes progress, STOPPING=1 at the end. The
//! shipped unit in contrib/ is a Type=notify service whose command line the daemon accepts.

use std::os::unix::net::UnixDatagram;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use crate::common::sim::BIN;

/// Runs `cmd`, which must exit 0.
fn succeeds(mut cmd: Command) {
    let out = cmd.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn run_notifies_ready_watchdog_and_stopping() {
    let dir = tempfile::tempdir().unwrap();
    let socket_path = dir.path().join("notify.sock");
    let socket = UnixDatagram::bind(&socket_path).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    // Read as systemd does, while the daemon runs (a full socket queue would block its sends).
    let reader = std::thread::spawn(move || {
        let mut messages = Vec::new();
        let mut buf = [0u8; 1024];
        while let Ok(n) = socket.recv(&mut buf) {
            let m = String::from_utf8_lossy(&buf[..n]).into_owned();
            let last = m.contains("STOPPING=1");
            messages.push(m);
            if last {
                break;
            }
        }
        messages
    });
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--duration", "2", "--log-dir"])
        .arg(dir.path().join("logs"))
        .env("NOTIFY_SOCKET", &socket_path)
        .env("WATCHDOG_USEC", "200000");
    succeeds(cmd);
    let messages = reader.join().unwrap();
    assert!(
        messages[0].contains("READY=1\n") && messages[0].contains("STATUS=running at 100 Hz"),
        "{messages:?}"
    );
    // 2 s with a 200 ms watchdog: a ping every 100 ms or so.
    let pings = messages.iter().filter(|m| *m == "WATCHDOG=1\n").count();
    assert!((10..=25).contains(&pings), "{pings} pings: {messages:?}");
    assert!(
        messages.last().is_some_and(|m| m.contains("STOPPING=1")),
        "{messages:?}"
    );
}

#[test]
fn the_shipped_unit_is_a_notify_service_the_daemon_accepts() {
    let unit = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("contrib/valve-bridge.service"),
    )
    .unwrap();
    for line in [
        "Type=notify",
        "WatchdogSec=10",
        "Restart=on-failure",
        "WantedBy=multi-user.target",
    ] {
        assert!(unit.lines().any(|l| l == line), "{line} missing");
    }
    // Its command line, with this build and the embedded default's settings, runs.
    let exec = unit
        .lines()
        .find_map(|l| l.strip_prefix("ExecStart="))
        .unwrap();
    let mut words = exec.split_whitespace();
    assert_eq!(words.next(), Some("/usr/local/bin/valve-bridge"));
    let args: Vec<&str> = words.collect();
    assert_eq!(
        args,
        [
            "run",
            "--config",
            "/etc/valve-bridge/config.toml",
            "--log-dir",
            "/var/log/valve-bridge"
        ]
    );
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("config.toml");
    std::fs::copy(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("config/emulated.toml"),
        &config,
    )
    .unwrap();
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--config"])
        .arg(&config)
        .arg("--log-dir")
        .arg(dir.path().join("logs"))
        .args(["--duration", "0.2"]);
    succeeds(cmd);
}
