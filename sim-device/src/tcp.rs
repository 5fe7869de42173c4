//! The Modbus TCP side of sim-device: the library's [`tcp_server`] (accept errors retried,
//! connections capped, idle ones closed) answering from the register bank through the fault
//! injection.
//!
//! Each connection counts its own requests for `--disconnect-after` (the N-th request of a
//! connection closes it, unanswered); the other faults follow the device-wide numbering of
//! [`Faults`]. A request goes to the unit of its MBAP unit id ([`Banks::for_tcp`]: any id with
//! one unit); with several units, an id none has gets exception 0B (gateway target device
//! failed to respond), what a gateway answers for a device that is not on its bus. Framing and
//! the accept loop are the library's; only the faults and the unit are decided here.

use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::net::TcpListener;
use tokio_modbus::{ExceptionCode, Request};
use vb_modbus::net::{Health, Limits};
use vb_modbus::tcp_server::{self, Garble, Reply, Respond};

use crate::faults::{Action, Decision, Faults};
use crate::units::Banks;

/// One client connection of the device.
struct Connection {
    banks: Banks,
    faults: Arc<Faults>,
    /// Requests on this connection so far.
    served: u64,
    peer: SocketAddr,
}

impl Respond for Connection {
    fn respond(&mut self, unit: u8, request: &Request<'_>) -> Reply {
        self.served += 1;
        if matches!(self.faults.disconnect_after(), Some(limit) if self.served >= limit) {
            tracing::info!(
                "closing the connection from {} on its request {} (--disconnect-after)",
                self.peer,
                self.served
            );
            return Reply::Close;
        }
        let Some(bank) = self.banks.for_tcp(unit) else {
            return Reply::Answer(Err(ExceptionCode::GatewayTargetDevice), Duration::ZERO);
        };
        let Decision { action, delay } = self.faults.next();
        match action {
            Action::Drop => Reply::Silent,
            Action::Exception => Reply::Answer(Err(ExceptionCode::ServerDeviceFailure), delay),
            Action::Answer | Action::CorruptCrc => Reply::Answer(bank.handle(request), delay),
            Action::BadByteCount => Reply::Garbled(bank.handle(request), delay, Garble::ByteCount),
            Action::BrokenFrame => Reply::Garbled(bank.handle(request), delay, Garble::FrameLength),
        }
    }
}

/// Serves `banks` over Modbus TCP on `listener` within `limits`, forever.
pub(crate) async fn serve(
    listener: TcpListener,
    banks: Banks,
    faults: Arc<Faults>,
    limits: Limits,
    health: Arc<Health>,
) {
    tcp_server::serve("Modbus TCP", listener, limits, health, move |peer, _| {
        tracing::info!("client connected from {peer}");
        Connection {
            banks: banks.clone(),
            faults: Arc::clone(&faults),
            served: 0,
            peer,
        }
    })
    .await
}
