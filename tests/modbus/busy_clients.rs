//! The controller always gets through: the daemon's servers, at their default limit of 8
//! connections, against clients that keep them busy, through the real binary over loopback TCP
//! (a client on 127.0.0.2 is another host to the server). Every busy client polls on one
//! connection and reconnects at once when it is closed, so the server is full all the time.
//!
//! - Eight Modbus readers polling every 2 ms and a process controller writing a set-point every
//!   100 ms on one connection (no `controllers` configured): at least 90 % of its writes land, the
//!   log has no `watchdog` row, and the evictions are told in one line per host per minute.
//! - With `controllers = ["127.0.0.2"]`, sixteen readers on 127.0.0.1: at least 90 % of the
//!   writes of the controller on 127.0.0.2 land, no `watchdog` row, the readers are answered; a
//!   client on 127.0.0.3 reads, and its write gets exception 01.
//! - Sixteen keep-alive clients polling `/metrics` from 127.0.0.1, and a scraper on 127.0.0.2
//!   with a connection per scrape: at least 95 % of its scrapes are answered.
//! - Eight browsers polling `/api/live` and a scraper keeping its connection, all on 127.0.0.1:
//!   at least 95 % of its scrapes are answered.

use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::common;

use crate::common::servers::{
    connect_from, daemon, get_kept, scrape_from, server_line, Client, Server,
};
use crate::common::sim::real_time_turn;

/// One row of a daemon log.
#[derive(Debug, serde::Deserialize)]
struct Row {
    status: String,
}

/// `n` clients running `client` on threads of their own until stopped; each returns how many
/// requests it had answered.
struct Busy {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<u64>>,
}

impl Busy {
    fn start<F>(n: usize, client: F) -> Busy
    where
        F: Fn(&AtomicBool) -> u64 + Send + Sync + 'static,
    {
        let stop = Arc::new(AtomicBool::new(false));
        let client = Arc::new(client);
        let threads = (0..n)
            .map(|_| {
                let (stop, client) = (Arc::clone(&stop), Arc::clone(&client));
                std::thread::spawn(move || client(&stop))
            })
            .collect();
        // Let them fill the server.
        std::thread::sleep(Duration::from_millis(300));
        Busy { stop, threads }
    }

    /// Stops the clients: the requests they had answered, all together.
    fn stop(self) -> u64 {
        self.stop.store(true, Ordering::Relaxed);
        self.threads.into_iter().map(|t| t.join().unwrap()).sum()
    }
}

/// A Modbus reader of `addr` from 127.0.0.1: holding 0-2 every 2 ms, reconnecting at once.
fn reader(addr: String) -> impl Fn(&AtomicBool) -> u64 {
    move |stop| {
        let mut answered = 0;
        while !stop.load(Ordering::Relaxed) {
            let Ok(mut c) = Client::connect_from("127.0.0.1", &addr) else {
                std::thread::sleep(Duration::from_millis(2));
                continue;
            };
            while !stop.load(Ordering::Relaxed) && c.read() {
                answered += 1;
                std::thread::sleep(Duration::from_millis(2));
            }
        }
        answered
    }
}

/// A process controller on `from` writing `n` set-points to `addr`, one every 100 ms, on one
/// connection (reopened before the next write when one fails): how many landed.
fn control(from: &str, addr: &str, n: u32) -> u32 {
    let start = Instant::now();
    let mut client = None;
    let mut landed = 0;
    for k in 0..n {
        std::thread::sleep(
            (start + Duration::from_millis(100) * k).saturating_duration_since(Instant::now()),
        );
        if client.is_none() {
            client = Client::connect_from(from, addr).ok();
        }
        let ok = client
            .as_mut()
            .is_some_and(|c| c.write(300 + (k % 100) as u16));
        if !ok {
            client = None;
        }
        landed += u32::from(ok);
    }
    landed
}

/// Stops `server`, whose logs are in `dir/logs`: its summary, its log and how many rows are
/// `watchdog`.
fn stop_hil(server: Server, dir: &std::path::Path) -> (String, String, usize) {
    let (summary, stderr) = server.stop();
    let rows: Vec<Row> = common::sim::read_log(&dir.join("logs"));
    let watchdog = rows.iter().filter(|r| r.status == "watchdog").count();
    (summary, stderr, watchdog)
}

const HIL: &str = "[source]\nkind = \"modbus-server\"\n[source.modbus-server]\nlisten = \"127.0.0.1:0\"\nwatchdog_s = 0.5\n";

