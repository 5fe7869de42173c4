//! The `modbus-server` source: a process controller drives the loop over Modbus TCP (hardware in
//! the loop).
//!
//! The daemon serves a [`RegisterBank`] with the map of `[source.modbus-server.registers]` on
//! `listen` (loopback unless configured otherwise). The controller writes O_P into the set-point
//! register and reads V_P from the position register and the loop's state from the status
//! register, whatever valve is behind (emulated, or a positioner over Modbus). A set-point outside
//! `[source] op_min_pct..op_max_pct` is refused with exception 03, an unmapped or read-only
//! address with 02. The server answers any unit id. With several valves driven by the
//! controller, each has its own bank, watchdog and status word, served side by side as
//! [`Blocks`]: the k-th such valve of the file at the map's addresses plus k × `block_size`.
//!
//! Each cycle the loop asks [`Controller::op_at`] for the last accepted set-point and hands the
//! cycle's row to [`Controller::feedback`], which publishes V_P (the last one read is kept when a
//! cycle read none) and the status bits:
//! - bit [`VALVE_FAULT_BIT`] (1): the last cycle read no V_P (timeout, error, disconnected);
//! - bit [`WATCHDOG_BIT`] (2): the watchdog has fired, the loop sends the safe O_P;
//! - bit [`HEALTH_ALARM_BIT`](vb_modbus::map::HEALTH_ALARM_BIT) (3): the live health
//!   check (`[health]`) is in alarm for the valve; set by the health thread
//!   ([`crate::monitor::health`]) at each window, not by the loop.
//!
//! Until the first write the O_P is `initial_pct`. Watchdog: when no set-point write has been
//! accepted for `watchdog_s` of loop time (counted from the start of the loop, so a controller
//! that never writes trips it too), the `[safety]` action applies: `on_stop = "hold"` keeps the
//! last O_P, `"go-to"` sends `go_to_pct`. The loop logs those cycles with the status `watchdog`,
//! and a warning is logged once when the watchdog fires and once when writes resume; the next
//! accepted write is followed at once. Refused writes do not feed the watchdog.
//!
//! The server runs on the daemon's network thread ([`serve`], a [`tcp_server`] that retries
//! accept errors, caps its connections at `max_connections` and closes a connection idle for
//! `idle_timeout_s`); the loop only touches the bank, whose lock is held for a few loads and
//! stores, so the loop never waits on the network. The controller always gets through: with
//! `controllers` configured, only their addresses may write (any other client's write gets
//! exception 01, its reads are answered), their connections are never closed for another
//! client's and a slot each is kept for them; without, anyone may write and a connection whose
//! write was accepted is a controller's from then on ([`Standing::Controller`]: never closed for
//! a reader's). Which connection gives way at the limit is [`vb_modbus::net`]'s choice.
//!
//! Not here: the choice of whom to close at the limit ([`vb_modbus::net`]), the Modbus framing
//! ([`tcp_server`]), the register map ([`RegisterBank`]).

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tokio::net::TcpListener;
use tokio_modbus::{ExceptionCode, Request};

use crate::config::{ModbusServerConfig, OnStop, SafetyConfig};
use vb_core::recording::log_format::Sample;
use vb_modbus::blocks::Blocks;
use vb_modbus::map::{VALVE_FAULT_BIT, WATCHDOG_BIT};
use vb_modbus::net::{Activity, Health, Limits, PeerLog, Standing};
use vb_modbus::server::{OutOfRange, RegisterBank};
use vb_modbus::tcp_server::{self, Reply, Respond};

/// The status bits the loop owns (the health thread owns
/// [`HEALTH_ALARM_BIT`](vb_modbus::map::HEALTH_ALARM_BIT)).
const STATUS_MASK: u16 = (1 << VALVE_FAULT_BIT) | (1 << WATCHDOG_BIT);

/// The loop's side of the `modbus-server` source: set-points in, V_P and status out, watchdog.
#[derive(Debug)]
pub struct Controller {
    /// The valve's name, in the watchdog's messages.
    valve: String,
    bank: Arc<RegisterBank>,
    watchdog_s: f64,
    /// The O_P the watchdog sends (`go-to`), or None to hold the last one.
    safe_pct: Option<f64>,
    op_pct: f64,
    writes_seen: u64,
    /// Loop time of the last accepted write (the start of the loop before the first).
    last_write_t_s: f64,
    tripped: bool,
    trips: u64,
}

