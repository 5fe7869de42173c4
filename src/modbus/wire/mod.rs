//! The byte streams under the valve client's tokio-modbus context: what tokio-modbus does not do
//! on its own, so that a link survives a late, lost or broken reply and a late reply is never
//! taken for the current one.
//!
//! - [`TcpWire`] passes on only the reply to the latest request, by its MBAP transaction id.
//! - [`RtuWire`] frames what arrives after each request and passes on only a frame that fits the
//!   request (unit, function code, size) and, where the read block holds the set-point
//!   register, reads back the set-point just written; it empties the port's input before each
//!   request. RTU frames carry no transaction id: this is how a late reply is told.
//!
//! Both share a [`WireState`] with the client: the bytes of the current RTU reply (for fault
//! messages), whether the device closed the stream, and how many replies were discarded as
//! late. Written by hand because they are thin pass-throughs with a side look at the bytes; no
//! crate offers that for tokio's I/O traits. Not here: timeouts, reconnection, fault kinds (the
//! client decides).

mod rtu;
mod tcp;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;

pub use rtu::{rtu_frame_fault, BadFrame, RtuWire};
pub use tcp::TcpWire;

const MODBUS_CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// Most bytes of one RTU reply recorded (a whole frame and some).
const RX_LOG_LIMIT: usize = 512;

/// What the wire saw, shared with the client.
#[derive(Debug, Default)]
pub struct WireState {
    rx: Mutex<Vec<u8>>,
    closed: AtomicBool,
    stale: AtomicU64,
    malformed: Mutex<Option<Malformed>>,
}

/// A reply to the current request, whole and in step with the stream, whose PDU does not fit
/// the request: not passed on, so the link is kept and the cycle fails on its own.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Malformed {
    /// A read's byte count is not two per register asked, or not what the frame holds.
    ByteCount { fc: u8, got: u8, want: usize },
    /// The PDU is not as long as its function code says.
    Length { fc: u8, bytes: usize },
    /// The reply carries another function code than the request.
    Function { asked: u8, got: u8 },
}

impl std::fmt::Display for Malformed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Malformed::ByteCount { fc, got, want } => write!(
                f,
                "malformed reply to FC {fc}: byte count {got}, {want} expected"
            ),
            Malformed::Length { fc, bytes } => {
                write!(f, "malformed reply to FC {fc}: a {bytes}-byte PDU")
            }
            Malformed::Function { asked, got } => {
                write!(f, "malformed reply to FC {asked}: function code {got}")
            }
        }
    }
}

impl WireState {
    /// The bytes received since the current RTU request began.
    pub fn received(&self) -> Vec<u8> {
        self.rx.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    /// True once the device closed the connection (the stream ended).
    pub fn closed(&self) -> bool {
        self.closed.load(Ordering::Relaxed)
    }

    /// Replies discarded because they answered an earlier request.
    pub fn stale_replies(&self) -> u64 {
        self.stale.load(Ordering::Relaxed)
    }

    /// The malformed reply to the current request, if one came.
    pub fn malformed(&self) -> Option<Malformed> {
        *self.malformed.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn set_malformed(&self, m: Option<Malformed>) {
        *self.malformed.lock().unwrap_or_else(|p| p.into_inner()) = m;
    }

    fn count_stale(&self) {
        self.stale.fetch_add(1, Ordering::Relaxed);
    }

    fn log_rx(&self, bytes: &[u8]) {
        let mut log = self.rx.lock().unwrap_or_else(|p| p.into_inner());
        let room = RX_LOG_LIMIT.saturating_sub(log.len());
        log.extend_from_slice(&bytes[..bytes.len().min(room)]);
    }

    /// Forgets what was received before a discarded reply: the reply being waited for starts
    /// with `rest`.
    fn restart_rx(&self, rest: &[u8]) {
        self.clear_rx();
        self.log_rx(rest);
    }

    fn clear_rx(&self) {
        self.rx.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }
}
