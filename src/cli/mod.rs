//! Command-line glue: one module per subcommand, plus logging set-up and error reporting.

pub mod demo;
pub mod diagnose;
pub mod identify;
pub mod input;
pub mod run;
pub mod simulate;
pub mod steps;

use std::process::ExitCode;

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
