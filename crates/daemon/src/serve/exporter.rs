//! The Prometheus endpoint of `[metrics]`: the loop's figures, served as text on `GET /metrics`.
//!
//! Names follow Prometheus conventions (base units, `_total` for counters, ratios 0-1); every
//! figure of a valve carries its name as the label `valve`:
//! - `valve_bridge_timing_error_seconds`: histogram of |actual - scheduled| cycle start (one
//!   per cycle, shared by the valves of that cycle);
//! - `valve_bridge_cycles_total`: cycles that ran a valve transaction;
//! - `valve_bridge_cycle_failures_total{kind="timeout"|"error"|"disconnected"}`;
//! - `valve_bridge_missed_cycles_total`: slots skipped because a cycle overran;
//! - `valve_bridge_op_ratio`, `valve_bridge_vp_ratio`: last O_P sent and last V_P read, as a
//!   fraction of full travel (0.45 = 45 %);
//! - `valve_bridge_reconnects_total`: Modbus valve links reopened;
//! - `valve_bridge_late_replies_total`: Modbus replies discarded as answers to earlier requests;
//! - `valve_bridge_line_noise_bytes_total`, `valve_bridge_unexpected_replies_total`: Modbus RTU
//!   bytes that formed no frame, and frames no request waited for (a noisy or slow line);
//! - `valve_bridge_watchdog_trips_total`: watchdog trips of the `modbus-server` source;
//! - `valve_bridge_log_rows_dropped_total`: rows that never reached the log (the logger fell
//!   behind, or the disk refused them past the hold, [`crate::runtime::log_file`]);
//!   `valve_bridge_log_rows_late_total`: lines written after the disk had refused them;
//!   `valve_bridge_log_write_failing`: 1 while one of the valve's files cannot be written;
//! - with `[health]`, per valve, each window's figures: `valve_bridge_health_dead_time_seconds`,
//!   `..._reversal_delay_seconds` (NaN when the window had too few steps),
//!   `..._opening_speed_ratio_per_second`, `..._closing_speed_ratio_per_second`,
//!   `..._tracking_error_ratio`, the limit of each against the baseline (past it the alarm is
//!   raised; NaN until there is a baseline): `valve_bridge_health_dead_time_limit_seconds`,
//!   `..._reversal_delay_limit_seconds`, `..._opening_speed_limit_ratio_per_second`,
//!   `..._closing_speed_limit_ratio_per_second`, `..._tracking_error_limit_ratio`, and
//!   `valve_bridge_health_alarm` (1 in alarm);
//! - with `[valve.compensation]`, per compensated valve: `valve_bridge_compensation_active` (1,
//!   0 once the guard has switched it off) and, each guard window,
//!   `valve_bridge_compensation_tracking_error_ratio{case="with"|"without"}` (RMS of O_P - V_P
//!   measured with compensation, and the model's without it);
//! - with `[diagnosis]`, per valve: `valve_bridge_effect_size{effect,unit}`,
//!   `valve_bridge_diagnosis_age_seconds` and `valve_bridge_diagnosis_alarm{effect}`
//!   (registered by [`crate::monitor::diagnosis::DiagnosisMetrics`]);
//! - per server (`server="modbus-server"|"metrics"`): `valve_bridge_server_up` (0 while
//!   `accept()` fails), `valve_bridge_server_connections` (open now),
//!   `valve_bridge_server_connections_accepted_total`, `..._evicted_total` (closed at the
//!   connection limit for a new one), `..._refused_total` (new ones closed at once: every slot
//!   a controller's), `..._idle_closed_total` and `valve_bridge_server_accept_errors_total`.
//!
//! [`LoopMetrics`] registers every metric once at start-up and keeps each valve's handles
//! ([`ValveMetrics`]), so the loop updates its own with atomic operations only (no lookup by label, no allocation); the server
//! figures are copied from their [`Health`] when the endpoint is scraped.
//!
//! Not here: the HTTP server ([`crate::serve::http`]), which encodes them ([`LoopMetrics::text`]) for
//! `GET /metrics` on the network thread, never on the loop thread.

