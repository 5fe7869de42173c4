//! The Modbus valve client: one cycle = write O_P, read V_P (and status), with a deadline.
//!
//! [`ModbusValve`] owns at most one tokio-modbus client context, over TCP or RTU: never more
//! than one connection per device. Each [`ModbusValve::transact`] runs the cycle's [`Plan`]
//! under one deadline (`timeout_ms`, by default 80 % of the loop period), because
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
//! device that accepts connections and then never answers is not flooded with new ones). A
//! cycle never waits for a reconnect beyond its own deadline, so the loop keeps its rhythm.
//!
//! Faults come back as [`Fault`]: `timeout` (no complete reply in time), `error` (exception,
//! CRC or framing error, unusable value, set-point refused by the device) and `disconnected`
//! (link down or reconnecting), each saying what happened in words.
//!
//! Not here: retries within a cycle (the next cycle is the retry), fault counting (the loop
//! counts what it receives), and any notion of the loop's clock.

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::time::Instant;
use tokio_modbus::client::{rtu, tcp, Context, Reader, Writer};
use tokio_modbus::Slave;

use super::budget::{Budget, BudgetError};
use super::exception;
pub use super::link::Link;
use super::map::{MapViolation, RegisterMap, Table};
use super::plan::{Plan, Transaction};
use super::wire::{rtu_frame_fault, RtuWire, TcpWire, WireState};

/// Wait after a failed connection attempt; doubles with each further one, up to [`MAX_BACKOFF`].
pub const FIRST_BACKOFF: Duration = Duration::from_millis(100);
/// Longest wait between connection attempts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(2);
/// A TCP connection on which the device has answered nothing for this long is reopened.
pub const SILENT_LINK: Duration = Duration::from_secs(3);
/// How long the first connection at start-up may take.
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(3);
/// Default deadline of a cycle, as a share of the loop period.
pub const DEFAULT_TIMEOUT_SHARE: f64 = 0.8;

/// Why a cycle gave no V_P.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Fault {
    /// No complete reply in time.
    #[error("timeout: {0}")]
    Timeout(String),
    /// An exception, CRC or framing error, or an unusable value.
    #[error("error: {0}")]
    Error(String),
    /// The link is down (and being reopened).
    #[error("disconnected: {0}")]
    Disconnected(String),
}

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
    TcpConnect { address: String, reason: String },
    /// The serial port cannot be opened.
    #[error("cannot open serial port {port}: {reason} (check [valve.modbus-rtu] port)")]
    Serial { port: String, reason: String },
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

/// A Modbus positioner driven one cycle at a time (see the module documentation).
pub struct ModbusValve {
    link: Link,
    tcp_addr: Option<SocketAddr>,
    map: RegisterMap,
    plan: Plan,
    timeout: Duration,
    budget: Option<Budget>,
    ctx: Option<Context>,
    wire: Arc<WireState>,
    /// The current connection has answered at least once.
    answered: bool,
    /// When the device last answered (or the connection opened).
    last_answer: Instant,
    /// Why the link is down, for the cycles that find it so.
    down_because: String,
    /// Late replies (TCP) counted so far on this connection.
    late_seen: u64,
    next_attempt: Instant,
    backoff: Duration,
    reconnects: u64,
    attempts: u64,
    sent_pct: Option<f64>,
}

impl std::fmt::Debug for ModbusValve {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // tokio-modbus's Context has no Debug; show whether one is open instead.
        f.debug_struct("ModbusValve")
            .field("link", &self.link)
            .field("map", &self.map)
            .field("timeout", &self.timeout)
            .field("connected", &self.ctx.is_some())
            .field("reconnects", &self.reconnects)
            .finish()
    }
}

