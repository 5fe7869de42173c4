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

use std::io::Read;
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use crate::common;

use crate::common::servers::{
    crowd, daemon, get_kept, metric, scrape, server_line, write_register, Client, Server,
};
use crate::common::sim::real_time_turn;

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

const HIL: &str = "[source]\nkind = \"modbus-server\"\n[source.modbus-server]\nlisten = \"127.0.0.1:0\"\nwatchdog_s = 60.0\n";

#[test]
fn daemon_servers_survive_running_out_of_file_descriptors() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = format!(
        "{HIL}max_connections = 1000\n[metrics]\nlisten = \"127.0.0.1:0\"\nmax_connections = 1000\n"
    );
    let server = Server::announced(spawn_with_fd_limit(&mut daemon(&config, dir.path()), 64), 2);
    let (modbus, metrics) = (&server.ends[0], &server.ends[1]);
    // More idle connections than descriptors: accept() fails with EMFILE.
    let idle = crowd(modbus, 100);
    std::thread::sleep(Duration::from_millis(500));
    drop(idle);
    std::thread::sleep(Duration::from_millis(500));
    // Served again: the controller's write is taken, the endpoint answers.
    assert_eq!(write_register(modbus, 420).unwrap(), 420);
    let text = scrape(metrics);
    let errors = metric(
        &text,
        "valve_bridge_server_accept_errors_total{server=\"modbus-server\"}",
    );
    assert!(errors > 0, "{text}");
    assert!(
        text.contains("valve_bridge_server_up{server=\"modbus-server\"} 1"),
        "{text}"
    );
    let (summary, stderr) = server.stop();
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

/// Writes `n` set-points 10 ms apart while idle sockets pile up against `addr` (`idle_per_write`
/// more before each write): how many were answered, and the idle sockets.
fn talk_through_a_crowd(addr: &str, n: usize, idle_per_write: usize) -> (usize, Vec<TcpStream>) {
    let mut controller = Client::connect(addr);
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
    let server = Server::start(&mut daemon(&config, dir.path()), 1);
    let modbus = server.ends[0].clone();
    // Eight idle sockets take every slot; the controller connects and talks while 28 more pile
    // up.
    let held = crowd(&modbus, 8);
    std::thread::sleep(Duration::from_millis(100));
    let (answered, idle) = talk_through_a_crowd(&modbus, 28, 1);
    assert_eq!(answered, 28);
    drop((held, idle));
    let (summary, stderr) = server.stop();
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

#[test]
fn idle_connections_cannot_lock_the_live_page_out() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(
        &mut daemon("[metrics]\nlisten = \"127.0.0.1:0\"\n", dir.path()),
        1,
    );
    let page = server.ends[0].clone();
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
    let evicted = metric(
        &text,
        "valve_bridge_server_connections_evicted_total{server=\"metrics\"}",
    );
    assert!(evicted >= 20, "{text}");
    drop((held, idle, browser));
    let (_, stderr) = server.stop();
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
    let server = Server::start(&mut daemon(&config, dir.path()), 1);
    let modbus = server.ends[0].clone();
    let mut idle = crowd(&modbus, 3);
    std::thread::sleep(Duration::from_millis(900));
    for s in &mut idle {
        s.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        assert!(matches!(s.read(&mut [0u8; 1]), Ok(0)), "still open");
    }
    assert_eq!(write_register(&modbus, 300).unwrap(), 300);
    let (summary, stderr) = server.stop();
    assert!(server_line(&summary).contains("3 closed idle"), "{summary}");
    assert!(stderr.contains("no first request for 0.5 s"), "{stderr}");
}

#[test]
fn sim_device_serves_a_client_through_a_crowd_of_idle_sockets() {
    let mut cmd = Command::new(common::sim::sim_device_bin());
    cmd.args(["--tcp", "127.0.0.1:0"]).env("RUST_LOG", "info");
    let server = Server::start(&mut cmd, 1);
    let addr = server.ends[0].clone();
    // sim-device's default limit is 16.
    let held = crowd(&addr, 16);
    std::thread::sleep(Duration::from_millis(100));
    let (answered, idle) = talk_through_a_crowd(&addr, 40, 1);
    assert_eq!(answered, 40);
    drop((held, idle));
    let (_, stderr) = server.stop();
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
    let mut server = Server::announced(spawn_with_fd_limit(&mut cmd, 48), 1);
    let addr = server.ends[0].clone();
    let idle = crowd(&addr, 80);
    std::thread::sleep(Duration::from_millis(500));
    drop(idle);
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(write_register(&addr, 250).unwrap(), 250);
    assert!(server.running(), "sim-device exited");
    let (_, stderr) = server.stop();
    assert!(stderr.contains("Too many open files"), "{stderr}");
    assert!(
        stderr.contains("SIGTERM: stopping; Modbus TCP served") && stderr.contains("accept errors"),
        "{stderr}"
    );
}
