//! Watching the valve beside the loop: its live [`health`] (figures per window, alarms,
//! `health-NAME.csv`; the figures in `health_figures`), live [`diagnosis`] of windows and its
//! history, and the [`analysis`] seam through which the program hands the daemon what it cannot
//! link (diagnosing a window, plotting health).
//!
//! Not here: the diagnosis itself (the analysis crate, reached only through [`analysis`]).

pub mod analysis;
pub mod diagnosis;
pub mod health;
pub(crate) mod health_figures;