use std::sync::Arc;
use std::time::Duration;

use prometheus::{
    Gauge, GaugeVec, Histogram, HistogramOpts, IntCounter, IntCounterVec, IntGaugeVec, Opts,
    Registry,
};

use crate::monitor::health_figures::{Figures, HealthLimits};
use vb_core::compensate::Window;
use vb_core::recording::log_format::{Sample, Status};
use vb_modbus::client::LinkStats;
use vb_modbus::net::{self, Health};

/// Upper bounds of the timing-error buckets, s.
const TIMING_BUCKETS_S: [f64; 12] = [
    10e-6, 20e-6, 50e-6, 100e-6, 200e-6, 500e-6, 1e-3, 2e-3, 5e-3, 10e-3, 20e-3, 50e-3,
];

/// The per-server metrics, by the `server` label.
#[derive(Debug, Clone)]
struct ServerMetrics {
    up: IntGaugeVec,
    open: IntGaugeVec,
    accepted: IntCounterVec,
    evicted: IntCounterVec,
    refused: IntCounterVec,
    idle_closed: IntCounterVec,
    accept_errors: IntCounterVec,
}

/// The loop's metrics and their registry.
#[derive(Debug, Clone)]
pub struct LoopMetrics {
    registry: Registry,
    timing_s: Histogram,
    /// Each valve's handles, in the order of the config.
    valves: Vec<ValveMetrics>,
    /// Each valve's health gauges, when `[health]` is on.
    health: Vec<HealthMetrics>,
    /// The compensation gauges (children only for compensated valves).
    compensation_active: GaugeVec,
    compensation_tracking: GaugeVec,
    servers: ServerMetrics,
}

/// One compensated valve's gauges (label `valve`), set when the guard judges a window.
#[derive(Debug, Clone)]
pub struct CompensationMetrics {
    active: Gauge,
    with: Gauge,
    without: Gauge,
}

impl CompensationMetrics {
    /// Publishes a judged window (if any) and whether compensation still acts.
    pub fn publish(&self, window: Option<&Window>, active: bool) {
        self.active.set(f64::from(u8::from(active)));
        if let Some(w) = window {
            self.with.set(w.with_pct / 100.0);
            self.without.set(w.without_pct / 100.0);
        }
    }
}

/// One valve's health gauges (label `valve`), set by the health thread once per window.
#[derive(Debug, Clone)]
pub struct HealthMetrics {
    dead_time_s: Gauge,
    reversal_delay_s: Gauge,
    opening_speed: Gauge,
    closing_speed: Gauge,
    tracking: Gauge,
    alarm: Gauge,
    /// The limits, in the order and units of the figures above.
    limits: [Gauge; 5],
}

impl HealthMetrics {
    /// Publishes a window's figures (NaN for a delay it could not measure), their limits (NaN
    /// without a baseline) and the alarm.
    pub fn publish(&self, f: &Figures, limits: Option<&HealthLimits>, alarm: bool) {
        self.dead_time_s.set(f.dead_time_s.unwrap_or(f64::NAN));
        self.reversal_delay_s
            .set(f.reversal_delay_s.unwrap_or(f64::NAN));
        self.opening_speed.set(f.opening_speed_pct_per_s / 100.0);
        self.closing_speed.set(f.closing_speed_pct_per_s / 100.0);
        self.tracking.set(f.tracking_rms_pct / 100.0);
        self.alarm.set(f64::from(u8::from(alarm)));
        let nan = f64::NAN;
        let values = match limits {
            Some(l) => [
                l.dead_time_s.unwrap_or(nan),
                l.reversal_delay_s.unwrap_or(nan),
                l.opening_speed_pct_per_s / 100.0,
                l.closing_speed_pct_per_s / 100.0,
                l.tracking_rms_pct / 100.0,
            ],
            None => [nan; 5],
        };
        for (g, v) in self.limits.iter().zip(values) {
            g.set(v);
        }
    }
}

