//! The foundation of valve-bridge, used by every other crate of the workspace and depending on
//! none of them: what a valve is and what is recorded of it.
//!
//! - [`model`]: every valve model, one `step` each, with TOML parameter files.
//! - [`recording`]: the CSV recording format (read with helpful errors, write, column mapping),
//!   the daemon's log format.
//! - [`compensate`]: the identified valve's backlash, deadband and calibration answered in the
//!   set-point it is sent (run by the daemon's `[valve.compensation]`, tried by the analysis).
//! - [`response_plan`]: a response test's plan and the schedule that walks it.
//! - [`signal`]: time-only O_P generators (random steps, steps, ramp, sine, PRBS, replay, constant).
//! - [`metrics`]: the paper's Table 1 metrics and the zero-phase Butterworth filter.
//! - [`vocabulary`]: each effect diagnosis names in plain words, with its severity and priority.
//! - [`human`], [`toml_file`], [`priority`], [`logging`], [`assets`]: number formats, TOML files
//!   with their lines, thread priorities, logging, the chart library the pages embed.
//!
//! Not here: Modbus (`vb-modbus`), the loop (`vb-daemon`), fitting and diagnosis
//! (`vb-analysis`), pages (`vb-report`).

pub mod assets;
pub mod compensate;
pub mod human;
pub mod logging;
pub mod metrics;
pub mod model;
pub mod priority;
pub mod recording;
pub mod response_plan;
pub mod signal;
pub mod toml_file;
pub mod vocabulary;

#[cfg(any(test, feature = "testkit"))]
pub mod testkit;
