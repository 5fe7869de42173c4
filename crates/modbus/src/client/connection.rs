//! One open Modbus link, a TCP connection or a serial port, and its health: the tokio-modbus
//! context, (re)connection with backoff, and what each exchange's outcome means for the link.
//!
//! A [`Connection`] serves one valve on TCP, or every valve of one serial bus: each exchange
//! addresses the unit of the valve it is for (its link's slave or unit id) and names that valve
//! in its faults, so a unit that does not answer costs its own transactions only (one that
//! answers after its deadline puts its reply on the wire during the next valve's transaction,
//! which it can spoil, as on any RTU bus: its deadline must cover its answers). The rules
//! for keeping, dropping and reopening the link are in [`super`]'s documentation. Not here:
//! the cycle's plan, deadlines and decoding ([`super::ModbusValve`]).

use std::io;
use std::net::SocketAddr;
use std::sync::Arc;
use std::time::Duration;

use tokio::time::Instant;
use tokio_modbus::client::{rtu, tcp, Context, Reader, Writer};
use tokio_modbus::slave::SlaveContext;
use tokio_modbus::Slave;

use super::{
    BrokenStream, ConnectError, Disconnected, Down, Fault, IoFailure, Link, ReplyError, StreamEnd,
    Timeout, Unlinked, FIRST_BACKOFF, MAX_BACKOFF, SILENT_LINK,
};
use crate::map::Table;
use crate::plan::Transaction;
use crate::wire::{rtu_frame_fault, RtuWire, TcpWire, WireState};

/// An open (or reopening) link and what it went through.
pub(super) struct Connection {
    /// Where it goes (on a bus, the first valve's link: the port's settings).
    link: Link,
    tcp_addr: Option<SocketAddr>,
    ctx: Option<Context>,
    wire: Arc<WireState>,
    /// The current connection has answered at least once.
    answered: bool,
    /// When the device last answered (or the connection opened).
    last_answer: Instant,
    /// Why the link is down, for the cycles that find it so.
    down_because: Down,
    /// Late replies counted so far on this connection.
    late_seen: u64,
    /// Late replies discarded on the connections before this one.
    late_before: u64,
    next_attempt: Instant,
    backoff: Duration,
    /// How often the link was dropped lately.
    drops: DropRate,
    /// How long an unanswered RTU request's reply is waited for (raised by the wire when a
    /// later one is seen, and kept across connections).
    late_reply: Duration,
    /// Line noise and unexpected replies counted on the connections before this one.
    noise_before: u64,
    unexpected_before: u64,
    pub(super) reconnects: u64,
    pub(super) attempts: u64,
}

impl Connection {
    /// A link to `link` (resolved to `tcp_addr` on TCP), not connected yet; on RTU an
    /// unanswered request's reply is waited for up to `late_reply`.
    pub(super) fn new(
        link: Link,
        tcp_addr: Option<SocketAddr>,
        late_reply: Duration,
    ) -> Connection {
        Connection {
            link,
            tcp_addr,
            ctx: None,
            wire: Arc::default(),
            answered: false,
            last_answer: Instant::now(),
            down_because: Down::NotConnectedYet,
            late_seen: 0,
            late_before: 0,
            next_attempt: Instant::now(),
            backoff: FIRST_BACKOFF,
            drops: DropRate::default(),
            late_reply,
            noise_before: 0,
            unexpected_before: 0,
            reconnects: 0,
            attempts: 0,
        }
    }

    /// Replies discarded as late, on every connection so far.
    pub(super) fn late_replies(&self) -> u64 {
        self.late_before + self.wire.stale_replies()
    }

    /// Waits at least `late_reply` for an unanswered RTU request's reply (a bus shared by
    /// valves with different deadlines waits for the longest).
    pub(super) fn wait_late_replies(&mut self, late_reply: Duration) {
        self.late_reply = self.late_reply.max(late_reply);
    }

    /// Bytes of line noise dropped, on every connection so far.
    pub(super) fn noise_bytes(&self) -> u64 {
        self.noise_before + self.wire.noise_bytes()
    }