/// The health gauges of `valves`, registered in `registry`.
fn health_metrics(
    registry: &Registry,
    valves: &[&str],
) -> Result<Vec<HealthMetrics>, prometheus::Error> {
    let gauge = |name: &str, help: &str| -> Result<GaugeVec, prometheus::Error> {
        let g = GaugeVec::new(Opts::new(name, help), &["valve"])?;
        registry.register(Box::new(g.clone()))?;
        Ok(g)
    };
    let gauges = [
        gauge(
            "valve_bridge_health_dead_time_seconds",
            "Mean delay of same-direction steps over the health window",
        )?,
        gauge(
            "valve_bridge_health_reversal_delay_seconds",
            "Mean delay of reversals over the health window",
        )?,
        gauge(
            "valve_bridge_health_opening_speed_ratio_per_second",
            "Opening stroke speed over the health window, fraction of travel per second",
        )?,
        gauge(
            "valve_bridge_health_closing_speed_ratio_per_second",
            "Closing stroke speed over the health window, fraction of travel per second",
        )?,
        gauge(
            "valve_bridge_health_tracking_error_ratio",
            "RMS of O_P - V_P over the health window, fraction of travel",
        )?,
        gauge(
            "valve_bridge_health_alarm",
            "1 while a health figure is past its limit against the baseline",
        )?,
        gauge(
            "valve_bridge_health_dead_time_limit_seconds",
            "Highest dead time before the alarm: the baseline's plus dead_time_rise_s",
        )?,
        gauge(
            "valve_bridge_health_reversal_delay_limit_seconds",
            "Highest reversal delay before the alarm: the baseline's plus reversal_delay_rise_s",
        )?,
        gauge(
            "valve_bridge_health_opening_speed_limit_ratio_per_second",
            "Lowest opening speed before the alarm: the baseline's less speed_drop",
        )?,
        gauge(
            "valve_bridge_health_closing_speed_limit_ratio_per_second",
            "Lowest closing speed before the alarm: the baseline's less speed_drop",
        )?,
        gauge(
            "valve_bridge_health_tracking_error_limit_ratio",
            "Highest tracking error before the alarm: the baseline's plus tracking_rise",
        )?,
    ];
    valves
        .iter()
        .map(|&v| {
            let [d, r, o, c, t, a, ld, lr, lo, lc, lt] = gauges
                .each_ref()
                .map(|g| g.get_metric_with_label_values(&[v]));
            Ok(HealthMetrics {
                dead_time_s: d?,
                reversal_delay_s: r?,
                opening_speed: o?,
                closing_speed: c?,
                tracking: t?,
                alarm: a?,
                limits: [ld?, lr?, lo?, lc?, lt?],
            })
        })
        .collect()
}

/// The compensation gauges (whether it acts, and the tracking error with and without it),
/// registered in `registry`.
fn compensation_gauges(registry: &Registry) -> Result<(GaugeVec, GaugeVec), prometheus::Error> {
    let active = GaugeVec::new(
        Opts::new(
            "valve_bridge_compensation_active",
            "1 while compensation shapes the valve's set-point, 0 once its guard switched it off",
        ),
        &["valve"],
    )?;
    let tracking = GaugeVec::new(
        Opts::new(
            "valve_bridge_compensation_tracking_error_ratio",
            "RMS of O_P - V_P over the last guard window: measured with compensation, and the model's without it",
        ),
        &["valve", "case"],
    )?;
    registry.register(Box::new(active.clone()))?;
    registry.register(Box::new(tracking.clone()))?;
    Ok((active, tracking))
}

/// One valve's metrics (label `valve`), updated by the loop with atomic operations only.
#[derive(Debug, Clone)]
pub struct ValveMetrics {
    cycles: IntCounter,
    /// Failures by kind: timeout, error, disconnected.
    failures: [IntCounter; 3],
    missed: IntCounter,
    op_ratio: Gauge,
    vp_ratio: Gauge,
    reconnects: IntCounter,
    late_replies: IntCounter,
    noise_bytes: IntCounter,
    unexpected_replies: IntCounter,
    watchdog_trips: IntCounter,
    dropped_log_rows: IntCounter,
    late_log_rows: IntCounter,
    log_failing: Gauge,
}

