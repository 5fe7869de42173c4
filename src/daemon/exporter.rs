//! The Prometheus endpoint of `[metrics]`: the loop's figures, served as text on `GET /metrics`.
//!
//! [`LoopMetrics`] registers every metric once at start-up and keeps the handles, so the loop
//! updates them with atomic operations only (no lookup by label, no allocation):
//! - `valve_bridge_timing_error_us`: histogram of |actual - scheduled| cycle start, µs;
//! - `valve_bridge_cycles_total`: cycles that ran a valve transaction;
//! - `valve_bridge_cycle_failures_total{kind="timeout"|"error"|"disconnected"}`;
//! - `valve_bridge_missed_cycles_total`: slots skipped because a cycle overran;
//! - `valve_bridge_op_pct`, `valve_bridge_vp_pct`: last O_P sent and last V_P read, %;
//! - `valve_bridge_reconnects_total`: Modbus valve links reopened;
//! - `valve_bridge_watchdog_trips_total`: watchdog trips of the `modbus-server` source.
//!
//! [`serve`] answers HTTP on the daemon's network thread: one request per connection
//! (`Connection: close`), `GET /metrics` gives the text format, other paths 404, other methods
//! 405. Encoding happens there, never on the loop thread.

use std::time::Duration;

use prometheus::{Gauge, Histogram, HistogramOpts, IntCounter, IntCounterVec, Opts, Registry};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

use super::logger::{Sample, Status};

/// Upper bounds of the timing-error buckets, µs.
const TIMING_BUCKETS_US: [f64; 12] = [
    10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1e3, 2e3, 5e3, 1e4, 2e4, 5e4,
];
/// Longest request head read, bytes.
const MAX_HEAD: usize = 8 * 1024;
/// Time a client gets to send its request head.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// The loop's metrics and their registry.
#[derive(Debug, Clone)]
pub struct LoopMetrics {
    registry: Registry,
    timing_us: Histogram,
    cycles: IntCounter,
    /// Failures by kind: timeout, error, disconnected.
    failures: [IntCounter; 3],
    missed: IntCounter,
    op_pct: Gauge,
    vp_pct: Gauge,
    reconnects: IntCounter,
    watchdog_trips: IntCounter,
}

impl LoopMetrics {
    /// Registers every metric in a new registry.
    pub fn new() -> Result<LoopMetrics, prometheus::Error> {
        let registry = Registry::new();
        let timing_us = Histogram::with_opts(
            HistogramOpts::new(
                "valve_bridge_timing_error_us",
                "Timing error of the cycle start, |actual - scheduled|, in microseconds",
            )
            .buckets(TIMING_BUCKETS_US.to_vec()),
        )?;
        let counter = |name: &str, help: &str| IntCounter::new(name, help);
        let gauge = |name: &str, help: &str| Gauge::new(name, help);
        let cycles = counter(
            "valve_bridge_cycles_total",
            "Cycles that ran a valve transaction",
        )?;
        let by_kind = IntCounterVec::new(
            Opts::new(
                "valve_bridge_cycle_failures_total",
                "Valve transactions that gave no V_P, by kind",
            ),
            &["kind"],
        )?;
        let failures = [
            by_kind.get_metric_with_label_values(&["timeout"])?,
            by_kind.get_metric_with_label_values(&["error"])?,
            by_kind.get_metric_with_label_values(&["disconnected"])?,
        ];
        let missed = counter(
            "valve_bridge_missed_cycles_total",
            "Slots skipped because the previous cycle overran",
        )?;
        let op_pct = gauge("valve_bridge_op_pct", "Last O_P sent to the valve, %")?;
        let vp_pct = gauge("valve_bridge_vp_pct", "Last V_P read from the valve, %")?;
        let reconnects = counter(
            "valve_bridge_reconnects_total",
            "Times the Modbus valve link was reopened after a fault",
        )?;
        let watchdog_trips = counter(
            "valve_bridge_watchdog_trips_total",
            "Times the process controller's watchdog fired (modbus-server source)",
        )?;
        registry.register(Box::new(timing_us.clone()))?;
        registry.register(Box::new(by_kind))?;
        for c in [&cycles, &missed, &reconnects, &watchdog_trips] {
            registry.register(Box::new(c.clone()))?;
        }
        for g in [&op_pct, &vp_pct] {
            registry.register(Box::new(g.clone()))?;
        }
        Ok(LoopMetrics {
            registry,
            timing_us,
            cycles,
            failures,
            missed,
            op_pct,
            vp_pct,
            reconnects,
            watchdog_trips,
        })
    }

    /// The registry the endpoint encodes.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// Counts a logged row and its timing error (None for a skipped slot).
    pub fn record(&self, row: &Sample, lateness: Option<Duration>) {
        if let Some(l) = lateness {
            self.timing_us.observe(l.as_nanos() as f64 / 1e3);
        }
        match row.status {
            Status::Skipped => self.missed.inc(),
            Status::Timeout => self.failures[0].inc(),
            Status::Error => self.failures[1].inc(),
            Status::Disconnected => self.failures[2].inc(),
            Status::Ok | Status::Watchdog | Status::SafeHold | Status::SafeGoTo => {}
        }
        if row.status != Status::Skipped {
            self.cycles.inc();
            if let Some(op) = row.op_pct {
                self.op_pct.set(op);
            }
        }
        if let Some(vp) = row.vp_pct {
            self.vp_pct.set(vp);
        }
    }

