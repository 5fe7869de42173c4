//! Modbus for valve positioners: the register map, the bus budget, the valve client and the
//! register bank a Modbus server answers from.
//!
//! - [`map`]: where the set-point, the position and the status live and how words convert to %
//!   (Bürkert-style per-mille by default; addresses are configuration).
//! - [`profile`]: the shipped register profiles of real devices (`config/profiles/*.toml`).
//! - [`link`]: the `[valve.modbus-tcp]` / `[valve.modbus-rtu]` settings.
//! - [`plan`]: the transactions of one cycle (FC 23, or FC 16 plus a read) and their RTU sizes.
//! - [`budget`]: a cycle's wire time on a serial line, and the verdict on the loop rate.
//! - [`client`]: [`client::ModbusValve`], one cycle `transact(O_P) -> V_P` with a deadline,
//!   fault kinds and reconnection.
//! - [`serial`]: opening a serial port with a link's settings (the client and sim-device).
//! - [`probe`]: one read of every mapped register, and an optional set-point write, as a table.
//! - [`wire`]: the byte streams under the client (late TCP replies dropped by transaction id,
//!   RTU input emptied before each request).
//! - [`exception`]: Modbus exception codes in words.
//! - [`server`]: [`server::RegisterBank`], the device side (used by `sim-device`, and by a
//!   Modbus server that the loop can offer to a process controller).
//! - [`blocks`]: several banks on one server, a block of addresses each (one per valve).
//! - [`tcp_server`]: a Modbus TCP server that stays up, answering from a [`tcp_server::Respond`].
//!
//! Not here: the loop, its clock and its log (`daemon`), and any valve model (`model`).

pub mod blocks;
pub mod budget;
pub mod client;
pub mod exception;
pub mod link;
pub mod map;
pub mod net;
pub mod plan;
pub mod probe;
pub mod profile;
pub mod serial;
pub mod server;
pub mod tcp_server;
pub mod wire;