impl LoopMetrics {
    /// Registers every metric in a new registry, for the valves named `valves` (with their
    /// health gauges when `health`).
    pub fn new(valves: &[&str], health: bool) -> Result<LoopMetrics, prometheus::Error> {
        let registry = Registry::new();
        let timing_s = Histogram::with_opts(
            HistogramOpts::new(
                "valve_bridge_timing_error_seconds",
                "Timing error of the cycle start, |actual - scheduled|",
            )
            .buckets(TIMING_BUCKETS_S.to_vec()),
        )?;
        // Each per-valve metric is registered as it is made.
        let counter = |name: &str, help: &str| {
            let c = IntCounterVec::new(Opts::new(name, help), &["valve"])?;
            registry.register(Box::new(c.clone())).map(|()| c)
        };
        let gauge = |name: &str, help: &str| {
            let g = GaugeVec::new(Opts::new(name, help), &["valve"])?;
            registry.register(Box::new(g.clone())).map(|()| g)
        };
        let cycles = counter(
            "valve_bridge_cycles_total",
            "Cycles that ran a valve transaction",
        )?;
        let by_kind = IntCounterVec::new(
            Opts::new(
                "valve_bridge_cycle_failures_total",
                "Valve transactions that gave no V_P, by kind",
            ),
            &["valve", "kind"],
        )?;
        let missed = counter(
            "valve_bridge_missed_cycles_total",
            "Slots skipped because the previous cycle overran",
        )?;
        let op_ratio = gauge(
            "valve_bridge_op_ratio",
            "Last O_P sent to the valve, as a fraction of full travel",
        )?;
        let vp_ratio = gauge(
            "valve_bridge_vp_ratio",
            "Last V_P read from the valve, as a fraction of full travel",
        )?;
        let reconnects = counter(
            "valve_bridge_reconnects_total",
            "Times the Modbus valve link was reopened after a fault",
        )?;
        let late_replies = counter(
            "valve_bridge_late_replies_total",
            "Modbus replies discarded because they answered an earlier request, after its deadline",
        )?;
        let noise_bytes = counter(
            "valve_bridge_line_noise_bytes_total",
            "Modbus RTU bytes received that formed no frame (line noise, broken frames), dropped",
        )?;
        let unexpected_replies = counter(
            "valve_bridge_unexpected_replies_total",
            "Modbus RTU frames no request was waiting for (replies later than late_reply_ms)",
        )?;
        let dropped_log_rows = counter(
            "valve_bridge_log_rows_dropped_total",
            "Rows that never reached the log: the logger's queue was full, or the disk refused them past the hold",
        )?;
        let late_log_rows = counter(
            "valve_bridge_log_rows_late_total",
            "Lines of the valve's files written late, after the disk had refused them",
        )?;
        let log_failing = gauge(
            "valve_bridge_log_write_failing",
            "1 while a file of the valve's log cannot be written (its lines are held)",
        )?;
        let watchdog_trips = counter(
            "valve_bridge_watchdog_trips_total",
            "Times the process controller's watchdog fired (modbus-server source)",
        )?;
        let servers = ServerMetrics::new()?;
        let (compensation_active, compensation_tracking) = compensation_gauges(&registry)?;
        let valves_names = valves;
        let valves = (valves.iter())
            .map(|&v| {
                let kind = |k| by_kind.get_metric_with_label_values(&[v, k]);
                Ok(ValveMetrics {
                    cycles: cycles.get_metric_with_label_values(&[v])?,
                    failures: [kind("timeout")?, kind("error")?, kind("disconnected")?],
                    missed: missed.get_metric_with_label_values(&[v])?,
                    op_ratio: op_ratio.get_metric_with_label_values(&[v])?,
                    vp_ratio: vp_ratio.get_metric_with_label_values(&[v])?,
                    reconnects: reconnects.get_metric_with_label_values(&[v])?,
                    late_replies: late_replies.get_metric_with_label_values(&[v])?,
                    noise_bytes: noise_bytes.get_metric_with_label_values(&[v])?,
                    unexpected_replies: unexpected_replies.get_metric_with_label_values(&[v])?,
                    watchdog_trips: watchdog_trips.get_metric_with_label_values(&[v])?,
                    dropped_log_rows: dropped_log_rows.get_metric_with_label_values(&[v])?,
                    late_log_rows: late_log_rows.get_metric_with_label_values(&[v])?,
                    log_failing: log_failing.get_metric_with_label_values(&[v])?,
                })
            })
            .collect::<Result<Vec<_>, prometheus::Error>>()?;
        registry.register(Box::new(timing_s.clone()))?;
        registry.register(Box::new(by_kind))?;
        servers.register(&registry)?;
        let health = if health {
            health_metrics(&registry, valves_names)?
        } else {
            Vec::new()
        };
        Ok(LoopMetrics {
            registry,
            timing_s,
            valves,
            health,
            compensation_active,
            compensation_tracking,
            servers,
        })
    }

