//! [`RtuWire`]: a serial stream that passes on only a reply that answers the current request.
//!
//! RTU frames carry no transaction id. A device that answers after the client's deadline puts
//! its reply on the line while the client waits for a later request's answer, and tokio-modbus
//! would take the first frame that arrives. The wire reads each request as it is written (unit,
//! function code, addresses, the set-point words of FC 16 and FC 23) and frames the bytes that
//! come back. A complete frame with a good CRC is passed on only if it fits the request: the same
//! unit and function code (or its exception), the expected size and, where the read block holds
//! the set-point register ([`crate::modbus::plan::Plan::rtu`] takes it in when it is near), the
//! set-point just written read back. A frame from another unit, with another function code or
//! size, or reading back an earlier set-point of the last [`WRITTEN_KEPT`] is a reply to an
//! earlier request: it is discarded and counted ([`super::WireState::stale_replies`]). A frame
//! that reads back a set-point never written here (the device clamped or refused it) is passed
//! on: the client decides. A frame with a bad CRC, and whatever follows it, is passed on as it
//! came, for tokio-modbus to refuse and the client to name ([`rtu_frame_fault`]). The port's
//! input is emptied before each request, so nothing that arrived between two exchanges is read
//! as an answer.
//!
//! What it cannot tell: a late reply to a request that wrote the same set-point as the current
//! one, with the same size and function code (a held O_P and a device slower than the deadline).
//! The timeouts that come with it, and the count of discarded replies, tell the user to raise
//! `timeout_ms` (see README, "sim-device and the Modbus client").

use std::io;
use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio_serial::{SerialPort, SerialStream};

use super::{WireState, MODBUS_CRC};
use crate::modbus::plan::Transaction;

/// The longest RTU frame: address, a 253-byte PDU, CRC.
const MAX_FRAME: usize = 256;
/// Set-points remembered: a reply that reads back one of them, not the current one, is late.
const WRITTEN_KEPT: usize = 16;
/// The most set-point bytes remembered per write (a 32-bit set-point takes 4).
const WRITTEN_BYTES: usize = 8;

/// A set-point written: the unit, the register address and the data bytes as sent.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Written {
    unit: u8,
    address: u16,
    bytes: [u8; WRITTEN_BYTES],
    len: usize,
}

impl Written {
    fn data(&self) -> &[u8] {
        &self.bytes[..self.len]
    }

    /// The byte offset of these registers in the data of a read of `count` from `start`.
    fn offset_in(&self, start: u16, count: u16) -> Option<usize> {
        let end = u32::from(start) + u32::from(count);
        let own_end = u32::from(self.address) + (self.len / 2) as u32;
        (self.address >= start && own_end <= end).then(|| 2 * usize::from(self.address - start))
    }
}

/// What the reply to the request being written must look like.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Expect {
    unit: u8,
    fc: u8,
    /// Frame size of a normal reply, bytes.
    len: usize,
    /// Where the reply's frame holds the set-point registers (byte offset), and what they must read.
    readback: Option<(usize, Written)>,
}

/// Why a frame was discarded.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Late {
    Unit(u8),
    Function(u8),
    Size(usize),
    EarlierSetpoint,
}

/// The framing of one link's replies (no I/O, see the module documentation).
#[derive(Debug)]
struct Framer {
    request: [u8; MAX_FRAME],
    request_len: usize,
    /// Set once the request is complete: `Some` when the wire knows its reply, `None` for a
    /// function it does not know (its reply passes unframed).
    expect: Option<Option<Expect>>,
    written: [Written; WRITTEN_KEPT],
    next_written: usize,
    /// Framing was given up for this request (a broken frame): the rest passes as it comes.
    unframed: bool,
    /// Received bytes not framed yet.
    rx: Vec<u8>,
    /// Bytes passed on, not yet handed to tokio-modbus.
    ready: Vec<u8>,
}

impl Framer {
    fn new() -> Framer {
        Framer {
            request: [0; MAX_FRAME],
            request_len: 0,
            expect: None,
            written: [Written::default(); WRITTEN_KEPT],
            next_written: 0,
            unframed: false,
            rx: Vec::with_capacity(2 * MAX_FRAME),
            ready: Vec::with_capacity(2 * MAX_FRAME),
        }
    }

    /// True while a request is being written (begun, not complete).
    fn writing(&self) -> bool {
        self.request_len > 0 && self.expect.is_none()
    }

