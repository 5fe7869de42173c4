//! Bad inputs meet a one-line error, never a panic: the corpus of bad recordings and configs in
//! `tests/data/bad/` (each listed in `expected.txt` with its error, `FILE` standing for its
//! path), recordings sampled every 30 s through every analysis command, and sample periods no
//! delay line can serve.

use std::path::{Path, PathBuf};
use std::process::Command;

fn bin() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_valve-bridge"));
    c.current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("RUST_LOG", "error");
    c
}

/// Runs `args`; returns (exit code, stderr's error line), asserting there was no panic and the
/// error is one line.
fn run(args: &[&str]) -> (i32, String) {
    let out = bin().args(args).output().expect("run valve-bridge");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    let code = out.status.code().unwrap_or(-1);
    assert!(code == 0 || code == 1, "{args:?}: exit {code}: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.starts_with("valve-bridge: error: "))
        .collect();
    assert!(errors.len() <= 1, "{args:?}: {stderr}");
    let line = errors
        .first()
        .map_or("", |l| &l["valve-bridge: error: ".len()..]);
    (code, line.to_string())
}

#[test]
fn every_bad_file_gets_its_one_line_error() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad");
    let list = std::fs::read_to_string(dir.join("expected.txt")).unwrap();
    let mut checked = 0;
    for entry in list.lines().filter(|l| !l.trim().is_empty()) {
        let (name, expected) = entry.split_once('\t').expect("NAME<TAB>ERROR");
        let rel = format!("tests/data/bad/{name}");
        let (code, line) = if name.ends_with(".toml") {
            let log = tempfile::tempdir().unwrap();
            let log = log.path().to_str().unwrap().to_string();
            run(&[
                "run",
                "--config",
                &rel,
                "--duration",
                "0.05",
                "--log-dir",
                &log,
            ])
        } else {
            run(&["steps", &rel])
        };
        assert_eq!(code, 1, "{name}");
        assert_eq!(line, expected.replace("FILE", &rel), "{name}");
        checked += 1;
    }
    assert!(checked >= 40, "{checked} bad files");
    let files = std::fs::read_dir(&dir).unwrap().count();
    // Every file but the list and the year-long replay the config points to is a case.
    assert_eq!(
        files,
        checked + 2,
        "a file in tests/data/bad without an expected error"
    );
}

/// A recording of `n` rows every `dt` seconds: steps of O_P every 5 rows, V_P following one
/// row late.
fn slow_recording(dir: &Path, n: usize, dt: f64) -> PathBuf {
    let mut text = String::from("t_s,op_pct,vp_pct\n");
    let level = |k: usize| 30.0 + 7.0 * ((k / 5) % 6) as f64;
    for k in 0..n {
        text += &format!(
            "{},{},{}\n",
            k as f64 * dt,
            level(k),
            level(k.saturating_sub(1)) + 0.01 * (k % 3) as f64
        );
    }
    let p = dir.join(format!("slow_{n}_{dt}.csv"));
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn recordings_sampled_every_25_to_60_s_give_a_result_or_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let model = "config/models/pincart2.toml";
    for dt in [25.0, 30.0, 60.0] {
        let rec = slow_recording(dir.path(), 240, dt);
        let rec = rec.to_str().unwrap();
        let sim = dir.path().join("sim.csv");
        for args in [
            vec!["identify", rec],
            vec!["steps", rec],
            vec!["diagnose", rec],
            vec![
                "simulate",
                "--model",
                model,
                "--input",
                rec,
                "--out",
                sim.to_str().unwrap(),
            ],
        ] {
            let (code, line) = run(&args);
            assert!(code == 0 || !line.is_empty(), "{args:?}");
        }
    }
}

#[test]
fn a_sample_period_no_delay_line_can_serve_is_refused_by_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("fast.csv");
    let mut text = String::from("t_s,op_pct,vp_pct\n");
    for k in 0..50 {
        text += &format!("{},{},50\n", k as f64 * 1e-9, 40 + k % 2);
    }
    std::fs::write(&rec, text).unwrap();
    let out = dir.path().join("sim.csv");
    let (code, line) = run(&[
        "simulate",
        "--model",
        "config/models/pincart2.toml",
        "--input",
        rec.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(
        line.contains("needs a delay line of 380000000 samples; at most 10000000 fit"),
        "{line}"
    );
}