    /// The registry the endpoint encodes.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// Every metric in the Prometheus text format.
    pub fn text(&self) -> Result<String, prometheus::Error> {
        prometheus::TextEncoder::new().encode_to_string(&self.registry.gather())
    }

    /// The handles of the `i`-th valve of the config (None past the last).
    pub fn valve(&self, i: usize) -> Option<ValveMetrics> {
        self.valves.get(i).cloned()
    }

    /// The health gauges of the `i`-th valve (None without `[health]`).
    pub fn health(&self, i: usize) -> Option<HealthMetrics> {
        self.health.get(i).cloned()
    }

    /// The compensation gauges of the valve named `valve` (they appear once asked for).
    pub fn compensation(&self, valve: &str) -> Result<CompensationMetrics, prometheus::Error> {
        let tracking = |case| {
            self.compensation_tracking
                .get_metric_with_label_values(&[valve, case])
        };
        Ok(CompensationMetrics {
            active: self
                .compensation_active
                .get_metric_with_label_values(&[valve])?,
            with: tracking("with")?,
            without: tracking("without")?,
        })
    }

    /// Observes the timing error of a cycle that ran.
    pub fn timing(&self, lateness: Duration) {
        self.timing_s.observe(lateness.as_secs_f64());
    }

    /// Copies the servers' figures into their metrics (at scrape time, off the loop thread).
    pub fn observe_servers(&self, servers: &[(&'static str, Arc<Health>)]) {
        for (name, health) in servers {
            self.servers.observe(name, &health.view());
        }
    }
}

impl ValveMetrics {
    /// Counts a logged row of this valve.
    pub fn record(&self, row: &Sample) {
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
                self.op_ratio.set(op / 100.0);
            }
        }
        if let Some(vp) = row.vp_pct {
            self.vp_ratio.set(vp / 100.0);
        }
    }

    /// Counts a row the logger's queue had no room for.
    pub fn dropped_log_row(&self) {
        self.dropped_log_rows.inc();
    }

    /// Counts lines of the valve's files written late and dropped after the disk refused them.
    pub fn log_rows_refused(&self, late: u64, dropped: u64) {
        self.late_log_rows.inc_by(late);
        self.dropped_log_rows.inc_by(dropped);
    }

    /// Raises (true) or clears the valve's log alarm gauge.
    pub fn log_failing(&self, on: bool) {
        self.log_failing.set(f64::from(u8::from(on)));
    }

    /// Brings the link's and the watchdog's counters up to the totals the loop's parts keep.
    pub fn totals(&self, link: LinkStats, watchdog_trips: u64) {
        for (c, total) in [
            (&self.reconnects, link.reconnects),
            (&self.late_replies, link.late_replies),
            (&self.noise_bytes, link.noise_bytes),
            (&self.unexpected_replies, link.unexpected_replies),
            (&self.watchdog_trips, watchdog_trips),
        ] {
            c.inc_by(total.saturating_sub(c.get()));
        }
    }
}

