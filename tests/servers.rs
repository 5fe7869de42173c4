//! Servers that stay up, through the real binaries: the daemon's Modbus server for a process
//! controller, its metrics endpoint, and sim-device.
//!
//! - With few file descriptors (RLIMIT_NOFILE 64) and no useful connection limit, a crowd of
//!   idle connections makes `accept()` fail (too many open files): the servers keep serving
//!   once connections are gone, and the summary and the metrics report the outage.
//! - With every slot of the connection limit held by idle sockets, and more arriving, a process
//!   controller connects and is answered every time (the longest idle makes room, named in the
//!   log; its watchdog never trips); the live page's browser on its kept-alive connection the
//!   same; sim-device the same. Sockets that never send a request are closed after
//!   `idle_timeout_s` (at most 5 s).

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
    #[allow(unsafe_code)]
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
        drop(out.read_to_string(&mut text));
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

/// The answer to `GET /metrics` (read to the end: the request asks the server to close).
fn scrape(addr: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(
        s,
        "GET /metrics HTTP/1.1\r\nHost: x\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut reply = String::new();
    s.read_to_string(&mut reply).unwrap();
    reply
}

/// SIGTERM, then the rest of its stdout and its stderr (it must exit 0).
fn stop(child: Child, stdout: JoinHandle<String>) -> (String, String) {
    common::signal(&child, libc::SIGTERM);
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

/// A process controller on one connection: writes per-mille set-points into holding register
/// 0 (FC 6), one request at a time.
struct Controller {
    stream: TcpStream,
    tid: u16,
}

impl Controller {
    fn connect(addr: &str) -> Controller {
        let stream = TcpStream::connect(addr).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        Controller { stream, tid: 0 }
    }

    /// Writes `value`; true when the echo came back.
    fn write(&mut self, value: u16) -> bool {
        self.tid = self.tid.wrapping_add(1);
        let (t, v) = (self.tid.to_be_bytes(), value.to_be_bytes());
        let request = [t[0], t[1], 0, 0, 0, 6, 1, 6, 0, 0, v[0], v[1]];
        let mut reply = [0u8; 12];
        self.stream.write_all(&request).is_ok()
            && self.stream.read_exact(&mut reply).is_ok()
            && reply[..2] == t
            && reply[10..] == v
    }
}

/// Writes `n` set-points 10 ms apart while idle sockets pile up against `addr` (`idle_per_write`
/// more before each write): how many were answered, and the idle sockets.
fn talk_through_a_crowd(addr: &str, n: usize, idle_per_write: usize) -> (usize, Vec<TcpStream>) {
    let mut controller = Controller::connect(addr);
    let mut idle = Vec::new();
    let mut answered = 0;
    for k in 0..n {
        idle.extend(crowd(addr, idle_per_write));
        answered += usize::from(controller.write(300 + k as u16));
        std::thread::sleep(Duration::from_millis(10));
    }
    (answered, idle)
}

#[test]
fn idle_connections_cannot_lock_the_controller_out() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    // The default limit (8 connections) and a short watchdog: a controller locked out for
    // 0.3 s would trip it.
    let config = HIL.replace("watchdog_s = 60.0", "watchdog_s = 0.3");
    let mut child = daemon(&config, dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut ends, rest) = endpoints(&mut child, 1);
    let modbus = ends.remove(0);
    // Eight idle sockets take every slot; the controller connects and talks while 28 more pile
    // up.
    let held = crowd(&modbus, 8);
    std::thread::sleep(Duration::from_millis(100));
    let (answered, idle) = talk_through_a_crowd(&modbus, 28, 1);
    assert_eq!(answered, 28);
    drop((held, idle));
    let (summary, stderr) = stop(child, rest);
    assert!(!summary.contains("cycles sent the safe O_P"), "{summary}");
    let line = server_line(&summary);
    assert!(line.contains("29 evicted at the limit"), "{line}");
    // The log names the peer that held the slot.
    assert!(
        stderr.contains("at the limit of 8 connections: closed the one from 127.0.0.1:")
            && stderr.contains("(no request, idle for "),
        "{stderr}"
    );
}

/// Asks for `path` on the kept-alive connection `s`: true when the whole answer came, 200.
fn get_kept(s: &mut TcpStream, path: &str) -> bool {
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    if write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").is_err() {
        return false;
    }
    while !head.ends_with(b"\r\n\r\n") {
        if !matches!(s.read(&mut byte), Ok(1)) {
            return false;
        }
        head.push(byte[0]);
    }
    let head = String::from_utf8_lossy(&head);
    let len = (head.lines())
        .find_map(|l| l.strip_prefix("content-length: "))
        .and_then(|v| v.trim().parse::<usize>().ok());
    let mut body = vec![0u8; len.unwrap_or(0)];
    head.starts_with("HTTP/1.1 200 OK") && len.is_some() && s.read_exact(&mut body).is_ok()
}

