//! TCP servers that stay up: one accept loop for the daemon's Modbus server (HIL), its metrics
//! endpoint and sim-device.
//!
//! [`serve`] accepts connections until its task is dropped and hands each to a handler task. It
//! never stops on its own: an `accept()` error (too many open files, no buffer space, a
//! connection aborted before it was taken) is logged once per outage, counted, and retried
//! after [`ACCEPT_RETRY`]. At most [`Limits::max_connections`] connections are open at once, so
//! a flood of clients cannot use up the file descriptors; a new connection is not turned away
//! for another client's, though: at the limit one open connection is closed to make room, chosen
//! by the `admission` module: never a process controller's, first from the host holding the most
//! connections, a socket that never sent a request in its first 100 ms before one that did, and
//! one that did before a newcomer still within those 100 ms, then the one idle longest. A
//! controller is a configured address ([`Limits::controllers`], with slots kept for it) or a
//! connection its handler raised to [`Standing::Controller`] (the HIL server does on an
//! accepted set-point write); the metrics endpoint raises a scraper's to
//! [`Standing::Preferred`]. Only when every slot is a controller's is a new connection refused.
//! The closings and refusals are logged through a [`PeerLog`]: one line per host a minute, with
//! how many more there were. Each handler tells [`serve`] of its requests through its
//! [`Activity`] and closes its connection after [`Limits::idle_timeout`] without one, or
//! [`FIRST_REQUEST_TIMEOUT`] without a first (it knows what a request is). [`Health`] keeps the
//! figures (accepted, evicted, refused, idle-closed, open, accept errors, time spent unable to
//! accept) for the summary and the metrics.
//!
//! Not here: any protocol (see [`crate::tcp_server`] and the daemon's exporter).

mod admission;
mod peer_log;

use std::future::Future;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::net::{TcpListener, TcpStream};

pub use admission::Standing;
use admission::{Held, Room};
pub use peer_log::{HeldBack, PeerLog};

/// Pause after a failed `accept()` before the next try.
pub const ACCEPT_RETRY: Duration = Duration::from_millis(100);
/// A connection that sends no first request for this long (or the idle timeout, if shorter)
/// is closed: a client connects to talk.
pub const FIRST_REQUEST_TIMEOUT: Duration = Duration::from_secs(5);

/// How many connections a server keeps, for how long an idle one, and whose it never closes
/// for another's.
#[derive(Debug, Clone, PartialEq)]
pub struct Limits {
    /// Connections open at once; at the limit one makes room for a new one (see [`serve`]).
    pub max_connections: usize,
    /// A connection without a request for this long is closed.
    pub idle_timeout: Duration,
    /// The process controllers' addresses: their connections have [`Standing::Controller`]
    /// from the start and one slot each is kept for them (the others hold at most
    /// `max_connections` minus their number). Fewer than `max_connections`.
    pub controllers: Arc<[IpAddr]>,
}

impl Limits {
    /// How long a connection may wait for its next request: its first ([`FIRST_REQUEST_TIMEOUT`]
    /// at most) or a later one.
    pub fn request_timeout(&self, activity: &Activity) -> Duration {
        if activity.requests() == 0 {
            self.idle_timeout.min(FIRST_REQUEST_TIMEOUT)
        } else {
            self.idle_timeout
        }
    }

    /// True when `ip` is a configured controller's address.
    pub fn is_controller(&self, ip: IpAddr) -> bool {
        self.controllers.contains(&ip.to_canonical())
    }
}

/// When a connection last sent a request and its standing, shared by its handler (which calls
/// [`Activity::request`] and [`Activity::raise`]) and [`serve`] (which chooses whom to close at
/// the limit).
#[derive(Debug, Clone)]
pub struct Activity(Arc<ActivityInner>);

#[derive(Debug)]
struct ActivityInner {
    opened: Instant,
    /// ns after `opened` of the last request.
    last_ns: AtomicU64,
    requests: AtomicU64,
    /// A [`Standing`] as its `u8`.
    standing: AtomicU8,
}

impl Activity {
    fn new(standing: Standing) -> Activity {
        Activity(Arc::new(ActivityInner {
            opened: Instant::now(),
            last_ns: AtomicU64::new(0),
            requests: AtomicU64::new(0),
            standing: AtomicU8::new(standing as u8),
        }))
    }

    /// A request arrived.
    pub fn request(&self) {
        let ns = self.0.opened.elapsed().as_nanos() as u64;
        self.0.last_ns.store(ns, Ordering::Relaxed);
        self.0.requests.fetch_add(1, Ordering::Relaxed);
    }