    /// A new request starts: nothing received so far answers it.
    fn begin(&mut self) {
        self.request_len = 0;
        self.expect = None;
        self.unframed = false;
        self.rx.clear();
        self.ready.clear();
    }

    /// Follows the bytes of the request being written.
    fn wrote(&mut self, bytes: &[u8]) {
        let room = MAX_FRAME - self.request_len;
        let n = bytes.len().min(room);
        self.request[self.request_len..self.request_len + n].copy_from_slice(&bytes[..n]);
        self.request_len += n;
        if self.expect.is_none() {
            match request_len(&self.request[..self.request_len]) {
                Some(len) if self.request_len >= len => self.expect = Some(self.parse_request()),
                // Longer than any frame: not a request the wire can read.
                _ if self.request_len == MAX_FRAME => self.expect = Some(None),
                _ => {}
            }
        }
    }

    /// What the complete request asks for; records the set-point it writes.
    fn parse_request(&mut self) -> Option<Expect> {
        let request = self.request;
        let r = &request[..self.request_len];
        let word = |i: usize| u16::from_be_bytes([r[i], r[i + 1]]);
        let (unit, fc) = (r[0], r[1]);
        match fc {
            3 | 4 => {
                let (start, count) = (word(2), word(4));
                let readback = (fc == 3)
                    .then(|| self.latest_written(unit))
                    .flatten()
                    .and_then(|w| w.offset_in(start, count).map(|off| (3 + off, w)));
                Some(Expect {
                    unit,
                    fc,
                    len: 5 + 2 * usize::from(count),
                    readback,
                })
            }
            6 | 16 => {
                let (address, data) = match fc {
                    6 => (word(2), &r[4..6]),
                    _ => (word(2), &r[7..7 + usize::from(r[6])]),
                };
                self.remember(unit, address, data);
                Some(Expect {
                    unit,
                    fc,
                    len: 8,
                    readback: None,
                })
            }
            23 => {
                let (start, count, address) = (word(2), word(4), word(6));
                let data = &r[11..11 + usize::from(r[10])];
                let w = self.remember(unit, address, data);
                let readback = w.and_then(|w| w.offset_in(start, count).map(|off| (3 + off, w)));
                Some(Expect {
                    unit,
                    fc,
                    len: 5 + 2 * usize::from(count),
                    readback,
                })
            }
            _ => None,
        }
    }

    fn remember(&mut self, unit: u8, address: u16, data: &[u8]) -> Option<Written> {
        if data.len() > WRITTEN_BYTES || !data.len().is_multiple_of(2) {
            return None;
        }
        let mut w = Written {
            unit,
            address,
            bytes: [0; WRITTEN_BYTES],
            len: data.len(),
        };
        w.bytes[..data.len()].copy_from_slice(data);
        self.written[self.next_written] = w;
        self.next_written = (self.next_written + 1) % WRITTEN_KEPT;
        Some(w)
    }

    /// The set-point written last to `unit`.
    fn latest_written(&self, unit: u8) -> Option<Written> {
        (1..=WRITTEN_KEPT)
            .map(|back| self.written[(self.next_written + WRITTEN_KEPT - back) % WRITTEN_KEPT])
            .find(|w| w.len > 0 && w.unit == unit)
    }

    /// Takes in received bytes: complete frames that answer the request go to `ready`, late ones
    /// are discarded and counted in `state`.
    fn received(&mut self, bytes: &[u8], state: &WireState) {
        let Some(Some(expect)) = self.expect.filter(|_| !self.unframed) else {
            // A request the wire cannot read (or none), or a broken frame: pass everything on.
            self.ready.extend_from_slice(bytes);
            return;
        };
        self.rx.extend_from_slice(bytes);
        while self.rx.len() >= 3 {
            let Some(len) = reply_len(&self.rx) else {
                self.pass_rest();
                return;
            };
            if self.rx.len() < len {
                return;
            }
            let frame = &self.rx[..len];
            let (body, crc) = frame.split_at(len - 2);
            if MODBUS_CRC.checksum(body).to_le_bytes() != [crc[0], crc[1]] {
                self.pass_rest();
                return;
            }
            match self.late(frame, &expect) {
                None => self.ready.extend_from_slice(frame),
                Some(why) => {
                    state.count_stale();
                    state.restart_rx(&self.rx[len..]);
                    tracing::debug!(
                        "RTU: discarded a reply to an earlier request ({why:?}; {frame:02X?})"
                    );
                }
            }
            self.rx.drain(..len);
        }
    }

