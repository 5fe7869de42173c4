//! Modbus on the wire, through the real binaries over loopback TCP and pseudo-terminals: the
//! daemon against sim-device (TCP, RTU, a shared RTU bus, links that misbehave, late RTU
//! replies), the daemon as a Modbus server for a process controller (hardware in the loop, busy
//! clients, servers that stay up), `valve-bridge probe`, the shipped register profiles and
//! Modbus configs. One module per subject; mbpoll and pymodbus are needed by some
//! (`tests/common/tools.rs`).

#[path = "../common/mod.rs"]
mod common;

mod busy_clients;
mod daemon_bus;
mod daemon_hil;
mod daemon_hil_valves;
mod daemon_links;
mod daemon_modbus;
mod daemon_startup;
mod modbus_configs;
mod probe;
mod profiles;
mod rtu_late_replies;
mod servers;