    /// Requests so far.
    pub fn requests(&self) -> u64 {
        self.0.requests.load(Ordering::Relaxed)
    }

    /// The connection has shown it is worth `standing` (kept if it already had a higher one).
    pub fn raise(&self, standing: Standing) {
        self.0.standing.fetch_max(standing as u8, Ordering::Relaxed);
    }

    /// Its standing now.
    fn standing(&self) -> Standing {
        Standing::from_u8(self.0.standing.load(Ordering::Relaxed))
    }

    /// Time since the last request (since the connection opened, before the first).
    fn idle(&self) -> Duration {
        let last = Duration::from_nanos(self.0.last_ns.load(Ordering::Relaxed));
        self.0.opened.elapsed().saturating_sub(last)
    }
}

/// The figures of one server, updated as it runs (lock-free but for the last error's text).
#[derive(Debug, Default)]
pub struct Health {
    accepted: AtomicU64,
    evicted: AtomicU64,
    refused: AtomicU64,
    idle_closed: AtomicU64,
    open: AtomicU64,
    accept_errors: AtomicU64,
    down_ns: AtomicU64,
    down: AtomicBool,
    last_error: Mutex<Option<String>>,
}

/// A snapshot of [`Health`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HealthView {
    /// Connections accepted (the refused ones too).
    pub accepted: u64,
    /// Connections closed at the limit to make room for a new one.
    pub evicted: u64,
    /// New connections closed at once at the limit: every slot was a controller's.
    pub refused: u64,
    /// Connections closed for being idle.
    pub idle_closed: u64,
    /// Connections open now.
    pub open: u64,
    /// Failed `accept()` calls.
    pub accept_errors: u64,
    /// Time spent unable to accept, s (outages that ended).
    pub down_s: f64,
    /// True while `accept()` fails.
    pub down: bool,
    /// The last `accept()` error.
    pub last_error: Option<String>,
}

impl Health {
    /// The figures now.
    pub fn view(&self) -> HealthView {
        HealthView {
            accepted: self.accepted.load(Ordering::Relaxed),
            evicted: self.evicted.load(Ordering::Relaxed),
            refused: self.refused.load(Ordering::Relaxed),
            idle_closed: self.idle_closed.load(Ordering::Relaxed),
            open: self.open.load(Ordering::Relaxed),
            accept_errors: self.accept_errors.load(Ordering::Relaxed),
            down_s: self.down_ns.load(Ordering::Relaxed) as f64 / 1e9,
            down: self.down.load(Ordering::Relaxed),
            last_error: self
                .last_error
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clone(),
        }
    }

    /// Counts a connection closed by its handler for being idle.
    pub fn idle_closed(&self) {
        self.idle_closed.fetch_add(1, Ordering::Relaxed);
    }
}

impl std::fmt::Display for HealthView {
    /// `12 connections (1 open), 3 evicted at the limit, 1 refused at the limit, 2 closed idle,
    /// 5 accept errors (the last: ...), unable to accept for 0.5 s`: the figures that are not
    /// zero.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} connections ({} open)", self.accepted, self.open)?;
        if self.evicted > 0 {
            write!(f, ", {} evicted at the limit", self.evicted)?;
        }
        if self.refused > 0 {
            write!(f, ", {} refused at the limit", self.refused)?;
        }
        if self.idle_closed > 0 {
            write!(f, ", {} closed idle", self.idle_closed)?;
        }
        if self.accept_errors > 0 {
            write!(f, ", {} accept errors", self.accept_errors)?;
            if let Some(e) = &self.last_error {
                write!(f, " (the last: {e})")?;
            }
            write!(f, ", unable to accept for {:.1} s", self.down_s)?;
            if self.down {
                write!(f, " and still failing")?;
            }
        }
        Ok(())
    }
}

/// Decrements the open count when a connection's task ends.
struct OpenGuard(Arc<Health>);

impl Drop for OpenGuard {
    fn drop(&mut self) {
        self.0.open.fetch_sub(1, Ordering::Relaxed);
    }
}

/// An open connection, as [`serve`] keeps track of it.
struct Open {
    peer: SocketAddr,
    activity: Activity,
    task: tokio::task::AbortHandle,
}

