//! Why a cycle gave no V_P, typed: what the loop counts (timeout, error, disconnected) and the
//! cause of each (the function code, the deadline, the exception code, the bad frame, why the
//! link is down), so a caller can tell causes apart without reading the words, which only
//! `Display` writes.
//!
//! Not here: deciding which fault a failed exchange is (`connection.rs`).

use std::fmt;
use std::io;
use std::time::Duration;

use tokio_modbus::ExceptionCode;

use super::super::exception;
use super::super::map::ValueError;
use super::super::wire::{BadFrame, Held, Malformed, Unverified};

/// Why a cycle gave no V_P.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Fault {
    /// No complete reply in time.
    #[error("timeout: {0}")]
    Timeout(Timeout),
    /// An exception, CRC or framing error, or an unusable value.
    #[error("error: {0}")]
    Error(ReplyError),
    /// The link is down (and being reopened): the link, and why (boxed: a fault is returned
    /// by every cycle, and this cause is the largest).
    #[error("disconnected: {0}")]
    Disconnected(Box<Disconnected>),
}

/// A cycle that found its link down, or broke it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{link}: {why}")]
pub struct Disconnected {
    /// The valve's link, described.
    pub link: String,
    /// Why no transaction went through.
    pub why: Unlinked,
}

/// Why a cycle's link could not carry its transaction.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Unlinked {
    /// The link is closed, for this reason.
    #[error("{0}")]
    NotOpen(Down),
    /// The link is down for this reason, and the next connection attempt waits `wait_ms`.
    #[error("{down}; next connection attempt in {wait_ms} ms")]
    Backoff { down: Down, wait_ms: u128 },
    /// A connection attempt failed just now; the next one waits `wait_ms`.
    #[error("cannot connect: {error}; next attempt in {wait_ms} ms")]
    CannotConnect { error: ConnectError, wait_ms: u128 },
    /// The transaction broke the stream.
    #[error("{0}")]
    Broken(BrokenStream),
}

/// Why a link is down, kept for the cycles that find it so.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Down {
    /// No connection was opened yet.
    #[error("not connected yet")]
    NotConnectedYet,
    /// The last connection attempt failed.
    #[error("cannot connect: {0}")]
    CannotConnect(ConnectError),
    /// The device answered nothing for this long on an open TCP connection.
    #[error("no answer for {:.1} s on an open connection, reopening it", .0.as_secs_f64())]
    Silent(Duration),
    /// A transaction of the valve on `link` broke the stream.
    #[error("{link}: {stream}")]
    Broken { link: String, stream: BrokenStream },
    /// A reply put the TCP stream out of step.
    #[error("{0}")]
    Reply(ReplyError),
}

/// Why a connection (or the serial port) could not be opened.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ConnectError {
    /// The operating system refused it.
    #[error("{0}")]
    Io(IoFailure),
    /// No connection within the deadline, ms.
    #[error("no connection within {ms} ms")]
    Timeout { ms: u128 },
}

/// A transaction that ended its link's stream.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("FC {fc}: {end}")]
pub struct BrokenStream {
    /// The request's function code.
    pub fc: u8,
    /// How the stream ended.
    pub end: StreamEnd,
}

/// How a link's stream ended.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StreamEnd {
    /// The device closed the connection.
    #[error("the device closed the connection")]
    Closed,
    /// The device reset the connection.
    #[error("the device reset the connection ({0})")]
    Reset(IoFailure),
    /// Writing found the connection broken.
    #[error("the connection is broken ({0})")]
    BrokenPipe(IoFailure),
    /// Another transport error (on RTU, the serial port's).
    #[error("{0}")]
    Io(IoFailure),
}

/// An I/O error as it was reported: its kind, for callers, and its words, for people.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct IoFailure {
    /// The error's kind.
    pub kind: io::ErrorKind,
    /// The error as it printed.
    pub message: String,
}

impl From<&io::Error> for IoFailure {
    fn from(e: &io::Error) -> IoFailure {
        IoFailure {
            kind: e.kind(),
            message: e.to_string(),
        }
    }
}

/// A transaction whose reply did not come complete before its deadline.
#[derive(Debug, Clone, PartialEq)]
pub struct Timeout {
    /// The request's function code.
    pub fc: u8,
    /// The valve's timeout, ms.
    pub ms: u128,
    /// Bytes of an RTU reply that did come, and how many the reply has.
    pub partial: Option<(usize, usize)>,
    /// Replies the link has seen arrive after their deadline so far (the device is there,
    /// only slow).
    pub late_replies: u64,
    /// The request was never sent: the RTU line was held for an earlier request's late reply.
    pub held: Option<Held>,
}

