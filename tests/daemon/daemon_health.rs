//! The live health check through the real binary, on the virtual clock:
//! - `config/worn-valve.toml`, whose emulated valve's dead time grows by 0.5 s per hour, raises
//!   the alarm within one window (10 min) and a minute of the drift passing the 0.2 s limit
//!   over the baseline (the first window), with a warning naming the dead time and the alarm in
//!   `health-worn.csv`;
//! - `config/friction-drift.toml`, a valve whose friction band widens by 3 % per hour beside a
//!   healthy one, over 3 hours: raises the alarm on the reversal delay within the window after
//!   it has grown past the 0.3 s limit, and its live diagnosis alarms with the effect's plain
//!   name (`lost motion (backlash)`) before the 3-hour mark, and its summary's alarms are the
//!   ones of [`PACKING_ALARMS`] (`docs/daemon.md` quotes them); the healthy valve raises
//!   neither;
//! - `config/two-valves.toml`, two healthy valves, runs 3 simulated hours (180 windows each)
//!   without an alarm; `docs/daemon.md` shows the 24-hour run;
//! - `config/healthy-valve.toml`, a healthy valve with live diagnosis, runs 24 simulated hours:
//!   48 diagnoses, no alarm.

use std::path::Path;
use std::process::{Command, Output};

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

/// The live diagnosis's alarms of the packing valve over 3 hours, as its summary lists them
/// (the run is on the virtual clock, so they are the same every run).
const PACKING_ALARMS: [&str; 2] = [
    "lost motion (backlash): new, crossing time at half travel 1.25 s (1.24-1.83) since 0:50 h",
    "slower the more open (opening-dependent delay): new, crossing time fully open 5.38 s (5.37-5.42) since 2:20 h",
];

fn run(config: &str, secs: &str, dir: &Path) -> Output {
    Command::new(BIN)
        .args([
            "run",
            "--config",
            &format!("{}/config/{config}", env!("CARGO_MANIFEST_DIR")),
            "--as-fast-as-possible",
            "--duration",
            secs,
            "--log-dir",
            dir.to_str().unwrap(),
        ])
        .env("RUST_LOG", "info")
        .output()
        .unwrap()
}

/// (t_s, alarm, note) of every row of a health CSV.
fn health_rows(path: &Path) -> Vec<(f64, bool, String)> {
    let mut r = csv::Reader::from_path(path).unwrap();
    assert_eq!(
        r.headers().unwrap().iter().collect::<Vec<_>>(),
        [
            "t_s",
            "same_steps",
            "reversals",
            "dead_time_s",
            "reversal_delay_s",
            "opening_speed_pct_per_s",
            "closing_speed_pct_per_s",
            "tracking_rms_pct",
            "alarm",
            "dead_time_base_s",
            "dead_time_limit_s",
            "reversal_delay_base_s",
            "reversal_delay_limit_s",
            "opening_speed_base_pct_per_s",
            "opening_speed_limit_pct_per_s",
            "closing_speed_base_pct_per_s",
            "closing_speed_limit_pct_per_s",
            "tracking_rms_base_pct",
            "tracking_rms_limit_pct",
            "note"
        ]
    );
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (rec[0].parse().unwrap(), &rec[8] == "1", rec[19].to_string())
        })
        .collect()
}

#[test]
fn a_growing_dead_time_raises_the_alarm_within_the_window() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("worn-valve.toml", "3600", dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    let rows = health_rows(&dir.path().join("health-worn.csv"));
    // The first estimate when the window is full, then one a minute.
    assert_eq!(rows.len(), 51, "{rows:?}");
    assert!((rows[0].0 - 599.99).abs() < 0.02, "{rows:?}");
    let first = rows.iter().find(|r| r.1).expect("an alarm");
    // The baseline window (0-600 s) saw 0.04 s of drift on average, so the dead time is 0.2 s
    // past it at 1740 s; the alarm comes within one window and one cadence after that.
    assert!(
        first.0 > 1740.0 && first.0 <= 1740.0 + 600.0 + 60.0,
        "{first:?}"
    );
    assert!(first.2.contains("dead time"), "{first:?}");
    assert!(rows.last().unwrap().1, "{rows:?}");
    assert!(stderr.contains("health alarm: dead time"), "{stderr}");
    assert!(
        stdout.contains("health: 51 windows, 1 alarms (first at"),
        "{stdout}"
    );
    // Each row carries the baseline and the limit it was judged against: the dead time's is
    // the baseline's plus dead_time_rise_s (0.2 s).
    let mut r = csv::Reader::from_path(dir.path().join("health-worn.csv")).unwrap();
    let last = r.records().last().unwrap().unwrap();
    let (base, limit): (f64, f64) = (last[9].parse().unwrap(), last[10].parse().unwrap());
    assert!((limit - base - 0.2).abs() < 1e-3, "{last:?}");
    // The plot: a panel per figure in its unit, with its baseline, limit and the alarm spans.
    let svg = std::fs::read_to_string(dir.path().join("health-worn.svg")).unwrap();
    for text in [
        "dead time (s)",
        "opening speed (%/s)",
        "alarm limit",
        "in alarm",
    ] {
        assert!(svg.contains(text), "{text} missing in the plot");
    }
}

