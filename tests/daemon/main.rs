//! The daemon, `valve-bridge run`, through the real binary with no hardware: runs on the virtual
//! clock and in real time, several valves, compensation, the live health check and diagnosis,
//! its log directory (rotation, a full disk, reading it back), every way out of a run, running
//! as a systemd service, and the metrics the Grafana dashboard queries. One module per subject;
//! the daemon over Modbus is in `tests/modbus/`.

#[path = "../common/mod.rs"]
mod common;

mod daemon;
mod daemon_compensation;
mod daemon_diagnosis;
mod daemon_health;
mod daemon_valves;
mod exit_paths;
mod grafana_dashboard;
mod log_dirs;
mod log_disk_full;
mod service;
