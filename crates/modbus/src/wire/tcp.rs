//! [`TcpWire`]: a Modbus TCP stream that passes on only the reply to the latest request.
//!
//! tokio-modbus numbers its requests (MBAP transaction id) and refuses a reply with another
//! number as a header mismatch, but it does not skip it: after a timeout, the late reply would be
//! taken (and refused) as the answer to the next request, and every later one too (its issue
//! #324). The wire reads the transaction id of each request it writes and drops whole frames
//! whose id is not that one, so the connection is kept after a timeout and the next cycle gets
//! its own reply. A reply to the latest request whose PDU does not fit it (a read's byte count
//! off, another function code) is not passed on either but recorded ([`Malformed`]): the
//! stream is still in step, so the client fails the cycle and keeps the connection, where
//! tokio-modbus would leave its framed stream in an error state. It also records that the
//! device closed the connection: tokio-modbus reports a closed stream with whatever `errno` the
//! thread last set (`Operation now in progress (os error 115)` after a reconnect).

use std::io;
use std::pin::Pin;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::task::{Context, Poll};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpStream;

use super::{Malformed, WireState};

/// MBAP header: transaction id, protocol id, length (of what follows it: unit id and PDU).
const MBAP_HEADER: usize = 6;
/// Largest MBAP length field: unit id and a 253-byte PDU.
const MAX_MBAP_LENGTH: usize = 254;
/// Bytes of a request kept after its MBAP header: unit id, function code, address, quantity.
const REQUEST_HEAD: usize = 6;

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
    /// The latest request's first bytes after its header (see [`REQUEST_HEAD`]).
    request: [u8; REQUEST_HEAD],
    request_len: usize,
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
            request: [0; REQUEST_HEAD],
            request_len: 0,
            rx: Vec::with_capacity(512),
            ready: Vec::with_capacity(512),
        }
    }

    /// Follows the request bytes written: the transaction id of each request's header, and
    /// the first bytes of its PDU.
    fn track_written(&mut self, mut bytes: &[u8]) {
        while !bytes.is_empty() {
            if self.out_rest > 0 {
                let n = self.out_rest.min(bytes.len());
                let keep = n.min(REQUEST_HEAD - self.request_len);
                self.request[self.request_len..self.request_len + keep]
                    .copy_from_slice(&bytes[..keep]);
                self.request_len += keep;
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
                self.request_len = 0;
                self.state.set_malformed(None);
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
                let request = &self.request[..self.request_len];
                match malformed(request, &self.rx[MBAP_HEADER + 1..total]) {
                    None => self.ready.extend_from_slice(&self.rx[..total]),
                    Some(m) => {
                        tracing::debug!("{m}: {:02X?}", &self.rx[..total]);
                        self.state.set_malformed(Some(m));
                    }
                }
            } else {
                self.state.count_stale();
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

/// Why the reply PDU `pdu` does not fit the request whose first bytes after the MBAP header are
/// `request` (unit id, function code, address, quantity), if it does not.
fn malformed(request: &[u8], pdu: &[u8]) -> Option<Malformed> {
    let (&asked, &fc) = (request.get(1)?, pdu.first()?);
    let bytes = pdu.len();
    if fc == asked | 0x80 {
        return (bytes != 2).then_some(Malformed::Length { fc: asked, bytes });
    }
    if fc != asked {
        return Some(Malformed::Function { asked, got: fc });
    }
    match fc {
        3 | 4 | 23 => {
            let count = u16::from_be_bytes([*request.get(4)?, *request.get(5)?]);
            let want = 2 * usize::from(count);
            let got = *pdu.get(1)?;
            (usize::from(got) != want || bytes != 2 + want).then_some(Malformed::ByteCount {
                fc,
                got,
                want,
            })
        }
        6 | 16 => (bytes != 5).then_some(Malformed::Length { fc, bytes }),
        _ => None,
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

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[test]
    fn replies_that_do_not_fit_the_request_are_told() {
        // Read 2 holding registers from 1 (unit 1).
        let read = [1, 3, 0, 1, 0, 2];
        assert_eq!(malformed(&read, &[3, 4, 0, 1, 0, 2]), None);
        assert_eq!(
            malformed(&read, &[3, 5, 0, 1, 0, 2, 0]),
            Some(Malformed::ByteCount {
                fc: 3,
                got: 5,
                want: 4
            })
        );
        // A byte count that fits the request but not the frame.
        assert!(malformed(&read, &[3, 4, 0, 1, 0]).is_some());
        assert_eq!(
            malformed(&read, &[4, 4, 0, 1, 0, 2]),
            Some(Malformed::Function { asked: 3, got: 4 })
        );
        assert_eq!(malformed(&read, &[0x83, 2]), None);
        assert_eq!(
            malformed(&read, &[0x83, 2, 0]),
            Some(Malformed::Length { fc: 3, bytes: 3 })
        );
        // FC 23 reads 3 registers; FC 16 echoes address and count.
        assert_eq!(
            malformed(&[1, 23, 0, 0, 0, 3], &[23, 6, 0, 0, 0, 0, 0, 0]),
            None
        );
        assert_eq!(malformed(&[1, 16, 0, 0, 0, 1], &[16, 0, 0, 0, 1]), None);
        assert!(malformed(&[1, 16, 0, 0, 0, 1], &[16, 0, 0, 0, 1, 0]).is_some());
        assert_eq!(
            Malformed::ByteCount {
                fc: 23,
                got: 5,
                want: 4
            }
            .to_string(),
            "malformed reply to FC 23: byte count 5, 4 expected"
        );
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
