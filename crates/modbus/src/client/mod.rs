//! The Modbus valve client: one cycle = write O_P, read V_P (and status), with a deadline.
//!
//! [`ModbusValve`] drives one device over at most one tokio-modbus client context, over TCP or
//! RTU: never more than one connection per device. Valves on one serial bus share a single
//! link ([`ModbusValve::sharing`]: one open port, each valve addressing its own slave id, one
//! transaction after the other since the loop drives them in turn). Each
//! [`ModbusValve::transact`] runs the cycle's [`Plan`] under one deadline (`timeout_ms`, by
//! default 80 % of the loop period, on a shared bus a share of it set by the caller), because
//! tokio-modbus's async client has no timeout of its own.
//!
//! A late or lost reply costs its own cycle only. The link is kept after a timeout, a CRC error
//! or an exception while the transport is healthy: on TCP the wire under the context drops any
//! reply that does not carry the latest request's transaction id, on RTU it empties the input
//! before each request ([`super::wire`]). The link is dropped when the transport breaks (the
//! device closed or reset the connection, the serial port failed) and, on TCP, when the device
//! has answered nothing for [`SILENT_LINK`] on an open connection. It is then reopened on a
//! later cycle: at once after a connection that had answered, otherwise after a backoff that
//! starts at [`FIRST_BACKOFF`] and doubles up to [`MAX_BACKOFF`] with each further failure (a
//! device that accepts connections and then never answers is not flooded with new ones); and
//! never sooner than the rate of dropped links allows: past two drops in about 5 s the wait
//! grows with their rate up to [`MAX_BACKOFF`], so a device that closes each connection after
//! one answer gets about one connection a second, not one every other cycle. A
//! cycle never waits for a reconnect beyond its own deadline, so the loop keeps its rhythm.
//!
//! Faults come back as [`Fault`]: `timeout` (no complete reply in time), `error` (exception,
//! CRC or framing error, unusable value, set-point refused by the device) and `disconnected`
//! (link down or reconnecting), each saying what happened in words.
//!
//! Not here: retries within a cycle (the next cycle is the retry), fault counting (the loop
//! counts what it receives), and any notion of the loop's clock.

mod connection;
mod fault;

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::Mutex;
use tokio::time::Instant;

use super::budget::{Budget, BudgetError, DEFAULT_TIMEOUT_SHARE};
pub use super::link::Link;
use super::map::{MapViolation, RegisterMap, Table};
use super::plan::{Plan, Transaction, MAX_JOINED_SPAN};
use connection::Connection;
pub use fault::{
    BrokenStream, ConnectError, Disconnected, Down, Fault, IoFailure, ReplyError, StreamEnd,
    Timeout, Unlinked,
};

/// Wait after a failed connection attempt; doubles with each further one, up to [`MAX_BACKOFF`].
pub const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// Longest wait between connection attempts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(2);
/// A TCP connection on which the device has answered nothing for this long is reopened.
pub const SILENT_LINK: Duration = Duration::from_secs(3);
/// How long the first connection at start-up may take.
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(3);

/// A valve that cannot be used at start-up.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// A link setting is out of range.
    #[error("{section}.{key}: {message}")]
    Setting {
        section: &'static str,
        key: &'static str,
        message: String,
    },
    /// The register map breaks a rule.
    #[error("valve.registers.{0}")]
    Map(MapViolation),
    /// The TCP address does not resolve.
    #[error("valve.modbus-tcp.address: {address:?} is not a reachable host:port ({reason})")]
    Address { address: String, reason: String },
    /// The TCP device did not accept a connection.
    #[error("cannot connect to Modbus TCP {address}: {reason} (check [valve.modbus-tcp] address and that the device is on)")]
    TcpConnect {
        address: String,
        reason: ConnectError,
    },
    /// The serial port cannot be opened.
    #[error("cannot open serial port {port}: {reason} (check [valve.modbus-rtu] port)")]
    Serial { port: String, reason: ConnectError },
    /// The serial line cannot carry the loop rate.
    #[error(transparent)]
    Budget(#[from] BudgetError),
}

/// One cycle's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reading {
    /// Valve position V_P, %.
    pub vp_pct: f64,
    /// The status word, when the map has a status register.
    pub status: Option<u16>,
    /// The set-point as the device received it: O_P after the register's scaling and rounding, %.
    pub sent_pct: f64,
}

