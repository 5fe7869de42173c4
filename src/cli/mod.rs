//! Command-line glue: one module per subcommand, plus logging set-up and error reporting.

pub mod demo;
pub mod diagnose;
pub mod fleet;
pub mod identify;
pub mod input;
pub mod probe;
pub mod run;
pub mod simulate;
pub mod steps;

use std::io::IsTerminal;
use std::process::ExitCode;

/// A progress bar of `len` units drawn with `template` (indicatif syntax), only when stderr is
/// a terminal: piped output and logs stay clean.
pub fn progress_bar(len: u64, template: &str) -> Option<indicatif::ProgressBar> {
    std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(len);
        b.set_style(
            indicatif::ProgressStyle::with_template(template)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    })
}

/// Prints an error and its causes on one line, `valve-bridge: error: ...` (each cause once, see
/// [`valve_bridge::error_line`]), and picks the exit code.
pub fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("valve-bridge: error: {}", valve_bridge::error_line(&e));
            ExitCode::FAILURE
        }
    }
}