impl Controller {
    /// The controller source `[source.modbus-server]` (`cfg`), `[source]`'s clamp range
    /// `(op_min_pct, op_max_pct)` and `[safety]` describe.
    pub fn new(
        cfg: &ModbusServerConfig,
        (op_min_pct, op_max_pct): (f64, f64),
        safety: &SafetyConfig,
    ) -> Controller {
        let safe_pct = match safety.on_stop {
            OnStop::Hold => None,
            OnStop::GoTo => safety.go_to_pct,
        };
        let initial = cfg.initial_pct.or(safe_pct).unwrap_or(op_min_pct);
        let bank = RegisterBank::new(cfg.registers, op_min_pct, op_max_pct, OutOfRange::Exception)
            .with_setpoint(initial);
        Controller {
            valve: crate::config::UNNAMED.to_string(),
            bank: Arc::new(bank),
            watchdog_s: cfg.watchdog_s,
            safe_pct,
            op_pct: initial,
            writes_seen: 0,
            last_write_t_s: 0.0,
            tripped: false,
            trips: 0,
        }
    }

    /// The same controller for the valve `name` (in its messages).
    pub fn named(self, name: &str) -> Controller {
        Controller {
            valve: name.to_string(),
            ..self
        }
    }

    /// The bank the server answers from.
    pub fn bank(&self) -> &Arc<RegisterBank> {
        &self.bank
    }

    /// The O_P for loop time `t_s`: the last accepted set-point, or the safe O_P while the
    /// watchdog holds. Never waits and never allocates.
    pub fn op_at(&mut self, t_s: f64) -> f64 {
        let (setpoint, writes) = self.bank.accepted();
        if writes != self.writes_seen {
            self.writes_seen = writes;
            self.last_write_t_s = t_s;
            self.op_pct = setpoint;
            if self.tripped {
                self.tripped = false;
                tracing::warn!(
                    valve = %self.valve,
                    "watchdog: set-point writes resumed at t = {t_s:.2} s, following the process \
                     controller again (O_P {setpoint:.2} %)"
                );
            }
        } else if !self.tripped && t_s - self.last_write_t_s >= self.watchdog_s {
            self.tripped = true;
            self.trips += 1;
            if let Some(safe) = self.safe_pct {
                self.op_pct = safe;
            }
            tracing::warn!(
                valve = %self.valve,
                "watchdog: no set-point from the process controller for {:.2} s at t = {t_s:.2} s, \
                 sending the safe O_P {:.2} %",
                self.watchdog_s,
                self.op_pct
            );
        }
        self.op_pct
    }

    /// True while the watchdog holds the safe O_P.
    pub fn tripped(&self) -> bool {
        self.tripped
    }

    /// How often the watchdog has fired.
    pub fn trips(&self) -> u64 {
        self.trips
    }

    /// Publishes a cycle's V_P (kept if none was read) and status bits to the controller.
    pub fn feedback(&self, row: &Sample) {
        let bits = (u16::from(row.vp_pct.is_none()) << VALVE_FAULT_BIT)
            | (u16::from(self.tripped) << WATCHDOG_BIT);
        self.bank.report(row.vp_pct, STATUS_MASK, bits);
    }
}

/// A client's connection: every request is answered from the banks at once, but a write from a
/// client that is not a configured controller (when there are some) gets exception 01.
struct Controlled {
    blocks: Arc<Blocks>,
    peer: SocketAddr,
    activity: Activity,
    /// Where its refused writes are told, when it may not write.
    refusals: Option<Arc<Mutex<PeerLog>>>,
}

impl Respond for Controlled {
    fn respond(&mut self, _unit: u8, request: &Request<'_>) -> Reply {
        let writes = matches!(
            request,
            Request::WriteSingleRegister(..)
                | Request::WriteMultipleRegisters(..)
                | Request::ReadWriteMultipleRegisters(..)
                | Request::MaskWriteRegister(..)
                | Request::WriteSingleCoil(..)
                | Request::WriteMultipleCoils(..)
        );
        if let (true, Some(told)) = (writes, &self.refusals) {
            let ip = self.peer.ip().to_canonical();
            let admitted = told
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .admit(ip, Instant::now());
            if let Some(held) = admitted {
                tracing::warn!(
                    "{SERVER}: refused a write from {}: it is not one of the configured \
                     controllers ([source.modbus-server] controllers), which alone may write; \
                     its reads are answered{held}",
                    self.peer
                );
            }
            return Reply::Answer(Err(ExceptionCode::IllegalFunction), Duration::ZERO);
        }
        let answer = self.blocks.handle(request);
        if writes && answer.is_ok() {
            // It writes set-points: a process controller, never closed for a reader.
            self.activity.raise(Standing::Controller);
        }
        Reply::Answer(answer, Duration::ZERO)
    }
}

/// The server's name in the log.
const SERVER: &str = "Modbus server for the process controller";

