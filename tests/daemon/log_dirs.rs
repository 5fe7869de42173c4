//! A log directory reads back as written: a run of exactly `rotate_after_s` leaves no file that
//! holds only the stop row, and a directory with several valves' logs and their `health-*.csv`
//! is read one valve at a time (`--valve`), the health files left out; rotated files are
//! gzipped and read as they are; the empty and header-only files a crash just after a rotation
//! leaves are skipped, each named in a warning. A restart into the same directory appends to the
//! health and diagnosis histories and writes its reports beside the first run's; a symbolic link
//! planted in the directory is not followed; a file killed right after its rotation holds its
//! header.

use crate::common;

use std::io::Read;
use std::path::Path;
use std::process::{Command, Output};

use valve_bridge::recording::gzip;
use valve_bridge::recording::log_format::HEADER;

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

/// Two named emulated valves with `[health]`, files rotated every 30 s.
const CONFIG: &str = r#"
[[valve]]
name = "level"
kind = "emulated"
[valve.source]
kind = "random-steps"
[valve.source.random-steps]
hold_min_s = 1.0
hold_max_s = 4.0
seed = 3
[[valve]]
name = "cyclone"
kind = "emulated"
[valve.source]
kind = "random-steps"
[valve.source.random-steps]
hold_min_s = 1.0
hold_max_s = 4.0
seed = 4
[log]
rotate_after_s = 30.0
[health]
window_s = 30.0
every_s = 30.0
"#;

fn valve_bridge(args: &[&str], cwd: &Path) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(cwd)
        .output()
        .unwrap()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

#[test]
fn a_log_directory_reads_back_one_valve_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("two.toml"), CONFIG).unwrap();
    let logs = dir.path().join("logs");
    let logs_arg = logs.to_str().unwrap();
    // Exactly two rotation spans: the stop row belongs to the second file of each valve.
    let run = valve_bridge(
        &[
            "run",
            "--config",
            "two.toml",
            "--as-fast-as-possible",
            "--duration",
            "60",
            "--log-dir",
            logs_arg,
        ],
        dir.path(),
    );
    assert!(run.status.success(), "{}", text(&run.stderr));
    let mut names: Vec<String> = std::fs::read_dir(&logs)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    // Per valve: its two log files, its health CSV and health plot.
    assert_eq!(names.len(), 8, "{names:?}");
    // Each valve's first file was compressed when the log rotated; the last stays plain.
    let compressed = names.iter().filter(|n| n.ends_with(".csv.gz")).count();
    assert_eq!(compressed, 2, "{names:?}");
    for n in names.iter().filter(|n| n.starts_with("vb-")) {
        let mut body = String::new();
        gzip::open(&logs.join(n))
            .unwrap()
            .read_to_string(&mut body)
            .unwrap();
        let rows = body.lines().count() - 1;
        assert!(rows >= 3000, "{n}: {rows} rows");
    }
    // Several valves: the reader asks which.
    let out = valve_bridge(&["steps", logs_arg], dir.path());
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        text(&out.stderr).lines().last().unwrap_or(""),
        format!(
            "valve-bridge: error: {logs_arg} holds the logs of 2 valves (cyclone, level): \
             choose one with --valve NAME"
        )
    );
    let out = valve_bridge(&["steps", logs_arg, "--valve", "pump"], dir.path());
    assert!(
        text(&out.stderr)
            .contains("holds no logs of valve pump (--valve); it holds those of: cyclone, level"),
        "{}",
        text(&out.stderr)
    );
    // One valve: its two files joined (6001 rows), the health files and the other valve's
    // logs left out, and said so.
    let out = Command::new(BIN)
        .args(["diagnose", logs_arg, "--valve", "level", "--json"])
        .current_dir(dir.path())
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("reading 2 files (vb-level-")
            && stderr.contains("left out 2 files that are not valve level's logs")
            && stderr.contains("left out 2 health files (the daemon's health figures)"),
        "{stderr}"
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(json.is_object(), "{json}");
}

