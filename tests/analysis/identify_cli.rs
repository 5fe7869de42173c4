//! `valve-bridge identify` and `steps` on recordings: every shared case file (100 Hz, hidden effects)
//! and DAMADICS actuator 3 (real plant, 1 Hz, mapped columns). Identification must finish,
//! beat the modelless reference, write model files that load and reproduce their score, and
//! write a report with charts. README's Table 1 of the paper-like case must be the one
//! `valve_bridge::report::readme` makes of its identification.

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;
use valve_bridge::metrics;
use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording::{self, ReadOptions};

// The generator of the figures README and docs/ quote: the example's own code, one implementation.
use crate::blocks;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
}

fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

const CASE: &str = "cases/pub_backlash_rs.csv";
const DAMADICS: &str = "real/damadics-actuator3-1h/actuator3_2001-10-11_1h_1Hz.csv";
const DAMADICS_COLUMNS: &str = "t=t_s,op=LC74_20CV_pct,vp=LC74_20X_pct";

fn identify_json(args: &[&str]) -> Value {
    let out = bin()
        .arg("identify")
        .args(args)
        .arg("--json")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn sse_of(doc: &Value, model: &str) -> f64 {
    doc["rows"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["model"] == model)
        .unwrap_or_else(|| panic!("no row {model}"))["sse"]
        .as_f64()
        .unwrap()
}

/// Every recording in `tests/data/cases/`: identification finishes, every model beats the
/// modelless reference on all samples and on the held-out blocks, and each row is complete.
#[test]
fn every_case_recording_is_identified_and_every_model_beats_modelless() {
    let mut cases: Vec<PathBuf> = std::fs::read_dir(data("cases"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    cases.sort();
    assert_eq!(cases.len(), 9, "{cases:?}");
    for case in &cases {
        let doc = identify_json(&[case.to_str().unwrap()]);
        let name = case.file_stem().unwrap().to_string_lossy();
        assert_eq!(doc["sample_period_s"], 0.01, "{name}");
        let rows = doc["rows"].as_array().unwrap();
        let models: Vec<&str> = rows.iter().map(|r| r["model"].as_str().unwrap()).collect();
        assert_eq!(
            models,
            [
                "modelless",
                "delayed",
                "fopdt",
                "stiction",
                "pincart1",
                "pincart2"
            ],
            "{name}"
        );
        let (sse, held) = (&rows[0]["sse"], &rows[0]["heldout"]["sse"]);
        let (sse, held) = (sse.as_f64().unwrap(), held.as_f64().unwrap());
        for r in rows.iter().skip(1) {
            for key in ["mae", "mae_filtered", "r2", "rel_sse", "heldout", "params"] {
                assert!(!r[key].is_null(), "{name}: {key} missing in {r}");
            }
            assert!(r["sse"].as_f64().unwrap() < sse, "{name}: {r}");
            assert!(r["heldout"]["sse"].as_f64().unwrap() < held, "{name}: {r}");
        }
        assert_eq!(rows[5]["params"].as_object().unwrap().len(), 7, "{name}");
        if name == blocks::TABLE1_CASE {
            // README quotes this Table 1 as generated from this very document.
            let page = blocks::page(blocks::IDENTIFY_TABLE1);
            let text =
                std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(page)).unwrap();
            if let Err(e) =
                blocks::check_block(&text, blocks::IDENTIFY_TABLE1, &blocks::table1(&doc))
            {
                panic!("{e}");
            }
        }
    }
}

/// A backlash valve: pin-cart II beats FOPDT, also on held-out blocks.
#[test]
fn backlash_case_prefers_pincart2_on_held_out_data() {
    let doc = identify_json(&[data(CASE).to_str().unwrap()]);
    assert_eq!(doc["n_samples"], 90_000);
    let held = |m: &str| {
        doc["rows"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["model"] == m)
            .unwrap()["heldout"]["sse"]
            .as_f64()
            .unwrap()
    };
    assert!(sse_of(&doc, "pincart2") < sse_of(&doc, "fopdt"));
    assert!(held("pincart2") < held("fopdt"));
}

#[test]
fn damadics_is_identified_and_the_model_files_reproduce_their_scores() {
    let dir = tempfile::tempdir().unwrap();
    let file = data(DAMADICS);
    let out = bin()
        .args([
            "identify",
            file.to_str().unwrap(),
            "--columns",
            DAMADICS_COLUMNS,
        ])
        .arg("--out")
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("Table 1") && text.contains("Table 2") && text.contains("Pin-cart II"));
    let doc: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("identify.json")).unwrap())
            .unwrap();
    assert_eq!(doc["sample_period_s"], 1.0);
    let rec = recording::read(
        &file,
        &ReadOptions {
            columns: DAMADICS_COLUMNS.parse().unwrap(),
            ..ReadOptions::default()
        },
    )
    .unwrap();
    let modelless = sse_of(&doc, "modelless");
    for model in ["delayed", "fopdt", "stiction", "pincart1", "pincart2"] {
        assert!(sse_of(&doc, model) < 0.5 * modelless, "{model}");
        // The file loads as any model file and reproduces the reported SSE.
        let spec = ModelSpec::load(&dir.path().join(format!("{model}.toml"))).unwrap();
        let sim = Valve::new(&spec, rec.sample_period)
            .unwrap()
            .simulate(&rec.op, rec.vp[0]);
        let s = metrics::scores(&rec.vp, &sim, &rec.op, rec.sample_period);
        let want = sse_of(&doc, model);
        assert!(
            (s.sse - want).abs() < 1e-6 * want,
            "{model}: {} vs {want}",
            s.sse
        );
    }
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.starts_with("<!doctype html>") && html.ends_with("</html>"));
    assert!(html.matches("<svg").count() >= 4, "charts missing");
    assert!(
        !html.contains("src=\"http"),
        "the report must be self-contained"
    );
}

#[test]
fn windows_restrict_scoring_and_bad_windows_say_why() {
    let file = data(CASE);
    let doc = identify_json(&[
        file.to_str().unwrap(),
        "--models",
        "fopdt",
        "--windows",
        "100-200,300-350",
    ]);
    // 100.00-200.00 s and 300.00-350.00 s at 100 Hz, both ends included.
    assert_eq!(doc["n_scored"], 10_001 + 5_001);
    assert_eq!(doc["rows"].as_array().unwrap().len(), 3);
    let out = bin()
        .args(["identify", file.to_str().unwrap(), "--windows", "200-100"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the end must come after the start"), "{err}");
}

#[test]
fn steps_finds_both_delay_populations() {
    let out = bin()
        .args(["steps", data(CASE).to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let a: Value = serde_json::from_slice(&out.stdout).unwrap();
    let same = a["same"]["mean_s"].as_f64().unwrap();
    let rev = a["reversal"]["mean_s"].as_f64().unwrap();
    assert!(a["same"]["count"].as_u64().unwrap() > 10);
    assert!(a["reversal"]["count"].as_u64().unwrap() > 10);
    // Backlash: reversals take longer.
    assert!(rev > same, "{rev} vs {same}");
    // And on 1 Hz plant data it runs and reports.
    let out = bin()
        .args([
            "steps",
            data(DAMADICS).to_str().unwrap(),
            "--columns",
            DAMADICS_COLUMNS,
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stdout).contains("same direction"));
}