/// One cycle, answered or not: what the device received and what it answered. A fault after
/// an acknowledged write keeps the set-point the device received.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    /// Valve position V_P, %, or why none was read.
    pub vp_pct: Result<f64, Fault>,
    /// The set-point as the device received it, % (None when no write was acknowledged).
    pub sent_pct: Option<f64>,
    /// The status word, when the map has a status register and the reply was read.
    pub status: Option<u16>,
}

/// What a Modbus link went through, for the summary and the metrics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Times a cycle (re)opened the link (not counting a connection made at start).
    pub reconnects: u64,
    /// Connection attempts, the first one included.
    pub attempts: u64,
    /// Replies discarded because they answered an earlier request (late replies).
    pub late_replies: u64,
    /// RTU: bytes received that formed no frame (line noise, broken frames), dropped.
    pub noise_bytes: u64,
    /// RTU: frames no request was waiting for (a reply later than `late_reply_ms`).
    pub unexpected_replies: u64,
    /// RTU: how long an unanswered request's reply is waited for now, ms.
    pub late_reply_ms: Option<u128>,
}

/// A Modbus positioner driven one cycle at a time (see the module documentation).
pub struct ModbusValve {
    /// This valve's link: its unit, its name in the log.
    link: Link,
    map: RegisterMap,
    plan: Plan,
    timeout: Duration,
    budget: Option<Budget>,
    /// The link, this valve's alone or its bus's. Locked for a transaction; never contended,
    /// since the valves of a bus take turns on one thread.
    conn: Arc<Mutex<Connection>>,
    /// The words of each of the cycle's replies, as tokio-modbus returns them (one `Vec` per
    /// read, which it allocates); the list itself is kept from cycle to cycle.
    replies: Vec<Vec<u16>>,
}

impl std::fmt::Debug for ModbusValve {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // tokio-modbus's Context has no Debug; show whether one is open instead.
        f.debug_struct("ModbusValve")
            .field("link", &self.link)
            .field("map", &self.map)
            .field("timeout", &self.timeout)
            .field("connected", &self.is_connected())
            .field("reconnects", &self.reconnects())
            .finish()
    }
}

impl ModbusValve {
    /// Checks the settings and the map for a loop of period `period_s`, and works out the
    /// cycle's transactions and (RTU) its bus budget; connects nothing yet.
    pub fn new(link: Link, map: RegisterMap, period_s: f64) -> Result<ModbusValve, OpenError> {
        ModbusValve::build(link, map, period_s, None)
    }

    /// Another valve on this valve's serial bus: the same link (opened once, reopened for
    /// both), `link`'s slave id and deadline, its own map. `link` must name the same port with
    /// the same line settings (the configuration checks it).
    pub fn sharing(
        &self,
        link: Link,
        map: RegisterMap,
        period_s: f64,
    ) -> Result<ModbusValve, OpenError> {
        ModbusValve::build(link, map, period_s, Some(Arc::clone(&self.conn)))
    }

    fn build(
        link: Link,
        map: RegisterMap,
        period_s: f64,
        conn: Option<Arc<Mutex<Connection>>>,
    ) -> Result<ModbusValve, OpenError> {
        let section = link.section();
        let violation = match &link {
            Link::Tcp(l) => l.violation(),
            Link::Rtu(l) => l.violation(),
        };
        if let Some((key, message)) = violation {
            return Err(OpenError::Setting {
                section,
                key,
                message,
            });
        }
        map.validate().map_err(OpenError::Map)?;
        let timeout = Duration::from_secs_f64(match link.timeout_ms() {
            Some(ms) => ms / 1000.0,
            None => DEFAULT_TIMEOUT_SHARE * period_s,
        });
        let plan = match &link {
            Link::Tcp(_) => Plan::new(&map),
            Link::Rtu(_) => Plan::rtu(&map),
        };
        if matches!(link, Link::Rtu(_)) && !plan.reads_back(&map) {
            tracing::warn!(
                "{}: the set-point register is not within {MAX_JOINED_SPAN} registers of the \
                 position in the holding table, so a reply cannot be checked against the \
                 set-point just written: a reply later than timeout_ms to an earlier request \
                 with the same function code could be taken for the current one (keep \
                 timeout_ms above the device's slowest answer)",
                link.describe()
            );
        }
        let late_reply = match &link {
            Link::Rtu(l) => l.late_reply(timeout),
            Link::Tcp(_) => Duration::ZERO,
        };
        let (tcp_addr, budget) = match &link {
            Link::Tcp(l) => {
                let addr = l.resolve().map_err(|reason| OpenError::Address {
                    address: l.address.clone(),
                    reason,
                })?;
                (Some(addr), None)
            }
            Link::Rtu(l) => (None, Some(Budget::rtu(l, &plan, period_s))),
        };
        let conn = match conn {
            Some(conn) => {
                if let Ok(mut c) = conn.try_lock() {
                    c.wait_late_replies(late_reply);
                }
                conn
            }
            None => Arc::new(Mutex::new(Connection::new(
                link.clone(),
                tcp_addr,
                late_reply,
            ))),
        };
        Ok(ModbusValve {
            link,
            map,
            replies: Vec::with_capacity(plan.transactions.len()),
            plan,
            timeout,
            budget,
            conn,
        })
    }

