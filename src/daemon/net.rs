//! The network thread (`vb-net`): the process controller's Modbus server ([`super::hil`]) and
//! the Prometheus endpoint ([`super::exporter`]), on a current-thread runtime of their own.
//!
//! [`Listeners`] binds the sockets at start-up (before the valve is opened, so a taken port stops
//! the start first); [`Net`] serves them until stopped. Not here: what is served.

use std::net::SocketAddr;
use std::sync::Arc;
use std::thread::JoinHandle;

use super::config::Config;
use super::control::current_thread_runtime;
use super::exporter::{self, LoopMetrics};
use super::hil;
use super::source::Source;
use super::DaemonError;
use crate::modbus::server::RegisterBank;

/// The listening sockets of a daemon, bound, with what each serves.
pub(super) struct Listeners {
    modbus: Option<(std::net::TcpListener, SocketAddr, Arc<RegisterBank>)>,
    exporter: Option<(std::net::TcpListener, SocketAddr, prometheus::Registry)>,
}

impl Listeners {
    /// Binds the Modbus server (when `source` serves a bank) and the metrics endpoint (when
    /// there are `metrics`).
    pub(super) fn bind(
        config: &Config,
        source: &Source,
        metrics: Option<&LoopMetrics>,
    ) -> Result<Listeners, DaemonError> {
        let modbus = match source.served_bank() {
            Some(bank) => {
                let key = "[source.modbus-server] listen";
                let (listener, addr) = bind(key, config.source.modbus_server.listen.0)?;
                Some((listener, addr, Arc::clone(bank)))
            }
            None => None,
        };
        let exporter = match (&config.metrics, metrics) {
            (Some(cfg), Some(m)) => {
                let (listener, addr) = bind("[metrics] listen", cfg.listen.0)?;
                Some((listener, addr, m.registry().clone()))
            }
            _ => None,
        };
        Ok(Listeners { modbus, exporter })
    }

    /// What is served, by name (`modbus-server`, `metrics`), with the bound addresses.
    pub(super) fn endpoints(&self) -> Vec<(&'static str, SocketAddr)> {
        let modbus = self.modbus.as_ref().map(|m| ("modbus-server", m.1));
        let metrics = self.exporter.as_ref().map(|m| ("metrics", m.1));
        modbus.into_iter().chain(metrics).collect()
    }
}

/// A listening socket on `addr` (named by its config `key` in errors), ready for tokio, and the
/// address it is bound to (the port chosen when the config said port 0).
fn bind(
    key: &'static str,
    addr: SocketAddr,
) -> Result<(std::net::TcpListener, SocketAddr), DaemonError> {
    let (listener, bound) = std::net::TcpListener::bind(addr)
        .and_then(|l| {
            l.set_nonblocking(true)?;
            let bound = l.local_addr()?;
            Ok((l, bound))
        })
        .map_err(|source| DaemonError::Listen { key, addr, source })?;
    if !addr.ip().is_loopback() {
        tracing::warn!(
            %addr,
            "{key} is not a loopback address: other machines can reach it, and neither Modbus \
             nor the metrics endpoint has any authentication"
        );
    }
    Ok((listener, bound))
}

/// The network thread (`vb-net`): the process controller's Modbus server and the metrics
/// endpoint, on a current-thread runtime of their own. It ends when [`Net`] is stopped or dropped.
pub(super) struct Net {
    stop: tokio::sync::oneshot::Sender<()>,
    handle: JoinHandle<()>,
}

impl Net {
    /// Starts serving `listeners` on a thread of its own; None when there is nothing to serve.
    pub(super) fn start(listeners: Listeners) -> Result<Option<Net>, DaemonError> {
        let Listeners { modbus, exporter } = listeners;
        if modbus.is_none() && exporter.is_none() {
            return Ok(None);
        }
        let rt = current_thread_runtime("network runtime")?;
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let serve = async move {
            let modbus = async {
                if let Some((listener, _, bank)) = modbus {
                    let serve = |l| hil::serve(l, bank);
                    serve_logged("Modbus server for the process controller", listener, serve).await;
                }
            };
            let metrics = async {
                if let Some((listener, _, registry)) = exporter {
                    let serve = |l| exporter::serve(l, registry);
                    serve_logged("metrics endpoint", listener, serve).await;
                }
            };
            tokio::select! {
                // Sent or dropped: either way the daemon is done.
                _ = stopped => {}
                _ = async { tokio::join!(modbus, metrics) } => {}
            }
        };
        let handle = std::thread::Builder::new()
            .name("vb-net".into())
            .spawn(move || rt.block_on(serve))
            .map_err(|source| DaemonError::Thread {
                what: "network thread",
                source,
            })?;
        Ok(Some(Net { stop, handle }))
    }

    /// Stops serving and waits for the thread.
    pub(super) fn stop(self) -> Result<(), DaemonError> {
        // An error only means the thread has already ended.
        let _ = self.stop.send(());
        self.handle
            .join()
            .map_err(|_| DaemonError::Panicked("network"))
    }
}

/// Serves `listener` with `serve` (on the network thread's runtime) and logs why it stopped.
async fn serve_logged<F, Fut>(what: &str, listener: std::net::TcpListener, serve: F)
where
    F: FnOnce(tokio::net::TcpListener) -> Fut,
    Fut: std::future::Future<Output = std::io::Result<()>>,
{
    let served = match tokio::net::TcpListener::from_std(listener) {
        Ok(l) => serve(l).await,
        Err(e) => Err(e),
    };
    if let Err(e) = served {
        tracing::error!("the {what} stopped: {e}");
    }
}