/// Accepts connections on `listener` forever (see the module documentation); `what` names the
/// server in the log. Each connection gets `TCP_NODELAY` and runs `handle(stream, peer,
/// activity)` on a task of its own; its error is logged at debug level.
pub async fn serve<F, Fut>(
    what: &'static str,
    listener: TcpListener,
    limits: Limits,
    health: Arc<Health>,
    handle: F,
) where
    F: Fn(TcpStream, SocketAddr, Activity) -> Fut,
    Fut: Future<Output = std::io::Result<()>> + Send + 'static,
{
    let mut down_since: Option<Instant> = None;
    let mut open: Vec<Open> = Vec::with_capacity(limits.max_connections);
    let mut door = Door {
        what,
        limits: &limits,
        health: &health,
        told: PeerLog::default(),
    };
    loop {
        let (stream, peer) = match listener.accept().await {
            Ok(accepted) => accepted,
            Err(e) => {
                health.accept_errors.fetch_add(1, Ordering::Relaxed);
                *health.last_error.lock().unwrap_or_else(|p| p.into_inner()) = Some(e.to_string());
                if down_since.is_none() {
                    down_since = Some(Instant::now());
                    health.down.store(true, Ordering::Relaxed);
                    tracing::error!(
                        "{what}: cannot accept connections: {e}; retrying every {} ms",
                        ACCEPT_RETRY.as_millis()
                    );
                }
                tokio::time::sleep(ACCEPT_RETRY).await;
                continue;
            }
        };
        if let Some(since) = down_since.take() {
            let down = since.elapsed();
            health
                .down_ns
                .fetch_add(down.as_nanos() as u64, Ordering::Relaxed);
            health.down.store(false, Ordering::Relaxed);
            tracing::warn!(
                "{what}: accepting connections again after {:.1} s",
                down.as_secs_f64()
            );
        }
        health.accepted.fetch_add(1, Ordering::Relaxed);
        let Some(activity) = door.admit(&mut open, peer) else {
            continue;
        };
        health.open.fetch_add(1, Ordering::Relaxed);
        let guard = OpenGuard(Arc::clone(&health));
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!("{what}: TCP_NODELAY on {peer}: {e}");
        }
        let task = handle(stream, peer, activity.clone());
        let task = tokio::spawn(async move {
            let _open = guard;
            if let Err(e) = task.await {
                tracing::debug!("{what}: connection from {peer} ended: {e}");
            }
        });
        open.push(Open {
            peer,
            activity,
            task: task.abort_handle(),
        });
    }
}

/// What [`serve`] decides a new connection by, and the log of what it closed or refused.
struct Door<'a> {
    what: &'static str,
    limits: &'a Limits,
    health: &'a Health,
    told: PeerLog,
}

