//! The live diagnosis (`[diagnosis]`) through the real binary, on the virtual clock, with
//! `config/friction-drift.toml` (a valve whose friction band widens beside a healthy one) and
//! a short window: every valve's history gets a line per diagnosis (each effect with its size,
//! unit and interval, the report beside it), a health alarm triggers one at once, and two runs
//! write the same histories but for their wall-clock times (the diagnosis thread is
//! deterministic on the virtual clock); and with diagnoses far slower than the virtual clock,
//! memory stays flat however long the run, no window skipped.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

/// Runs friction-drift with `[diagnosis]` for `secs` s in `dir`; the summary.
fn run(dir: &Path, secs: &str) -> String {
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/friction-drift.toml"
    ))
    .unwrap();
    let config = dir.join("c.toml");
    let text = base.replace(
        "\n[diagnosis]\n",
        "\n[diagnosis]\nwindow_s = 300.0\nevery_s = 600.0\n",
    );
    assert_ne!(
        text, base,
        "config/friction-drift.toml has no [diagnosis] table"
    );
    std::fs::write(&config, text).unwrap();
    let out = Command::new(BIN)
        .args(["run", "--config", config.to_str().unwrap()])
        .args(["--as-fast-as-possible", "--duration", secs, "--log-dir"])
        .arg(dir)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    stdout
}

/// A history line without its wall-clock fields (`utc`, and `report`, named by it).
fn without_wall_clock(mut line: Value) -> Value {
    let fields = line.as_object_mut().unwrap();
    assert!(fields.remove("utc").unwrap().is_string());
    assert!(fields.remove("report").unwrap().is_string());
    line
}

fn history(path: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn each_valve_gets_a_history_of_sized_effects_the_same_on_every_run() {
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let (pa, pb) = (a.path().to_path_buf(), b.path().to_path_buf());
    let other = std::thread::spawn(move || run(&pb, "1200"));
    let summary = run(&pa, "1200");
    other.join().unwrap();
    for valve in ["packing", "healthy"] {
        let name = format!("diagnosis-{valve}.jsonl");
        let lines = history(&a.path().join(&name));
        let times: Vec<(f64, &str)> = (lines.iter())
            .filter(|l| l["trigger"] == "every_s")
            .map(|l| (l["t_s"].as_f64().unwrap(), l["window_s"].as_f64().unwrap()))
            .map(|(t, w)| {
                (
                    t,
                    if (w - 300.0).abs() < 0.02 {
                        "whole"
                    } else {
                        "part"
                    },
                )
            })
            .collect();
        assert_eq!(times, [(300.0, "whole"), (900.0, "whole")], "{lines:?}");
        for l in &lines {
            assert!(l["error"].is_null(), "{l}");
            assert!(l["verdict"].as_str().unwrap().len() > 10, "{l}");
            for e in l["effects"].as_array().unwrap() {
                let s = &e["size"];
                let (v, lo, hi) = (s["value"].as_f64(), s["low"].as_f64(), s["high"].as_f64());
                let (v, lo, hi) = (v.unwrap(), lo.unwrap(), hi.unwrap());
                assert!(lo <= v && v <= hi, "{e}");
                assert!(!s["unit"].as_str().unwrap().is_empty(), "{e}");
                assert!(e["effect"].is_string() && e["finding"].is_boolean(), "{e}");
            }
            let report = a.path().join(l["report"].as_str().unwrap());
            let html = std::fs::read_to_string(&report).unwrap();
            assert!(html.contains("live diagnosis"), "{}", report.display());
        }
        // The same rows, the same jobs in the same order: the same history, but for the
        // wall-clock times (the window's end, the report's name) of runs started apart.
        let again: Vec<Value> = history(&b.path().join(&name))
            .into_iter()
            .map(without_wall_clock)
            .collect();
        let once: Vec<Value> = lines.iter().cloned().map(without_wall_clock).collect();
        assert_eq!(once, again);
        assert!(
            summary.contains(&format!("diagnosis: {}", lines.len())),
            "{summary}"
        );
    }
    // The packing valve's health alarm (its reversal delay, after about 17 min) asked for a
    // diagnosis at once; the healthy valve raised none.
    let packing = history(&a.path().join("diagnosis-packing.jsonl"));
    assert!(
        packing.iter().any(|l| l["trigger"] == "health alarm"),
        "{packing:?}"
    );
    let healthy = history(&a.path().join("diagnosis-healthy.jsonl"));
    assert!(
        healthy.iter().all(|l| l["trigger"] == "every_s"),
        "{healthy:?}"
    );
    // The first whole window is diagnosed from scratch; the next starts from its final model.
    let started_from: Vec<String> = (healthy.iter())
        .map(|l| {
            let report = a.path().join(l["report"].as_str().unwrap());
            let json = std::fs::read_to_string(report.with_file_name("diagnosis.json")).unwrap();
            let doc: Value = serde_json::from_str(&json).unwrap();
            doc["baseline"]["model"].as_str().unwrap().to_string()
        })
        .collect();
    assert_eq!(started_from, ["fopdt", "pincart2 (given)"]);
}

#[test]
fn a_daemon_handed_no_diagnosis_refuses_the_diagnosis_table_before_it_starts() {
    use valve_bridge::daemon::{self, Analysis, Config, DaemonError, RunOptions};
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/friction-drift.toml"
    ))
    .unwrap();
    let path = dir.path().join("c.toml");
    assert!(base.contains("\n[diagnosis]\n"));
    std::fs::write(&path, base).unwrap();
    let config = Config::load(Some(&path)).unwrap();
    let logs = dir.path().join("logs");
    let started = daemon::start(
        config,
        RunOptions {
            duration_s: Some(1.0),
            log_dir: Some(logs.clone()),
            virtual_clock: true,
            analysis: Analysis::default(),
            ..RunOptions::default()
        },
    );
    let err = started.expect_err("started without a diagnosis to run");
    assert!(matches!(err, DaemonError::NoDiagnosis), "{err}");
    assert!(err.to_string().starts_with("[diagnosis]: "), "{err}");
    assert!(
        !logs.join("diagnosis-packing.jsonl").exists(),
        "no history before the refusal"
    );
}