#[test]
fn busy_readers_cannot_lock_the_controller_out() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&mut daemon(HIL, dir.path()), 1);
    let addr = server.ends[0].clone();
    let readers = Busy::start(8, reader(addr.clone()));
    let landed = control("127.0.0.1", &addr, 90);
    let reads = readers.stop();
    let (summary, stderr, watchdog) = stop_hil(server, dir.path());
    let line = server_line(&summary);
    let evictions = stderr.matches("at the limit of 8 connections").count();
    println!(
        "8 readers every 2 ms, a controller every 100 ms: {landed} of 90 writes landed, \
         {watchdog} watchdog rows, {reads} reads answered; {line}; {evictions} eviction lines"
    );
    assert!(landed >= 81, "{landed} of 90 writes landed\n{summary}");
    assert_eq!(watchdog, 0, "{summary}");
    // The readers' host loses connections all the time: told once (within the minute).
    assert!(line.contains("evicted at the limit"), "{line}");
    assert_eq!(evictions, 1, "{stderr}");
}

#[test]
fn configured_controllers_keep_their_slot_and_alone_may_write() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = format!("{HIL}controllers = [\"127.0.0.2\"]\n");
    let server = Server::start(&mut daemon(&config, dir.path()), 1);
    let addr = server.ends[0].clone();
    let readers = Busy::start(16, reader(addr.clone()));
    let landed = control("127.0.0.2", &addr, 50);
    // A client on another host that is not a controller may read but not write: exception 01
    // (illegal function) for FC 6.
    let mut other = Client::connect_from("127.0.0.3", &addr).unwrap();
    assert!(other.read());
    let refused = other.write_reply(500);
    let reads = readers.stop();
    let (summary, stderr, watchdog) = stop_hil(server, dir.path());
    println!(
        "16 readers, a configured controller every 100 ms: {landed} of 50 writes landed, \
         {watchdog} watchdog rows, {reads} reads answered; {}",
        server_line(&summary)
    );
    assert!(landed >= 45, "{landed} of 50 writes landed\n{summary}");
    assert_eq!(watchdog, 0, "{summary}");
    assert!(reads > 1000, "{reads} reads answered");
    assert_eq!(refused, Some(vec![0x86, 1]));
    assert!(
        stderr.contains("refused a write from 127.0.0.3:"),
        "{stderr}"
    );
}

/// A client of the HTTP server `addr` from 127.0.0.1 asking for `path` every `every` on a
/// kept-alive connection, reconnecting at once.
fn browser(addr: String, path: &'static str, every: Duration) -> impl Fn(&AtomicBool) -> u64 {
    move |stop| {
        let mut answered = 0;
        while !stop.load(Ordering::Relaxed) {
            let Ok(mut s) = connect_from("127.0.0.1", &addr, Duration::from_secs(2)) else {
                std::thread::sleep(every);
                continue;
            };
            while !stop.load(Ordering::Relaxed) && get_kept(&mut s, path) {
                answered += 1;
                std::thread::sleep(every);
            }
        }
        answered
    }
}

const METRICS: &str = "[metrics]\nlisten = \"127.0.0.1:0\"\n";

/// True when `reply` is a whole answer of `GET /metrics`.
fn scraped(reply: &str) -> bool {
    reply.starts_with("HTTP/1.1 200 OK") && reply.contains("valve_bridge_cycles_total")
}

#[test]
fn keep_alive_clients_cannot_push_out_a_scraper_on_another_host() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&mut daemon(METRICS, dir.path()), 1);
    let addr = server.ends[0].clone();
    let clients = Busy::start(
        16,
        browser(addr.clone(), "/metrics", Duration::from_millis(2)),
    );
    let mut answered = 0;
    for _ in 0..50 {
        answered += usize::from(scrape_from("127.0.0.2", &addr).is_ok_and(|r| scraped(&r)));
        std::thread::sleep(Duration::from_millis(100));
    }
    let theirs = clients.stop();
    let (_, stderr) = server.stop();
    let lines = stderr.matches("at the limit of 8 connections").count();
    println!(
        "16 keep-alive clients on /metrics: {answered} of 50 scrapes from another host answered, \
         {theirs} of the clients' requests answered, {lines} eviction lines"
    );
    assert!(answered >= 48, "{answered} of 50 scrapes answered");
    assert!(lines <= 2, "{stderr}");
}

#[test]
fn browsers_cannot_push_out_a_scraper_that_keeps_its_connection() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&mut daemon(METRICS, dir.path()), 1);
    let addr = server.ends[0].clone();
    let browsers = Busy::start(
        8,
        browser(addr.clone(), "/api/live", Duration::from_millis(2)),
    );
    let mut scraper: Option<TcpStream> = None;
    let mut answered = 0;
    for _ in 0..20 {
        if scraper.is_none() {
            scraper = connect_from("127.0.0.1", &addr, Duration::from_secs(2)).ok();
        }
        let ok = scraper.as_mut().is_some_and(|s| get_kept(s, "/metrics"));
        if !ok {
            scraper = None;
        }
        answered += usize::from(ok);
        std::thread::sleep(Duration::from_millis(200));
    }
    let theirs = browsers.stop();
    drop(server.stop());
    println!(
        "8 browsers on /api/live: {answered} of 20 scrapes on a kept connection answered, \
         {theirs} of the browsers' requests answered"
    );
    assert!(answered >= 19, "{answered} of 20 scrapes answered");
}