    /// Replies no request waited for, on every connection so far.
    pub(super) fn unexpected_replies(&self) -> u64 {
        self.unexpected_before + self.wire.unexpected_replies()
    }

    /// How long an unanswered RTU request's reply is waited for now.
    pub(super) fn late_reply(&self) -> Duration {
        (self.wire.raised_horizon()).map_or(self.late_reply, |h| h.max(self.late_reply))
    }

    /// True while a context is open.
    pub(super) fn is_connected(&self) -> bool {
        self.ctx.is_some()
    }

    /// One connection attempt within `deadline`; on failure, the reason, and the next attempt
    /// waits the backoff (which doubles).
    pub(super) async fn attempt(&mut self, deadline: Instant) -> Result<(), ConnectError> {
        self.ctx = None;
        self.attempts += 1;
        let (late_reply, raised) = (self.late_reply, self.wire.raised_horizon());
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
                    let port = crate::serial::open(l)?;
                    let wire = RtuWire::new(port, Arc::clone(&wire), late_reply, raised);
                    Ok(rtu::attach_slave(wire, Slave(l.slave_id)))
                }
            }
        };
        match tokio::time::timeout_at(deadline, connecting).await {
            Ok(Ok(ctx)) => {
                self.ctx = Some(ctx);
                self.late_before = self.late_replies();
                self.noise_before = self.noise_bytes();
                self.unexpected_before = self.unexpected_replies();
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
                    Ok(Err(e)) => ConnectError::Io(IoFailure::from(&e)),
                    _ => ConnectError::Timeout {
                        ms: allowed.as_millis(),
                    },
                })
            }
        }
    }

    /// Drops the link of the valve `who` because `why`. It is reopened at once if it had
    /// answered (a device that restarted), otherwise after the backoff (a device that takes
    /// connections but never answers on them); either way no sooner than the rate of drops
    /// allows ([`DropRate`]): a device that answers on every new connection, but then closes it
    /// or garbles a reply, now and then or after every answer, would otherwise be reconnected
    /// at once each time.
    fn drop_link(&mut self, who: &Link, why: Down) {
        self.ctx = None;
        let now = Instant::now();
        let wait = self.drops.hit(now);
        if self.answered {
            self.next_attempt = now;
            self.backoff = FIRST_BACKOFF;
        } else {
            self.next_attempt = now + self.backoff;
            self.backoff = (self.backoff * 2).min(MAX_BACKOFF);
        }
        if !wait.is_zero() {
            self.next_attempt = self.next_attempt.max(now + wait);
            tracing::warn!(
                "{}: the link was dropped {:.1} times in the last {} s (the last time: {why}): \
                 next connection in {} ms",
                who.describe(),
                self.drops.level,
                DropRate::HALF_LIFE.as_secs(),
                (self.next_attempt - now).as_millis()
            );
        }
        self.down_because = why;
    }

    /// Reopens the link if the backoff allows, within `deadline`, for the valve `who` (its
    /// link names it in the faults).
    pub(super) async fn reconnect(&mut self, who: &Link, deadline: Instant) -> Result<(), Fault> {
        let now = Instant::now();
        if now < self.next_attempt {
            return Err(Fault::Disconnected(Box::new(Disconnected {
                link: who.describe(),
                why: Unlinked::Backoff {
                    down: self.down_because.clone(),
                    wait_ms: (self.next_attempt - now).as_millis(),
                },
            })));
        }
        match self.attempt(deadline).await {
            Ok(()) => {
                self.reconnects += 1;
                tracing::info!("{}: connected", who.describe());
                Ok(())
            }
            Err(error) => {
                self.down_because = Down::CannotConnect(error.clone());
                Err(Fault::Disconnected(Box::new(Disconnected {
                    link: who.describe(),
                    why: Unlinked::CannotConnect {
                        error,
                        wait_ms: (self.next_attempt - Instant::now()).as_millis(),
                    },
                })))
            }
        }
    }

    /// Runs one transaction until `deadline`; decides from its outcome whether the link stays.
    /// `who` is the valve's link: its unit is addressed, its name is in the faults, and
    /// `timeout` is its deadline in them.
    pub(super) async fn exchange(
        &mut self,
        who: &Link,
        timeout: Duration,
        t: Transaction,
        setpoint: &[u16],
        deadline: Instant,
    ) -> Result<Vec<u16>, Fault> {
        let Some(ctx) = self.ctx.as_mut() else {
            return Err(Fault::Disconnected(Box::new(Disconnected {
                link: who.describe(),
                why: Unlinked::NotOpen(self.down_because.clone()),
            })));
        };
        // On a shared bus each valve addresses its own unit.
        ctx.set_slave(Slave(who.unit_id()));
        let fc = t.function_code();
        match tokio::time::timeout_at(deadline, call(ctx, t, setpoint)).await {
            Ok(Ok(answer)) => {
                self.heard();
                if let Some(u) = self.wire.window().unverified {
                    return Err(Fault::Error(ReplyError::Unverified(u)));
                }
                answer.map_err(|code| Fault::Error(ReplyError::Exception { fc, code }))
            }
            Err(_) => {
                let mut fault = self.classify_silence(timeout, t);
                // Late replies show the device is there, only slow: no reason to reopen.
                // Once seen, every timeout says so (the summary quotes the last one, which
                // may fall between two late replies).
                let late = self.wire.stale_replies();
                if late > self.late_seen {
                    self.late_seen = late;
                    self.last_answer = Instant::now();
                }
                if let Fault::Timeout(t) = &mut fault {
                    t.late_replies = late;
                }
                let silent = Instant::now() - self.last_answer;
                if matches!(self.link, Link::Tcp(_)) && silent >= SILENT_LINK {
                    let why = Down::Silent(silent);
                    tracing::warn!("{}: {why}", who.describe());
                    self.drop_link(who, why);
                }
                Err(fault)
            }
            Ok(Err(tokio_modbus::Error::Transport(e))) => {
                let (fault, broken) = self.classify_transport(who, t, e);
                if let Some(why) = broken {
                    self.drop_link(who, why);
                }
                Err(fault)
            }
            Ok(Err(tokio_modbus::Error::Protocol(e))) => {
                // With the wire's transaction filter a mismatch means the stream is out of
                // step: on TCP it is reopened. RTU has nothing to resynchronise.
                let fault = ReplyError::Unusable {
                    fc,
                    why: e.to_string(),
                };
                if matches!(self.link, Link::Tcp(_)) {
                    self.drop_link(who, Down::Reply(fault.clone()));
                }
                Err(Fault::Error(fault))
            }
        }
    }

    /// The device answered: the connection is proven and the backoff starts afresh.
    fn heard(&mut self) {
        self.answered = true;
        self.last_answer = Instant::now();
        self.backoff = FIRST_BACKOFF;
    }

    /// What a missed deadline means: silence, a partial reply, or a reply with a bad CRC.
    fn classify_silence(&self, timeout: Duration, t: Transaction) -> Fault {
        let timed_out = |partial, held| {
            Fault::Timeout(Timeout {
                fc: t.function_code(),
                ms: timeout.as_millis(),
                partial,
                late_replies: 0,
                held,
            })
        };
        if !matches!(self.link, Link::Rtu(_)) {
            return match self.wire.malformed() {
                Some(m) => Fault::Error(ReplyError::Malformed(m)),
                None => timed_out(None, None),
            };
        }
        if let Some(held) = self.wire.window().held {
            return timed_out(None, Some(held));
        }
        let rx = self.wire.received();
        if rx.is_empty() {
            return timed_out(None, None);
        }
        match rtu_frame_fault(&rx, &t) {
            Some(bad) => Fault::Error(ReplyError::Frame(bad)),
            None => timed_out(Some((rx.len(), t.rtu_response_bytes())), None),
        }
    }

    /// The fault of a transport error, and why the link is down if it broke it. A bad RTU
    /// frame leaves the line usable (the input is emptied before the next request); anything
    /// else on RTU, and any transport error on TCP, breaks it.
    fn classify_transport(
        &self,
        who: &Link,
        t: Transaction,
        e: io::Error,
    ) -> (Fault, Option<Down>) {
        let fc = t.function_code();
        let rtu = matches!(self.link, Link::Rtu(_));
        if e.kind() == io::ErrorKind::InvalidData {
            if rtu {
                if let Some(bad) = rtu_frame_fault(&self.wire.received(), &t) {
                    return (Fault::Error(ReplyError::Frame(bad)), None);
                }
            }
            let why = format!("unusable reply: {e}");
            let unusable = ReplyError::Unusable { fc, why };
            let broken = (!rtu).then(|| Down::Reply(unusable.clone()));
            return (Fault::Error(unusable), broken);
        }
        // tokio-modbus reports a stream that ended with the thread's last errno, which says
        // nothing about it (`Operation now in progress`): the wire knows what happened.
        let end = if self.wire.closed() {
            StreamEnd::Closed
        } else {
            let failure = IoFailure::from(&e);
            match e.kind() {
                io::ErrorKind::ConnectionReset => StreamEnd::Reset(failure),
                io::ErrorKind::BrokenPipe => StreamEnd::BrokenPipe(failure),
                _ => StreamEnd::Io(failure),
            }
        };
        let stream = BrokenStream { fc, end };
        let link = who.describe();
        let fault = Fault::Disconnected(Box::new(Disconnected {
            link: link.clone(),
            why: Unlinked::Broken(stream.clone()),
        }));
        (fault, Some(Down::Broken { link, stream }))
    }
}

