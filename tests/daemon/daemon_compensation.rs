//! `valve-bridge run` with `[valve.compensation]`, through the real binary on the virtual clock:
//!
//! - the log holds the set-point sent (`op_pct`, what identification reads) and the
//!   controller's O_P (`op_controller_pct`) side by side; the recording reader's O_P replays
//!   through the emulated valve to its V_P, so it is what the valve received; compensation
//!   lowers the tracking error of a valve with a friction band on small reversing steps;
//! - the deadband step is on the side of the move, closing as well as opening: on the emulated
//!   valve the model describes, and on the same valve as a Modbus device (sim-device over
//!   loopback TCP, per-mille set-points and positions), the valve comes to rest at the target;
//! - a compensator whose model overstates the valve's faults (a healthy valve given a worn
//!   valve's band) is switched off by its guard in its first window, with a warning naming
//!   the figure, and the controller's O_P is sent unchanged from then on;
//! - the walk-through of docs/compensation.md: `config/models/physical-band-diagnosed.toml` is
//!   the model `diagnose` finds in the log of `config/physical-band.toml`, and the page quotes
//!   the finding's size, the compensated run's summary and its O_P - V_P with and without.

use std::path::{Path, PathBuf};

use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording::{self, ReadOptions};

use crate::common::sim::{read_log, real_time_turn, run_cmd, stdout, SimDevice};

/// A valve whose stem crosses a 1.5 % friction band on reversals, pushed at 8 % per s and % of
/// error up to 60 %/s, 0.05 s of dead time: the form `diagnose` writes.
const BAND_MODEL: &str = "model = \"pincart2\"\ndead_time_s = 0.05\n[pincart2]\np_gain_per_s = 8.0\ndy_max_pct_per_s = 60.0\ndy_min_pct_per_s = 0.0\na_p = 0.0\nb_p = 0.0\nc_p = 0.0\nbacklash_pct = 0.0\n[effects]\nfriction_band_pct = 1.5\n";

/// A valve with a band of 0.744 % on its input (the form `diagnose` may write for a 0.6 %
/// positioner deadband), otherwise as [`BAND_MODEL`] without its friction band.
const DEADBAND_MODEL: &str = "model = \"pincart2\"\ndead_time_s = 0.05\n[pincart2]\np_gain_per_s = 8.0\ndy_max_pct_per_s = 60.0\ndy_min_pct_per_s = 0.0\na_p = 0.0\nb_p = 0.0\nc_p = 0.0\nbacklash_pct = 0.0\n[effects]\ndeadband_pct = 0.744\n";

/// Steps closing and opening, each held `hold_s`.
const BOTH_WAYS: [f64; 6] = [50.0, 49.0, 51.0, 49.5, 48.0, 49.0];

fn both_ways(hold_s: f64) -> String {
    format!("[source]\nkind = \"steps\"\n[source.steps]\nlevels_pct = {BOTH_WAYS:?}\nhold_s = {hold_s}\nrepeat = false\n")
}

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

/// A row whose V_P may be missing (a Modbus timeout).
#[derive(Debug, serde::Deserialize)]
struct BusRow {
    op_pct: f64,
    vp_pct: Option<f64>,
    t_s: f64,
}

/// Each step of [`BOTH_WAYS`] after the first: the target, the move's direction, the
/// set-points sent in its hold of `hold_s` and the last V_P read in it.
fn holds(rows: &[BusRow], hold_s: f64) -> Vec<(f64, f64, Vec<f64>, f64)> {
    BOTH_WAYS
        .windows(2)
        .enumerate()
        .map(|(i, w)| {
            let span = hold_s * (i + 1) as f64..hold_s * (i + 2) as f64;
            let hold: Vec<&BusRow> = rows.iter().filter(|r| span.contains(&r.t_s)).collect();
            let end = hold.iter().rev().find_map(|r| r.vp_pct).unwrap();
            let sent = hold.iter().map(|r| r.op_pct).collect();
            (w[1], (w[1] - w[0]).signum(), sent, end)
        })
        .collect()
}

