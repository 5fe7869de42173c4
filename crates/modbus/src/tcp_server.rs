//! A Modbus TCP server that stays up: the daemon's server for a process controller and
//! sim-device's TCP side.
//!
//! Connections come from [`crate::net::serve`] (accept errors retried, connections capped).
//! Each connection reads MBAP frames (transaction id, protocol 0, length, unit id, PDU),
//! decodes the request with tokio-modbus, asks its [`Respond`] what to do with it and the unit
//! id it is for, and writes the reply with the request's transaction and unit id. A connection
//! that sends no request for [`Limits::idle_timeout`] (no first one for
//! [`net::FIRST_REQUEST_TIMEOUT`]) is closed and counted in [`Health`]; at the connection limit
//! one makes room for a new one as [`net::serve`] chooses (the responder may raise its
//! connection's standing through the [`Activity`] it is given).
//!
//! Written here rather than with tokio-modbus's `server::tcp::Server` because that one stops
//! serving at the first `accept()` error (and cancels every open connection when it returns),
//! and has no connection limit or idle timeout; its request decoding is still used.
//!
//! Not here: what a request does (the [`Respond`] implementation: a register bank, fault
//! injection).

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio_modbus::bytes::Bytes;
use tokio_modbus::{ExceptionCode, Request, Response};

use super::server::response_pdu;
use crate::net::{self, Activity, Health, Limits};

/// What a server does with one request.
#[derive(Debug, Clone, PartialEq)]
pub enum Reply {
    /// Answer (a response or an exception) after `delay`.
    Answer(Result<Response, ExceptionCode>, Duration),
    /// Answer garbled as `Garble` says (a device's fault, for tests of clients).
    Garbled(Result<Response, ExceptionCode>, Duration, Garble),
    /// Send nothing; keep reading requests.
    Silent,
    /// Send nothing and close the connection.
    Close,
}

/// How a [`Reply::Garbled`] answer is spoiled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Garble {
    /// One data byte too many, counted in the PDU's byte count (a read) or not (a write's
    /// echo): the frame is whole, its PDU does not fit the request.
    ByteCount,
    /// An MBAP length of 0: the stream is out of step.
    FrameLength,
}

/// Spoils the PDU `body` of a reply as `garble` says (only [`Garble::ByteCount`] touches it).
pub fn garble_pdu(body: &mut Vec<u8>, garble: Garble) {
    if garble == Garble::ByteCount {
        if matches!(body.first(), Some(3 | 4 | 23)) {
            body[1] = body[1].wrapping_add(1);
        }
        body.push(0);
    }
}

/// Answers the requests of one connection, in order.
pub trait Respond: Send + 'static {
    /// The reply to `request`, sent to unit id `unit`.
    fn respond(&mut self, unit: u8, request: &Request<'_>) -> Reply;
}

/// Serves Modbus TCP on `listener` forever (drop the task to stop); `what` names it in the log,
/// `connected(peer, activity)` makes the responder of each new connection.
pub async fn serve<R, C>(
    what: &'static str,
    listener: TcpListener,
    limits: Limits,
    health: Arc<Health>,
    connected: C,
) where
    R: Respond,
    C: Fn(SocketAddr, &Activity) -> R,
{
    let conn_health = Arc::clone(&health);
    let conn_limits = limits.clone();
    net::serve(
        what,
        listener,
        limits,
        health,
        move |stream, peer, activity| {
            let responder = connected(peer, &activity);
            connection(
                what,
                (stream, peer, activity),
                responder,
                conn_limits.clone(),
                Arc::clone(&conn_health),
            )
        },
    )
    .await
}

