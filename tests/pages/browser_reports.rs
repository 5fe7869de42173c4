//! The report pages in a real browser: identify's and diagnose's `report.html` (of a 30 s
//! recording), fleet's `index.html` with one of its valves' pages, a daemon's health plot and a
//! response test's `report.html` (eight steps and a signature on the emulated valve), written by
//! the binary and opened in headless Chromium by `tests/browser/check_reports.py` (Playwright
//! for Python driving Debian's Chromium). Fails on a console error, a chart that drew nothing, a
//! drag that does not zoom (Shift+wheel that does not pan, a double-click that does not reset) a
//! chart's time range, chart text under 11 px or overlapping, and a page that does not say at
//! first sight what it must (identify's best model, diagnose's mismatch, the fleet's rule and
//! severities; see the script).
//!
//! With `VB_SCREENSHOTS=DIR` the pages' screenshots are saved as `DIR/report-{identify,
//! diagnose,fleet,fleet-valve,response}.png` (README's with `VB_SCREENSHOTS=docs`), identify's and
//! diagnose's then of README's examples (`pub_sdd_paper_rs`, `pub_backlash_rs`). Without
//! Chromium or Playwright the test is a visible skip, or a failure under `VB_REQUIRE_TOOLS=1`.

use std::path::Path;
use std::process::Command;

use crate::common::sim::BIN;
use crate::common::tools;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn run(args: &[&str]) {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(
        out.status.success(),
        "valve-bridge {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The first `seconds` of the shared case `name` written to `to`.
fn cut(name: &str, seconds: usize, to: &Path) {
    let text =
        std::fs::read_to_string(Path::new(ROOT).join("tests/data/cases").join(name)).unwrap();
    let rows: Vec<&str> = text.lines().take(1 + 100 * seconds).collect();
    std::fs::write(to, rows.join("\n") + "\n").unwrap();
}

#[test]
fn reports_draw_zoom_and_log_no_errors_in_chromium() {
    if !tools::have_browser() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |p: &str| dir.path().join(p).to_str().unwrap().to_string();
    let shots = std::env::var("VB_SCREENSHOTS").ok();
    let recording = format!("{ROOT}/tests/data/daemon/normal_op_30s.csv");
    // The screenshots show README's examples (a minute or two more); the check itself runs on
    // the 30 s recording.
    let (identified, diagnosed) = match &shots {
        Some(_) => (
            format!("{ROOT}/tests/data/cases/pub_sdd_paper_rs.csv"),
            format!("{ROOT}/tests/data/cases/pub_backlash_rs.csv"),
        ),
        None => (recording.clone(), recording.clone()),
    };
    run(&["identify", &identified, "--out", &d("identify")]);
    run(&["diagnose", &diagnosed, "--out", &d("diagnose")]);
    std::fs::create_dir(d("valves")).unwrap();
    std::fs::copy(&recording, d("valves/fv-101.csv")).unwrap();
    cut("pub_asym_rs.csv", 60, &dir.path().join("valves/fv-102.csv"));
    run(&["fleet", &d("valves"), "--out", &d("fleet")]);
    // A health plot: 15 minutes of the wearing valve, two windows.
    let worn = format!("{ROOT}/config/worn-valve.toml");
    let duration = ["--as-fast-as-possible", "--duration", "900"];
    run(&[
        &["run", "--config", &worn, "--log-dir", &d("worn")][..],
        &duration[..],
    ]
    .concat());
    std::fs::write(
        d("plan.toml"),
        "openings_pct = [50.0]\nsizes_pct = [1.0, 5.0]\npattern = [1, 1, -1, -1]\n\
         [hold]\nmin_s = 3.0\nmax_s = 10.0\nstill_s = 1.0\nstill_pct = 0.05\n\
         [signature]\nopening_pct = 50.0\nspan_pct = 1.0\nrate_pct_per_s = 0.5\n",
    )
    .unwrap();
    let emulated = format!("{ROOT}/config/emulated.toml");
    let plan = d("plan.toml");
    let out = d("response");
    run(&[
        "response-test",
        "--config",
        &emulated,
        "--plan",
        &plan,
        "--out",
        &out,
        "--as-fast-as-possible",
    ]);

    let mut cmd = Command::new("python3");
    cmd.arg(format!("{ROOT}/tests/browser/check_reports.py"))
        .env("VB_CHROMIUM", tools::chromium())
        // Nothing written beside the scripts: the test writes only in its own directory.
        .env("PYTHONDONTWRITEBYTECODE", "1");
    if let Some(shots) = &shots {
        // Relative to the checkout, like README's command.
        cmd.arg("--screenshots").arg(Path::new(ROOT).join(shots));
    }
    for (name, page, charts) in [
        ("identify", d("identify/report.html"), "2"),
        ("diagnose", d("diagnose/report.html"), "2"),
        ("fleet", d("fleet/index.html"), "0"),
        ("fleet-valve", d("fleet/valves/fv-102/report.html"), "2"),
        ("health", d("worn/health-worn.svg"), "0"),
        // Eight steps and the signature.
        ("response", d("response/report.html"), "9"),
    ] {
        cmd.args(["--page", name, &page, charts]);
    }
    let out = cmd.output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "the pages failed in Chromium:\n{text}"
    );
    for name in ["identify", "diagnose", "fleet", "health", "response"] {
        assert!(
            text.contains(&format!("{name}: ")),
            "{name} was not checked:\n{text}"
        );
    }
}
