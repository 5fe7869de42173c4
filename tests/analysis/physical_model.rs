//! The physical valve loads wherever a model file does: `simulate --model`, the daemon's
//! emulated valve (`[valve.emulated]` by name or file), and it is refused where only the
//! paper's models make sense (`identify --models`, `diagnose --model`) with a one-line error.

use std::path::{Path, PathBuf};
use std::process::Command;

use valve_bridge::daemon::config::{Config, ValveSpec};
use valve_bridge::model::ModelKind;

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
}

fn root(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

const CASE: &str = "tests/data/cases/pub_clean_rs.csv";

#[test]
fn simulate_runs_the_physical_model_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim.csv");
    let run = bin()
        .args(["simulate", "--model"])
        .arg(root("config/models/physical.toml"))
        .arg("--input")
        .arg(root(CASE))
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(stdout.contains("Physical"), "{stdout}");
    let rows = std::fs::read_to_string(&out).unwrap().lines().count();
    assert_eq!(rows, 60_001);
}

/// The model of the first valve of `c`, an emulated one.
fn emulated_model(c: &Config) -> ModelKind {
    match &c.valves[0].backend {
        ValveSpec::Emulated(e) => e.model_spec().unwrap().model,
        other => panic!("{other:?}"),
    }
}

#[test]
fn emulated_valve_takes_the_physical_model_by_name_and_file() {
    let c = Config::from_toml(
        "[valve.emulated]\nmodel = \"physical\"\n",
        Path::new("c.toml"),
    )
    .unwrap();
    assert_eq!(emulated_model(&c), ModelKind::Physical);
    let file = root("config/models/physical.toml");
    let c = Config::from_toml(
        &format!(
            "[valve.emulated]\nmodel_file = {:?}\n",
            file.display().to_string()
        ),
        Path::new("c.toml"),
    )
    .unwrap();
    assert_eq!(emulated_model(&c), ModelKind::Physical);
}

#[test]
fn identify_and_diagnose_refuse_the_simulator_in_one_line() {
    let run = bin()
        .args(["identify", "--models", "pincart2,physical"])
        .arg(root(CASE))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("physical is a simulator with 16 parameters, not one of the paper's identifiable models"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    let run = bin()
        .arg("diagnose")
        .arg(root(CASE))
        .arg("--model")
        .arg(root("config/models/physical.toml"))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("is a simulator, not a starting model"),
        "{err}"
    );
}
