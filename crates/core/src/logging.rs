//! Logging for both binaries (`valve-bridge`, `sim-device`): `tracing` to stderr with a filter
//! `RUST_LOG` can change, a stderr that never stops the caller, and errors printed on one line.
//!
//! Not here: what is logged (each module logs its own events).

/// The log filter when `RUST_LOG` is not set: `info`, except tokio-modbus's own per-frame
/// decoding warnings (several multi-line entries per bad reply), which the Modbus client already
/// reports once per fault in its own words.
const DEFAULT_LOG_FILTER: &str = "info,tokio_modbus=error";

/// Sends `tracing` logs to stderr, coloured only on a terminal; `RUST_LOG` overrides the default
/// filter (`info`, tokio-modbus at `error`). Used by both binaries (`valve-bridge`, `sim-device`).
/// A line stderr cannot take (a full disk, a closed pipe) is dropped ([`LossyStderr`]): logging
/// never stops the daemon.
pub fn init_tracing() {
    use std::io::IsTerminal;
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(DEFAULT_LOG_FILTER));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(|| LossyStderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_target(false)
        .compact()
        .init();
}

/// Standard error that drops what it cannot write. tracing-subscriber reports a failed write
/// with `eprintln!`, which panics when stderr itself is the problem (`2>/dev/full`, a closed
/// pipe): on the loop thread that would skip the valve's stop action.
#[derive(Debug, Clone, Copy)]
pub struct LossyStderr;

impl std::io::Write for LossyStderr {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        // Dropped, not retried: a log line is worth less than the loop's next cycle.
        let _lost = std::io::stderr().write_all(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        let _lost = std::io::stderr().flush();
        Ok(())
    }
}

/// An error and its causes on one line, `what: cause: cause`, for both binaries. A cause whose
/// text the previous message already contains is left out: many errors print their source in
/// their own message (`cannot read x.toml: No such file or directory (os error 2)`), and the
/// source would otherwise appear twice.
pub fn error_line(err: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in err.chain().map(|c| c.to_string()) {
        let repeated = parts.last().is_some_and(|last| last.contains(&cause));
        if !repeated && !cause.is_empty() {
            parts.push(cause);
        }
    }
    parts.join(": ").replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("x.toml: cannot read: {source}")]
    struct Outer {
        #[source]
        source: std::io::Error,
    }

    #[test]
    fn error_line_prints_each_cause_once() {
        let io = std::io::Error::from_raw_os_error(2);
        let text = io.to_string();
        let e = anyhow::Error::new(Outer { source: io });
        assert_eq!(error_line(&e), format!("x.toml: cannot read: {text}"));
        assert_eq!(text.matches("os error 2").count(), 1);
        // A context that does not repeat its cause keeps it.
        let e =
            anyhow::Error::new(std::io::Error::from_raw_os_error(2)).context("cannot open port");
        assert_eq!(error_line(&e), format!("cannot open port: {text}"));
    }
}
