//! [`DaemonError`]: why the daemon could not start or finish, for every thread of it.
//!
//! Not here: the errors of the configuration ([`vb_core::toml_file::TomlError`]) and of the valve
//! backends ([`crate::runtime::valve::BackendError`]), which this wraps.

use std::net::SocketAddr;
use std::path::PathBuf;

use crate::runtime::valve::BackendError;
use vb_core::toml_file::TomlError;

/// Why the daemon could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] TomlError),
    /// The valve backend cannot start (model, Modbus settings, bus budget, connection).
    #[error(transparent)]
    Valve(#[from] BackendError),
    /// A valve's compensation cannot start (its model file).
    #[error("[valve.compensation]: {0}")]
    Compensation(#[from] vb_core::compensate::CompensateError),
    /// `--duration` is not a positive number.
    #[error("--duration {0}: must be a positive number of seconds")]
    Duration(f64),
    /// The virtual clock was asked for a real valve.
    #[error("the virtual clock (--as-fast-as-possible, [loop] clock = \"virtual\") needs a simulated valve, not {0}")]
    VirtualClock(String),
    /// The virtual clock was asked for a process controller.
    #[error("the virtual clock (--as-fast-as-possible) cannot serve a process controller ([source] kind = \"modbus-server\"), which runs on the wall clock: leave the option out")]
    VirtualClockController,
    /// A listening socket cannot be opened.
    #[error(
        "cannot listen on {addr} ({key}): {source} (is the port taken? set another address there)"
    )]
    Listen {
        key: &'static str,
        addr: SocketAddr,
        #[source]
        source: std::io::Error,
    },
    /// The Prometheus metrics cannot be registered (a bug).
    #[error("cannot set up the metrics: {0}")]
    Metrics(#[from] prometheus::Error),
    /// The log directory cannot be created.
    #[error(
        "cannot create log directory `{dir}`: {source} (set another with --log-dir or [log] dir)"
    )]
    LogDir {
        dir: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A log file cannot be created.
    #[error("cannot create log file `{path}`: {source}")]
    LogFile {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A log file cannot be written.
    #[error("cannot write log file `{path}`: {source} (is the disk full?)")]
    LogWrite {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A symbolic link where the daemon would open a file or directory of its log directory.
    #[error("`{path}` is a symbolic link: the daemon does not follow links in its log directory (remove it; to log elsewhere, set --log-dir or [log] dir)")]
    LogLink { path: PathBuf },
    /// A history the daemon appends to starts with another header than the one it writes.
    #[error("`{path}` starts with another header than this version writes: move it aside (the daemon then starts a new one)")]
    LogHeader { path: PathBuf },
    /// `[diagnosis]` asked of a daemon started without a diagnosis to run (a program that
    /// embeds the daemon's crate without the analysis; `valve-bridge run` always has it).
    #[error("[diagnosis]: this program runs the loop without diagnosis; remove [diagnosis] from the config or run it with `valve-bridge run`")]
    NoDiagnosis,
    /// A thread, runtime or signal handler could not be set up.
    #[error("cannot start the {what}: {source}")]
    Thread {
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// A daemon thread panicked (a bug).
    #[error("the {0} thread stopped unexpectedly")]
    Panicked(&'static str),
}