/// Serves `banks` over Modbus TCP on `listener`, within `limits`, forever (drop the task to stop).
/// With configured controllers (`limits.controllers`) only they may write. New connections are
/// told once a minute per host, with how many more there were.
pub async fn serve(listener: TcpListener, bank: Arc<Blocks>, limits: Limits, health: Arc<Health>) {
    let refusals = Arc::new(Mutex::new(PeerLog::default()));
    let connections = Mutex::new(PeerLog::default());
    let checked = limits.clone();
    tcp_server::serve(SERVER, listener, limits, health, move |peer, activity| {
        let may_write = checked.controllers.is_empty() || checked.is_controller(peer.ip());
        let mut told = connections.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(held) = told.admit(peer.ip().to_canonical(), Instant::now()) {
            let who = if may_write {
                "process controller"
            } else {
                "reader (not a configured controller)"
            };
            tracing::info!("{who} connected from {peer}{held}");
        }
        Controlled {
            blocks: Arc::clone(&bank),
            peer,
            activity: activity.clone(),
            refusals: (!may_write).then(|| Arc::clone(&refusals)),
        }
    })
    .await
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use std::borrow::Cow;
    use std::path::Path;
    use tokio_modbus::ExceptionCode;
    use vb_core::recording::log_format::Status;

    fn controller(toml: &str) -> Controller {
        let cfg = Config::from_toml(
            &format!(
                "[source]\nkind = \"modbus-server\"\nop_min_pct = 10.0\nop_max_pct = 90.0\n{toml}"
            ),
            Path::new("t.toml"),
        )
        .unwrap();
        let server = cfg.source.server().unwrap();
        Controller::new(server, cfg.source.op_range(), &cfg.safety)
    }

    fn write(c: &Controller, per_mille: u16) -> Result<(), ExceptionCode> {
        c.bank()
            .handle(&Request::WriteSingleRegister(0, per_mille))
            .map(|_| ())
    }

    fn row(vp: Option<f64>) -> Sample {
        Sample {
            t_s: 0.0,
            op_pct: Some(50.0),
            vp_pct: vp,
            status: Status::Ok,
            lateness_us: None,
            latency_us: None,
            op_sent_pct: None,
            op_controller_pct: None,
            utc: std::time::SystemTime::UNIX_EPOCH,
        }
    }

    fn read(c: &Controller) -> Vec<u16> {
        match c.bank().handle(&Request::ReadHoldingRegisters(0, 3)) {
            Ok(tokio_modbus::Response::ReadHoldingRegisters(w)) => w,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn follows_writes_and_refuses_out_of_range() {
        let mut c = controller("");
        assert_eq!(c.op_at(0.0), 10.0, "op_min_pct before the first write");
        assert_eq!(write(&c, 950), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(write(&c, 50), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(
            c.bank()
                .handle(&Request::WriteMultipleRegisters(7, Cow::Owned(vec![1]))),
            Err(ExceptionCode::IllegalDataAddress)
        );
        assert_eq!(c.op_at(0.01), 10.0);
        write(&c, 425).unwrap();
        assert_eq!(c.op_at(0.02), 42.5);
        c.feedback(&row(Some(40.1)));
        assert_eq!(read(&c), vec![425, 401, 0]);
        c.feedback(&row(None));
        assert_eq!(read(&c), vec![425, 401, 1 << VALVE_FAULT_BIT], "V_P kept");
    }

    #[test]
    fn watchdog_holds_then_follows_again() {
        let mut c = controller("[source.modbus-server]\nwatchdog_s = 0.5\n");
        write(&c, 300).unwrap();
        assert_eq!(c.op_at(1.0), 30.0);
        assert_eq!(c.op_at(1.49), 30.0);
        assert!(!c.tripped());
        assert_eq!(c.op_at(1.5), 30.0, "hold keeps the last O_P");
        assert!(c.tripped());
        c.feedback(&row(Some(29.0)));
        assert_eq!(read(&c)[2], 1 << WATCHDOG_BIT);
        assert_eq!(c.op_at(3.0), 30.0);
        assert_eq!(c.trips(), 1, "fires once per silence");
        write(&c, 600).unwrap();
        assert_eq!(c.op_at(3.01), 60.0);
        assert!(!c.tripped());
        c.feedback(&row(Some(31.0)));
        assert_eq!(read(&c)[2], 0);
    }

    #[test]
    fn go_to_safety_sets_the_initial_and_watchdog_o_p() {
        let safety = "[safety]\non_stop = \"go-to\"\ngo_to_pct = 5.0\n";
        let mut c = controller(&format!(
            "[source.modbus-server]\nwatchdog_s = 1.0\n{safety}"
        ));
        assert_eq!(c.op_at(0.0), 5.0, "go_to_pct before the first write");
        assert_eq!(read(&c)[0], 50, "the set-point register shows it");
        write(&c, 700).unwrap();
        assert_eq!(c.op_at(0.5), 70.0);
        assert_eq!(c.op_at(1.5), 5.0);
        assert!(c.tripped());
        let mut c = controller(&format!(
            "[source.modbus-server]\ninitial_pct = 20.0\nwatchdog_s = 1.0\n{safety}"
        ));
        assert_eq!(c.op_at(0.0), 20.0);
        assert_eq!(
            c.op_at(1.0),
            5.0,
            "a controller that never writes trips it too"
        );
        assert_eq!(c.trips(), 1);
    }
}
