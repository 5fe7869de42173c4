//! `valve-bridge run`: the valve loop (see `valve_bridge::daemon`), with a summary at the end.

use std::io::Write;
use std::path::PathBuf;

use valve_bridge::daemon::{self, Config, RunOptions};
use valve_bridge::live::analysis;

/// Arguments of `valve-bridge run`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Daemon config (TOML). Default: the embedded config/emulated.toml (emulated pin-cart II,
    /// random steps, logs in ./logs/).
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Stop after this much loop time, s (default: run until SIGINT/SIGTERM).
    #[arg(long, value_name = "SECS")]
    duration: Option<f64>,
    /// Write the CSV logs here instead of `[log] dir`.
    #[arg(long, value_name = "DIR")]
    log_dir: Option<PathBuf>,
    /// Run on the virtual clock, as fast as possible (same as `[loop] clock = "virtual"`):
    /// for tests and offline runs with the emulated valve; --duration is then loop time.
    #[arg(long)]
    as_fast_as_possible: bool,
    /// Stop at start when the Modbus device cannot be reached (by default the loop starts,
    /// logs `disconnected` rows and connects as soon as the device answers).
    #[arg(long)]
    require_device: bool,
}

/// Loads the config, runs the loop and prints the summary on stdout; fails when no cycle read a
/// V_P.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let config = Config::load(args.config.as_deref())?;
    let summary = daemon::run(
        config,
        RunOptions {
            duration_s: args.duration,
            log_dir: args.log_dir,
            virtual_clock: args.as_fast_as_possible,
            progress: true,
            require_device: args.require_device,
            analysis: analysis(),
        },
    )?;
    // The loop has stopped, the safe action is applied and the log is flushed: a closed stdout
    // (a pager quit early) must not turn that into a panic; the summary goes to the log instead.
    if let Err(e) = writeln!(std::io::stdout(), "{summary}") {
        tracing::warn!("summary not printed on stdout ({e}):\n{summary}");
    }
    // A run in which no cycle read a V_P did not do its job: exit 1 and say why.
    summary.check()?;
    Ok(())
}