    /// Passes the unframed rest on as it came (a broken frame, for tokio-modbus to refuse).
    fn pass_rest(&mut self) {
        self.unframed = true;
        self.ready.extend_from_slice(&self.rx);
        self.rx.clear();
    }

    /// Why a complete, intact frame does not answer the request, if it does not.
    fn late(&self, frame: &[u8], e: &Expect) -> Option<Late> {
        let (unit, fc) = (frame[0], frame[1]);
        if unit != e.unit {
            return Some(Late::Unit(unit));
        }
        if fc == e.fc | 0x80 {
            return None;
        }
        if fc != e.fc {
            return Some(Late::Function(fc));
        }
        if frame.len() != e.len {
            return Some(Late::Size(frame.len()));
        }
        let (off, w) = e.readback?;
        let got = &frame[off..off + w.len];
        if got == w.data() {
            return None;
        }
        let earlier = self
            .written
            .iter()
            .any(|o| o.unit == w.unit && o.address == w.address && o.data() == got);
        earlier.then_some(Late::EarlierSetpoint)
    }
}

/// The size of a request from its first bytes, once they tell it.
fn request_len(r: &[u8]) -> Option<usize> {
    match *r.get(1)? {
        16 => Some(9 + usize::from(*r.get(6)?)),
        23 => Some(13 + usize::from(*r.get(10)?)),
        // FC 3, 4 and every function the wire does not read: 8 bytes (address, FC, 4, CRC).
        _ => Some(8),
    }
}

/// The size of a reply frame from its first three bytes, or None for a function code whose
/// replies the wire does not know.
fn reply_len(rx: &[u8]) -> Option<usize> {
    match rx[1] {
        fc if fc & 0x80 != 0 => Some(5),
        3 | 4 | 23 => Some(5 + usize::from(rx[2])),
        6 | 16 => Some(8),
        _ => None,
    }
}

/// A serial stream that passes on only replies to the current request (module documentation).
#[derive(Debug)]
pub struct RtuWire {
    inner: SerialStream,
    state: Arc<WireState>,
    framer: Framer,
}

impl RtuWire {
    /// Wraps an open port; `state` is shared with the client.
    pub fn new(inner: SerialStream, state: Arc<WireState>) -> Self {
        RtuWire {
            inner,
            state,
            framer: Framer::new(),
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
                    let new = read.filled();
                    this.state.log_rx(new);
                    this.framer.received(new, &this.state);
                }
            }
        }
    }
}

