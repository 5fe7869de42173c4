//! The `valve-bridge` command: a thin layer of clap commands over the `valve_bridge` library.
//!
//! Each subcommand lives in `src/cli/<name>.rs` with its arguments and a `run` function that
//! calls the library. Errors are printed as one line (with their causes) and exit code 1; no
//! backtrace. `RUST_LOG` sets the log level (default `info`, see `valve_bridge::init_tracing`).

mod cli;

use clap::{Parser, Subcommand};

/// Run, emulate, log and identify pneumatic control valves.
#[derive(Parser)]
#[command(name = "valve-bridge", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the valve loop (100 Hz by default): source -> valve -> CSV log, until stopped.
    Run(cli::run::Args),
    /// Read every register of a config's map once from the device (writes only with --write-test).
    Probe(cli::probe::Args),
    #[command(flatten)]
    Analysis(Analysis),
}

/// The offline analysis commands.
#[derive(Subcommand)]
enum Analysis {
    /// Run a valve model over the O_P of a recording and score it against the measured V_P.
    Simulate(cli::simulate::Args),
    /// Find where a model and a recording differ, name the missing physics, add it, show the gain.
    Diagnose(cli::diagnose::Args),
    /// Fit every model of the paper to a recording: Table 1 (with held-out scores), Table 2, model files.
    Identify(cli::identify::Args),
    /// Diagnose every recording of a directory in parallel and rank the valves for maintenance.
    Fleet(cli::fleet::Args),
    /// Step-delay analysis: same-direction and reversal delays, pin-cart II's delay polynomial.
    Steps(cli::steps::Args),
    /// Demonstrations: `demo concealed` hides an effect in a recording and diagnoses it.
    Demo(cli::demo::Args),
    /// Run a response test on a valve (steps of several sizes both ways, a slow ramp out and
    /// back) and report its dead time, T63, T86, overshoot, resolution and dead band.
    ResponseTest(cli::response_test::Args),
}

impl Analysis {
    fn run(self) -> anyhow::Result<()> {
        match self {
            Analysis::Simulate(a) => cli::simulate::run(a),
            Analysis::Diagnose(a) => cli::diagnose::run(a),
            Analysis::Demo(a) => cli::demo::run(a),
            Analysis::Identify(a) => cli::identify::run(a),
            Analysis::Steps(a) => cli::steps::run(a),
            Analysis::Fleet(a) => cli::fleet::run(a),
            Analysis::ResponseTest(a) => cli::response_test::run(a),
        }
    }
}

fn main() -> std::process::ExitCode {
    valve_bridge::init_tracing();
    let result = match Cli::parse().command {
        Command::Run(a) => cli::run::run(a),
        Command::Probe(a) => cli::probe::run(a),
        Command::Analysis(a) => a.run(),
    };
    cli::report(result)
}
