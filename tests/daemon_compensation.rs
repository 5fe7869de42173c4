//! `valve-bridge run` with `[valve.compensation]`, through the real binary on the virtual clock:
//!
//! - the log holds the set-point sent (`op_pct`, what identification reads) and the
//!   controller's O_P (`op_controller_pct`) side by side; the recording reader's O_P replays
//!   through the emulated valve to its V_P, so it is what the valve received; compensation
//!   lowers the tracking error of a valve with a friction band on small reversing steps;
//! - a compensator whose model is far from the valve is switched off by its guard, with a
//!   warning, and the controller's O_P is sent unchanged from then on;
//! - README's walk-through: `config/models/physical-band-diagnosed.toml` is the model
//!   `diagnose` finds in the log of `config/physical-band.toml`.

use std::path::{Path, PathBuf};

use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording::{self, ReadOptions};

mod common;

use common::sim::{read_log, run_cmd, stdout};

/// A valve whose stem crosses a 1.5 % friction band on reversals, pushed at 8 % per s and % of
/// error up to 60 %/s, 0.05 s of dead time: the form `diagnose` writes.
const BAND_MODEL: &str = "model = \"pincart2\"\ndead_time_s = 0.05\n[pincart2]\np_gain_per_s = 8.0\ndy_max_pct_per_s = 60.0\ndy_min_pct_per_s = 0.0\na_p = 0.0\nb_p = 0.0\nc_p = 0.0\nbacklash_pct = 0.0\n[effects]\nfriction_band_pct = 1.5\n";

/// Small steps that reverse every 2 s.
const STEPS: &str = "[source]\nkind = \"steps\"\n[source.steps]\nlevels_pct = [40.0, 40.6, 40.2, 40.9, 40.5]\nhold_s = 2.0\nrepeat = true\n";

/// One row of a log, the columns this test reads.
#[derive(Debug, serde::Deserialize)]
struct Row {
    op_pct: f64,
    vp_pct: f64,
    op_controller_pct: f64,
    t_s: f64,
}

/// Runs the daemon on `config` (written into `dir`) for `secs` of loop time on the virtual
/// clock; returns its stdout, its stderr, the rows of its one log and that log's path.
fn run(dir: &Path, config: &str, secs: f64) -> (String, String, Vec<Row>, PathBuf) {
    let logs = dir.join(format!("logs-{}", std::fs::read_dir(dir).unwrap().count()));
    let cfg = dir.join("run.toml");
    std::fs::write(&cfg, config).unwrap();
    let out = run_cmd(&cfg, &logs, secs)
        .arg("--as-fast-as-possible")
        .current_dir(dir)
        .output()
        .unwrap();
    let text = stdout(&out);
    let log = std::fs::read_dir(&logs)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (text, stderr, read_log(&logs), log)
}

fn rms(rows: &[Row]) -> f64 {
    (rows
        .iter()
        .map(|r| (r.op_controller_pct - r.vp_pct).powi(2))
        .sum::<f64>()
        / rows.len() as f64)
        .sqrt()
}

#[test]
fn the_log_holds_both_set_points_and_identification_reads_what_the_valve_got() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), BAND_MODEL).unwrap();
    let valve = "[valve.emulated]\nmodel_file = \"model.toml\"\n";
    let comp = "[valve.compensation]\nmodel_file = \"model.toml\"\nguard_window_s = 5.0\n";
    let (_, _, plain, _) = run(dir.path(), &format!("{valve}{STEPS}"), 30.0);
    let (stdout, _, rows, log) = run(dir.path(), &format!("{valve}{comp}{STEPS}"), 30.0);
    assert!(
        stdout.contains("compensation: on, 6 windows judged"),
        "{stdout}"
    );
    // The controller's O_P is the source's steps; the set-point sent kicks on some samples.
    let levels = [40.0, 40.6, 40.2, 40.9, 40.5];
    assert!(rows.iter().all(|r| levels.contains(&r.op_controller_pct)));
    let kicked = rows
        .iter()
        .filter(|r| r.op_pct != r.op_controller_pct)
        .count();
    assert!(kicked > 10 && kicked * 20 < rows.len(), "{kicked} kicks");
    // Without compensation both columns are the same.
    assert!(plain.iter().all(|r| r.op_pct == r.op_controller_pct));
    // The recording reader takes `op_pct`: replayed through the valve, it gives the logged V_P.
    let rec = recording::read(&log, &ReadOptions::default()).unwrap();
    assert_eq!(rec.op, rows.iter().map(|r| r.op_pct).collect::<Vec<_>>());
    let spec = ModelSpec::load(&dir.path().join("model.toml")).unwrap();
    let sim = Valve::new(&spec, 0.01)
        .unwrap()
        .simulate(&rec.op, rec.op[0]);
    let worst = sim
        .iter()
        .zip(&rec.vp)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-4, "replay differs by {worst} %");
    // Reversals of 0.4-0.7 % cross the band 0.3-0.5 s sooner: a quarter less tracking error.
    let (before, after) = (rms(&plain), rms(&rows));
    assert!(after < 0.75 * before, "{before} -> {after}");
}

#[test]
fn a_model_far_from_the_valve_is_switched_off_by_the_guard() {
    // The valve is the bundled pin-cart II (0.38 s of dead time, 20 %/s): it tracks far worse
    // than the fast model the compensation was given says it would.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), BAND_MODEL).unwrap();
    let config = format!("[valve.emulated]\nmodel = \"pincart2\"\n[valve.compensation]\nmodel_file = \"model.toml\"\nguard_window_s = 5.0\n{STEPS}");
    let (stdout, stderr, rows, _) = run(dir.path(), &config, 20.0);
    assert!(stderr.contains("compensation switched off"), "{stderr}");
    assert!(
        stdout.contains("compensation: switched off by its guard at 5.0 s"),
        "{stdout}"
    );
    // Before: some kicks; after: the controller's O_P itself.
    assert!(rows
        .iter()
        .any(|r| r.t_s < 5.0 && r.op_pct != r.op_controller_pct));
    assert!(rows
        .iter()
        .filter(|r| r.t_s >= 5.0)
        .all(|r| r.op_pct == r.op_controller_pct));
}

#[test]
fn the_shipped_diagnosed_model_is_what_diagnose_finds_in_the_worn_valve_s_log() {
    // README's walk-through: the worn valve's own log, diagnosed, is the model
    // config/compensated.toml compensates with.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("band-log");
    let out = run_cmd(&root.join("config/physical-band.toml"), &logs, 900.0)
        .arg("--as-fast-as-possible")
        .current_dir(root)
        .output()
        .unwrap();
    stdout(&out);
    let diag = dir.path().join("band-diag");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
        .arg("diagnose")
        .arg(&logs)
        .arg("--out")
        .arg(&diag)
        .output()
        .unwrap();
    stdout(&out);
    let found = ModelSpec::load(&diag.join("model.toml")).unwrap();
    let shipped =
        ModelSpec::load(&root.join("config/models/physical-band-diagnosed.toml")).unwrap();
    assert_eq!(found, shipped);
}
