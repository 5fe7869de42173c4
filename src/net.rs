//! TCP servers that stay up: one accept loop for the daemon's Modbus server (HIL), its metrics
//! endpoint and sim-device.
//!
//! [`serve`] accepts connections until its task is dropped and hands each to a handler task. It
//! never stops on its own: an `accept()` error (too many open files, no buffer space, a
//! connection aborted before it was taken) is logged once per outage, counted, and retried
//! after [`ACCEPT_RETRY`]. At most [`Limits::max_connections`] connections are open at once; a
//! connection beyond that is closed at once (and counted), so a flood of idle clients cannot
//! use up the file descriptors. Closing idle connections after [`Limits::idle_timeout`] is the
//! handler's part (it knows what a request is). [`Health`] keeps the figures (accepted,
//! refused, open, accept errors, time spent unable to accept) for the summary and the metrics.
//!
//! Not here: any protocol (see [`crate::modbus::tcp_server`] and the daemon's exporter).

use std::future::Future;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::net::{TcpListener, TcpStream};

/// Pause after a failed `accept()` before the next try.
pub const ACCEPT_RETRY: Duration = Duration::from_millis(100);

/// How many connections a server keeps, and for how long an idle one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Connections open at once; more are closed as they arrive.
    pub max_connections: usize,
    /// A connection without a request for this long is closed.
    pub idle_timeout: Duration,
}

/// The figures of one server, updated as it runs (lock-free but for the last error's text).
#[derive(Debug, Default)]
pub struct Health {
    accepted: AtomicU64,
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
    /// Connections accepted.
    pub accepted: u64,
    /// Connections closed on arrival because the limit was reached.
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
    /// `12 connections (1 open), 3 refused at the limit, 2 closed idle, 5 accept errors (the
    /// last: ...), unable to accept for 0.5 s`: the figures that are not zero.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} connections ({} open)", self.accepted, self.open)?;
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

/// Accepts connections on `listener` forever (see the module documentation); `what` names the
/// server in the log. Each connection gets `TCP_NODELAY` and runs `handle(stream, peer)` on a
/// task of its own; its error is logged at debug level.
pub async fn serve<F, Fut>(
    what: &'static str,
    listener: TcpListener,
    limits: Limits,
    health: Arc<Health>,
    handle: F,
) where
    F: Fn(TcpStream, SocketAddr) -> Fut,
    Fut: Future<Output = std::io::Result<()>> + Send + 'static,
{
    let mut down_since: Option<Instant> = None;
    let mut refusing = false;
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
        if health.open.load(Ordering::Relaxed) >= limits.max_connections as u64 {
            health.refused.fetch_add(1, Ordering::Relaxed);
            if !refusing {
                tracing::warn!(
                    "{what}: {} connections open, the limit: closing new ones (from {peer}) \
                     until one ends",
                    limits.max_connections
                );
            }
            refusing = true;
            continue;
        }
        refusing = false;
        health.accepted.fetch_add(1, Ordering::Relaxed);
        health.open.fetch_add(1, Ordering::Relaxed);
        let guard = OpenGuard(Arc::clone(&health));
        if let Err(e) = stream.set_nodelay(true) {
            tracing::debug!("{what}: TCP_NODELAY on {peer}: {e}");
        }
        let task = handle(stream, peer);
        tokio::spawn(async move {
            let _open = guard;
            if let Err(e) = task.await {
                tracing::debug!("{what}: connection from {peer} ended: {e}");
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncReadExt;

    #[tokio::test]
    async fn connections_beyond_the_limit_are_closed_and_counted() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let health = Arc::new(Health::default());
        let limits = Limits {
            max_connections: 2,
            idle_timeout: Duration::from_secs(60),
        };
        // Handlers hold their connection until the client closes it.
        let server = tokio::spawn(serve(
            "test",
            listener,
            limits,
            Arc::clone(&health),
            |mut s, _| async move {
                let mut b = [0u8; 1];
                while s.read(&mut b).await? > 0 {}
                Ok(())
            },
        ));
        let mut clients = Vec::new();
        for _ in 0..5 {
            clients.push(TcpStream::connect(addr).await.unwrap());
        }
        // The three beyond the limit read end-of-stream at once.
        let mut closed = 0;
        for c in &mut clients {
            let mut b = [0u8; 1];
            if let Ok(Ok(0)) =
                tokio::time::timeout(Duration::from_millis(200), c.read(&mut b)).await
            {
                closed += 1;
            }
        }
        assert_eq!(closed, 3);
        let v = health.view();
        assert_eq!((v.accepted, v.refused, v.open), (2, 3, 2));
        // One leaves: a new one is taken.
        clients.remove(0);
        tokio::time::sleep(Duration::from_millis(50)).await;
        let _new = TcpStream::connect(addr).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
        assert_eq!(health.view().accepted, 3);
        assert!(health
            .view()
            .to_string()
            .starts_with("3 connections (2 open), 3 refused"));
        server.abort();
    }
}
