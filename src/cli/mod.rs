//! Command-line glue: one module per subcommand, plus logging set-up and error reporting.
//!
//! Output goes through [`outln!`] and [`out!`] (standard output; a failed write is the
//! command's error, a closed pipe ends it quietly, as Unix tools do) and [`errln!`] (messages on
//! standard error, dropped if it cannot take them): nothing printed can panic.

/// `println!` that returns the write's error instead of panicking.
macro_rules! outln {
    ($($arg:tt)*) => { $crate::cli::write_stdout(format_args!("{}\n", format_args!($($arg)*))) };
}

/// `print!` that returns the write's error instead of panicking.
macro_rules! out {
    ($($arg:tt)*) => { $crate::cli::write_stdout(format_args!($($arg)*)) };
}

/// `eprintln!` that drops what standard error cannot take.
macro_rules! errln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _lost = writeln!(std::io::stderr(), $($arg)*);
    }};
}

pub(crate) mod demo;
pub(crate) mod diagnose;
pub(crate) mod fleet;
pub(crate) mod identify;
pub(crate) mod input;
pub(crate) mod probe;
pub(crate) mod response_test;
pub(crate) mod run;
pub(crate) mod simulate;
pub(crate) mod steps;

use std::io::Write;
use std::process::ExitCode;

/// Standard output could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot write to standard output: {0}")]
pub(crate) struct StdoutError(#[source] std::io::Error);

/// Writes `args` to standard output.
pub(crate) fn write_stdout(args: std::fmt::Arguments) -> Result<(), StdoutError> {
    std::io::stdout().write_fmt(args).map_err(StdoutError)
}

/// A progress bar of `len` units drawn with `template` (indicatif syntax), only when stderr is
/// a terminal: piped output and logs stay clean.
pub(crate) fn progress_bar(len: u64, template: &str) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
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
/// [`valve_bridge::error_line`]), and picks the exit code. A reader that closed the pipe (`|
/// head`) ends the command quietly and successfully, as Unix tools do.
pub(crate) fn report(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let closed_pipe = e
                .downcast_ref::<StdoutError>()
                .is_some_and(|StdoutError(io)| io.kind() == std::io::ErrorKind::BrokenPipe);
            if closed_pipe {
                return ExitCode::SUCCESS;
            }
            errln!("valve-bridge: error: {}", valve_bridge::error_line(&e));
            ExitCode::FAILURE
        }
    }
}