impl fmt::Display for Timeout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (fc, ms) = (self.fc, self.ms);
        match (self.held, self.partial) {
            (Some(held), _) => write!(f, "FC {fc} not sent within {ms} ms: {held}")?,
            (None, None) => write!(f, "no reply to FC {fc} within {ms} ms")?,
            (None, Some((got, want))) => write!(
                f,
                "reply to FC {fc} incomplete within {ms} ms: {got} of {want} bytes"
            )?,
        }
        if self.late_replies > 0 {
            write!(
                f,
                " (the device does answer, later: {} replies came after their deadline; a \
                 longer timeout_ms may fit the loop period)",
                self.late_replies
            )?;
        }
        Ok(())
    }
}

/// A reply that came but gives no V_P.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplyError {
    /// The device answered with an exception.
    #[error("device answered FC {fc} with {}", exception::explain(*code))]
    Exception { fc: u8, code: ExceptionCode },
    /// A complete RTU frame that is no answer (a bad CRC, or refused by tokio-modbus).
    #[error("{0}")]
    Frame(BadFrame),
    /// A TCP reply whose PDU breaks the protocol.
    #[error("{0}")]
    Malformed(Malformed),
    /// A reply tokio-modbus could not decode, or a protocol error (a mismatched header).
    #[error("FC {fc}: {why}")]
    Unusable { fc: u8, why: String },
    /// A reply with another number of registers than asked.
    #[error("FC {fc}: {got} registers in reply, {want} asked")]
    Registers { fc: u8, got: usize, want: u16 },
    /// A value that does not fit its register (the set-point) or its valid range (V_P).
    #[error("{0}")]
    Value(#[from] ValueError),
    /// An RTU reply that cannot be told from an earlier request's late reply.
    #[error("{0}")]
    Unverified(Unverified),
    /// The status word flags the set-point as refused.
    #[error("device flags the set-point as refused (status 0x{word:04X}, bit {bit}) after O_P {op_pct:.2} %")]
    Refused { word: u16, bit: u8, op_pct: f64 },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timeout_says_what_came_and_that_the_device_answers_late() {
        let t = Timeout {
            fc: 23,
            ms: 8,
            partial: Some((5, 11)),
            late_replies: 0,
            held: None,
        };
        assert_eq!(
            Fault::Timeout(t.clone()).to_string(),
            "timeout: reply to FC 23 incomplete within 8 ms: 5 of 11 bytes"
        );
        let late = Timeout {
            partial: None,
            late_replies: 3,
            ..t
        };
        assert_eq!(
            late.to_string(),
            "no reply to FC 23 within 8 ms (the device does answer, later: 3 replies came after \
             their deadline; a longer timeout_ms may fit the loop period)"
        );
    }

    #[test]
    fn a_disconnection_names_the_link_and_why_it_is_down() {
        let link = "Modbus TCP 10.0.0.7:502 unit 1".to_string();
        let refused = ConnectError::Io(IoFailure {
            kind: io::ErrorKind::ConnectionRefused,
            message: "Connection refused (os error 111)".into(),
        });
        let broken = BrokenStream {
            fc: 23,
            end: StreamEnd::Closed,
        };
        let cases = [
            (
                Unlinked::NotOpen(Down::NotConnectedYet),
                "not connected yet",
            ),
            (
                Unlinked::Backoff {
                    down: Down::Silent(Duration::from_millis(3040)),
                    wait_ms: 90,
                },
                "no answer for 3.0 s on an open connection, reopening it; next connection \
                 attempt in 90 ms",
            ),
            (
                Unlinked::CannotConnect {
                    error: refused.clone(),
                    wait_ms: 200,
                },
                "cannot connect: Connection refused (os error 111); next attempt in 200 ms",
            ),
            (
                Unlinked::Backoff {
                    down: Down::CannotConnect(ConnectError::Timeout { ms: 8 }),
                    wait_ms: 150,
                },
                "cannot connect: no connection within 8 ms; next connection attempt in 150 ms",
            ),
            (
                Unlinked::Broken(broken.clone()),
                "FC 23: the device closed the connection",
            ),
            (
                Unlinked::NotOpen(Down::Broken {
                    link: link.clone(),
                    stream: broken,
                }),
                "Modbus TCP 10.0.0.7:502 unit 1: FC 23: the device closed the connection",
            ),
            (
                Unlinked::Broken(BrokenStream {
                    fc: 3,
                    end: StreamEnd::Reset(IoFailure {
                        kind: io::ErrorKind::ConnectionReset,
                        message: "Connection reset by peer (os error 104)".into(),
                    }),
                }),
                "FC 3: the device reset the connection (Connection reset by peer (os error 104))",
            ),
        ];
        for (why, words) in cases {
            let fault = Fault::Disconnected(Box::new(Disconnected {
                link: link.clone(),
                why,
            }));
            assert_eq!(fault.to_string(), format!("disconnected: {link}: {words}"));
        }
    }

    #[test]
    fn an_exception_is_named_by_its_code() {
        let e = ReplyError::Exception {
            fc: 23,
            code: ExceptionCode::ServerDeviceFailure,
        };
        assert!(
            e.to_string()
                .starts_with("device answered FC 23 with exception 04 (server device failure"),
            "{e}"
        );
    }
}
