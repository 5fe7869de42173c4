//! `valve-bridge diagnose --json` on recordings whose hidden physics is known (`tests/data/cases`,
//! with a truth file each): the effects named must be the truth's, nothing on the clean case,
//! and the held-out error must drop whenever something is added.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

fn diagnose(case: &str) -> (Value, Vec<String>) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cases");
    let out = Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
        .arg("diagnose")
        .arg(dir.join(format!("{case}.csv")))
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let d: Value = serde_json::from_slice(&out.stdout).unwrap();
    let truth: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join(format!("{case}.truth.json"))).unwrap(),
    )
    .unwrap();
    let mut want: Vec<String> = truth["effects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e.as_str().unwrap().to_string())
        .collect();
    want.sort();
    (d, want)
}

fn check(case: &str) {
    let (d, want) = diagnose(case);
    for key in [
        "baseline",
        "noise_floor_pct",
        "mismatch_windows",
        "findings",
        "final",
        "verdict",
    ] {
        assert!(d.get(key).is_some(), "{case}: no `{key}` in the JSON");
    }
    let mut found: Vec<String> = d["findings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["effect"].as_str().unwrap().to_string())
        .collect();
    found.sort();
    assert_eq!(found, want, "{case}: {}", d["verdict"]);
    let before = d["baseline"]["heldout_sse"].as_f64().unwrap();
    let after = d["final"]["heldout_sse"].as_f64().unwrap();
    if want.is_empty() {
        assert_eq!(before, after, "{case}: nothing found, nothing changed");
    } else {
        assert!(
            after < 0.9 * before,
            "{case}: held-out SSE {before} -> {after}"
        );
        for f in d["findings"].as_array().unwrap() {
            assert!(
                f["delta_bic"].as_f64().unwrap() < 0.0
                    && !f["evidence"].as_str().unwrap().is_empty()
            );
        }
    }
}

#[test]
fn clean_valve_has_nothing_missing() {
    check("pub_clean_rs");
}

#[test]
fn backlash_under_random_steps_is_named() {
    check("pub_backlash_rs");
}

#[test]
fn slow_venting_is_asymmetry() {
    check("pub_asym_rs");
}

#[test]
fn air_supply_limit_is_slew_rate() {
    check("pub_slew_mixed");
}

#[test]
fn transport_delay_is_dead_time() {
    check("pub_deadtime_mixed");
}