impl Door<'_> {
    /// Makes room for the new connection from `peer` among `open` (closing one if need be):
    /// its [`Activity`], or None when it is refused.
    fn admit(&mut self, open: &mut Vec<Open>, peer: SocketAddr) -> Option<Activity> {
        open.retain(|c| !c.task.is_finished());
        let ip = peer.ip().to_canonical();
        let standing = if self.limits.is_controller(ip) {
            Standing::Controller
        } else {
            Standing::Ordinary
        };
        let max = self.limits.max_connections;
        let reserved = self.limits.controllers.len();
        // Below the limit, with room for either kind, no list of the open ones is needed.
        let room = if open.len() + reserved < max {
            Room::Free
        } else {
            let held: Vec<Held> = open
                .iter()
                .map(|c| Held {
                    ip: c.peer.ip().to_canonical(),
                    standing: c.activity.standing(),
                    silent: c.activity.requests() == 0,
                    idle: c.activity.idle(),
                })
                .collect();
            admission::room(&held, (ip, standing), max, reserved)
        };
        match room {
            Room::Free => {}
            Room::Close(i) => self.evict(open, i, peer),
            Room::Refuse => {
                self.health.refused.fetch_add(1, Ordering::Relaxed);
                if let Some(held) = self.told.admit(ip, Instant::now()) {
                    tracing::warn!(
                        "{}: at the limit of {max} connections, every one a process \
                         controller's: refused the new one from {peer}{held}",
                        self.what
                    );
                }
                return None;
            }
        }
        Some(Activity::new(standing))
    }

    /// Closes `open[i]` for the new connection from `new_peer`.
    fn evict(&mut self, open: &mut Vec<Open>, i: usize, new_peer: SocketAddr) {
        let gone = open.swap_remove(i);
        gone.task.abort();
        self.health.evicted.fetch_add(1, Ordering::Relaxed);
        let Some(held) = self
            .told
            .admit(gone.peer.ip().to_canonical(), Instant::now())
        else {
            return;
        };
        let requests = gone.activity.requests();
        tracing::warn!(
            "{}: at the limit of {} connections: closed the one from {} ({}, idle for {:.1} s) \
             to take the new one from {new_peer}{held}",
            self.what,
            self.limits.max_connections,
            gone.peer,
            match requests {
                0 => "no request".to_string(),
                n => format!("{n} requests"),
            },
            gone.activity.idle().as_secs_f64()
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    /// Reads `c` until it closes or `ms` pass: true when it was closed.
    async fn closed(c: &mut TcpStream, ms: u64) -> bool {
        let mut b = [0u8; 1];
        matches!(
            tokio::time::timeout(Duration::from_millis(ms), c.read(&mut b)).await,
            Ok(Ok(0) | Err(_))
        )
    }

    #[tokio::test]
    async fn at_the_limit_the_longest_idle_connection_makes_room() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let health = Arc::new(Health::default());
        let limits = Limits {
            max_connections: 3,
            idle_timeout: Duration::from_secs(60),
            controllers: Arc::default(),
        };
        // Handlers count every byte as a request and hold their connection until it closes.
        let server = tokio::spawn(serve(
            "test",
            listener,
            limits,
            Arc::clone(&health),
            |mut s, _, activity| async move {
                let mut b = [0u8; 1];
                while s.read(&mut b).await? > 0 {
                    activity.request();
                }
                Ok(())
            },
        ));
        // A controller that talks, then two sockets that never do.
        let mut controller = TcpStream::connect(addr).await.unwrap();
        controller.write_all(b"x").await.unwrap();
        let mut idle = Vec::new();
        for _ in 0..2 {
            idle.push(TcpStream::connect(addr).await.unwrap());
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        // Ten more arrive, each while the controller keeps talking and after the silent ones'
        // grace: each takes the place of the socket that has waited longest without a request;
        // the controller stays.
        for _ in 0..10 {
            controller.write_all(b"x").await.unwrap();
            tokio::time::sleep(Duration::from_millis(120)).await;
            idle.push(TcpStream::connect(addr).await.unwrap());
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert!(!closed(&mut controller, 100).await);
        let mut still_open = 0;
        for c in &mut idle {
            still_open += usize::from(!closed(c, 50).await);
        }
        assert_eq!(still_open, 2);
        let v = health.view();
        assert_eq!((v.accepted, v.evicted, v.open), (13, 10, 3));
        assert!(v
            .to_string()
            .starts_with("13 connections (3 open), 10 evicted at the limit"));
        server.abort();
    }

    #[tokio::test]
    async fn a_controller_is_never_closed_for_another_and_when_all_are_the_new_one_is_refused() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let health = Arc::new(Health::default());
        let limits = Limits {
            max_connections: 2,
            idle_timeout: Duration::from_secs(60),
            controllers: Arc::default(),
        };
        // A `w` is an accepted set-point write: the connection is a controller's from then on.
        let server = tokio::spawn(serve(
            "test",
            listener,
            limits,
            Arc::clone(&health),
            |mut s, _, activity| async move {
                let mut b = [0u8; 1];
                while s.read(&mut b).await? > 0 {
                    activity.request();
                    if b[0] == b'w' {
                        activity.raise(Standing::Controller);
                    }
                }
                Ok(())
            },
        ));
        let pause = || tokio::time::sleep(Duration::from_millis(30));
        let mut controller = TcpStream::connect(addr).await.unwrap();
        controller.write_all(b"w").await.unwrap();
        pause().await;
        // Readers keep coming, each busier than the controller: they take each other's place.
        let mut readers = Vec::new();
        for _ in 0..5 {
            let mut r = TcpStream::connect(addr).await.unwrap();
            r.write_all(b"rrr").await.unwrap();
            readers.push(r);
            pause().await;
        }
        assert!(!closed(&mut controller, 50).await);
        let mut open = 0;
        for r in &mut readers {
            open += usize::from(!closed(r, 20).await);
        }
        assert_eq!(open, 1);
        // Once every slot is a controller's, a new connection is closed at once.
        readers.last_mut().unwrap().write_all(b"w").await.unwrap();
        pause().await;
        let mut late = TcpStream::connect(addr).await.unwrap();
        assert!(closed(&mut late, 200).await);
        assert!(!closed(&mut controller, 20).await);
        let v = health.view();
        assert_eq!((v.accepted, v.evicted, v.refused, v.open), (7, 4, 1, 2));
        assert!(v
            .to_string()
            .contains("4 evicted at the limit, 1 refused at the limit"));
        server.abort();
    }
}
