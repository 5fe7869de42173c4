//! The live page, `GET /` on the `[metrics]` address: each valve's status, its O_P and V_P over
//! the last [`board::TRACE_S`] (a chart that updates every second from `/api/live`), its health
//! figures against their limits, its alarms, and its diagnosis history (effect sizes over time,
//! each diagnosis linked to its report). One self-contained page: `index.html` with the
//! vendored uPlot (`crates/core/src/assets/uplot/`, the reports' charts) and `live.js` inlined, so a browser
//! needs nothing but the daemon.
//!
//! [`board`] keeps what the page shows; [`history_tail`] reads a valve's diagnosis history for
//! `/api/diagnoses/NAME`.
//!
//! Not here: serving ([`super::http`]).

pub(crate) mod board;

use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

const INDEX: &str = include_str!("index.html");
const LIVE_JS: &str = include_str!("live.js");
use vb_core::assets::{UPLOT_CSS, UPLOT_JS};

/// Most of a diagnosis history sent to the page: its last this many bytes (some 600
/// diagnoses).
const HISTORY_TAIL: u64 = 1 << 20;

/// The page: `index.html` with uPlot's styles and script and `live.js` in place of their
/// markers.
pub(crate) fn html() -> String {
    INDEX
        .replace("/*uplot.css*/", UPLOT_CSS)
        .replace("/*uplot.js*/", UPLOT_JS)
        .replace("/*live.js*/", LIVE_JS)
}

/// The diagnoses of the history file `path` (JSON lines) from byte `from` (where this run's
/// start) as a JSON array: the whole lines of its last [`HISTORY_TAIL`] bytes, but a line still
/// being written or not JSON. A link there is not followed.
pub(crate) fn history_tail(path: &Path, from: u64) -> std::io::Result<String> {
    let (dir, name) = (path.parent(), path.file_name().and_then(|n| n.to_str()));
    let (Some(dir), Some(name)) = (dir, name) else {
        return Err(std::io::ErrorKind::InvalidInput.into());
    };
    let mut file = crate::runtime::files::open_read(dir, &[name])?;
    let start = (file.metadata()?.len().saturating_sub(HISTORY_TAIL)).max(from);
    file.seek(SeekFrom::Start(start))?;
    let mut bytes = Vec::new();
    file.take(HISTORY_TAIL).read_to_end(&mut bytes)?;
    let text = String::from_utf8_lossy(&bytes);
    // The line a tail shorter than this run's lines starts in is cut; each line is a JSON
    // object, passed on as it is.
    let skip = usize::from(start > from);
    let records: Vec<&str> = (text.split_inclusive('\n').skip(skip))
        .filter(|line| line.ends_with('\n'))
        .map(str::trim_end)
        .filter(|line| serde_json::from_str::<serde::de::IgnoredAny>(line).is_ok())
        .collect();
    Ok(format!("[{}]", records.join(",")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_page_holds_its_scripts_and_no_link_out() {
        let page = html();
        assert!(page.starts_with("<!DOCTYPE html>"));
        for marker in ["/*uplot.css*/", "/*uplot.js*/", "/*live.js*/"] {
            assert!(!page.contains(marker), "{marker} left in the page");
        }
        assert!(page.contains("uPlot") && page.contains("/api/live"));
        // Self-contained: no script, style or font is fetched.
        for outside in [
            "<script src",
            "<link rel=\"stylesheet\"",
            "@import",
            "url(http",
        ] {
            assert!(!page.contains(outside), "{outside} in the page");
        }
    }

    #[test]
    fn a_long_history_gives_its_last_whole_lines() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("diagnosis-a.jsonl");
        let line = |k: usize| format!("{{\"t_s\":{k},\"verdict\":\"{}\"}}\n", "x".repeat(1000));
        let text: String = (0..2000).map(line).collect();
        let earlier: u64 = (0..1990).map(|k| line(k).len() as u64).sum();
        std::fs::write(&path, text + "not json\n").unwrap();
        let tail = |from| history_tail(&path, from).unwrap();
        let v: Vec<serde_json::Value> = serde_json::from_str(&tail(0)).unwrap();
        let n = v.len();
        assert!((1000..1050).contains(&n), "{n}");
        assert_eq!(v[n - 1]["t_s"], 1999);
        assert_eq!(v[0]["t_s"].as_u64(), Some(2000 - n as u64));
        // This run's lines only: those from its start on.
        let v: Vec<serde_json::Value> = serde_json::from_str(&tail(earlier)).unwrap();
        let t: Vec<u64> = v.iter().map(|r| r["t_s"].as_u64().unwrap()).collect();
        assert_eq!(t, (1990..2000).collect::<Vec<_>>());
        assert!(history_tail(&dir.path().join("none.jsonl"), 0).is_err());
        let link = dir.path().join("diagnosis-b.jsonl");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        assert!(history_tail(&link, 0).is_err());
    }
}
