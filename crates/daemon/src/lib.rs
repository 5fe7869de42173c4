//! `valve-bridge run`: the valve loop, at 100 Hz by default, from source to valve to log.
//!
//! Every slot of an absolute time grid, the loop asks the [`runtime::source::Source`] for the
//! wanted opening O_P, sends it to the valve [`runtime::valve::Backend`] and reads V_P back in
//! one transaction, and hands a [`vb_core::recording::log_format::Sample`] to the
//! [`runtime::logger`]. Missed slots and failed transactions are logged as such with an empty
//! V_P. On stop (SIGINT, SIGTERM, `--duration`, or the end of a replay) the loop applies the
//! configured safe action in the next slot, logs it, the log is flushed and closed, and a
//! [`Summary`] is returned.
//!
//! Threads: the loop runs on its own OS thread (`vb-loop`) that sleeps to absolute deadlines
//! ([`runtime::schedule`]) and runs each valve transaction on a current-thread tokio runtime it
//! owns, so async backends need no other thread and no cross-thread hop. The logger writes on
//! its own thread, and passes the rows on to the health thread (`vb-health`, with `[health]`,
//! [`monitor::health`]), which estimates each valve's health off the loop and, with
//! `[diagnosis]`, hands windows to the diagnosis thread (`vb-diagnosis`,
//! [`monitor::diagnosis`]). The network thread (`vb-net`, only when there is something to
//! serve, [`serve`]) runs the process controller's Modbus server ([`serve::hil`]) and the HTTP
//! server of the Prometheus metrics ([`serve::exporter`]) and the live page on a runtime of its
//! own: the loop shares only a register bank and atomic metric handles with it and never waits
//! on a socket; the page reads what the logger, health and diagnosis threads put on its board.
//! The calling thread waits for signals (tokio), drives the progress display, talks to systemd
//! when run as a service ([`service`]) and joins.
//!
//! Sample convention (as [`vb_core::model::Valve::simulate_into`]): in slot `k` the valve gets
//! `op_k` and the V_P it returns is sample `k`. The emulated valve starts at rest at the first
//! O_P, so a log replays through `Valve::simulate(op, op[0])`: O_P exactly (the loop rounds it to
//! the log's 0.0001 % before sending), V_P to the log's precision.
//!
//! Rooms, by concern:
//! - [`runtime`]: the loop, its schedule, sources, valve backends, compensation, the log and its
//!   files, the run's statistics;
//! - [`config`]: the TOML configuration and its checks;
//! - [`serve`]: the network thread (HIL Modbus server, HTTP: metrics and live page);
//! - [`monitor`]: live health and diagnosis beside the loop, and the [`Analysis`] seam;
//! - here: the options and [`run`] (signals and progress display), [`start`] ([`Running`],
//!   in `running.rs`), the errors ([`DaemonError`]), [`response`] (a response test through all
//!   of it), [`service`] (systemd).
//!
//! Not here: the Modbus protocol (`vb-modbus`; a backend variant in [`runtime::valve`]),
//! recording analysis (the daemon runs diagnosis and plotting only as the [`Analysis`] it is
//! handed).

pub mod config;
mod error;
pub mod monitor;
pub mod response;
mod running;
pub mod runtime;
pub mod serve;
pub mod service;

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

pub use config::Config;
pub use error::DaemonError;
pub use monitor::analysis::Analysis;
pub use running::{start, Running};
pub use runtime::compensation::CompensationReport;
pub use runtime::stats::{Summary, ValveSummary};
/// Command-line overrides of the configuration.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Stop after this much loop time, s.
    pub duration_s: Option<f64>,
    /// Log directory instead of `[log] dir`.
    pub log_dir: Option<PathBuf>,
    /// Run on the virtual clock whatever `[loop] clock` says.
    pub virtual_clock: bool,
    /// Show the one-line progress display (only drawn on a terminal).
    pub progress: bool,
    /// Refuse to start when a Modbus device cannot be reached (otherwise the loop starts and
    /// retries the link).
    pub require_device: bool,
    /// The diagnosis and plotting the daemon may run beside the loop.
    pub analysis: Analysis,
}

/// Runs until SIGINT/SIGTERM, `--duration` or the end of the source, showing progress.
pub fn run(config: Config, opts: RunOptions) -> Result<Summary, DaemonError> {
    let thread_err = |what| move |source| DaemonError::Thread { what, source };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(thread_err("signal runtime"))?;
    let progress = opts.progress;
    let running = rt.block_on(async {
        use tokio::signal::unix::{signal, SignalKind};
        // Handlers first, so a signal during start-up already stops cleanly.
        let mut sigint = signal(SignalKind::interrupt()).map_err(thread_err("SIGINT handler"))?;
        let mut sigterm = signal(SignalKind::terminate()).map_err(thread_err("SIGTERM handler"))?;
        let mut service = service::Service::new();
        let running = start(config, opts)?;
        announce(running.endpoints());
        service.ready(&format!("running at {} Hz", running.rate_hz()));
        let bar = progress_bar(progress);
        let mut tick = tokio::time::interval(Duration::from_millis(50));
        while !running.is_finished() {
            tokio::select! {
                _ = sigint.recv() => {
                    tracing::info!("SIGINT: stopping");
                    service.stopping();
                    running.stop();
                }
                _ = sigterm.recv() => {
                    tracing::info!("SIGTERM: stopping");
                    service.stopping();
                    running.stop();
                }
                _ = tick.tick() => {
                    service.tick(running.live().view().samples);
                    show(&bar, &running);
                }
            }
        }
        service.stopping();
        bar.finish_and_clear();
        Ok::<_, DaemonError>(running)
    })?;
    running.finish()
}

/// Prints one `name: ADDR` line per endpoint on stdout, at once (a client may be waiting for it).
fn announce(endpoints: &[(&'static str, SocketAddr)]) {
    let mut out = std::io::stdout().lock();
    let written = (endpoints.iter())
        .try_for_each(|(name, addr)| writeln!(out, "{name}: {addr}"))
        .and_then(|()| out.flush());
    // A closed stdout only loses the announcement; the daemon runs on.
    if let Err(e) = written {
        tracing::debug!("endpoints not announced on stdout: {e}");
    }
}

fn progress_bar(enabled: bool) -> ProgressBar {
    if !enabled {
        return ProgressBar::hidden();
    }
    // Drawn on stderr only when it is a terminal; otherwise indicatif stays quiet.
    let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg}") {
        bar.set_style(style);
    }
    bar
}

fn show(bar: &ProgressBar, running: &Running) {
    if bar.is_hidden() {
        return;
    }
    let v = running.live().view();
    let moves = v.moves.map_or(String::new(), |(done, all)| {
        format!("  move {done} of {all}")
    });
    bar.set_message(format!(
        "t {:.1} s  samples {}  O_P {:.2} %  V_P {:.2} %  timing p99 {:.0} us{moves}",
        v.samples as f64 / running.rate_hz(),
        v.samples,
        v.op_pct,
        v.vp_pct,
        v.p99_us
    ));
    bar.tick();
}
