//! Running as a systemd service (`Type=notify`, see `contrib/valve-bridge.service`): readiness,
//! a status line, the watchdog and stopping, through the `sd-notify` crate.
//!
//! [`Service::ready`] is sent once the loop runs and the servers listen (so units ordered after
//! this one find the Modbus server up). With `WatchdogSec=` set, [`Service::tick`] pings the
//! watchdog at half its interval, but only while the loop makes progress: a loop thread that
//! hangs stops the pings and systemd restarts the service. Outside systemd (no `NOTIFY_SOCKET`)
//! every call does nothing. A notification that cannot be sent is logged at debug level and
//! never stops the daemon.
//!
//! Not here: logging (stderr, which the journal collects), restart policy (the unit's).

use std::time::{Duration, Instant};

use sd_notify::NotifyState;

/// The daemon's side of systemd's notification protocol.
#[derive(Debug)]
pub struct Service {
    /// Half the watchdog interval, when systemd set one for this process.
    ping_every: Option<Duration>,
    last_ping: Instant,
    samples_at_ping: u64,
    stopping: bool,
}

impl Service {
    /// Reads the watchdog interval systemd gave this process, if any.
    pub fn new() -> Service {
        Service {
            ping_every: sd_notify::watchdog_enabled().map(|d| d / 2),
            last_ping: Instant::now(),
            samples_at_ping: 0,
            stopping: false,
        }
    }

    /// Tells systemd the daemon is up, with a status line.
    pub fn ready(&self, status: &str) {
        send(&[NotifyState::Ready, NotifyState::Status(status)]);
    }

    /// Pings the watchdog when it is due and the loop has logged rows since the last ping.
    pub fn tick(&mut self, samples: u64) {
        let Some(every) = self.ping_every else {
            return;
        };
        if self.last_ping.elapsed() >= every && samples > self.samples_at_ping {
            send(&[NotifyState::Watchdog]);
            self.last_ping = Instant::now();
            self.samples_at_ping = samples;
        }
    }

    /// Tells systemd the daemon is stopping (the safe action and the log flush follow); once.
    pub fn stopping(&mut self) {
        if !self.stopping {
            self.stopping = true;
            send(&[NotifyState::Stopping, NotifyState::Status("stopping")]);
        }
    }
}

impl Default for Service {
    fn default() -> Self {
        Service::new()
    }
}

fn send(states: &[NotifyState<'_>]) {
    if let Err(e) = sd_notify::notify(states) {
        tracing::debug!("cannot notify systemd: {e}");
    }
}