    /// Refuses (RTU) a serial line that cannot carry the loop rate; logs the budget once.
    pub fn check_budget(&mut self) -> Result<(), OpenError> {
        if let Some(b) = self.budget.take() {
            self.budget = Some(b.check()?);
        }
        Ok(())
    }

    /// Connects (or opens the serial port) now, allowing [`OPEN_TIMEOUT`]. On failure the
    /// valve stays usable: its cycles report `disconnected` and retry with backoff.
    pub async fn connect_now(&mut self) -> Result<(), OpenError> {
        let deadline = Instant::now() + OPEN_TIMEOUT;
        let attempt = self.conn.lock().await.attempt(deadline).await;
        match attempt {
            Ok(()) => Ok(()),
            Err(reason) => Err(match &self.link {
                Link::Tcp(l) => OpenError::TcpConnect {
                    address: l.address.clone(),
                    reason,
                },
                Link::Rtu(l) => OpenError::Serial {
                    port: l.port.clone(),
                    reason,
                },
            }),
        }
    }

    /// [`ModbusValve::new`], the budget check and a first connection that must succeed.
    pub async fn open(
        link: Link,
        map: RegisterMap,
        period_s: f64,
    ) -> Result<ModbusValve, OpenError> {
        let mut valve = ModbusValve::new(link, map, period_s)?;
        valve.check_budget()?;
        valve.connect_now().await?;
        Ok(valve)
    }

    /// The deadline of one cycle.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Sets the deadline of one cycle (or one probe request).
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// The register map.
    pub fn map(&self) -> &RegisterMap {
        &self.map
    }

    /// The bus budget (RTU only).
    pub fn budget(&self) -> Option<&Budget> {
        self.budget.as_ref()
    }

    /// How many times a cycle (re)opened the link (not counting a connection made at start;
    /// on a shared bus, the bus's).
    pub fn reconnects(&self) -> u64 {
        self.conn.try_lock().map_or(0, |c| c.reconnects)
    }

    /// Connection attempts so far (the first one included; on a shared bus, the bus's).
    pub fn attempts(&self) -> u64 {
        self.conn.try_lock().map_or(0, |c| c.attempts)
    }

    /// Reconnects, attempts, late replies and (RTU) line noise so far (on a shared bus, the
    /// bus's).
    pub fn link_stats(&self) -> LinkStats {
        self.conn
            .try_lock()
            .map_or(LinkStats::default(), |c| LinkStats {
                reconnects: c.reconnects,
                attempts: c.attempts,
                late_replies: c.late_replies(),
                noise_bytes: c.noise_bytes(),
                unexpected_replies: c.unexpected_replies(),
                late_reply_ms: matches!(self.link, Link::Rtu(_))
                    .then(|| c.late_reply().as_millis()),
            })
    }

    /// True while a context is open.
    pub fn is_connected(&self) -> bool {
        self.conn.try_lock().is_ok_and(|c| c.is_connected())
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        self.link.describe()
    }

    /// Writes `op_pct` as the set-point and returns the position (and status).
    pub async fn transact(&mut self, op_pct: f64) -> Result<Reading, Fault> {
        self.exchange_cycle(op_pct, &mut None).await
    }

    /// One loop cycle: writes `op_pct` as the set-point and reads the position (and status),
    /// keeping what the device received even when the read fails.
    pub async fn cycle(&mut self, op_pct: f64) -> Cycle {
        let mut sent_pct = None;
        match self.exchange_cycle(op_pct, &mut sent_pct).await {
            Ok(r) => Cycle {
                vp_pct: Ok(r.vp_pct),
                sent_pct,
                status: r.status,
            },
            Err(fault) => Cycle {
                vp_pct: Err(fault),
                sent_pct,
                status: None,
            },
        }
    }