impl AsyncWrite for RtuWire {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        if !self.framer.writing() {
            // A new request: what is still in the input (a late reply, the rest of a broken
            // frame) is not its answer.
            self.inner.clear(tokio_serial::ClearBuffer::Input)?;
            self.state.clear_rx();
            self.framer.begin();
        }
        let this = self.get_mut();
        let written = Pin::new(&mut this.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = written {
            this.framer.wrote(&buf[..n]);
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
    use crate::modbus::map::Table;

    /// `body` with its CRC.
    fn frame(body: &[u8]) -> Vec<u8> {
        let mut f = body.to_vec();
        f.extend_from_slice(&MODBUS_CRC.checksum(body).to_le_bytes());
        f
    }

    /// An FC 23 request of unit 1: write `sp` at 0, read 3 registers from 0.
    fn fc23(sp: u16) -> Vec<u8> {
        let [h, l] = sp.to_be_bytes();
        frame(&[1, 23, 0, 0, 0, 3, 0, 0, 0, 1, 2, h, l])
    }

    /// Its reply: set-point `sp`, position `pos`, status 0.
    fn fc23_reply(sp: u16, pos: u16) -> Vec<u8> {
        let ([sh, sl], [ph, pl]) = (sp.to_be_bytes(), pos.to_be_bytes());
        frame(&[1, 23, 6, sh, sl, ph, pl, 0, 0])
    }

    fn exchange(f: &mut Framer, request: &[u8], replies: &[&[u8]], state: &WireState) -> Vec<u8> {
        // Whether or not the last request was answered, the next one begins afresh.
        assert!(!f.writing());
        f.begin();
        // Written in two pieces, as a driver may.
        f.wrote(&request[..3]);
        assert!(f.writing());
        f.wrote(&request[3..]);
        assert!(!f.writing());
        for r in replies {
            // Received byte by byte: framing does not depend on how the bytes come.
            for b in r.iter() {
                f.received(std::slice::from_ref(b), state);
            }
        }
        std::mem::take(&mut f.ready)
    }

    #[test]
    fn a_late_reply_is_told_by_the_set_point_it_reads_back() {
        let state = WireState::default();
        let mut f = Framer::new();
        // Cycle 1 (set-point 500) is answered at once.
        let got = exchange(&mut f, &fc23(500), &[&fc23_reply(500, 490)], &state);
        assert_eq!(got, fc23_reply(500, 490));
        // Cycle 2 (501) gets no reply in time; cycle 3 (502) receives the replies to 2 and 3.
        assert!(exchange(&mut f, &fc23(501), &[], &state).is_empty());
        let late = fc23_reply(501, 495);
        let current = fc23_reply(502, 497);
        let got = exchange(&mut f, &fc23(502), &[&late, &current], &state);
        assert_eq!(got, current);
        assert_eq!(state.stale_replies(), 1);
        // A set-point the device changed (never written here) is passed on for the client.
        let clamped = fc23_reply(1000, 497);
        assert_eq!(exchange(&mut f, &fc23(1500), &[&clamped], &state), clamped);
        assert_eq!(state.stale_replies(), 1);
    }

    #[test]
    fn other_units_functions_and_sizes_are_late() {
        let state = WireState::default();
        let mut f = Framer::new();
        // FC 16 of set-point 7 at 0, then FC 3 of registers 0-1 reads it back.
        let write = frame(&[1, 16, 0, 0, 0, 1, 2, 0, 7]);
        let echo = frame(&[1, 16, 0, 0, 0, 1]);
        assert_eq!(exchange(&mut f, &write, &[&echo], &state), echo);
        let read = frame(&[1, 3, 0, 0, 0, 2]);
        let late_echo = echo.clone();
        let other_unit = frame(&[2, 3, 4, 0, 7, 0, 9]);
        let short = frame(&[1, 3, 2, 0, 7]);
        let reply = frame(&[1, 3, 4, 0, 7, 1, 0xF4]);
        let got = exchange(
            &mut f,
            &read,
            &[&late_echo, &other_unit, &short, &reply],
            &state,
        );
        assert_eq!(got, reply);
        assert_eq!(state.stale_replies(), 3);
        // An exception to the request is its answer.
        let exc = frame(&[1, 0x83, 2]);
        assert_eq!(exchange(&mut f, &read, &[&exc], &state), exc);
    }

    #[test]
    fn an_fc6_write_is_read_back_like_fc16() {
        let state = WireState::default();
        let mut f = Framer::new();
        // FC 6 of set-point 7 at 0 (its reply echoes it), then FC 3 of registers 0-1.
        let write = frame(&[1, 6, 0, 0, 0, 7]);
        assert_eq!(exchange(&mut f, &write, &[&write], &state), write);
        let read = frame(&[1, 3, 0, 0, 0, 2]);
        let reply = frame(&[1, 3, 4, 0, 7, 1, 0xF4]);
        assert_eq!(exchange(&mut f, &read, &[&reply], &state), reply);
        // A late reply of an earlier cycle reads another set-point: dropped as stale.
        exchange(&mut f, &frame(&[1, 6, 0, 0, 0, 9]), &[], &state);
        let stale = frame(&[1, 3, 4, 0, 7, 1, 0xF0]);
        let current = frame(&[1, 3, 4, 0, 9, 1, 0xF4]);
        assert_eq!(
            exchange(&mut f, &read, &[&stale, &current], &state),
            current
        );
        assert_eq!(state.stale_replies(), 1);
    }

    #[test]
    fn a_broken_frame_is_passed_on_as_it_came() {
        let state = WireState::default();
        let mut f = Framer::new();
        let mut bad = fc23_reply(500, 490);
        bad[4] ^= 0xFF;
        let tail = [9u8, 9];
        let got = exchange(&mut f, &fc23(500), &[&bad, &tail], &state);
        assert_eq!(got, [bad.as_slice(), &tail].concat());
        assert_eq!(state.stale_replies(), 0);
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