impl ServerMetrics {
    fn new() -> Result<ServerMetrics, prometheus::Error> {
        let gauge = |name: &str, help: &str| IntGaugeVec::new(Opts::new(name, help), &["server"]);
        let counter =
            |name: &str, help: &str| IntCounterVec::new(Opts::new(name, help), &["server"]);
        Ok(ServerMetrics {
            up: gauge(
                "valve_bridge_server_up",
                "1 while the server accepts connections, 0 while accept() fails",
            )?,
            open: gauge("valve_bridge_server_connections", "Connections open now")?,
            accepted: counter(
                "valve_bridge_server_connections_accepted_total",
                "Connections accepted",
            )?,
            evicted: counter(
                "valve_bridge_server_connections_evicted_total",
                "Connections closed at the connection limit to make room for a new one",
            )?,
            refused: counter(
                "valve_bridge_server_connections_refused_total",
                "New connections closed at once at the connection limit: every slot was a \
                 process controller's",
            )?,
            idle_closed: counter(
                "valve_bridge_server_connections_idle_closed_total",
                "Connections closed for sending no request",
            )?,
            accept_errors: counter(
                "valve_bridge_server_accept_errors_total",
                "Failed accept() calls (each retried)",
            )?,
        })
    }

    fn register(&self, registry: &Registry) -> Result<(), prometheus::Error> {
        for g in [&self.up, &self.open] {
            registry.register(Box::new(g.clone()))?;
        }
        let counters = [
            &self.accepted,
            &self.evicted,
            &self.refused,
            &self.idle_closed,
            &self.accept_errors,
        ];
        for c in counters {
            registry.register(Box::new(c.clone()))?;
        }
        Ok(())
    }