    /// The transactions of one cycle; `sent_pct` is set once a write is acknowledged and
    /// cleared again when the reply turns out unusable.
    async fn exchange_cycle(
        &mut self,
        op_pct: f64,
        sent_pct: &mut Option<f64>,
    ) -> Result<Reading, Fault> {
        let setpoint = self
            .map
            .encode_setpoint(op_pct)
            .map_err(|e| Fault::Error(e.into()))?;
        // What the device makes of the words: the O_P after scaling and rounding.
        let sent = self
            .map
            .setpoint
            .decode("set-point", &setpoint, self.map.word_order)
            .map_err(|e| Fault::Error(e.into()))?;
        let deadline = Instant::now() + self.timeout;
        let mut conn = self.conn.lock().await;
        if !conn.is_connected() {
            conn.reconnect(&self.link, deadline).await?;
        }
        self.replies.clear();
        for i in 0..self.plan.transactions.len() {
            let t = self.plan.transactions[i];
            let words = (conn.exchange(&self.link, self.timeout, t, &setpoint, deadline)).await?;
            self.replies.push(words);
            if !matches!(t, Transaction::Read { .. }) {
                *sent_pct = Some(sent);
            }
        }
        let reading = self.decode(&self.replies, op_pct, sent);
        if reading.is_err() {
            *sent_pct = None;
        }
        reading
    }

    /// Reads `count` registers of `table` from `address` once (`valve-bridge probe`).
    pub async fn read_registers(
        &mut self,
        table: Table,
        address: u16,
        count: u16,
    ) -> Result<Vec<u16>, Fault> {
        let deadline = Instant::now() + self.timeout;
        let mut conn = self.conn.lock().await;
        if !conn.is_connected() {
            conn.reconnect(&self.link, deadline).await?;
        }
        let t = Transaction::Read {
            table,
            address,
            count,
        };
        conn.exchange(&self.link, self.timeout, t, &[], deadline)
            .await
    }

    /// Writes `pct` into the set-point register once (`valve-bridge probe --write-test`) and
    /// returns the value the device received, %.
    pub async fn write_setpoint(&mut self, pct: f64) -> Result<f64, Fault> {
        let words = self
            .map
            .encode_setpoint(pct)
            .map_err(|e| Fault::Error(e.into()))?;
        let deadline = Instant::now() + self.timeout;
        let mut conn = self.conn.lock().await;
        if !conn.is_connected() {
            conn.reconnect(&self.link, deadline).await?;
        }
        let t = match self.plan.transactions.first() {
            Some(&single @ Transaction::WriteSingle { .. }) => single,
            _ => Transaction::Write {
                address: self.map.setpoint.address,
                count: words.len() as u16,
            },
        };
        conn.exchange(&self.link, self.timeout, t, &words, deadline)
            .await?;
        self.map
            .setpoint
            .decode("set-point", &words, self.map.word_order)
            .map_err(|e| Fault::Error(e.into()))
    }

    fn decode(&self, replies: &[Vec<u16>], op_pct: f64, sent: f64) -> Result<Reading, Fault> {
        for (t, words) in self.plan.transactions.iter().zip(replies) {
            let want = match *t {
                Transaction::Write { .. } | Transaction::WriteSingle { .. } => 0,
                Transaction::Read { count, .. } => count,
                Transaction::ReadWrite { read_count, .. } => read_count,
            };
            if words.len() != usize::from(want) {
                return Err(Fault::Error(ReplyError::Registers {
                    fc: t.function_code(),
                    got: words.len(),
                    want,
                }));
            }
        }
        let at = |slot: super::plan::Slot| {
            replies
                .get(slot.transaction)
                .and_then(|w| w.get(slot.offset..))
                .unwrap_or(&[])
        };
        let vp_pct = self
            .map
            .decode_position(at(self.plan.position))
            .map_err(|e| Fault::Error(e.into()))?;
        let status = self.plan.status.and_then(|s| at(s).first().copied());
        if let (Some(word), Some(reg)) = (status, self.map.status) {
            if word & reg.error_mask() != 0 {
                return Err(Fault::Error(ReplyError::Refused {
                    word,
                    bit: reg.setpoint_error_bit,
                    op_pct,
                }));
            }
        }
        Ok(Reading {
            vp_pct,
            status,
            sent_pct: sent,
        })
    }
}

#[cfg(test)]
mod tests;
