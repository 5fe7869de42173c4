//! [`RtuWire`]: a serial stream that passes on only the reply that answers the current request.
//!
//! RTU frames carry no transaction id. A device that answers after the client's deadline puts
//! its reply on the line while the client waits for a later request's answer, and tokio-modbus
//! would take the first frame that arrives (skipping any bytes before it). The wire reads each
//! request as it is written and frames every byte that comes back ([`framer`]): line noise is
//! dropped, a late reply is given to the request it answers and dropped, and only a frame that
//! answers the current request is passed on. Before each request, what arrived since the last
//! reply is read and accounted for, and the request is held back while an earlier request of a
//! device that answers is still unanswered, younger than `late_reply_ms`, and would be answered
//! by the same bytes (a held set-point; [`Framer::hold`]): its reply then cannot land in
//! another request's window. A held request is not written at all; the client's deadline ends
//! its cycle ([`super::Held`]).
//!
//! What it guarantees: a reply passed on without an [`super::Unverified`] mark answers its own
//! request, provided the device answers each request within `late_reply_ms` or never, and
//! answers requests in the order they came (as an RTU slave does). A reply later than that is
//! still told when it reads back another set-point than the current one, and raises
//! `late_reply_ms`; on a held set-point it cannot be told, and may be taken once for the next
//! request's (then a second reply follows, which is counted and raises `late_reply_ms` too).
//!
//! Not here: timeouts, fault kinds (the client decides).

mod framer;
mod request;

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};
use tokio_serial::{SerialPort, SerialStream};

use super::{WireState, MODBUS_CRC};
use crate::plan::Transaction;
use framer::Framer;
pub use framer::MAX_HORIZON;

/// The longest RTU frame: address, a 253-byte PDU, CRC.
const MAX_FRAME: usize = 256;
/// How long a late reply is waited for when `late_reply_ms` is not set.
pub const DEFAULT_LATE_REPLY: Duration = Duration::from_millis(100);
/// Reads of the input between two requests before the rest is discarded unread (a line that
/// never stops talking must not keep a request from going out).
const DRAIN_READS: usize = 16;

/// A serial stream that passes on only replies to the current request (module documentation).
#[derive(Debug)]
pub struct RtuWire {
    inner: SerialStream,
    state: Arc<WireState>,
    framer: Framer,
    /// The end of the current hold (reset, never reallocated).
    hold: Pin<Box<Sleep>>,
    /// The size of the request last kept waiting by a hold. Its cycle may end before the hold
    /// does; tokio-modbus then keeps its bytes and puts the next request behind them.
    held_request: Option<usize>,
}

impl RtuWire {
    /// Wraps an open port; `state` is shared with the client; a late reply is waited for up to
    /// `late_reply` (`late_reply_ms`), from the start up to `raised` if that is longer (a later
    /// reply was seen on the connection before). Must be called within a tokio runtime.
    pub fn new(
        inner: SerialStream,
        state: Arc<WireState>,
        late_reply: Duration,
        raised: Option<Duration>,
    ) -> Self {
        RtuWire {
            inner,
            state,
            framer: Framer::new(late_reply, raised.unwrap_or(late_reply)),
            hold: Box::pin(tokio::time::sleep(Duration::ZERO)),
            held_request: None,
        }
    }

    /// Reads what arrived since the last reply, then waits while the line is held for the
    /// request `next`. Ready when it may go out.
    fn poll_settle(&mut self, next: &[u8], cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        self.framer.end_window();
        let mut reads = 0;
        loop {
            if reads == DRAIN_READS {
                self.inner.clear(tokio_serial::ClearBuffer::Input)?;
                break;
            }
            reads += 1;
            let mut chunk = [0u8; MAX_FRAME];
            let mut read = ReadBuf::new(&mut chunk);
            match Pin::new(&mut self.inner).poll_read(cx, &mut read) {
                Poll::Pending => break,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                // The port closed: the write will tell.
                Poll::Ready(Ok(())) if read.filled().is_empty() => break,
                Poll::Ready(Ok(())) => {
                    self.framer
                        .received(read.filled(), Instant::now(), &self.state)
                }
            }
        }
        let now = Instant::now();
        let Some((until, held)) = self.framer.hold(next, now, &self.state) else {
            return Poll::Ready(Ok(()));
        };
        self.state.set_held(held);
        if self.hold.deadline() != until {
            self.hold.as_mut().reset(until);
        }
        match self.hold.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(Ok(())),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl AsyncRead for RtuWire {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        loop {
            if !this.framer.ready.is_empty() {
                let n = this.framer.ready.len().min(buf.remaining());
                buf.put_slice(&this.framer.ready[..n]);
                this.framer.ready.drain(..n);
                return Poll::Ready(Ok(()));
            }
            let mut chunk = [0u8; MAX_FRAME];
            let mut read = ReadBuf::new(&mut chunk);
            match Pin::new(&mut this.inner).poll_read(cx, &mut read) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                // The port closed: tokio-modbus sees the end of the stream.
                Poll::Ready(Ok(())) if read.filled().is_empty() => return Poll::Ready(Ok(())),
                Poll::Ready(Ok(())) => {
                    this.framer
                        .received(read.filled(), Instant::now(), &this.state)
                }
            }
        }
    }
}