/// With compensation the valve rests within `tol` of each target, the set-points beyond it on
/// the side of the move; without, it stops short by at least `short`.
fn rests_at_the_targets(plain: &[BusRow], comped: &[BusRow], hold_s: f64, tol: f64, short: f64) {
    for ((to, dir, sent, with), (_, _, _, without)) in
        holds(comped, hold_s).into_iter().zip(holds(plain, hold_s))
    {
        assert!(
            sent.iter().all(|s| dir * (s - to) >= -1e-9),
            "to {to}: {sent:?}"
        );
        assert!(
            (with - to).abs() <= tol && dir * (to - without) >= short,
            "to {to}: V_P {with} with compensation, {without} without"
        );
    }
}

#[test]
fn the_deadband_step_brings_the_emulated_valve_to_its_targets_both_ways() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), DEADBAND_MODEL).unwrap();
    let valve = "[valve.emulated]\nmodel_file = \"model.toml\"\n";
    let comp = "[valve.compensation]\nmodel_file = \"model.toml\"\n";
    let logs = |name: &str| {
        let cfg = dir.path().join(format!("{name}.toml"));
        let source = both_ways(3.0);
        let text = if name == "with" {
            format!("{valve}{comp}{source}")
        } else {
            format!("{valve}{source}")
        };
        std::fs::write(&cfg, text).unwrap();
        let logs = dir.path().join(name);
        let out = run_cmd(&cfg, &logs, 18.0)
            .arg("--as-fast-as-possible")
            .current_dir(dir.path())
            .output()
            .unwrap();
        stdout(&out);
        read_log::<BusRow>(&logs)
    };
    // Without, the valve stops short by half the band, 0.372 %.
    rests_at_the_targets(&logs("without"), &logs("with"), 3.0, 0.01, 0.36);
}

