//! valve-bridge: run, emulate, log and identify pneumatic control valves.
//!
//! The workspace's crates under one name, for the binaries, the tests, the Python module and
//! users: data runs one way, and the crates are layered the same way (the compiler keeps the
//! order; no crate uses one above it):
//!
//! - `vb-core` ([`model`], [`recording`], [`compensate`], [`response_plan`], [`signal`],
//!   [`metrics`], [`vocabulary`], [`human`], [`toml_file`], [`priority`]): the valve models, the
//!   recordings and log format, the compensator, metrics and plain words.
//! - `vb-modbus` ([`modbus`], [`net`]): register maps, the valve client and its wire, servers.
//! - `vb-daemon` ([`daemon`]): `valve-bridge run`, the 100 Hz valve loop (sources, valve
//!   backends, log, HIL, health, live page). It links none of the analysis.
//! - `vb-analysis` ([`fit`], [`diagnose`], [`synth`], [`response`], [`compensation_trial`]):
//!   identification, diagnosis, synthetic valves, the response test's figures.
//! - `vb-report` ([`report`], [`fleet`]): HTML pages with charts, verdicts in words, the fleet.
//!
//! [`live`] is where the daemon and the analysis meet: the daemon's live diagnosis.

pub use vb_analysis::{compensation_trial, diagnose, fit, response, synth};
pub use vb_core::logging::{error_line, init_tracing, LossyStderr};
pub use vb_core::{
    compensate, human, metrics, model, priority, recording, response_plan, signal, toml_file,
    vocabulary,
};
pub use vb_daemon as daemon;
pub use vb_modbus as modbus;
pub use vb_modbus::net;
pub use vb_report as report;
pub use vb_report::fleet;

pub mod live;