/// Serves one connection until the client closes it, it idles or the responder closes it.
async fn connection<R: Respond>(
    what: &'static str,
    (mut stream, peer, activity): (TcpStream, SocketAddr, Activity),
    mut responder: R,
    limits: Limits,
    health: Arc<Health>,
) -> io::Result<()> {
    let mut header = [0u8; 7];
    loop {
        let idle = limits.request_timeout(&activity);
        match tokio::time::timeout(idle, stream.read_exact(&mut header)).await {
            Err(_) => {
                health.idle_closed();
                tracing::info!(
                    "{what}: closing the connection from {peer}: no {}request for {:.1} s",
                    if activity.requests() == 0 {
                        "first "
                    } else {
                        ""
                    },
                    idle.as_secs_f64()
                );
                return Ok(());
            }
            Ok(Err(e)) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(()),
            Ok(read) => read?,
        };
        let protocol = u16::from_be_bytes([header[2], header[3]]);
        let length = usize::from(u16::from_be_bytes([header[4], header[5]]));
        if protocol != 0 || !(2..=254).contains(&length) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("not a Modbus TCP request: protocol {protocol}, length {length}"),
            ));
        }
        let mut pdu = vec![0u8; length - 1];
        stream.read_exact(&mut pdu).await?;
        activity.request();
        let fc = pdu[0];
        let reply = match Request::try_from(Bytes::from(pdu)) {
            Ok(request) => responder.respond(header[6], &request),
            Err(_) => Reply::Answer(Err(ExceptionCode::IllegalFunction), Duration::ZERO),
        };
        let (result, delay, garble) = match reply {
            Reply::Answer(result, delay) => (result, delay, None),
            Reply::Garbled(result, delay, garble) => (result, delay, Some(garble)),
            Reply::Silent => continue,
            Reply::Close => return Ok(()),
        };
        if !delay.is_zero() {
            tokio::time::sleep(delay).await;
        }
        let mut body = response_pdu(fc, &result);
        if let Some(g) = garble {
            garble_pdu(&mut body, g);
        }
        let length = match garble {
            Some(Garble::FrameLength) => 0,
            _ => body.len() as u16 + 1,
        };
        let mut frame = Vec::with_capacity(7 + body.len());
        frame.extend_from_slice(&header[..4]);
        frame.extend_from_slice(&length.to_be_bytes());
        frame.push(header[6]);
        frame.extend_from_slice(&body);
        stream.write_all(&frame).await?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::RegisterMap;
    use crate::server::{OutOfRange, RegisterBank};
    use tokio_modbus::client::{Reader, Writer};

    struct Bank(Arc<RegisterBank>);

    impl Respond for Bank {
        fn respond(&mut self, _unit: u8, request: &Request<'_>) -> Reply {
            Reply::Answer(self.0.handle(request), Duration::ZERO)
        }
    }

    #[tokio::test]
    async fn answers_tokio_modbus_and_closes_idle_connections() {
        let listener = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let addr = listener.local_addr().unwrap();
        let bank = Arc::new(RegisterBank::new(
            RegisterMap::default(),
            0.0,
            100.0,
            OutOfRange::Exception,
        ));
        let health = Arc::new(Health::default());
        let limits = Limits {
            max_connections: 4,
            idle_timeout: Duration::from_millis(200),
            controllers: Arc::default(),
        };
        let served = Arc::clone(&bank);
        let server = tokio::spawn(serve(
            "test",
            listener,
            limits,
            Arc::clone(&health),
            move |_, _| Bank(Arc::clone(&served)),
        ));
        let mut ctx = tokio_modbus::client::tcp::connect(addr).await.unwrap();
        ctx.write_multiple_registers(0, &[420])
            .await
            .unwrap()
            .unwrap();
        assert_eq!(bank.setpoint_pct(), 42.0);
        assert_eq!(
            ctx.read_holding_registers(0, 1).await.unwrap(),
            Ok(vec![420])
        );
        assert_eq!(
            ctx.read_holding_registers(9, 1).await.unwrap(),
            Err(ExceptionCode::IllegalDataAddress)
        );
        // Silent for longer than the idle timeout: the server closes the connection.
        tokio::time::sleep(Duration::from_millis(400)).await;
        assert!(ctx.read_holding_registers(0, 1).await.is_err());
        let v = health.view();
        assert_eq!((v.accepted, v.idle_closed, v.open), (1, 1, 0));
        server.abort();
    }
}
