//! The network thread (`vb-net`): the process controller's Modbus server ([`crate::serve::hil`]) and
//! the HTTP server of the metrics and the live page ([`crate::serve::http`]), on a current-thread
//! runtime of their own.
//!
//! [`Listeners`] binds the sockets at start-up (before the valve is opened, so a taken port stops
//! the start first); [`Net`] serves them until stopped, each as a [`vb_modbus::net`] server that
//! survives accept errors and caps its connections; their [`Health`] goes into the summary and
//! the metrics. Not here: what is served.

pub mod exporter;
pub mod hil;
pub(crate) mod http;
pub(crate) mod page;

use std::net::SocketAddr;
use std::sync::Arc;
use std::thread::JoinHandle;

use crate::config::Config;
use crate::error::DaemonError;
use crate::runtime::control::current_thread_runtime;
use crate::runtime::source::Source;
use crate::serve::exporter::LoopMetrics;
use crate::serve::page::board::Board;
use http::Site;
use vb_modbus::blocks::Blocks;
use vb_modbus::net::{Health, Limits};

/// One bound listening socket, what it serves, its limits and its health.
struct Served<T> {
    listener: std::net::TcpListener,
    addr: SocketAddr,
    limits: Limits,
    health: Arc<Health>,
    what: T,
}

/// The listening sockets of a daemon, bound, with what each serves.
pub(crate) struct Listeners {
    modbus: Option<Served<Arc<Blocks>>>,
    exporter: Option<Served<(LoopMetrics, Arc<Board>)>>,
}

impl Listeners {
    /// Binds the Modbus server (when `sources`, the valves' in order, serve banks: one block
    /// each) and the HTTP server of the metrics and the live page (when there are `metrics`
    /// and a `board`).
    pub(crate) fn bind(
        config: &Config,
        sources: &[Source],
        (metrics, board): (Option<&LoopMetrics>, Option<&Arc<Board>>),
    ) -> Result<Listeners, DaemonError> {
        let banks: Vec<_> = sources
            .iter()
            .filter_map(Source::served_bank)
            .cloned()
            .collect();
        let served = config.controller_server().filter(|_| !banks.is_empty());
        let modbus = match served {
            Some(cfg) => {
                let (listener, addr) = bind("[source.modbus-server] listen", cfg.listen.0)?;
                Some(Served {
                    listener,
                    addr,
                    limits: cfg.limits(),
                    health: Arc::default(),
                    what: Arc::new(Blocks::new(banks, cfg.block_size)),
                })
            }
            None => None,
        };
        let exporter = match (&config.metrics, metrics, board) {
            (Some(cfg), Some(m), Some(board)) => {
                let (listener, addr) = bind("[metrics] listen", cfg.listen.0)?;
                Some(Served {
                    listener,
                    addr,
                    limits: Limits {
                        max_connections: cfg.max_connections,
                        idle_timeout: http::HEAD_TIMEOUT,
                        controllers: Arc::default(),
                    },
                    health: Arc::default(),
                    what: (m.clone(), Arc::clone(board)),
                })
            }
            _ => None,
        };
        Ok(Listeners { modbus, exporter })
    }

    /// What is served, by name (`modbus-server`, `metrics`), with the bound addresses.
    pub(crate) fn endpoints(&self) -> Vec<(&'static str, SocketAddr)> {
        let modbus = self.modbus.as_ref().map(|m| ("modbus-server", m.addr));
        let metrics = self.exporter.as_ref().map(|m| ("metrics", m.addr));
        modbus.into_iter().chain(metrics).collect()
    }

    /// The health of each server, by the same names.
    pub(crate) fn health(&self) -> Vec<(&'static str, Arc<Health>)> {
        let modbus = (self.modbus.as_ref()).map(|m| ("modbus-server", Arc::clone(&m.health)));
        let metrics = (self.exporter.as_ref()).map(|m| ("metrics", Arc::clone(&m.health)));
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
             nor the metrics endpoint and live page has any authentication"
        );
    }
    Ok((listener, bound))
}

/// The network thread (`vb-net`): the process controller's Modbus server and the HTTP server,
/// on a current-thread runtime of their own. It ends when [`Net`] is stopped or dropped.
#[derive(Debug)]
pub(crate) struct Net {
    stop: tokio::sync::oneshot::Sender<()>,
    handle: JoinHandle<()>,
}

impl Net {
    /// Starts serving `listeners` on a thread of its own; None when there is nothing to serve.
    pub(crate) fn start(listeners: Listeners) -> Result<Option<Net>, DaemonError> {
        let servers = listeners.health();
        let Listeners { modbus, exporter } = listeners;
        if modbus.is_none() && exporter.is_none() {
            return Ok(None);
        }
        let rt = current_thread_runtime("network runtime")?;
        let tokio_listener = |l: std::net::TcpListener| {
            // Registered with the network runtime's reactor, which drives it.
            let _in_runtime = rt.enter();
            tokio::net::TcpListener::from_std(l).map_err(|source| DaemonError::Thread {
                what: "network listener",
                source,
            })
        };
        let modbus = match modbus {
            Some(m) => Some((tokio_listener(m.listener)?, m.limits, m.health, m.what)),
            None => None,
        };
        let exporter = match exporter {
            Some(m) => Some((tokio_listener(m.listener)?, m.limits, m.health, m.what)),
            None => None,
        };
        let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
        let serve = async move {
            let modbus = async {
                if let Some((listener, limits, health, bank)) = modbus {
                    hil::serve(listener, bank, limits, health).await;
                }
            };
            let metrics = async {
                if let Some((listener, limits, health, (metrics, board))) = exporter {
                    let site = Site::new(metrics, servers, board);
                    http::serve(listener, site, limits, health).await;
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
    pub(crate) fn stop(self) -> Result<(), DaemonError> {
        // An error only means the thread has already ended.
        let _ = self.stop.send(());
        self.handle
            .join()
            .map_err(|_| DaemonError::Panicked("network"))
    }
}
