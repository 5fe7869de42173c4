//! 20 s of the main job's log (`valve-bridge run`, the emulated valve at rest at its set-point
//! for most of the held-out blocks): `diagnose` and `identify` print no figure the data cannot
//! support. R² of a V_P that does not move is `n/a` with the reason (it was printed as
//! −6.96 × 10²⁵ %), and every percentage printed is one a reader can use.

use std::path::Path;
use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_valve-bridge");

fn run(args: &[&str]) -> String {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "valve-bridge {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Every number printed as a percentage (`12.34%`, `-5 %`) in `text`.
fn percentages(text: &str) -> Vec<f64> {
    let words: Vec<&str> = text.split_whitespace().collect();
    let mut out = Vec::new();
    for (k, w) in words.iter().enumerate() {
        let number = match w.strip_suffix('%') {
            Some(n) if !n.is_empty() => Some(n),
            Some(_) => k.checked_sub(1).map(|p| words[p]),
            None => None,
        };
        if let Some(v) = number.and_then(|n| n.trim_start_matches('(').parse::<f64>().ok()) {
            out.push(v);
        }
    }
    out
}

#[test]
fn a_20_s_log_gets_no_figure_the_data_cannot_support() {
    let dir = tempfile::tempdir().unwrap();
    let logs = dir.path().join("logs");
    let logs = logs.to_str().unwrap();
    let args = ["run", "--as-fast-as-possible", "--duration", "20"];
    run(&[&args[..], &["--log-dir", logs]].concat());
    assert!(Path::new(logs).is_dir());
    let diagnosed = run(&["diagnose", logs]);
    assert!(
        diagnosed.contains("(R² n/a: the measured V_P spreads by "),
        "{diagnosed}"
    );
    let identified = run(&["identify", logs]);
    for (what, text) in [("diagnose", &diagnosed), ("identify", &identified)] {
        let all = percentages(text);
        assert!(!all.is_empty(), "{what}: no percentage in {text}");
        // The largest a reader can use: a model ten times worse than taking V_P = O_P.
        let absurd: Vec<f64> = all.into_iter().filter(|v| v.abs() > 10_000.0).collect();
        assert!(absurd.is_empty(), "{what} prints {absurd:?}:\n{text}");
        assert!(
            !text.contains("NaN") && !text.contains("inf%"),
            "{what}:\n{text}"
        );
    }
}
