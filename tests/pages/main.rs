//! The pages the binary writes and serves, in a real browser (headless Chromium driven by the
//! Playwright scripts in `tests/browser/`): the report pages (`browser_reports`) and the
//! daemon's live page (`live_page`).

#[path = "../common/mod.rs"]
mod common;

mod browser_reports;
mod live_page;
