//! The Modbus valve client: one cycle = write O_P, read V_P (and status), with a deadline.
//!
//! [`ModbusValve`] owns at most one tokio-modbus client context, over TCP or RTU. Each
//! [`ModbusValve::transact`] runs the cycle's [`Plan`] under one deadline (`timeout_ms`, by
//! default 80 % of the loop period), because tokio-modbus's async client has no timeout of its
//! own. After a timeout or a transport/framing error the context is dropped, never reused: a late
//! reply would otherwise be taken as the answer to the next request (tokio-modbus issue #324). The
//! link is reopened on a later cycle, with a backoff that starts at one timeout and doubles up to
//! [`MAX_BACKOFF`]; a cycle never waits for a reconnect beyond its own deadline, so the loop keeps
//! its rhythm. Exception replies keep the link (the device answered cleanly).
//!
//! Faults come back as [`Fault`]: `timeout` (no complete reply in time), `error` (exception,
//! CRC or framing error, unusable value, set-point refused by the device) and `disconnected`
//! (link down or reconnecting). An RTU link is tapped (a thin byte recorder around the serial
//! stream) so that a reply with a bad CRC, which tokio-modbus silently discards and then waits
//! on, is reported as the CRC error it is instead of a timeout.
//!
//! Not here: retries within a cycle (the next cycle is the retry), fault counting (the loop
//! counts what it receives), and any notion of the loop's clock.

use std::io;
use std::net::{SocketAddr, ToSocketAddrs};
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context as TaskContext, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::Instant;
use tokio_modbus::client::{rtu, tcp, Context, Reader, Writer};
use tokio_modbus::Slave;
use tokio_serial::SerialStream;

use super::budget::{Budget, BudgetError};
use super::link::{Parity, RtuLink, TcpLink};
use super::map::{MapViolation, RegisterMap, Table};
use super::plan::{Plan, Transaction};

/// Longest wait between reconnect attempts.
pub const MAX_BACKOFF: Duration = Duration::from_secs(1);
/// How long the first connection at start-up may take.
pub const OPEN_TIMEOUT: Duration = Duration::from_secs(3);
/// Default deadline of a cycle, as a share of the loop period.
pub const DEFAULT_TIMEOUT_SHARE: f64 = 0.8;

const MODBUS_CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// Where the valve is.
#[derive(Debug, Clone, PartialEq)]
pub enum Link {
    /// `[valve] kind = "modbus-tcp"`.
    Tcp(TcpLink),
    /// `[valve] kind = "modbus-rtu"`.
    Rtu(RtuLink),
}

impl Link {
    fn section(&self) -> &'static str {
        match self {
            Link::Tcp(_) => "valve.modbus-tcp",
            Link::Rtu(_) => "valve.modbus-rtu",
        }
    }

    fn timeout_ms(&self) -> Option<f64> {
        match self {
            Link::Tcp(l) => l.timeout_ms,
            Link::Rtu(l) => l.timeout_ms,
        }
    }
}

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
}

/// Bytes received on an RTU link since the current request, for classifying bad replies.
type RxLog = Arc<Mutex<Vec<u8>>>;

