//! External programs some integration tests need (mbpoll, pymodbus, Chromium with Playwright),
//! and what happens when one is missing. Shared by the test crates of both packages (included with `#[path]`).
//!
//! A test that needs a missing tool cannot run. With `VB_REQUIRE_TOOLS=1` (set by `.ci/run`,
//! which installs them) that is a failure naming the tool and how to install it. Otherwise the
//! test returns early, and says so on the real stderr, past the test harness's output capture,
//! so `cargo test` shows a `SKIPPED` line (with a running count) next to its `ok`.

use std::io::Write;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};

/// How to install mbpoll (libmodbus's command-line client).
pub(crate) const MBPOLL_INSTALL: &str = "apt-get install mbpoll";
/// How to install pymodbus with its serial support.
pub(crate) const PYMODBUS_INSTALL: &str = "python3 -m pip install 'pymodbus[serial]>=3.6,<4'";

/// How to install Debian's Chromium.
pub(crate) const CHROMIUM_INSTALL: &str = "apt-get install chromium";
/// How to install Playwright for Python (pointed at the system's Chromium, no browser download).
pub(crate) const PLAYWRIGHT_INSTALL: &str = "python3 -m pip install 'playwright>=1.40,<2'";
/// The Chromium the browser tests drive: `VB_CHROMIUM`, else Debian's.
pub(crate) fn chromium() -> String {
    std::env::var("VB_CHROMIUM").unwrap_or_else(|_| "/usr/bin/chromium".into())
}

static SKIPPED: AtomicUsize = AtomicUsize::new(0);

/// True if `program probe...` runs and succeeds. If not, fails the test under
/// `VB_REQUIRE_TOOLS=1`, else reports the skip and returns false.
pub(crate) fn have(program: &str, probe: &[&str], install: &str) -> bool {
    let ok = Command::new(program)
        .args(probe)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        missing(&format!("`{program} {}`", probe.join(" ")), install);
    }
    ok
}

/// True if mbpoll is installed (see [`have`]).
pub(crate) fn have_mbpoll() -> bool {
    have("mbpoll", &["-V"], MBPOLL_INSTALL)
}

/// True if python3 can import pymodbus and pyserial (see [`have`]).
pub(crate) fn have_pymodbus() -> bool {
    have(
        "python3",
        &["-c", "import pymodbus, serial"],
        PYMODBUS_INSTALL,
    )
}

/// True if Chromium runs and python3 can import Playwright (see [`have`]).
pub(crate) fn have_browser() -> bool {
    have(&chromium(), &["--version"], CHROMIUM_INSTALL)
        && have(
            "python3",
            &["-c", "import playwright.sync_api"],
            PLAYWRIGHT_INSTALL,
        )
}

/// True when a missing tool must fail the test (`VB_REQUIRE_TOOLS` set and not `0`).
pub(crate) fn tools_required() -> bool {
    std::env::var("VB_REQUIRE_TOOLS").is_ok_and(|v| !v.is_empty() && v != "0")
}

/// Reports that `what` did not run: a failure under `VB_REQUIRE_TOOLS=1`, else a visible skip.
pub(crate) fn missing(what: &str, install: &str) {
    let test = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    assert!(
        !tools_required(),
        "{test}: {what} is not available and VB_REQUIRE_TOOLS is set: install it ({install})"
    );
    let n = SKIPPED.fetch_add(1, Ordering::SeqCst) + 1;
    // Straight to the process's stderr: `eprintln!` would be captured and shown only on failure.
    drop(writeln!(
        std::io::stderr(),
        "SKIPPED ({n} in this test binary): {test}: {what} is not available; install it \
         ({install}), or set VB_REQUIRE_TOOLS=1 to make this a failure"
    ));
}