#[test]
fn healthy_valves_raise_no_alarm_over_hours() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("two-valves.toml", "10800", dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    for name in ["level", "cyclone"] {
        let rows = health_rows(&dir.path().join(format!("health-{name}.csv")));
        assert_eq!(rows.len(), 171, "{name}");
        assert!(rows.iter().all(|r| !r.1), "{name}: {rows:?}");
        // Every window measures both delays against the first one.
        assert!(rows.iter().all(|r| r.2.is_empty()), "{name}: {rows:?}");
    }
    assert!(!stderr.contains("health alarm"), "{stderr}");
}

#[test]
fn a_widening_friction_band_raises_the_alarm_and_the_healthy_valve_none() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("friction-drift.toml", "10800", dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    let rows = health_rows(&dir.path().join("health-packing.csv"));
    assert_eq!(rows.len(), 171, "{rows:?}");
    let first = rows.iter().find(|r| r.1).expect("an alarm");
    // The band is 3 % per hour wider: at mid travel eq. 7's crossing (0.5 s for B_L = 1 %)
    // grows by 1.5 s per hour, so the reversal delay passes the first window's (which saw
    // +0.25 % of band on average) by 0.3 s after about 17 min at mid travel; the alarm
    // comes within one window and one cadence of that, whatever openings the steps visit.
    assert!(
        first.0 > 900.0 && first.0 <= 1020.0 + 600.0 + 60.0,
        "{first:?}"
    );
    assert!(first.2.contains("reversal delay"), "{first:?}");
    assert!(!first.2.contains("dead time"), "{first:?}");
    assert!(rows.last().unwrap().1, "{rows:?}");
    let healthy = health_rows(&dir.path().join("health-healthy.csv"));
    assert_eq!(healthy.len(), 171);
    assert!(healthy.iter().all(|r| !r.1), "{healthy:?}");
    assert!(stderr.contains("health alarm: reversal delay"), "{stderr}");
    // The live diagnosis: the packing valve's first alarm names its lost motion before the
    // 3-hour mark; the healthy valve's diagnoses raise none.
    let (packing, healthy) = stdout.split_once("valve healthy:").unwrap();
    let alarms: Vec<&str> = (packing.lines())
        .filter_map(|l| l.trim().strip_prefix("alarm: "))
        .collect();
    let first = alarms.first().expect("a diagnosis alarm");
    assert!(first.starts_with("lost motion (backlash): "), "{packing}");
    let since = first.rsplit_once("since ").unwrap().1;
    let (h, m) = since.trim_end_matches(" h").split_once(':').unwrap();
    assert!(
        h.parse::<u32>().unwrap() * 60 + m.parse::<u32>().unwrap() < 180,
        "{first}"
    );
    assert_eq!(alarms, PACKING_ALARMS, "{packing}");
    assert_eq!(
        diagnoses(packing),
        "diagnosis: 8 diagnoses, 2 alarms",
        "{packing}"
    );
    assert_eq!(
        diagnoses(healthy),
        "diagnosis: 6 diagnoses, 0 alarms",
        "{healthy}"
    );
    // docs/daemon.md quotes this run's summaries and alarms.
    let doc = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/daemon.md"))
        .unwrap()
        .replace('\n', " ");
    for quoted in PACKING_ALARMS.iter().chain(&[
        "diagnosis: 8 diagnoses, 2 alarms",
        "diagnosis: 6 diagnoses, 0 alarms",
    ]) {
        assert!(
            doc.contains(&format!("`{quoted}`")),
            "docs/daemon.md: {quoted}"
        );
    }
}

#[test]
fn a_healthy_valve_raises_no_alarm_in_a_day_of_live_diagnosis() {
    let dir = tempfile::tempdir().unwrap();
    let out = run("healthy-valve.toml", "86400", dir.path());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    // A window every 30 minutes once the first 20 are logged: 48 in a day, none alarmed.
    let summary = diagnoses(&stdout);
    assert_eq!(summary, "diagnosis: 48 diagnoses, 0 alarms", "{stdout}");
    let history = std::fs::read_to_string(dir.path().join("diagnosis-healthy.jsonl")).unwrap();
    assert_eq!(history.lines().count(), 48);
    let rows = health_rows(&dir.path().join("health-healthy.csv"));
    assert!(rows.iter().all(|r| !r.1), "{rows:?}");
    for warning in ["health alarm", "diagnosis alarm"] {
        assert!(!stderr.contains(warning), "{stderr}");
    }
}

/// The `diagnosis: N diagnoses, M alarms` line of a valve's summary in `text`.
fn diagnoses(text: &str) -> String {
    let line = (text.lines())
        .find(|l| l.trim().starts_with("diagnosis: "))
        .unwrap_or_else(|| panic!("no diagnosis line in {text}"));
    line.trim().split(", in ").next().unwrap().to_string()
}