impl AsyncWrite for RtuWire {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        if !this.framer.writing() {
            if let Some(held) = this.held_request.take() {
                if buf.len() > held {
                    // The held request's cycle ended and the next request follows it: it is
                    // dropped unsent (tokio-modbus takes it as written).
                    return Poll::Ready(Ok(held));
                }
            }
            // A new request: what came since the last reply is accounted for, and it waits
            // while an earlier reply may still come.
            match this.poll_settle(buf, cx) {
                Poll::Ready(Ok(())) => {}
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Pending => {
                    this.held_request = Some(request::request_len(buf).unwrap_or(buf.len()));
                    return Poll::Pending;
                }
            }
            this.framer.begin(&this.state);
            this.state.begin_window();
        }
        let written = Pin::new(&mut this.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = written {
            this.framer.wrote(&buf[..n], Instant::now());
        }
        written
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// A complete RTU reply that is no answer to its request.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadFrame {
    /// Its CRC is not the one computed over its body.
    #[error("CRC error in reply to FC {fc}: received 0x{received:04X}, computed 0x{computed:04X} over {body:02X?}")]
    Crc {
        fc: u8,
        received: u16,
        computed: u16,
        body: Vec<u8>,
    },
    /// Its CRC is good, but tokio-modbus refused it.
    #[error("unexpected reply to FC {fc}: {frame:02X?}")]
    Unexpected { fc: u8, frame: Vec<u8> },
}

/// What is wrong with a complete but unusable RTU reply `rx` to `t`, or None if the reply is
/// incomplete.
pub fn rtu_frame_fault(rx: &[u8], t: &Transaction) -> Option<BadFrame> {
    let fc = t.function_code();
    let len = match rx.get(1) {
        Some(&f) if f == fc | 0x80 => 5,
        _ => t.rtu_response_bytes(),
    };
    let frame = rx.get(..len)?;
    let (body, crc) = frame.split_at(len - 2);
    let received = u16::from_le_bytes([crc[0], crc[1]]);
    let computed = MODBUS_CRC.checksum(body);
    Some(if received != computed {
        BadFrame::Crc {
            fc,
            received,
            computed,
            body: body.to_vec(),
        }
    } else {
        BadFrame::Unexpected {
            fc,
            frame: frame.to_vec(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::Table;

    /// `body` with its CRC.
    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&MODBUS_CRC.checksum(body).to_le_bytes());
        f
    }

    #[test]
    fn crc_errors_are_told_from_incomplete_replies() {
        let t = Transaction::Read {
            table: Table::Holding,
            address: 1,
            count: 1,
        };
        let frame = frame(&[1u8, 3, 2, 0x01, 0xF4]);
        assert!(rtu_frame_fault(&frame[..5], &t).is_none(), "incomplete");
        let ok = rtu_frame_fault(&frame, &t).unwrap();
        assert!(matches!(ok, BadFrame::Unexpected { fc: 3, .. }), "{ok}");
        assert!(ok.to_string().starts_with("unexpected reply"), "{ok}");
        let mut frame = frame;
        frame[6] ^= 0xFF;
        let bad = rtu_frame_fault(&frame, &t).unwrap();
        assert!(matches!(bad, BadFrame::Crc { fc: 3, .. }), "{bad}");
        assert!(
            bad.to_string().starts_with("CRC error in reply to FC 3"),
            "{bad}"
        );
        // An exception reply is 5 bytes.
        let mut exc = vec![1u8, 0x83, 2];
        exc.extend_from_slice(&(MODBUS_CRC.checksum(&exc) ^ 1).to_le_bytes());
        let exc = rtu_frame_fault(&exc, &t).unwrap();
        assert!(exc.to_string().starts_with("CRC error"), "{exc}");
    }
}
