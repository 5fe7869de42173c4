//! Command-line glue: one module per subcommand, plus logging set-up and error reporting.

pub mod demo;
pub mod diagnose;
pub mod input;
pub mod run;
pub mod simulate;

use std::process::ExitCode;

/// Logs go to stderr through `tracing`; `RUST_LOG` overrides the default level `info`.
pub fn init_tracing() {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .compact()
        .init();
}

/// Prints an error and its causes on one line, `valve-bridge: error: ...`, and picks the exit code.
pub fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let chain: Vec<String> = e.chain().map(|c| c.to_string()).collect();
            eprintln!("valve-bridge: error: {}", chain.join(": "));
            ExitCode::FAILURE
        }
    }
}
