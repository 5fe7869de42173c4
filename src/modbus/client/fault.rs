//! Why a cycle gave no V_P, typed: what the loop counts (timeout, error, disconnected) and the
//! cause of each (the function code, the deadline, the exception code, the bad frame), so
//! a caller can tell causes apart without reading the words, which only `Display` writes.
//!
//! Not here: deciding which fault a failed exchange is (`connection.rs`).

use std::fmt;

use tokio_modbus::ExceptionCode;

use super::super::exception;
use super::super::map::ValueError;
use super::super::wire::{BadFrame, Malformed};

/// Why a cycle gave no V_P.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Fault {
    /// No complete reply in time.
    #[error("timeout: {0}")]
    Timeout(Timeout),
    /// An exception, CRC or framing error, or an unusable value.
    #[error("error: {0}")]
    Error(ReplyError),
    /// The link is down (and being reopened): the link, and why.
    #[error("disconnected: {0}")]
    Disconnected(String),
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
}

impl fmt::Display for Timeout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (fc, ms) = (self.fc, self.ms);
        match self.partial {
            None => write!(f, "no reply to FC {fc} within {ms} ms")?,
            Some((got, want)) => write!(
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
