//! The chart library the pages embed, uPlot (MIT, `uplot/LICENSE`, `uplot/SOURCE.md`): the
//! daemon's live page and the reports carry it inline, so a page works with no network.
//!
//! Not here: the charts themselves (the live page's script, the reports' `charts.js`).

/// uPlot's script.
pub const UPLOT_JS: &str = include_str!("uplot/uPlot.iife.min.js");
/// uPlot's style sheet.
pub const UPLOT_CSS: &str = include_str!("uplot/uPlot.min.css");