/// A diagnosis that takes 30 ms and finds nothing: the real one takes seconds, far longer than
/// the virtual clock takes for a window of rows.
fn slow_nothing(
    _rec: &valve_bridge::recording::RecordingView,
    _base: Option<&valve_bridge::model::ModelSpec>,
    _title: Option<&str>,
) -> Result<valve_bridge::daemon::monitor::analysis::WindowDiagnosis, String> {
    std::thread::sleep(std::time::Duration::from_millis(30));
    Ok(valve_bridge::daemon::monitor::analysis::WindowDiagnosis {
        verdict: "nothing found".into(),
        effects: Vec::new(),
        report: Vec::new(),
        model: valve_bridge::model::bundled(valve_bridge::model::ModelKind::Pincart2),
    })
}

/// This process's peak resident memory so far, KiB (`VmHWM`).
fn peak_kib() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let line = status.lines().find(|l| l.starts_with("VmHWM:")).unwrap();
    line.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn memory_stays_flat_with_diagnoses_slower_than_the_virtual_clock() {
    use valve_bridge::daemon::{self, Analysis, Config, RunOptions};
    // Two valves, a 600 s window every 60 s: each window a job of about 1 MB, some 50 of them
    // in 30 min of loop time and 220 in 2 h. Diagnosed one at a time in 30 ms each, they
    // queued up behind the first (the peak grew with the run); now none is skipped on the
    // virtual clock, and the health thread waits for a valve's previous diagnosis instead.
    let dir = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/config/friction-drift.toml"
    ))
    .unwrap();
    let text = base.replace(
        "\n[diagnosis]\n",
        "\n[diagnosis]\nwindow_s = 600.0\nevery_s = 60.0\non_alarm = false\nreports = false\n",
    );
    let path = dir.path().join("c.toml");
    std::fs::write(&path, text).unwrap();
    let run = |secs: f64, sub: &str| {
        let running = daemon::start(
            Config::load(Some(&path)).unwrap(),
            RunOptions {
                duration_s: Some(secs),
                log_dir: Some(dir.path().join(sub)),
                virtual_clock: true,
                analysis: Analysis {
                    diagnose: Some(slow_nothing),
                    plot_health: None,
                },
                ..RunOptions::default()
            },
        )
        .unwrap();
        let summary = running.finish().unwrap();
        let counts: Vec<(u64, u64)> = (summary.valves.iter())
            .map(|v| v.diagnosis.as_ref().unwrap())
            .map(|d| (d.diagnoses, d.skipped))
            .collect();
        (peak_kib(), counts)
    };
    let (short, counts) = run(1800.0, "short");
    // A window at 600 s (less half a cycle) and every 60 s after it: every one diagnosed.
    assert_eq!(counts, [(21, 0), (21, 0)]);
    let (long, counts) = run(7200.0, "long");
    assert_eq!(counts, [(111, 0), (111, 0)]);
    assert!(
        long < short + 8192,
        "peak {short} KiB after 30 min, {long} KiB after 2 h"
    );
}