#[test]
fn idle_connections_cannot_lock_the_live_page_out() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let mut child = daemon("[metrics]\nlisten = \"127.0.0.1:0\"\n", dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut ends, rest) = endpoints(&mut child, 1);
    let page = ends.remove(0);
    // Eight idle sockets take every slot (the default limit); the page's browser polls on one
    // kept-alive connection while 20 more pile up.
    let held = crowd(&page, 8);
    std::thread::sleep(Duration::from_millis(100));
    let mut browser = TcpStream::connect(&page).unwrap();
    browser
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let mut idle = Vec::new();
    let mut answered = 0;
    for _ in 0..20 {
        idle.extend(crowd(&page, 1));
        answered += usize::from(get_kept(&mut browser, "/api/live"));
        std::thread::sleep(Duration::from_millis(10));
    }
    assert_eq!(answered, 20);
    let text = scrape(&page);
    let evicted: u64 = text
        .lines()
        .find_map(|l| {
            l.strip_prefix("valve_bridge_server_connections_evicted_total{server=\"metrics\"} ")
        })
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{text}"));
    assert!(evicted >= 20, "{text}");
    drop((held, idle, browser));
    let (_, stderr) = stop(child, rest);
    assert!(
        stderr.contains("metrics endpoint: at the limit of 8 connections: closed the one from"),
        "{stderr}"
    );
}

#[test]
fn connections_that_never_send_a_request_are_closed() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = format!("{HIL}idle_timeout_s = 0.5\n");
    let mut child = daemon(&config, dir.path())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut ends, rest) = endpoints(&mut child, 1);
    let modbus = ends.remove(0);
    let mut idle = crowd(&modbus, 3);
    std::thread::sleep(Duration::from_millis(900));
    for s in &mut idle {
        s.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        assert!(matches!(s.read(&mut [0u8; 1]), Ok(0)), "still open");
    }
    assert_eq!(write_register(&modbus, 300).unwrap(), 300);
    let (summary, stderr) = stop(child, rest);
    assert!(server_line(&summary).contains("3 closed idle"), "{summary}");
    assert!(stderr.contains("no first request for 0.5 s"), "{stderr}");
}

#[test]
fn sim_device_serves_a_client_through_a_crowd_of_idle_sockets() {
    let mut cmd = Command::new(common::sim::sim_device_bin());
    cmd.args(["--tcp", "127.0.0.1:0"]).env("RUST_LOG", "info");
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (mut ends, rest) = endpoints(&mut child, 1);
    let addr = ends.remove(0);
    // sim-device's default limit is 16.
    let held = crowd(&addr, 16);
    std::thread::sleep(Duration::from_millis(100));
    let (answered, idle) = talk_through_a_crowd(&addr, 40, 1);
    assert_eq!(answered, 40);
    drop((held, idle));
    let (_, stderr) = stop(child, rest);
    assert!(
        stderr.contains("at the limit of 16 connections"),
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
