//! The daemon's live page in a real browser: `valve-bridge run` with the shipped
//! `config/live-page.toml` in real time (two emulated valves on small random steps, a worn one
//! whose dead time is 1.5 s longer than the model's and a healthy one, both against the bundled
//! pin-cart II model as their health baseline, 30 s health windows every 2 s, 45 s diagnosis
//! windows), its `[metrics]` moved to a free loopback port.
//! `tests/browser/check_live.py` (Playwright for Python driving Debian's Chromium, like the
//! reports' test) loads `/` and fails on a console error; on a valve without a health window
//! or the page without a diagnosis a minute after the daemon started; on a trace chart that
//! drew nothing or did not move on between two screenshots; on time labels that overlap; on the
//! worn valve's alarm not shown, or shown without its figure, its limit (the same numbers as
//! the figure's row, which is marked past its limit), since when and the diagnosis that
//! explains it, or an alarm shown where no figure is past its limit (the healthy valve); on
//! the alarm's diagnosis not listed with a report that opens, or the effect it names not
//! charted over time; on the healthy valve not diagnosed, or its diagnosis finding anything
//! (it is the bundled model, which its diagnoses start from); and on a snake_case name or `%²`
//! in the page's text.
//!
//! With `VB_SCREENSHOTS=DIR` the page's screenshot is saved as `DIR/live-page.png` (README's
//! with `VB_SCREENSHOTS=docs`). Without Chromium or Playwright the test is a visible skip, or a
//! failure under `VB_REQUIRE_TOOLS=1`.

use std::io::{BufRead, BufReader, Read};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{SystemTime, UNIX_EPOCH};

use crate::common;

use crate::common::sim::BIN;
use crate::common::tools;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// The shipped live-page config, its page on a free port.
fn config() -> String {
    let text = std::fs::read_to_string(format!("{ROOT}/config/live-page.toml")).unwrap();
    let listen = "listen = \"127.0.0.1:9100\"";
    assert!(
        text.contains(listen),
        "config/live-page.toml: no `{listen}`"
    );
    text.replace(listen, "listen = \"127.0.0.1:0\"")
}

/// The daemon, stopped with SIGTERM when dropped (the test failing or not).
struct Daemon(Child);

impl Daemon {
    /// SIGTERM, then its exit and the rest of its stdout (the summary).
    fn stop(&mut self) -> (bool, String) {
        if matches!(self.0.try_wait(), Ok(None)) {
            // Not yet reaped: the pid is still our child's.
            common::signal(&self.0, libc::SIGTERM);
        }
        let ok = self.0.wait().is_ok_and(|s| s.success());
        let mut rest = String::new();
        if let Some(mut out) = self.0.stdout.take() {
            drop(out.read_to_string(&mut rest));
        }
        (ok, rest)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.stop();
    }
}

#[test]
fn the_live_page_updates_and_shows_the_drift_alarm_in_chromium() {
    if !tools::have_browser() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cfg = dir.path().join("live.toml");
    std::fs::write(&cfg, config()).unwrap();
    let log = std::fs::File::create(dir.path().join("daemon.log")).unwrap();
    let started = SystemTime::now().duration_since(UNIX_EPOCH).unwrap();
    let child = Command::new(BIN)
        // The config names the bundled model from the checkout.
        .current_dir(ROOT)
        .args(["run", "--config"])
        .arg(&cfg)
        .arg("--log-dir")
        .arg(dir.path().join("logs"))
        .env("RUST_LOG", "info")
        .stdout(Stdio::piped())
        .stderr(log)
        .spawn()
        .unwrap();
    let mut daemon = Daemon(child);
    let mut stdout = BufReader::new(daemon.0.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    let addr = line
        .trim()
        .strip_prefix("metrics: ")
        .expect("the metrics address");
    daemon.0.stdout = Some(stdout.into_inner());

    let mut cmd = Command::new("python3");
    cmd.arg(format!("{ROOT}/tests/browser/check_live.py"))
        .arg(format!("http://{addr}/"))
        .args(["--valves", "2", "--alarm", "worn", "--healthy", "healthy"])
        .args(["--diagnosis", "--wait", "90"])
        .args([
            "--started",
            &started.as_secs_f64().to_string(),
            "--within",
            "60",
        ])
        .env("VB_CHROMIUM", tools::chromium())
        // Nothing written beside the scripts: the test writes only in its own directory.
        .env("PYTHONDONTWRITEBYTECODE", "1");
    if let Ok(shots) = std::env::var("VB_SCREENSHOTS") {
        // Relative to the checkout, like README's command.
        cmd.arg("--screenshots").arg(Path::new(ROOT).join(shots));
    }
    let out = cmd.output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout) + String::from_utf8_lossy(&out.stderr);
    let (stopped, summary) = daemon.stop();
    let log = std::fs::read_to_string(dir.path().join("daemon.log")).unwrap_or_default();
    assert!(
        out.status.success(),
        "the live page failed in Chromium:\n{text}\ndaemon log:\n{log}"
    );
    assert!(text.contains("worn: health alarm: "), "{text}");
    assert!(
        stopped,
        "the daemon did not exit cleanly:\n{summary}\n{log}"
    );
    // The summary agrees: the worn valve's alarm, none for the healthy one.
    let health = |file: &str| {
        (summary.lines())
            .find(|l| l.contains(file))
            .unwrap_or_else(|| panic!("no {file} in the summary:\n{summary}"))
            .to_string()
    };
    assert!(
        health("health-worn.csv").contains(" 1 alarms (first at"),
        "{summary}"
    );
    assert!(
        health("health-healthy.csv").contains(" 0 alarms,"),
        "{summary}"
    );
}