/// A Modbus positioner driven one cycle at a time (see the module documentation).
pub struct ModbusValve {
    link: Link,
    tcp_addr: Option<SocketAddr>,
    map: RegisterMap,
    plan: Plan,
    timeout: Duration,
    budget: Option<Budget>,
    ctx: Option<Context>,
    rx: RxLog,
    next_attempt: Instant,
    backoff: Duration,
    reconnects: u64,
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
    /// Checks the settings and the bus budget for a loop of period `period_s`, and connects.
    pub async fn open(
        link: Link,
        map: RegisterMap,
        period_s: f64,
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
        let plan = Plan::new(&map);
        let (tcp_addr, budget) = match &link {
            Link::Tcp(l) => {
                let addr = l
                    .address
                    .to_socket_addrs()
                    .map_err(|e| OpenError::Address {
                        address: l.address.clone(),
                        reason: e.to_string(),
                    })?
                    .next()
                    .ok_or_else(|| OpenError::Address {
                        address: l.address.clone(),
                        reason: "no address found".into(),
                    })?;
                (Some(addr), None)
            }
            Link::Rtu(l) => (None, Some(Budget::rtu(l, &plan, period_s).check()?)),
        };
        let mut valve = ModbusValve {
            link,
            tcp_addr,
            map,
            plan,
            timeout,
            budget,
            ctx: None,
            rx: RxLog::default(),
            next_attempt: Instant::now(),
            backoff: timeout,
            reconnects: 0,
        };
        match tokio::time::timeout(OPEN_TIMEOUT, valve.connect()).await {
            Ok(Ok(ctx)) => valve.ctx = Some(ctx),
            Ok(Err(e)) => return Err(valve.open_error(e.to_string())),
            Err(_) => {
                return Err(valve.open_error(format!(
                    "no answer within {:.1} s",
                    OPEN_TIMEOUT.as_secs_f64()
                )));
            }
        }
        Ok(valve)
    }

    fn open_error(&self, reason: String) -> OpenError {
        match &self.link {
            Link::Tcp(l) => OpenError::TcpConnect {
                address: l.address.clone(),
                reason,
            },
            Link::Rtu(l) => OpenError::Serial {
                port: l.port.clone(),
                reason,
            },
        }
    }

    /// The deadline of one cycle.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// The bus budget computed at start-up (RTU only).
    pub fn budget(&self) -> Option<&Budget> {
        self.budget.as_ref()
    }

    /// How many times the link was reopened after a fault.
    pub fn reconnects(&self) -> u64 {
        self.reconnects
    }

    /// True while a context is open.
    pub fn is_connected(&self) -> bool {
        self.ctx.is_some()
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        match &self.link {
            Link::Tcp(l) => format!("Modbus TCP {} unit {}", l.address, l.unit_id),
            Link::Rtu(l) => format!(
                "Modbus RTU {} {} baud {}{}{} slave {}",
                l.port,
                l.baud,
                l.data_bits,
                match l.parity {
                    Parity::None => 'N',
                    Parity::Even => 'E',
                    Parity::Odd => 'O',
                },
                l.stop_bits,
                l.slave_id
            ),
        }
    }

    async fn connect(&self) -> io::Result<Context> {
        match &self.link {
            Link::Tcp(l) => {
                let addr = self
                    .tcp_addr
                    .ok_or_else(|| io::Error::other("no resolved address"))?;
                tcp::connect_slave(addr, Slave(l.unit_id)).await
            }
            Link::Rtu(l) => {
                // Whatever a previous context left unread (a late reply) is discarded on opening.
                let stream = super::serial::open(l).map_err(io::Error::from)?;
                let tap = Tap {
                    inner: stream,
                    rx: Arc::clone(&self.rx),
                };
                Ok(rtu::attach_slave(tap, Slave(l.slave_id)))
            }
        }
    }

    /// Drops the context after a fault and schedules the next reconnect attempt.
    fn drop_link(&mut self) {
        self.ctx = None;
        self.next_attempt = Instant::now() + self.backoff;
    }

    /// Reopens the link if the backoff allows, within `deadline`.
    async fn reconnect(&mut self, deadline: Instant) -> Result<(), Fault> {
        let now = Instant::now();
        if now < self.next_attempt {
            return Err(Fault::Disconnected(format!(
                "{}: link down, next reconnect attempt in {} ms",
                self.describe(),
                (self.next_attempt - now).as_millis()
            )));
        }
        let result = tokio::time::timeout_at(deadline, self.connect()).await;
        match result {
            Ok(Ok(ctx)) => {
                self.ctx = Some(ctx);
                self.reconnects += 1;
                tracing::info!("{}: reconnected", self.describe());
                Ok(())
            }
            other => {
                let why = match other {
                    Ok(Err(e)) => e.to_string(),
                    _ => format!("no connection within {} ms", self.timeout.as_millis()),
                };
                self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
                self.next_attempt = Instant::now() + self.backoff;
                Err(Fault::Disconnected(format!(
                    "{}: reconnect failed: {why}; next attempt in {} ms",
                    self.describe(),
                    self.backoff.as_millis()
                )))
            }
        }
    }

