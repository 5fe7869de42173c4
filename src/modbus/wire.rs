//! The byte streams under the valve client's tokio-modbus context: what tokio-modbus does not do
//! on its own, so that a link survives a late, lost or broken reply.
//!
//! - [`TcpWire`] passes on only the reply to the latest request. tokio-modbus numbers its
//!   requests (MBAP transaction id) and refuses a reply with another number as a header
//!   mismatch, but it does not skip it: after a timeout, the late reply would be taken (and
//!   refused) as the answer to the next request, and every later one too (its issue #324). The
//!   wire reads the transaction id of each request it writes and drops whole frames whose id
//!   is not that one, so the connection is kept after a timeout and the next cycle gets its
//!   own reply. It also records that the device closed the connection: tokio-modbus reports a
//!   closed stream with whatever `errno` the thread last set (`Operation now in progress (os
//!   error 115)` after a reconnect).
//! - [`RtuWire`] records what arrives after each request (so a reply with a bad CRC, which
//!   tokio-modbus silently discards and then waits on, is reported as a CRC error, see
//!   [`rtu_frame_fault`]), and empties the port's input before each request: a late reply or a
//!   broken frame cannot be taken for the next answer (RTU frames carry no transaction id).
//!
//! Both share a [`WireState`] with the client. Written by hand because they are thin
//! pass-throughs with a side look at the bytes; no crate offers that for tokio's I/O traits.
//! Not here: timeouts, reconnection, fault kinds (the client decides).

use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;
use tokio_serial::{SerialPort, SerialStream};

use super::plan::Transaction;

const MODBUS_CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// MBAP header: transaction id, protocol id, length (of what follows it: unit id and PDU).
const MBAP_HEADER: usize = 6;
/// Largest MBAP length field: unit id and a 253-byte PDU.
const MAX_MBAP_LENGTH: usize = 254;
/// Most bytes of one RTU reply recorded (a whole frame and some).
const RX_LOG_LIMIT: usize = 512;

/// What the wire saw, shared with the client.
#[derive(Debug, Default)]
pub struct WireState {
    rx: Mutex<Vec<u8>>,
    closed: AtomicBool,
    stale: AtomicU64,
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

    /// Replies dropped because they answered an earlier request (TCP).
    pub fn stale_replies(&self) -> u64 {
        self.stale.load(Ordering::Relaxed)
    }

    fn log_rx(&self, bytes: &[u8]) {
        let mut log = self.rx.lock().unwrap_or_else(|p| p.into_inner());
        let room = RX_LOG_LIMIT.saturating_sub(log.len());
        log.extend_from_slice(&bytes[..bytes.len().min(room)]);
    }
}

/// A Modbus TCP stream that passes on only replies to the latest request (module docs).
#[derive(Debug)]
pub struct TcpWire {
    inner: TcpStream,
    state: Arc<WireState>,
    /// Header bytes of the request being written, until all six are seen.
    out_header: Vec<u8>,
    /// Bytes of the request being written that follow its header.
    out_rest: usize,
    /// Transaction id of the latest request.
    expected: Option<u16>,
    /// Received bytes not yet framed.
    rx: Vec<u8>,
    /// Bytes of accepted replies not yet handed to tokio-modbus.
    ready: Vec<u8>,
}

impl TcpWire {
    /// Wraps a connected stream; `state` is shared with the client.
    pub fn new(inner: TcpStream, state: Arc<WireState>) -> Self {
        TcpWire {
            inner,
            state,
            out_header: Vec::with_capacity(MBAP_HEADER),
            out_rest: 0,
            expected: None,
            rx: Vec::with_capacity(512),
            ready: Vec::with_capacity(512),
        }
    }

