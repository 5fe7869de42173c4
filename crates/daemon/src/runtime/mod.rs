//! The loop at run time: the loop thread ([`control`]) on its absolute [`schedule`], the
//! [`source`] of O_P, the valve [`valve`] backends, a valve's [`compensation`], the sample
//! [`logger`] and the files of the log directory ([`files`] opens them, [`log_file`] writes them
//! and outlives a full disk), and the run's [`stats`].
//!
//! Not here: the configuration (`crate::config`), serving (`crate::serve`), health and
//! diagnosis (`crate::monitor`).

pub mod compensation;
pub(crate) mod control;
pub(crate) mod files;
pub mod log_file;
pub mod logger;
pub mod schedule;
pub mod source;
pub mod stats;
pub mod valve;