impl ModbusValve {
    /// Checks the settings and the map for a loop of period `period_s`, and works out the
    /// cycle's transactions and (RTU) its bus budget; connects nothing yet.
    pub fn new(link: Link, map: RegisterMap, period_s: f64) -> Result<ModbusValve, OpenError> {
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
        let plan = Plan::new(&map);
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
        Ok(ModbusValve {
            link,
            tcp_addr,
            map,
            plan,
            timeout,
            budget,
            ctx: None,
            wire: Arc::default(),
            answered: false,
            last_answer: Instant::now(),
            down_because: "not connected yet".into(),
            late_seen: 0,
            next_attempt: Instant::now(),
            backoff: FIRST_BACKOFF,
            reconnects: 0,
            attempts: 0,
            sent_pct: None,
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
        match self.attempt(deadline).await {
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

    /// How many times a cycle (re)opened the link (not counting a connection made at start).
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// Connection attempts so far (the first one included).
    pub fn attempts(&self) -> u64 {
        self.attempts
    }

    /// True while a context is open.
    pub fn is_connected(&self) -> bool {
        self.ctx.is_some()
    }

    /// The set-point the device acknowledged in the last cycle, as it received it, %.
    pub fn sent_pct(&self) -> Option<f64> {
        self.sent_pct
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        self.link.describe()
    }

    /// One connection attempt within `deadline`; on failure, the reason, and the next attempt
    /// waits the backoff (which doubles).
    async fn attempt(&mut self, deadline: Instant) -> Result<(), String> {
        self.ctx = None;
        self.attempts += 1;
        let allowed = deadline.saturating_duration_since(Instant::now());
        let wire = Arc::new(WireState::default());
        let connecting = async {
            match &self.link {
                Link::Tcp(l) => {
                    let addr = self
                        .tcp_addr
                        .ok_or_else(|| io::Error::other("no resolved address"))?;
                    let stream = tokio::net::TcpStream::connect(addr).await?;
                    // One small request per cycle: latency matters more than throughput.
                    stream.set_nodelay(true)?;
                    let wire = TcpWire::new(stream, Arc::clone(&wire));
                    Ok::<_, io::Error>(tcp::attach_slave(wire, Slave(l.unit_id)))
                }
                Link::Rtu(l) => {
                    let port = super::serial::open(l).map_err(io::Error::from)?;
                    let wire = RtuWire::new(port, Arc::clone(&wire));
                    Ok(rtu::attach_slave(wire, Slave(l.slave_id)))
                }
            }
        };
        match tokio::time::timeout_at(deadline, connecting).await {
            Ok(Ok(ctx)) => {
                self.ctx = Some(ctx);
                self.wire = wire;
                self.late_seen = 0;
                self.answered = false;
                self.last_answer = Instant::now();
                Ok(())
            }
            failed => {
                self.next_attempt = Instant::now() + self.backoff;
                self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
                Err(match failed {
                    Ok(Err(e)) => e.to_string(),
                    _ => format!("no connection within {} ms", allowed.as_millis()),
                })
            }
        }
    }

    /// Drops the link because `why`. It is reopened at once if it had answered (a device that
    /// restarted), otherwise after the backoff (a device that takes connections but never
    /// answers on them).
    fn drop_link(&mut self, why: String) {
        self.ctx = None;
        if self.answered {
            self.next_attempt = Instant::now();
            self.backoff = FIRST_BACKOFF;
        } else {
            self.next_attempt = Instant::now() + self.backoff;
            self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
        }
        self.down_because = why;
    }

    /// Reopens the link if the backoff allows, within `deadline`.
    async fn reconnect(&mut self, deadline: Instant) -> Result<(), Fault> {
        let now = Instant::now();
        if now < self.next_attempt {
            return Err(Fault::Disconnected(format!(
                "{}: {}; next connection attempt in {} ms",
                self.describe(),
                self.down_because,
                (self.next_attempt - now).as_millis()
            )));
        }
        match self.attempt(deadline).await {
            Ok(()) => {
                self.reconnects += 1;
                tracing::info!("{}: connected", self.describe());
                Ok(())
            }
            Err(why) => {
                self.down_because = format!("cannot connect: {why}");
                Err(Fault::Disconnected(format!(
                    "{}: {}; next attempt in {} ms",
                    self.describe(),
                    self.down_because,
                    (self.next_attempt - Instant::now()).as_millis()
                )))
            }
        }
    }

    /// Writes `op_pct` as the set-point and returns the position (and status).
    pub async fn transact(&mut self, op_pct: f64) -> Result<Reading, Fault> {
        self.sent_pct = None;
        let setpoint = self
            .map
            .encode_setpoint(op_pct)
            .map_err(|e| Fault::Error(e.to_string()))?;
        // What the device makes of the words: the O_P after scaling and rounding.
        let sent = self
            .map
            .setpoint
            .decode("set-point", &setpoint, self.map.word_order)
            .map_err(|e| Fault::Error(e.to_string()))?;
        let deadline = Instant::now() + self.timeout;
        if self.ctx.is_none() {
            self.reconnect(deadline).await?;
        }
        let mut replies: Vec<Vec<u16>> = Vec::with_capacity(self.plan.transactions.len());
        for i in 0..self.plan.transactions.len() {
            let t = self.plan.transactions[i];
            replies.push(self.exchange(t, &setpoint, deadline).await?);
            if !matches!(t, Transaction::Read { .. }) {
                self.sent_pct = Some(sent);
            }
        }
        let reading = self.decode(&replies, op_pct, sent);
        if reading.is_err() {
            self.sent_pct = None;
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
        if self.ctx.is_none() {
            self.reconnect(deadline).await?;
        }
        let t = Transaction::Read {
            table,
            address,
            count,
        };
        self.exchange(t, &[], deadline).await
    }

    /// Writes `pct` into the set-point register once (`valve-bridge probe --write-test`) and
    /// returns the value the device received, %.
    pub async fn write_setpoint(&mut self, pct: f64) -> Result<f64, Fault> {
        let words = self
            .map
            .encode_setpoint(pct)
            .map_err(|e| Fault::Error(e.to_string()))?;
        let deadline = Instant::now() + self.timeout;
        if self.ctx.is_none() {
            self.reconnect(deadline).await?;
        }
        let t = Transaction::Write {
            address: self.map.setpoint.address,
            count: words.len() as u16,
        };
        self.exchange(t, &words, deadline).await?;
        self.map
            .setpoint
            .decode("set-point", &words, self.map.word_order)
            .map_err(|e| Fault::Error(e.to_string()))
    }

    /// Runs one transaction until `deadline`; decides from its outcome whether the link stays.
    async fn exchange(
        &mut self,
        t: Transaction,
        setpoint: &[u16],
        deadline: Instant,
    ) -> Result<Vec<u16>, Fault> {
        let Some(ctx) = self.ctx.as_mut() else {
            return Err(Fault::Disconnected(format!(
                "{}: {}",
                self.describe(),
                self.down_because
            )));
        };
        let fc = t.function_code();
        match tokio::time::timeout_at(deadline, call(ctx, t, setpoint)).await {
            Ok(Ok(Ok(words))) => {
                self.heard();
                Ok(words)
            }
            Ok(Ok(Err(code))) => {
                self.heard();
                Err(Fault::Error(format!(
                    "device answered FC {fc} with {}",
                    exception::explain(code)
                )))
            }
            Err(_) => {
                let mut fault = self.classify_silence(t);
                // Late replies show the device is there, only slow: no reason to reopen.
                // Once seen, every timeout says so (the summary quotes the last one, which
                // may fall between two late replies).
                let late = self.wire.stale_replies();
                if late > self.late_seen {
                    self.late_seen = late;
                    self.last_answer = Instant::now();
                }
                if late > 0 {
                    if let Fault::Timeout(m) = &mut fault {
                        m.push_str(&format!(
                            " (the device does answer, later: {late} replies came after their \
                             deadline; a longer timeout_ms may fit the loop period)"
                        ));
                    }
                }
                let silent = Instant::now() - self.last_answer;
                if matches!(self.link, Link::Tcp(_)) && silent >= SILENT_LINK {
                    let why = format!(
                        "no answer for {:.1} s on an open connection, reopening it",
                        silent.as_secs_f64()
                    );
                    tracing::warn!("{}: {why}", self.describe());
                    self.drop_link(why);
                }
                Err(fault)
            }
            Ok(Err(tokio_modbus::Error::Transport(e))) => {
                let (fault, broken) = self.classify_transport(t, e);
                if broken {
                    let why = match &fault {
                        Fault::Disconnected(m) | Fault::Error(m) | Fault::Timeout(m) => m.clone(),
                    };
                    self.drop_link(why);
                }
                Err(fault)
            }
            Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                // With the wire's transaction filter a mismatch means the stream is out of
                // step: on TCP it is reopened. RTU has nothing to resynchronise.
                if matches!(self.link, Link::Tcp(_)) {
                    self.drop_link(format!("FC {fc}: {e}"));
                }
                Err(Fault::Error(format!("FC {fc}: {e}")))
            }
        }
    }

    /// The device answered: the connection is proven and the backoff starts afresh.
    fn heard(&mut self) {
        self.answered = true;
        self.last_answer = Instant::now();
        self.backoff = FIRST_BACKOFF;
    }

    fn decode(&self, replies: &[Vec<u16>], op_pct: f64, sent: f64) -> Result<Reading, Fault> {
        for (t, words) in self.plan.transactions.iter().zip(replies) {
            let want = match *t {
                Transaction::Write { .. } => 0,
                Transaction::Read { count, .. } => count,
                Transaction::ReadWrite { read_count, .. } => read_count,
            };
            if words.len() != usize::from(want) {
                return Err(Fault::Error(format!(
                    "FC {}: {} registers in reply, {want} asked",
                    t.function_code(),
                    words.len()
                )));
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
            .map_err(|e| Fault::Error(e.to_string()))?;
        let status = self.plan.status.and_then(|s| at(s).first().copied());
        if let (Some(word), Some(reg)) = (status, self.map.status) {
            if word & reg.error_mask() != 0 {
                return Err(Fault::Error(format!(
                    "device flags the set-point as refused (status 0x{word:04X}, bit {}) after O_P {op_pct:.2} %",
                    reg.setpoint_error_bit
                )));
            }
        }
        Ok(Reading {
            vp_pct,
            status,
            sent_pct: sent,
        })
    }

    /// What a missed deadline means: silence, a partial reply, or a reply with a bad CRC.
    fn classify_silence(&self, t: Transaction) -> Fault {
        let ms = self.timeout.as_millis();
        let fc = t.function_code();
        if !matches!(self.link, Link::Rtu(_)) {
            return Fault::Timeout(format!("no reply to FC {fc} within {ms} ms"));
        }
        let rx = self.wire.received();
        if rx.is_empty() {
            return Fault::Timeout(format!("no reply to FC {fc} within {ms} ms"));
        }
        match rtu_frame_fault(&rx, &t) {
            Some(message) => Fault::Error(message),
            None => Fault::Timeout(format!(
                "reply to FC {fc} incomplete within {ms} ms: {} of {} bytes",
                rx.len(),
                t.rtu_response_bytes()
            )),
        }
    }

    /// The fault of a transport error, and whether it broke the link. A bad RTU frame leaves
    /// the line usable (the input is emptied before the next request); anything else on RTU,
    /// and any transport error on TCP, breaks it.
    fn classify_transport(&self, t: Transaction, e: io::Error) -> (Fault, bool) {
        let fc = t.function_code();
        let rtu = matches!(self.link, Link::Rtu(_));
        if e.kind() == io::ErrorKind::InvalidData {
            if rtu {
                if let Some(message) = rtu_frame_fault(&self.wire.received(), &t) {
                    return (Fault::Error(message), false);
                }
            }
            return (Fault::Error(format!("FC {fc}: unusable reply: {e}")), !rtu);
        }
        // tokio-modbus reports a stream that ended with the thread's last errno, which says
        // nothing about it (`Operation now in progress`): the wire knows what happened.
        let what = if self.wire.closed() {
            "the device closed the connection".to_string()
        } else {
            match e.kind() {
                io::ErrorKind::ConnectionReset => format!("the device reset the connection ({e})"),
                io::ErrorKind::BrokenPipe => format!("the connection is broken ({e})"),
                _ => e.to_string(),
            }
        };
        (
            Fault::Disconnected(format!("{}: FC {fc}: {what}", self.describe())),
            true,
        )
    }
}

/// Runs one transaction; a write returns no words.
async fn call(
    ctx: &mut Context,
    t: Transaction,
    setpoint: &[u16],
) -> tokio_modbus::Result<Vec<u16>> {
    match t {
        Transaction::Write { address, .. } => Ok(ctx
            .write_multiple_registers(address, setpoint)
            .await?
            .map(|()| Vec::new())),
        Transaction::Read {
            table: Table::Holding,
            address,
            count,
        } => ctx.read_holding_registers(address, count).await,
        Transaction::Read {
            table: Table::Input,
            address,
            count,
        } => ctx.read_input_registers(address, count).await,
        Transaction::ReadWrite {
            read_address,
            read_count,
            write_address,
            ..
        } => {
            ctx.read_write_multiple_registers(read_address, read_count, write_address, setpoint)
                .await
        }
    }
}

#[cfg(test)]
mod tests;