#[test]
fn the_empty_and_header_only_files_of_a_crash_are_skipped_with_a_warning_naming_each() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let logs_arg = logs.to_str().unwrap();
    std::fs::write(
        dir.path().join("one.toml"),
        "[log]\nrotate_after_s = 10.0\n[source]\nkind = \"random-steps\"\n\
         [source.random-steps]\nhold_min_s = 1.0\nhold_max_s = 4.0\nseed = 5\n",
    )
    .unwrap();
    let run = valve_bridge(
        &[
            "run",
            "--config",
            "one.toml",
            "--as-fast-as-possible",
            "--duration",
            "20",
            "--log-dir",
            logs_arg,
        ],
        dir.path(),
    );
    assert!(run.status.success(), "{}", text(&run.stderr));
    // What a kill -9 right after rotations leaves: the newest files empty, or with only their
    // header.
    let empty = logs.join("vb-29991231T235958Z.csv");
    let header_only = logs.join("vb-29991231T235959Z.csv");
    std::fs::write(&empty, "").unwrap();
    std::fs::write(&header_only, format!("{}\n", HEADER.join(","))).unwrap();
    let sim = dir.path().join("sim.csv");
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/models/pincart2.toml");
    for args in [
        vec!["steps", logs_arg],
        vec![
            "simulate",
            "--model",
            model.to_str().unwrap(),
            "--input",
            logs_arg,
            "--out",
            sim.to_str().unwrap(),
        ],
    ] {
        let out = valve_bridge(&args, dir.path());
        let stderr = text(&out.stderr);
        assert!(out.status.success(), "{args:?}: {stderr}");
        for warning in [
            format!(
                "{}: no data rows (empty file, not even a header), skipped",
                empty.display()
            ),
            format!("{}: no data rows, skipped", header_only.display()),
        ] {
            assert!(stderr.contains(&warning), "{args:?}: {warning}: {stderr}");
        }
    }
    // The rows of the run are all there: 20 s at 100 Hz and the stop row.
    let rows = std::fs::read_to_string(&sim).unwrap().lines().count() - 1;
    assert_eq!(rows, 2001);
}

/// One named valve with `[health]` and `[diagnosis]` on minute windows.
const DIAGNOSED: &str = r#"
[[valve]]
name = "level"
kind = "emulated"
[valve.source]
kind = "random-steps"
[valve.source.random-steps]
hold_min_s = 1.0
hold_max_s = 4.0
seed = 3
[health]
window_s = 60.0
every_s = 60.0
[diagnosis]
window_s = 60.0
every_s = 60.0
"#;

/// `valve-bridge run` of `config` in `dir` on the virtual clock for `secs` s, logging to
/// `dir/logs`; its output, which must be a success.
fn run_into_logs(dir: &Path, config: &str, secs: &str) -> Output {
    std::fs::write(dir.join("c.toml"), config).unwrap();
    let args = ["run", "--config", "c.toml", "--as-fast-as-possible"];
    let out = valve_bridge(
        &[&args[..], &["--duration", secs, "--log-dir", "logs"]].concat(),
        dir,
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    out
}

/// The report paths a diagnosis history names, in order.
fn reports(history: &str) -> Vec<String> {
    (history.lines())
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| v["report"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn a_restart_into_the_same_directory_appends_its_history() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let first = run_into_logs(dir.path(), DIAGNOSED, "150");
    assert!(text(&first.stdout).contains("health: 2 windows"));
    let health = std::fs::read_to_string(logs.join("health-level.csv")).unwrap();
    let history = std::fs::read_to_string(logs.join("diagnosis-level.jsonl")).unwrap();
    assert_eq!(health.lines().count(), 3, "{health}");
    let first_reports = reports(&history);
    assert_eq!(first_reports.len(), 2, "{history}");
    let first_html: Vec<Vec<u8>> = (first_reports.iter())
        .map(|r| std::fs::read(logs.join(r)).unwrap())
        .collect();
    // Loop time starts again at 0: the same windows, at the same loop times.
    let second = run_into_logs(dir.path(), DIAGNOSED, "150");
    assert!(text(&second.stdout).contains("health: 2 windows"));
    let health_after = std::fs::read_to_string(logs.join("health-level.csv")).unwrap();
    assert!(health_after.starts_with(&health), "{health_after}");
    assert_eq!(
        health_after.lines().count(),
        5,
        "one header: {health_after}"
    );
    let history_after = std::fs::read_to_string(logs.join("diagnosis-level.jsonl")).unwrap();
    assert!(history_after.starts_with(&history), "{history_after}");
    let all = reports(&history_after);
    assert_eq!(all.len(), 4, "{history_after}");
    let mut distinct = all.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), 4, "a report of each diagnosis: {all:?}");
    for (r, html) in first_reports.iter().zip(&first_html) {
        assert_eq!(&std::fs::read(logs.join(r)).unwrap(), html, "{r} rewritten");
    }
    for r in &all[2..] {
        assert!(logs.join(r).is_file(), "{r}");
    }
}