    /// Follows the request bytes written: the transaction id of each request's header.
    fn track_written(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            if self.out_rest > 0 {
                let n = self.out_rest.min(bytes.len());
                self.out_rest -= n;
                bytes = &bytes[n..];
                continue;
            }
            let n = (MBAP_HEADER - self.out_header.len()).min(bytes.len());
            self.out_header.extend_from_slice(&bytes[..n]);
            bytes = &bytes[n..];
            if self.out_header.len() == MBAP_HEADER {
                let h = &self.out_header;
                self.expected = Some(u16::from_be_bytes([h[0], h[1]]));
                self.out_rest = usize::from(u16::from_be_bytes([h[4], h[5]]));
                self.out_header.clear();
                // What was not handed over yet belongs to an earlier exchange.
                self.ready.clear();
            }
        }
    }

    /// Moves the complete frames of `rx` that answer the latest request to `ready`, drops the
    /// others.
    fn frame(&mut self) -> io::Result<()> {
        while self.rx.len() > MBAP_HEADER {
            let length = usize::from(u16::from_be_bytes([self.rx[4], self.rx[5]]));
            if !(2..=MAX_MBAP_LENGTH).contains(&length) {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    format!("not a Modbus TCP reply: MBAP length {length}"),
                ));
            }
            let total = MBAP_HEADER + length;
            if self.rx.len() < total {
                break;
            }
            let tid = u16::from_be_bytes([self.rx[0], self.rx[1]]);
            if Some(tid) == self.expected {
                self.ready.extend_from_slice(&self.rx[..total]);
            } else {
                self.state.stale.fetch_add(1, Ordering::Relaxed);
                tracing::debug!(
                    "dropped a late reply (transaction {tid}, waiting for {:?})",
                    self.expected
                );
            }
            self.rx.drain(..total);
        }
        Ok(())
    }
}

impl AsyncRead for TcpWire {
    fn poll_read(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let this = self.get_mut();
        loop {
            if !this.ready.is_empty() {
                let n = this.ready.len().min(buf.remaining());
                buf.put_slice(&this.ready[..n]);
                this.ready.drain(..n);
                return Poll::Ready(Ok(()));
            }
            let mut chunk = [0u8; 512];
            let mut read = ReadBuf::new(&mut chunk);
            match Pin::new(&mut this.inner).poll_read(cx, &mut read) {
                Poll::Pending => return Poll::Pending,
                Poll::Ready(Err(e)) => return Poll::Ready(Err(e)),
                Poll::Ready(Ok(())) if read.filled().is_empty() => {
                    this.state.closed.store(true, Ordering::Relaxed);
                    return Poll::Ready(Ok(()));
                }
                Poll::Ready(Ok(())) => {
                    this.rx.extend_from_slice(read.filled());
                    this.frame()?;
                }
            }
        }
    }
}