    /// Writes `op_pct` as the set-point and returns the position (and status).
    pub async fn transact(&mut self, op_pct: f64) -> Result<Reading, Fault> {
        let setpoint = self
            .map
            .encode_setpoint(op_pct)
            .map_err(|e| Fault::Error(e.to_string()))?;
        let deadline = Instant::now() + self.timeout;
        if self.ctx.is_none() {
            self.reconnect(deadline).await?;
        }
        let mut replies: Vec<Vec<u16>> = Vec::with_capacity(self.plan.transactions.len());
        for i in 0..self.plan.transactions.len() {
            let t = self.plan.transactions[i];
            let Some(ctx) = self.ctx.as_mut() else {
                return Err(Fault::Disconnected("link closed".into()));
            };
            clear(&self.rx);
            let result = tokio::time::timeout_at(deadline, call(ctx, t, &setpoint)).await;
            let fault = match result {
                Ok(Ok(Ok(words))) => {
                    replies.push(words);
                    continue;
                }
                Ok(Ok(Err(code))) => {
                    return Err(Fault::Error(format!(
                        "device answered FC {} with exception {code:?}",
                        t.function_code()
                    )));
                }
                Err(_) => self.classify_silence(t),
                Ok(Err(tokio_modbus::Error::Transport(e))) => self.classify_transport(t, e),
                Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                    Fault::Error(format!("FC {}: {e}", t.function_code()))
                }
            };
            self.drop_link();
            return Err(fault);
        }
        let reading = self.decode(&replies, op_pct)?;
        self.backoff = self.timeout;
        Ok(reading)
    }

    fn decode(&self, replies: &[Vec<u16>], op_pct: f64) -> Result<Reading, Fault> {
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
                    "device flags the set-point as refused (status 0x{word:04X}, bit {}) after O_P {op_pct} %",
                    reg.setpoint_error_bit
                )));
            }
        }
        Ok(Reading { vp_pct, status })
    }

    /// What a missed deadline means: silence, a partial reply, or a reply with a bad CRC.
    fn classify_silence(&self, t: Transaction) -> Fault {
        let ms = self.timeout.as_millis();
        let fc = t.function_code();
        if !matches!(self.link, Link::Rtu(_)) {
            return Fault::Timeout(format!("no reply to FC {fc} within {ms} ms"));
        }
        let rx = snapshot(&self.rx);
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

    fn classify_transport(&self, t: Transaction, e: io::Error) -> Fault {
        let fc = t.function_code();
        if e.kind() == io::ErrorKind::InvalidData {
            if matches!(self.link, Link::Rtu(_)) {
                if let Some(message) = rtu_frame_fault(&snapshot(&self.rx), &t) {
                    return Fault::Error(message);
                }
            }
            return Fault::Error(format!("FC {fc}: unusable reply: {e}"));
        }
        Fault::Disconnected(format!("{}: FC {fc}: {e}", self.describe()))
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

/// The fault of a complete but unusable RTU reply in `rx`, or None if the reply is incomplete.
fn rtu_frame_fault(rx: &[u8], t: &Transaction) -> Option<String> {
    let fc = t.function_code();
    let len = match rx.get(1) {
        Some(&f) if f == fc | 0x80 => 5,
        _ => t.rtu_response_bytes(),
    };
    let frame = rx.get(..len)?;
    let (body, crc) = frame.split_at(len - 2);
    let got = u16::from_le_bytes([crc[0], crc[1]]);
    let want = MODBUS_CRC.checksum(body);
    Some(if got != want {
        format!("CRC error in reply to FC {fc}: received 0x{got:04X}, computed 0x{want:04X} over {:02X?}", body)
    } else {
        format!("unexpected reply to FC {fc}: {:02X?}", frame)
    })
}

fn clear(rx: &RxLog) {
    rx.lock().unwrap_or_else(|p| p.into_inner()).clear();
}

fn snapshot(rx: &RxLog) -> Vec<u8> {
    rx.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// A serial stream that records what it receives (up to one RTU frame's worth beyond the
/// largest reply) into a log shared with the valve. Written by hand because it is only a
/// pass-through with a side copy; no crate offers that for tokio's I/O traits.
#[derive(Debug)]
struct Tap {
    inner: SerialStream,
    rx: RxLog,
}

const TAP_LIMIT: usize = 512;

impl AsyncRead for Tap {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let result = Pin::new(&mut self.inner).poll_read(cx, buf);
        if let Poll::Ready(Ok(())) = result {
            let mut log = self.rx.lock().unwrap_or_else(|p| p.into_inner());
            let new = &buf.filled()[before..];
            let room = TAP_LIMIT.saturating_sub(log.len());
            log.extend_from_slice(&new[..new.len().min(room)]);
        }
        result
    }
}

impl AsyncWrite for Tap {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut TaskContext<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut TaskContext<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::modbus::map::RegisterMap;

    #[test]
    fn crc_errors_are_told_from_incomplete_replies() {
        let t = Transaction::Read {
            table: Table::Holding,
            address: 1,
            count: 1,
        };
        let mut frame = vec![1u8, 3, 2, 0x01, 0xF4];
        let crc = MODBUS_CRC.checksum(&frame).to_le_bytes();
        frame.extend_from_slice(&crc);
        assert!(rtu_frame_fault(&frame[..5], &t).is_none(), "incomplete");
        let ok = rtu_frame_fault(&frame, &t).unwrap();
        assert!(ok.starts_with("unexpected reply"), "{ok}");
        frame[6] ^= 0xFF;
        let bad = rtu_frame_fault(&frame, &t).unwrap();
        assert!(bad.starts_with("CRC error in reply to FC 3"), "{bad}");
        // An exception reply is 5 bytes.
        let mut exc = vec![1u8, 0x83, 2];
        exc.extend_from_slice(&(MODBUS_CRC.checksum(&exc) ^ 1).to_le_bytes());
        assert!(rtu_frame_fault(&exc, &t).unwrap().starts_with("CRC error"));
    }

    #[tokio::test]
    async fn unreachable_devices_give_one_line_errors() {
        let rtu = RtuLink {
            baud: 115200,
            ..RtuLink::new("/dev/ttyUSB-missing-7")
        };
        let map = RegisterMap {
            fc23: true,
            ..RegisterMap::default()
        };
        let err = ModbusValve::open(Link::Rtu(rtu), map, 0.01)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("cannot open serial port /dev/ttyUSB-missing-7: "),
            "{err}"
        );
        assert!(
            err.ends_with("(check [valve.modbus-rtu] port)") && !err.contains('\n'),
            "{err}"
        );

        // A port nobody listens on (bound then released).
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let tcp = TcpLink {
            address: format!("127.0.0.1:{port}"),
            unit_id: 1,
            timeout_ms: None,
        };
        let err = ModbusValve::open(Link::Tcp(tcp), RegisterMap::default(), 0.01)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with(&format!("cannot connect to Modbus TCP 127.0.0.1:{port}: ")),
            "{err}"
        );

        let tcp = TcpLink {
            address: "no-port-here".into(),
            unit_id: 1,
            timeout_ms: None,
        };
        let err = ModbusValve::open(Link::Tcp(tcp), RegisterMap::default(), 0.01)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("valve.modbus-tcp.address: \"no-port-here\""),
            "{err}"
        );
    }

    #[tokio::test]
    async fn settings_and_budget_are_checked_before_connecting() {
        let rtu = RtuLink::new("/dev/ttyUSB-missing-7"); // 19200 baud
        let err = ModbusValve::open(Link::Rtu(rtu.clone()), RegisterMap::default(), 0.01)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("bus budget: one cycle takes 29.5 ms"),
            "{err}"
        );
        let bad = RtuLink {
            stop_bits: 3,
            ..rtu
        };
        let err = ModbusValve::open(Link::Rtu(bad), RegisterMap::default(), 0.01)
            .await
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("valve.modbus-rtu.stop_bits: 3 is not allowed"),
            "{err}"
        );
    }
}