#[test]
fn a_link_planted_in_the_log_directory_is_not_followed() {
    use std::os::unix::fs::symlink;
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    std::fs::create_dir(&logs).unwrap();
    let outside = dir.path().join("outside");
    std::fs::create_dir(&outside).unwrap();
    let target = outside.join("precious.txt");
    std::fs::write(&target, "precious\n").unwrap();
    std::fs::write(dir.path().join("c.toml"), DIAGNOSED).unwrap();
    let args = [
        "run",
        "--config",
        "c.toml",
        "--as-fast-as-possible",
        "--duration",
        "5",
        "--log-dir",
        "logs",
    ];
    for (name, to) in [
        ("health-level.csv", &target),
        ("diagnosis-level.jsonl", &target),
        ("diagnosis-level", &outside),
        ("vb-level-new.part", &target),
    ] {
        // Each case in a directory of its own making.
        std::fs::remove_dir_all(&logs).unwrap();
        std::fs::create_dir(&logs).unwrap();
        let link = logs.join(name);
        symlink(to, &link).unwrap();
        let out = valve_bridge(&args, dir.path());
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{name}: {stderr}");
        assert!(
            stderr.contains(&format!("`logs/{name}` is a symbolic link"))
                && stderr.contains("does not follow links"),
            "{name}: {stderr}"
        );
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "precious\n");
        assert_eq!(std::fs::read_dir(&outside).unwrap().count(), 1, "{name}");
    }
    std::fs::remove_dir_all(&logs).unwrap();
    // Without the links the same run goes.
    let out = valve_bridge(&args, dir.path());
    assert!(out.status.success(), "{}", text(&out.stderr));
}

#[test]
fn a_file_killed_right_after_its_rotation_holds_its_header() {
    let _turn = common::sim::real_time_turn();
    let dir = tempfile::tempdir().unwrap();
    let config = "[log]\nrotate_after_s = 1.0\ncompress = false\n";
    std::fs::write(dir.path().join("c.toml"), config).unwrap();
    // Killed as soon as the second, then the third file appears: twice on each.
    for (run, files) in [(0, 2), (1, 2), (2, 3), (3, 3)] {
        let logs = dir.path().join(format!("logs-{run}"));
        let mut child = Command::new(BIN)
            .args(["run", "--config", "c.toml", "--duration", "30", "--log-dir"])
            .arg(&logs)
            .current_dir(dir.path())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        let started = std::time::Instant::now();
        while !logs.exists() || common::logs(&logs, "vb-").len() < files {
            assert!(started.elapsed().as_secs() < 20, "no rotation");
            std::thread::yield_now();
        }
        assert!(common::signal(&child, libc::SIGKILL));
        child.wait().unwrap();
        let on_disk = common::logs(&logs, "vb-");
        assert!(on_disk.len() >= files, "{on_disk:?}");
        for f in &on_disk {
            let body = std::fs::read_to_string(f).unwrap();
            assert!(
                body.starts_with(
                    "t_s,op_pct,vp_pct,status,lateness_us,latency_us,op_sent_pct,utc,op_controller_pct\n"
                ),
                "{}: {body:?}",
                f.display()
            );
        }
    }
}