impl AsyncWrite for TcpWire {
    fn poll_write(
        self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let this = self.get_mut();
        let written = Pin::new(&mut this.inner).poll_write(cx, buf);
        if let Poll::Ready(Ok(n)) = written {
            this.track_written(&buf[..n]);
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

/// A serial stream that empties its input before each request and records each reply
/// (module docs).
#[derive(Debug)]
pub struct RtuWire {
    inner: SerialStream,
    state: Arc<WireState>,
    /// True between the first byte of a request written and the first byte of a reply read.
    requesting: bool,
}

impl RtuWire {
    /// Wraps an open port; `state` is shared with the client.
    pub fn new(inner: SerialStream, state: Arc<WireState>) -> Self {
        RtuWire {
            inner,
            state,
            requesting: false,
        }
    }
}

impl AsyncRead for RtuWire {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let result = Pin::new(&mut self.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = result {
            let new = &buf.filled()[before..];
            if !new.is_empty() {
                self.requesting = false;
                self.state.log_rx(new);
            }
        }
        result
    }
}

impl AsyncWrite for RtuWire {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        if !self.requesting {
            // A new request: what is still in the input (a late reply, the rest of a broken
            // frame) is not its answer.
            self.inner.clear(tokio_serial::ClearBuffer::Input)?;
            self.state
                .rx
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clear();
            self.requesting = true;
        }
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

/// The fault of a complete but unusable RTU reply `rx` to `t`, or None if the reply is
/// incomplete.
pub fn rtu_frame_fault(rx: &[u8], t: &Transaction) -> Option<String> {
    let fc = t.function_code();
    let len = match rx.get(1) {
        Some(&f) if f == fc | 0x80 => 5,
        _ => t.rtu_response_bytes(),
    };
    let frame = rx.get(..len)?;
    let (body, crc) = frame.split_at(len - 2);
    let got = u16::from_le_bytes([crc[0], crc[1]]);
    let want = MODBUS_CRC.checksum(body);
    Some(if got != want {
        format!("CRC error in reply to FC {fc}: received 0x{got:04X}, computed 0x{want:04X} over {body:02X?}")
    } else {
        format!("unexpected reply to FC {fc}: {frame:02X?}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::map::Table;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[test]
    fn crc_errors_are_told_from_incomplete_replies() {
        let t = Transaction::Read {
            table: Table::Holding,
            address: 1,
            count: 1,
        };
        let mut frame = vec![1u8, 3, 2, 0x01, 0xF4];
        let crc = MODBUS_CRC.checksum(&frame).to_le_bytes();
        frame.extend_from_slice(&crc);
        assert!(rtu_frame_fault(&frame[..5], &t).is_none(), "incomplete");
        let ok = rtu_frame_fault(&frame, &t).unwrap();
        assert!(ok.starts_with("unexpected reply"), "{ok}");
        frame[6] ^= 0xFF;
        let bad = rtu_frame_fault(&frame, &t).unwrap();
        assert!(bad.starts_with("CRC error in reply to FC 3"), "{bad}");
        // An exception reply is 5 bytes.
        let mut exc = vec![1u8, 0x83, 2];
        exc.extend_from_slice(&(MODBUS_CRC.checksum(&exc) ^ 1).to_le_bytes());
        assert!(rtu_frame_fault(&exc, &t).unwrap().starts_with("CRC error"));
    }

    /// An MBAP frame: transaction `tid`, unit 1, `pdu`.
    fn mbap(tid: u16, pdu: &[u8]) -> Vec<u8> {
        let mut f = tid.to_be_bytes().to_vec();
        f.extend_from_slice(&[0, 0]);
        f.extend_from_slice(&(pdu.len() as u16 + 1).to_be_bytes());
        f.push(1);
        f.extend_from_slice(pdu);
        f
    }

    #[tokio::test]
    async fn tcp_wire_passes_only_the_reply_to_the_latest_request() {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let state = Arc::new(WireState::default());
        let client = TcpStream::connect(addr).await.unwrap();
        let (mut device, _) = listener.accept().await.unwrap();
        let mut wire = TcpWire::new(client, Arc::clone(&state));
        // Request 7 is written in two pieces; the device then answers request 6 (late), a
        // second copy split across writes, and request 7.
        let request = mbap(7, &[3, 0, 1, 0, 1]);
        wire.write_all(&request[..3]).await.unwrap();
        wire.write_all(&request[3..]).await.unwrap();
        let mut got = vec![0u8; request.len()];
        device.read_exact(&mut got).await.unwrap();
        assert_eq!(got, request);
        let late = mbap(6, &[3, 2, 0, 9]);
        let answer = mbap(7, &[3, 2, 1, 0xF4]);
        device.write_all(&late).await.unwrap();
        device.write_all(&late[..4]).await.unwrap();
        device.flush().await.unwrap();
        device.write_all(&late[4..]).await.unwrap();
        device.write_all(&answer).await.unwrap();
        let mut read = vec![0u8; answer.len()];
        wire.read_exact(&mut read).await.unwrap();
        assert_eq!(read, answer);
        assert_eq!(state.stale_replies(), 2);
        assert!(!state.closed());
        // The device closes: the stream ends and the wire says so.
        drop(device);
        let mut rest = Vec::new();
        wire.read_to_end(&mut rest).await.unwrap();
        assert!(rest.is_empty() && state.closed());
    }
}