    fn observe(&self, name: &str, v: &net::HealthView) {
        self.up.with_label_values(&[name]).set(i64::from(!v.down));
        self.open.with_label_values(&[name]).set(v.open as i64);
        for (c, total) in [
            (&self.accepted, v.accepted),
            (&self.evicted, v.evicted),
            (&self.refused, v.refused),
            (&self.idle_closed, v.idle_closed),
            (&self.accept_errors, v.accept_errors),
        ] {
            let c = c.with_label_values(&[name]);
            c.inc_by(total.saturating_sub(c.get()));
        }
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
            op_sent_pct: None,
            op_controller_pct: None,
            utc: std::time::SystemTime::UNIX_EPOCH,
        }
    }

    #[test]
    fn rows_update_counters_and_gauges() {
        let m = LoopMetrics::new(&["a", "b"], false).unwrap();
        let (a, b) = (m.valve(0).unwrap(), m.valve(1).unwrap());
        assert!(m.valve(2).is_none());
        a.record(&row(Status::Ok, Some(41.5)));
        m.timing(Duration::from_micros(30));
        a.record(&row(Status::Timeout, None));
        m.timing(Duration::from_micros(3));
        a.record(&row(Status::Skipped, None));
        b.record(&row(Status::Ok, Some(40.0)));
        let link = LinkStats {
            reconnects: 2,
            attempts: 3,
            late_replies: 4,
            noise_bytes: 17,
            unexpected_replies: 1,
            late_reply_ms: Some(100),
        };
        a.totals(link, 1);
        a.totals(link, 1);
        let health = Arc::new(Health::default());
        health.idle_closed();
        m.observe_servers(&[("modbus-server", Arc::clone(&health))]);
        m.observe_servers(&[("modbus-server", health)]);
        let text = m.text().unwrap();
        for line in [
            "valve_bridge_cycles_total{valve=\"a\"} 2",
            "valve_bridge_cycles_total{valve=\"b\"} 1",
            "valve_bridge_cycle_failures_total{kind=\"timeout\",valve=\"a\"} 1",
            "valve_bridge_cycle_failures_total{kind=\"error\",valve=\"a\"} 0",
            "valve_bridge_cycle_failures_total{kind=\"timeout\",valve=\"b\"} 0",
            "valve_bridge_missed_cycles_total{valve=\"a\"} 1",
            "valve_bridge_op_ratio{valve=\"a\"} 0.42",
            "valve_bridge_vp_ratio{valve=\"a\"} 0.415",
            "valve_bridge_vp_ratio{valve=\"b\"} 0.4",
            "valve_bridge_reconnects_total{valve=\"a\"} 2",
            "valve_bridge_late_replies_total{valve=\"a\"} 4",
            "valve_bridge_line_noise_bytes_total{valve=\"a\"} 17",
            "valve_bridge_unexpected_replies_total{valve=\"a\"} 1",
            "valve_bridge_watchdog_trips_total{valve=\"a\"} 1",
            "valve_bridge_watchdog_trips_total{valve=\"b\"} 0",
            "valve_bridge_server_up{server=\"modbus-server\"} 1",
            "valve_bridge_server_connections{server=\"modbus-server\"} 0",
            "valve_bridge_server_connections_idle_closed_total{server=\"modbus-server\"} 1",
            "valve_bridge_server_connections_refused_total{server=\"modbus-server\"} 0",
            "valve_bridge_server_accept_errors_total{server=\"modbus-server\"} 0",
            "valve_bridge_timing_error_seconds_bucket{le=\"0.00005\"} 2",
            "valve_bridge_timing_error_seconds_bucket{le=\"0.00001\"} 1",
            "valve_bridge_timing_error_seconds_count 2",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
    }

    #[test]
    fn health_gauges_carry_the_valve_label() {
        let m = LoopMetrics::new(&["a"], true).unwrap();
        assert!(m.health(1).is_none());
        let f = Figures {
            same_steps: 9,
            reversals: 2,
            dead_time_s: Some(0.45),
            reversal_delay_s: None,
            opening_speed_pct_per_s: 20.0,
            closing_speed_pct_per_s: 10.0,
            tracking_rms_pct: 5.0,
        };
        m.health(0).unwrap().publish(&f, None, false);
        let text = m.text().unwrap();
        assert!(
            text.contains("valve_bridge_health_tracking_error_limit_ratio{valve=\"a\"} NaN"),
            "no baseline, no limit: {text}"
        );
        // Against a baseline of itself: the limits of the default [health].
        let limits = Figures::limits(&f, &crate::config::HealthConfig::default());
        m.health(0).unwrap().publish(&f, Some(&limits), true);
        let text = m.text().unwrap();
        for line in [
            "valve_bridge_health_dead_time_limit_seconds{valve=\"a\"} 0.65",
            "valve_bridge_health_reversal_delay_limit_seconds{valve=\"a\"} NaN",
            "valve_bridge_health_opening_speed_limit_ratio_per_second{valve=\"a\"} 0.14",
            "valve_bridge_health_closing_speed_limit_ratio_per_second{valve=\"a\"} 0.07",
            "valve_bridge_health_tracking_error_limit_ratio{valve=\"a\"} 0.1",
            "valve_bridge_health_dead_time_seconds{valve=\"a\"} 0.45",
            "valve_bridge_health_reversal_delay_seconds{valve=\"a\"} NaN",
            "valve_bridge_health_opening_speed_ratio_per_second{valve=\"a\"} 0.2",
            "valve_bridge_health_closing_speed_ratio_per_second{valve=\"a\"} 0.1",
            "valve_bridge_health_tracking_error_ratio{valve=\"a\"} 0.05",
            "valve_bridge_health_alarm{valve=\"a\"} 1",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
        let plain = LoopMetrics::new(&["a"], false).unwrap();
        assert!(plain.health(0).is_none());
    }

    #[test]
    fn compensation_gauges_appear_for_compensated_valves_only() {
        let m = LoopMetrics::new(&["a", "b"], false).unwrap();
        let text = m.text().unwrap();
        assert!(
            !text.contains("valve_bridge_compensation_active{"),
            "{text}"
        );
        let b = m.compensation("b").unwrap();
        b.publish(None, true);
        let w = Window {
            with_pct: 0.5,
            without_pct: 0.25,
            rows: 100,
            worse: true,
            ..Window::default()
        };
        b.publish(Some(&w), false);
        let text = m.text().unwrap();
        for line in [
            "valve_bridge_compensation_active{valve=\"b\"} 0",
            "valve_bridge_compensation_tracking_error_ratio{case=\"with\",valve=\"b\"} 0.005",
            "valve_bridge_compensation_tracking_error_ratio{case=\"without\",valve=\"b\"} 0.0025",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
        assert!(!text.contains("valve_bridge_compensation_active{valve=\"a\"}"));
    }
}