/// Dropped links (the device closed or reset the connection, a reply broke the stream, the
/// device went silent) as a count that halves every [`DropRate::HALF_LIFE`]: the wait before
/// reopening grows with it, whatever good replies came between. At about one drop a second
/// the wait and the drops balance: a device that closes each connection after one answer gets
/// about a connection a second, not one every other cycle.
#[derive(Debug, Default)]
struct DropRate {
    level: f64,
    at: Option<Instant>,
}

impl DropRate {
    const HALF_LIFE: Duration = Duration::from_secs(5);
    /// Drops within about a half-life before the reopening waits (a device that restarts is
    /// reconnected at once).
    const FREE: f64 = 2.0;

    /// Counts one failure at `now`; the wait before the next connection.
    fn hit(&mut self, now: Instant) -> Duration {
        let decay = self.at.map_or(0.0, |at| {
            0.5f64.powf((now - at).as_secs_f64() / Self::HALF_LIFE.as_secs_f64())
        });
        self.level = self.level * decay + 1.0;
        self.at = Some(now);
        if self.level <= Self::FREE {
            return Duration::ZERO;
        }
        // Past 2^5 the wait is MAX_BACKOFF anyway.
        let doublings = (self.level - Self::FREE - 1.0).min(5.0);
        FIRST_BACKOFF.mul_f64(2f64.powf(doublings)).min(MAX_BACKOFF)
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
        Transaction::WriteSingle { address } => {
            // The plan gives FC 6 only to a one-register set-point.
            let word = setpoint.first().copied().unwrap_or(0);
            Ok(ctx
                .write_single_register(address, word)
                .await?
                .map(|()| Vec::new()))
        }
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
mod tests {
    use super::*;

    #[test]
    fn the_wait_grows_with_the_rate_of_drops_not_the_run_of_them() {
        let t0 = Instant::now();
        let mut rate = DropRate::default();
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        // Two within a half-life: reopened at once.
        assert_eq!(rate.hit(at(0)), Duration::ZERO);
        assert_eq!(rate.hit(at(20)), Duration::ZERO);
        // Then every 20 ms, good replies or not between: the wait doubles up to the most.
        let waits: Vec<Duration> = (2..12).map(|k| rate.hit(at(20 * k))).collect();
        assert!(waits.windows(2).all(|w| w[1] >= w[0]), "{waits:?}");
        assert!(waits[0] > Duration::ZERO && waits[0] < FIRST_BACKOFF * 2);
        assert_eq!(waits[9], MAX_BACKOFF);
        // Quiet for a minute: the next one is reopened at once again.
        assert_eq!(rate.hit(at(60_000)), Duration::ZERO);
    }
}
