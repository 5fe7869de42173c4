//! `contrib/grafana/valve-bridge.json` queries only metrics the daemon exports: every metric name
//! in its PromQL (panels and template variables) is a family of the daemon's registry, with every
//! family set up as a running daemon with `[metrics]`, `[health]` and `[diagnosis]` sets it up;
//! and `contrib/prometheus/prometheus.yml` scrapes the endpoint's path at the default address.

use std::collections::BTreeSet;
use std::sync::Arc;

use serde_json::Value;
use valve_bridge::daemon::config::{HealthConfig, MetricsConfig};
use valve_bridge::daemon::monitor::diagnosis::history::{Entry, Record};
use valve_bridge::daemon::monitor::diagnosis::DiagnosisMetrics;
use valve_bridge::daemon::monitor::health::Figures;
use valve_bridge::daemon::serve::exporter::LoopMetrics;
use valve_bridge::diagnose::{Effect, Size};

const DASHBOARD: &str = include_str!("../../contrib/grafana/valve-bridge.json");
const PROMETHEUS: &str = include_str!("../../contrib/prometheus/prometheus.yml");

/// Every string under a key `expr`, `query` or `definition`, anywhere in `v`.
fn queries(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(map) => {
            for (k, x) in map {
                match (k.as_str(), x) {
                    ("expr" | "query" | "definition", Value::String(s)) => out.push(s.clone()),
                    _ => queries(x, out),
                }
            }
        }
        Value::Array(list) => list.iter().for_each(|x| queries(x, out)),
        _ => {}
    }
}

/// The `valve_bridge_*` names in a PromQL expression.
fn names(expr: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut rest = expr;
    while let Some(i) = rest.find("valve_bridge_") {
        let tail = &rest[i..];
        let end = tail
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(tail.len());
        out.push(tail[..end].to_string());
        rest = &tail[end..];
    }
    out
}

/// The families of a daemon's registry, each set up as a running daemon sets it up.
fn exported() -> BTreeSet<String> {
    let m = LoopMetrics::new(&["a"], true).unwrap();
    let f = Figures {
        same_steps: 10,
        reversals: 10,
        dead_time_s: Some(0.4),
        reversal_delay_s: Some(1.0),
        opening_speed_pct_per_s: 20.0,
        closing_speed_pct_per_s: 20.0,
        tracking_rms_pct: 2.0,
    };
    let limits = Figures::limits(&f, &HealthConfig::default());
    m.health(0).unwrap().publish(&f, Some(&limits), true);
    m.observe_servers(&[("metrics", Arc::new(valve_bridge::net::Health::default()))]);
    let d = DiagnosisMetrics::register(m.registry()).unwrap();
    let band = Size {
        name: "friction_band_pct",
        unit: "%",
        value: 1.3,
        low: 1.1,
        high: 1.5,
        worth: 4.3,
        worth_low: 3.7,
    };
    let record = Record {
        t_s: 3600.0,
        utc: "2026-11-23T19:27:09.045Z".into(),
        window_s: 1200.0,
        trigger: "every_s",
        verdict: String::new(),
        compared: true,
        reference: false,
        effects: vec![Entry::new(Effect::Backlash, true, band)],
        advice: Vec::new(),
        alarms: vec![
            "lost motion (backlash): new, friction band 1.30 % (1.10-1.50) since 1:00 h".into(),
        ],
        alarm_effects: vec![Effect::Backlash],
        report: None,
        error: None,
    };
    let none = Record {
        effects: Vec::new(),
        alarms: Vec::new(),
        alarm_effects: Vec::new(),
        ..record.clone()
    };
    d.publish("a", &record, &none);
    d.age("a").unwrap().set(60.0);
    let mut names = BTreeSet::new();
    for family in m.registry().gather() {
        let name = family.name().to_string();
        if family.get_field_type() == prometheus::proto::MetricType::HISTOGRAM {
            for suffix in ["_bucket", "_sum", "_count"] {
                names.insert(format!("{name}{suffix}"));
            }
        }
        names.insert(name);
    }
    names
}

#[test]
fn every_metric_the_dashboard_queries_is_one_the_daemon_exports() {
    let dash: Value = serde_json::from_str(DASHBOARD).unwrap();
    let mut exprs = Vec::new();
    queries(&dash, &mut exprs);
    let queried: BTreeSet<String> = exprs.iter().flat_map(|e| names(e)).collect();
    let exported = exported();
    let unknown: Vec<&String> = queried.difference(&exported).collect();
    assert!(
        unknown.is_empty(),
        "not exported: {unknown:?}\nexported: {exported:?}"
    );
    // The dashboard shows what it is for: timing, failures, reconnects, O_P/V_P, each health
    // figure with its limit, effect sizes and alarms.
    for name in [
        "valve_bridge_timing_error_seconds_bucket",
        "valve_bridge_cycle_failures_total",
        "valve_bridge_reconnects_total",
        "valve_bridge_op_ratio",
        "valve_bridge_vp_ratio",
        "valve_bridge_health_dead_time_seconds",
        "valve_bridge_health_dead_time_limit_seconds",
        "valve_bridge_health_reversal_delay_limit_seconds",
        "valve_bridge_health_opening_speed_limit_ratio_per_second",
        "valve_bridge_health_closing_speed_limit_ratio_per_second",
        "valve_bridge_health_tracking_error_limit_ratio",
        "valve_bridge_effect_size",
        "valve_bridge_health_alarm",
        "valve_bridge_diagnosis_alarm",
    ] {
        assert!(queried.contains(name), "the dashboard does not show {name}");
    }
    // The check can fail: a misspelt name is caught.
    assert!(!exported.contains("valve_bridge_op_percent"));
}

#[test]
fn the_scrape_config_points_at_the_metrics_endpoint() {
    assert!(
        PROMETHEUS.contains("metrics_path: /metrics"),
        "{PROMETHEUS}"
    );
    let default = MetricsConfig::default().listen.0.to_string();
    assert!(
        PROMETHEUS.contains(&format!("targets: [\"{default}\"]")),
        "{PROMETHEUS}"
    );
}
