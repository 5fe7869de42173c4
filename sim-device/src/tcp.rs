//! The Modbus TCP side of sim-device: the library's [`tcp_server`] (accept errors retried,
//! connections capped, idle ones closed) answering from the register bank through the fault
//! injection.
//!
//! Each connection counts its own requests for `--disconnect-after` (the N-th request of a
//! connection closes it, unanswered); the other faults follow the device-wide numbering of
//! [`Faults`]. Framing and the accept loop are the library's; only the faults are decided here.

use std::net::SocketAddr;
use std::sync::Arc;

use tokio::net::TcpListener;
use tokio_modbus::{ExceptionCode, Request};
use valve_bridge::modbus::server::RegisterBank;
use valve_bridge::modbus::tcp_server::{self, Reply, Respond};
use valve_bridge::net::{Health, Limits};

use crate::faults::{Action, Decision, Faults};

/// One client connection of the device.
struct Connection {
    bank: Arc<RegisterBank>,
    faults: Arc<Faults>,
    /// Requests on this connection so far.
    served: u64,
    peer: SocketAddr,
}

impl Respond for Connection {
    fn respond(&mut self, request: &Request<'_>) -> Reply {
        self.served += 1;
        if matches!(self.faults.disconnect_after(), Some(limit) if self.served >= limit) {
            tracing::info!(
                "closing the connection from {} on its request {} (--disconnect-after)",
                self.peer,
                self.served
            );
            return Reply::Close;
        }
        let Decision { action, delay } = self.faults.next();
        match action {
            Action::Drop => Reply::Silent,
            Action::Exception => Reply::Answer(Err(ExceptionCode::ServerDeviceFailure), delay),
            Action::Answer | Action::CorruptCrc => Reply::Answer(self.bank.handle(request), delay),
        }
    }
}

/// Serves `bank` over Modbus TCP on `listener` within `limits`, forever.
pub async fn serve(
    listener: TcpListener,
    bank: Arc<RegisterBank>,
    faults: Arc<Faults>,
    limits: Limits,
    health: Arc<Health>,
) {
    tcp_server::serve("Modbus TCP", listener, limits, health, move |peer| {
        tracing::info!("client connected from {peer}");
        Connection {
            bank: Arc::clone(&bank),
            faults: Arc::clone(&faults),
            served: 0,
            peer,
        }
    })
    .await
}
