//! valve-bridge: run, emulate, log and identify pneumatic control valves.
//!
//! - [`model`]: every valve model, one `step` each, with TOML parameter files.

pub mod model;
pub mod toml_file;
