//! Servers that stay up, through the real binaries: the daemon's Modbus server for a process
//! controller, its metrics endpoint, and sim-device.
//!
//! - With few file descriptors (RLIMIT_NOFILE 64) and no useful connection limit, a crowd of
//!   idle connections makes `accept()` fail (too many open files): the servers keep serving
//!   once connections are gone, and the summary and the metrics report the outage.
//! - With the default limit, connections beyond it are closed at once, idle ones are closed
//!   after `idle_timeout_s`, and a controller connecting afterwards is served.

use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::thread::JoinHandle;
use std::time::Duration;

mod common;

use common::sim::{real_time_turn, BIN};

/// Starts `cmd` with at most `fds` open file descriptors.
fn spawn_with_fd_limit(cmd: &mut Command, fds: u64) -> Child {
    // SAFETY: setrlimit is async-signal-safe; the closure touches nothing else.
    unsafe {
        cmd.pre_exec(move || {
            let limit = libc::rlimit {
                rlim_cur: fds,
                rlim_max: fds,
            };
            if libc::setrlimit(libc::RLIMIT_NOFILE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    cmd.stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// The addresses of the `name: ADDR` lines a server prints at start, and the rest of its
/// stdout (read in the background so the process never blocks on it).
fn endpoints(child: &mut Child, n: usize) -> (Vec<String>, JoinHandle<String>) {
    use std::io::BufRead;
    let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut found = Vec::new();
    for _ in 0..n {
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        let (_, addr) = line.trim().split_once(": ").expect("an endpoint line");
        found.push(addr.to_string());
    }
    let rest = std::thread::spawn(move || {
        let mut text = String::new();
        let _ = out.read_to_string(&mut text);
        text
    });
    (found, rest)
}

/// Writes per-mille `value` into holding register 0 (FC 6) and returns the echoed value.
fn write_register(addr: &str, value: u16) -> std::io::Result<u16> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(2)))?;
    let v = value.to_be_bytes();
    s.write_all(&[0, 7, 0, 0, 0, 6, 1, 6, 0, 0, v[0], v[1]])?;
    let mut reply = [0u8; 12];
    s.read_exact(&mut reply)?;
    Ok(u16::from_be_bytes([reply[10], reply[11]]))
}

/// `n` idle connections to `addr` (those the kernel takes; a refused one is left out).
fn crowd(addr: &str, n: usize) -> Vec<TcpStream> {
    (0..n)
        .filter_map(|_| TcpStream::connect(addr).ok())
        .collect()
}

/// The body of `GET /metrics`.
fn scrape(addr: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(s, "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    reply
}

/// SIGTERM, then the rest of its stdout and its stderr (it must exit 0).
fn stop(child: Child, stdout: JoinHandle<String>) -> (String, String) {
    // SAFETY: kill(2) on our own child's pid with a standard signal.
    unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGTERM) };
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    (stdout.join().unwrap(), stderr)
}

fn daemon(config: &str, dir: &std::path::Path) -> Command {
    let cfg = dir.join("hil.toml");
    std::fs::write(&cfg, config).unwrap();
    let mut cmd = Command::new(BIN);
    cmd.args(["run", "--config"])
        .arg(&cfg)
        .arg("--log-dir")
        .arg(dir.join("logs"))
        .env("RUST_LOG", "info");
    cmd
}

/// The summary's line about the Modbus server.
fn server_line(summary: &str) -> &str {
    summary
        .lines()
        .find(|l| l.starts_with("modbus-server: "))
        .unwrap_or_else(|| panic!("{summary}"))
}

const HIL: &str = "[source]\nkind = \"modbus-server\"\n[source.modbus-server]\nlisten = \"127.0.0.1:0\"\nwatchdog_s = 60.0\n";

#[test]
fn daemon_servers_survive_running_out_of_file_descriptors() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = format!(
        "{HIL}max_connections = 1000\n[metrics]\nlisten = \"127.0.0.1:0\"\nmax_connections = 1000\n"
    );
    let mut child = spawn_with_fd_limit(&mut daemon(&config, dir.path()), 64);
    let (ends, rest) = endpoints(&mut child, 2);
    let (modbus, metrics) = (&ends[0], &ends[1]);
    // More idle connections than descriptors: accept() fails with EMFILE.
    let idle = crowd(modbus, 100);
    std::thread::sleep(Duration::from_millis(500));
    drop(idle);
    std::thread::sleep(Duration::from_millis(500));
    // Served again: the controller's write is taken, the endpoint answers.
    assert_eq!(write_register(modbus, 420).unwrap(), 420);
    let text = scrape(metrics);
    let errors: u64 = text
        .lines()
        .find_map(|l| {
            l.strip_prefix("valve_bridge_server_accept_errors_total{server=\"modbus-server\"} ")
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!(errors > 0, "{text}");
    assert!(
        text.contains("valve_bridge_server_up{server=\"modbus-server\"} 1"),
        "{text}"
    );
    let (summary, stderr) = stop(child, rest);
    let line = server_line(&summary);
    assert!(
        line.contains("accept errors (the last: Too many open files (os error 24))")
            && line.contains("unable to accept for"),
        "{line}"
    );
    assert!(!line.contains("still failing"), "{line}");
    println!("{line}");
    // Logged once per outage, not once per failed accept().
    let outages = stderr.matches("cannot accept connections").count();
    assert!((1..=3).contains(&outages), "{stderr}");
    assert!(
        stderr.contains("accepting connections again after"),
        "{stderr}"
    );
    common::assert_for_people(&summary);
}

#[test]
fn connections_beyond_the_limit_and_idle_ones_are_closed() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = format!("{HIL}max_connections = 4\nidle_timeout_s = 0.5\n");
    let mut child = daemon(&config, dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut ends, rest) = endpoints(&mut child, 1);
    let modbus = ends.remove(0);
    let idle = crowd(&modbus, 30);
    std::thread::sleep(Duration::from_millis(300));
    // The limit is reached by idle connections: one more is closed at once.
    assert!(write_register(&modbus, 300).is_err());
    // Idle ones are closed after 0.5 s; then the controller is served.
    std::thread::sleep(Duration::from_millis(700));
    assert_eq!(write_register(&modbus, 300).unwrap(), 300);
    drop(idle);
    let (summary, stderr) = stop(child, rest);
    let line = server_line(&summary);
    assert!(
        line.contains("refused at the limit") && line.contains("closed idle"),
        "{line}"
    );
    assert!(!line.contains("accept errors"), "{line}");
    assert_eq!(
        stderr.matches("the limit: closing new ones").count(),
        1,
        "{stderr}"
    );
}

#[test]
fn sim_device_survives_running_out_of_file_descriptors() {
    let mut cmd = Command::new(common::sim::sim_device_bin());
    cmd.args(["--tcp", "127.0.0.1:0", "--max-connections", "1000"])
        .env("RUST_LOG", "info");
    let mut child = spawn_with_fd_limit(&mut cmd, 48);
    let (mut ends, rest) = endpoints(&mut child, 1);
    let addr = ends.remove(0);
    let idle = crowd(&addr, 80);
    std::thread::sleep(Duration::from_millis(500));
    drop(idle);
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(write_register(&addr, 250).unwrap(), 250);
    assert!(child.try_wait().unwrap().is_none(), "sim-device exited");
    let (_, stderr) = stop(child, rest);
    assert!(stderr.contains("Too many open files"), "{stderr}");
    assert!(
        stderr.contains("SIGTERM: stopping; Modbus TCP served") && stderr.contains("accept errors"),
        "{stderr}"
    );
}