#[test]
fn the_deadband_step_brings_a_modbus_device_to_its_targets_both_ways() {
    let _turn = real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("model.toml");
    std::fs::write(&model, DEADBAND_MODEL).unwrap();
    let run = |compensated: bool| {
        let dev = SimDevice::start(&["--tcp", "127.0.0.1:0", "--model", model.to_str().unwrap()]);
        let comp = format!("[valve.compensation]\nmodel_file = {model:?}\n");
        let source = both_ways(1.5);
        let sub = dir
            .path()
            .join(if compensated { "with" } else { "without" });
        std::fs::create_dir_all(&sub).unwrap();
        let text = if compensated {
            format!("{comp}{source}")
        } else {
            source
        };
        let cfg = dev.config(&sub, &[], &text);
        let logs = sub.join("logs");
        stdout(&run_cmd(&cfg, &logs, 9.0).output().unwrap());
        read_log::<BusRow>(&logs)
    };
    // Set-points go out in steps of 0.1 % and positions come back in steps of 0.1 %: the valve
    // rests within a step of each target with compensation, a quarter of a percent short
    // without.
    rests_at_the_targets(&run(false), &run(true), 1.5, 0.1 + 1e-9, 0.25);
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
fn a_model_that_overstates_the_valve_s_faults_is_switched_off_by_the_guard() {
    // The valve is healthy (the physical simulator, 0.1 % friction band): the kicks a 1.5 %
    // band asks for carry it past its targets, which its model says they do not. Windows of
    // 5 s: the evidence needs holds of two, so the earliest verdict comes after 5 s.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("model.toml"), BAND_MODEL).unwrap();
    let config = format!("[valve.emulated]\nmodel = \"physical\"\n[valve.compensation]\nmodel_file = \"model.toml\"\nguard_window_s = 5.0\n{STEPS}");
    let (stdout, stderr, rows, _) = run(dir.path(), &config, 30.0);
    assert!(
        stderr.contains("compensation switched off: over the last 3 guard windows the valve's overshoot past the target beyond its model's in "),
        "{stderr}"
    );
    let off: f64 = stdout
        .split_once("compensation: switched off by its guard at ")
        .and_then(|(_, r)| r.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(off > 5.0 && off < 20.0, "{stdout}");
    assert!(
        stdout.contains(" s (overshoot past the target beyond its model's in "),
        "{stdout}"
    );
    // Before: some kicks; after: the controller's O_P itself.
    assert!(rows
        .iter()
        .any(|r| r.t_s < off && r.op_pct != r.op_controller_pct));
    assert!(rows
        .iter()
        .filter(|r| r.t_s > off)
        .all(|r| r.op_pct == r.op_controller_pct));
}

/// `valve-bridge run --as-fast-as-possible` on `cfg` from the checkout's root for `secs`:
/// its summary, and the RMS of the controller's O_P minus V_P over its log, %.
fn walk_through_run(root: &Path, cfg: &Path, logs: &Path, secs: f64) -> (String, f64) {
    let out = run_cmd(cfg, logs, secs)
        .arg("--as-fast-as-possible")
        .current_dir(root)
        .output()
        .unwrap();
    let summary = stdout(&out);
    let rows: Vec<Row> = read_log(logs);
    let squares: f64 = rows
        .iter()
        .map(|r| (r.op_controller_pct - r.vp_pct).powi(2))
        .sum();
    (summary, (squares / rows.len() as f64).sqrt())
}

#[test]
fn the_shipped_diagnosed_model_is_what_diagnose_finds_in_the_worn_valve_s_log() {
    // the walk-through of docs/compensation.md: the worn valve's own log, diagnosed, is the model
    // config/compensated.toml compensates with, and the page quotes what each step prints.
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The page's words, one space apart (its lines wrap anywhere).
    let page = std::fs::read_to_string(root.join("docs/compensation.md")).unwrap();
    let page = page.split_whitespace().collect::<Vec<_>>().join(" ");
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("band-log");
    walk_through_run(root, &root.join("config/physical-band.toml"), &logs, 900.0);
    let diag = dir.path().join("band-diag");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
        .arg("diagnose")
        .arg(&logs)
        .arg("--out")
        .arg(&diag)
        .output()
        .unwrap();
    let report = stdout(&out);
    let found = ModelSpec::load(&diag.join("model.toml")).unwrap();
    let shipped =
        ModelSpec::load(&root.join("config/models/physical-band-diagnosed.toml")).unwrap();
    assert_eq!(found, shipped);
    // The finding's size line, as the page quotes it.
    let size = report
        .split("finding: backlash\n  size: ")
        .nth(1)
        .and_then(|rest| rest.split(" (90 % interval)").next())
        .unwrap_or_else(|| panic!("no backlash size in\n{report}"));
    assert!(page.contains(&format!("`{size}`")), "page lacks `{size}`");
    // The compensated run's last summary line, and the whole run's O_P - V_P with and without.
    let cfg = root.join("config/compensated.toml");
    let (summary, with) = walk_through_run(root, &cfg, &dir.path().join("band-comp"), 120.0);
    let line = summary
        .lines()
        .find_map(|l| {
            l.split(" (backlash")
                .next()
                .filter(|_| l.starts_with("compensation: "))
        })
        .unwrap_or_else(|| panic!("no compensation line in\n{summary}"));
    assert!(page.contains(&format!("`{line}`")), "page lacks `{line}`");
    // The diagnosed model's gain and deadband trace, as the page quotes them.
    let gain = found.pincart2.as_ref().map(|p| p.p_gain_per_s).unwrap();
    let deadband = found.effects.deadband_pct;
    for quoted in [
        format!("gain of {gain:.1} /s"),
        format!("deadband of {deadband:.3} %"),
    ] {
        assert!(page.contains(&quoted), "page lacks {quoted}");
    }
    let text = std::fs::read_to_string(&cfg).unwrap();
    let (head, rest) = text.split_once("[valve.compensation]").unwrap();
    let plain = dir.path().join("plain.toml");
    std::fs::write(
        &plain,
        format!("{head}[source]{}", rest.split_once("[source]").unwrap().1),
    )
    .unwrap();
    let (_, without) = walk_through_run(root, &plain, &dir.path().join("band-plain"), 120.0);
    let figures = format!(
        "is {with:.3} % RMS; the same run without `[valve.compensation]` gives {without:.3} % ({:.0} % less with it)",
        100.0 * (1.0 - with / without)
    );
    assert!(page.contains(&figures), "page lacks {figures}");
}
