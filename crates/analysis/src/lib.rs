//! The offline analysis of valve-bridge: from recordings to the valve's model and what it lacks.
//!
//! - [`fit`]: identification: fit every model of the pin-cart paper by simulation error, Table 1
//!   and 2, step delays.
//! - [`diagnose`]: locate model mismatch, name the missing physics, add it, prove it on held-out
//!   data.
//! - [`synth`]: synthetic recordings (random steps, small steps, ramps, a mix, a closed level
//!   loop) and physical valves with named effects, for demos, tests and benchmarks.
//! - [`response`]: a response test's log read for what the valve did (dead time, T63, T86,
//!   overshoot, resolution, dead band).
//! - [`compensation_trial`]: the compensator tried on simulated valves (the compensation bench).
//!
//! Not here: the loop (`vb-daemon`, which links none of this), pages and words (`vb-report`).

pub mod compensation_trial;
pub mod diagnose;
pub mod fit;
pub mod response;
pub mod synth;
