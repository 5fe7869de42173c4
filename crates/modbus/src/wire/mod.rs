//! The byte streams under the valve client's tokio-modbus context: what tokio-modbus does not do
//! on its own, so that a link survives a late, lost or broken reply and a late reply is never
//! taken for the current one.
//!
//! - [`TcpWire`] passes on only the reply to the latest request, by its MBAP transaction id.
//! - [`RtuWire`] frames what arrives, drops line noise, passes on only a frame that fits the
//!   request (unit, function code, size and, where the read block holds the set-point register,
//!   the set-point just written read back), and holds the line after an unanswered request until
//!   its late reply came or cannot come any more. RTU frames carry no transaction id: this is
//!   how a late reply is told.
//!
//! Both share a [`WireState`] with the client: the bytes of the current RTU reply (for fault
//! messages), whether the device closed the stream, how many replies were discarded as late,
//! and (RTU) why the current request was held or its reply cannot be trusted. Written by hand because they are thin pass-throughs with a side look at the bytes; no
//! crate offers that for tokio's I/O traits. Not here: timeouts, reconnection, fault kinds (the
//! client decides).

mod rtu;
mod tcp;

use std::fmt;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Duration;

pub use rtu::{rtu_frame_fault, BadFrame, RtuWire, DEFAULT_LATE_REPLY, MAX_HORIZON};
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
    noise: AtomicU64,
    unexpected: AtomicU64,
    horizon_ms: AtomicU64,
    malformed: Mutex<Option<Malformed>>,
    window: Mutex<Window>,
}

/// What the RTU wire found about the current request (cleared when the next one begins).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Window {
    /// The request was not sent: the line was held for an earlier request's late reply.
    pub held: Option<Held>,
    /// The reply passed on cannot be told from an earlier request's late reply.
    pub unverified: Option<Unverified>,
}

/// A request held back while an earlier one's reply may still come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Held {
    /// The unit and function code of the unanswered request.
    pub unit: u8,
    pub fc: u8,
    /// How long ago it was sent, ms.
    pub sent_ms_ago: u32,
    /// How long its reply is waited for, ms (`late_reply_ms`, or more once a later one was seen).
    pub horizon_ms: u32,
}

impl fmt::Display for Held {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the line is held for unit {}'s reply to FC {} sent {} ms before (a late reply is \
             waited for up to {} ms, late_reply_ms)",
            self.unit, self.fc, self.sent_ms_ago, self.horizon_ms
        )
    }
}

/// A reply that may answer an earlier request: a second one followed it in its window.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unverified {
    /// The unit and function code of the request.
    pub unit: u8,
    pub fc: u8,
}

impl fmt::Display for Unverified {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "reply to FC {} not used: unit {} sent a second reply to it, so the first may answer \
             an earlier request (a reply later than late_reply_ms)",
            self.fc, self.unit
        )
    }
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
    /// The bytes of the current RTU reply as far as they came: a broken frame shaped like it,
    /// or its beginning (empty when nothing like it came).
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

    /// Bytes received that formed no frame (line noise, broken frames).
    pub fn noise_bytes(&self) -> u64 {
        self.noise.load(Ordering::Relaxed)
    }

    /// Frames that answered no request waiting for one.
    pub fn unexpected_replies(&self) -> u64 {
        self.unexpected.load(Ordering::Relaxed)
    }

    /// How long a late reply is waited for, once raised above the configured `late_reply_ms`.
    pub fn raised_horizon(&self) -> Option<Duration> {
        match self.horizon_ms.load(Ordering::Relaxed) {
            0 => None,
            ms => Some(Duration::from_millis(ms)),
        }
    }

    /// What the RTU wire found about the current request.
    pub fn window(&self) -> Window {
        *self.window.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn set_window(&self, set: impl FnOnce(&mut Window)) {
        set(&mut self.window.lock().unwrap_or_else(|p| p.into_inner()));
    }

    fn set_held(&self, held: Held) {
        self.set_window(|w| w.held = Some(held));
    }

    fn set_unverified(&self, u: Unverified) {
        self.set_window(|w| w.unverified = Some(u));
    }

    fn count_noise(&self, bytes: usize) {
        if bytes > 0 {
            self.noise.fetch_add(bytes as u64, Ordering::Relaxed);
        }
    }

    fn count_unexpected(&self) {
        self.unexpected.fetch_add(1, Ordering::Relaxed);
    }

    /// A raised horizon, or None once it went back to `late_reply_ms`.
    fn set_horizon(&self, raised: Option<Duration>) {
        let ms = raised.map_or(0, |h| h.as_millis() as u64);
        self.horizon_ms.store(ms, Ordering::Relaxed);
    }

    /// A new request begins: what was found about the last one is forgotten.
    fn begin_window(&self) {
        self.clear_rx();
        self.set_window(|w| *w = Window::default());
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

    /// The bytes of the awaited reply are `rest` (a broken frame, or the beginning of one).
    fn restart_rx(&self, rest: &[u8]) {
        self.clear_rx();
        self.log_rx(rest);
    }

    fn clear_rx(&self) {
        self.rx.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }
}