    /// Brings the reconnect and watchdog counters up to the totals the loop's parts keep.
    pub fn totals(&self, reconnects: u64, watchdog_trips: u64) {
        for (c, total) in [
            (&self.reconnects, reconnects),
            (&self.watchdog_trips, watchdog_trips),
        ] {
            c.inc_by(total.saturating_sub(c.get()));
        }
    }
}

/// Answers `GET /metrics` on `listener` from `registry` until the listener fails.
pub async fn serve(listener: TcpListener, registry: Registry) -> std::io::Result<()> {
    loop {
        let (stream, peer) = listener.accept().await?;
        let registry = registry.clone();
        tokio::spawn(async move {
            if let Err(e) = answer(stream, &registry).await {
                tracing::debug!("metrics request from {peer}: {e}");
            }
        });
    }
}

/// Reads one request head and writes the response.
async fn answer(mut stream: TcpStream, registry: &Registry) -> std::io::Result<()> {
    let mut head = Vec::with_capacity(512);
    let mut chunk = [0u8; 1024];
    let read_head = async {
        while !head.windows(4).any(|w| w == b"\r\n\r\n") && head.len() < MAX_HEAD {
            let n = stream.read(&mut chunk).await?;
            if n == 0 {
                break;
            }
            head.extend_from_slice(&chunk[..n]);
        }
        Ok::<_, std::io::Error>(())
    };
    tokio::time::timeout(HEAD_TIMEOUT, read_head)
        .await
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "no request head"))??;
    let (status, content_type, body) = respond(&head, registry);
    let reply = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Connection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(reply.as_bytes()).await?;
    stream.write_all(body.as_bytes()).await?;
    stream.shutdown().await
}

/// Status line, content type and body for a request head.
fn respond(head: &[u8], registry: &Registry) -> (&'static str, &'static str, String) {
    const TEXT: &str = "text/plain; charset=utf-8";
    let line = head
        .split(|&b| b == b'\r' || b == b'\n')
        .next()
        .unwrap_or(&[]);
    let line = String::from_utf8_lossy(line);
    let mut parts = line.split_whitespace();
    let (method, target) = (parts.next(), parts.next());
    let path = target.map(|t| t.split('?').next().unwrap_or(t));
    match (method, path) {
        (Some("GET"), Some("/metrics")) => {
            let encoder = prometheus::TextEncoder::new();
            match encoder.encode_to_string(&registry.gather()) {
                Ok(text) => ("200 OK", prometheus::TEXT_FORMAT, text),
                Err(e) => (
                    "500 Internal Server Error",
                    TEXT,
                    format!("cannot encode the metrics: {e}\n"),
                ),
            }
        }
        (Some("GET"), Some(_)) => (
            "404 Not Found",
            TEXT,
            "the metrics are at /metrics\n".into(),
        ),
        (Some(_), Some(_)) => (
            "405 Method Not Allowed",
            TEXT,
            "only GET /metrics is served\n".into(),
        ),
        _ => ("400 Bad Request", TEXT, "not an HTTP request\n".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(status: Status, vp: Option<f64>) -> Sample {
        Sample {
            t_s: 0.0,
            op_pct: Some(42.0),
            vp_pct: vp,
            status,
            lateness_us: None,
            latency_us: None,
        }
    }

    #[test]
    fn rows_update_counters_and_gauges() {
        let m = LoopMetrics::new().unwrap();
        m.record(
            &row(Status::Ok, Some(41.5)),
            Some(Duration::from_micros(30)),
        );
        m.record(&row(Status::Timeout, None), Some(Duration::from_micros(3)));
        m.record(&row(Status::Skipped, None), None);
        m.totals(2, 1);
        m.totals(2, 1);
        let (status, ctype, text) =
            respond(b"GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n", m.registry());
        assert_eq!((status, ctype), ("200 OK", prometheus::TEXT_FORMAT));
        for line in [
            "valve_bridge_cycles_total 2",
            "valve_bridge_cycle_failures_total{kind=\"timeout\"} 1",
            "valve_bridge_cycle_failures_total{kind=\"error\"} 0",
            "valve_bridge_missed_cycles_total 1",
            "valve_bridge_op_pct 42",
            "valve_bridge_vp_pct 41.5",
            "valve_bridge_reconnects_total 2",
            "valve_bridge_watchdog_trips_total 1",
            "valve_bridge_timing_error_us_bucket{le=\"50\"} 2",
            "valve_bridge_timing_error_us_bucket{le=\"10\"} 1",
            "valve_bridge_timing_error_us_count 2",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
    }

    #[test]
    fn other_requests_are_refused() {
        let m = LoopMetrics::new().unwrap();
        let r = m.registry();
        assert_eq!(respond(b"GET /metrics?x=1 HTTP/1.0\r\n\r\n", r).0, "200 OK");
        assert_eq!(respond(b"GET / HTTP/1.1\r\n\r\n", r).0, "404 Not Found");
        assert_eq!(
            respond(b"POST /metrics HTTP/1.1\r\n\r\n", r).0,
            "405 Method Not Allowed"
        );
        assert_eq!(respond(b"\x16\x03\x01", r).0, "400 Bad Request");
    }
}
