//! Link settings of a Modbus valve: the `[valve.modbus-tcp]` and `[valve.modbus-rtu]` tables.
//!
//! Plain serde structs with defaults, plus the serial character size that the bus budget needs,
//! [`Link`] (either of them, as the client takes it) and its description for the log.
//! Opening the link is [`crate::client`]'s job.

use std::net::{SocketAddr, ToSocketAddrs};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::wire::{DEFAULT_LATE_REPLY, MAX_HORIZON};

/// `[valve.modbus-tcp]`: a positioner (or gateway) reached over Modbus TCP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TcpLink {
    /// `host:port`, e.g. `192.168.0.20:502` or `127.0.0.1:5502`.
    pub address: String,
    /// Unit identifier (default 1).
    #[serde(default = "one")]
    pub unit_id: u8,
    /// Per-transaction timeout in ms (default: 80 % of the loop period).
    #[serde(default)]
    pub timeout_ms: Option<f64>,
}

/// Serial parity.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    /// No parity bit.
    None,
    /// Even parity (the Modbus RTU default).
    #[default]
    Even,
    /// Odd parity.
    Odd,
}

/// `[valve.modbus-rtu]`: a positioner on a serial line (RS-485 adapter or a pseudo-terminal).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RtuLink {
    /// Serial device, e.g. `/dev/ttyUSB0`.
    pub port: String,
    /// Baud rate (default 19200, the Modbus default).
    #[serde(default = "default_baud")]
    pub baud: u32,
    /// Parity (default even, the Modbus default).
    #[serde(default)]
    pub parity: Parity,
    /// Data bits, 7 or 8 (default 8; Modbus RTU needs 8).
    #[serde(default = "eight")]
    pub data_bits: u8,
    /// Stop bits, 1 or 2 (default 1).
    #[serde(default = "one")]
    pub stop_bits: u8,
    /// Slave address of the positioner, 1-247 (default 1).
    #[serde(default = "one")]
    pub slave_id: u8,
    /// Per-transaction timeout in ms (default: 80 % of the loop period).
    #[serde(default)]
    pub timeout_ms: Option<f64>,
    /// Device response time from the end of a request to the start of its reply, ms, used in the
    /// bus budget (default 1 ms; measure your device and set it).
    #[serde(default = "default_turnaround")]
    pub turnaround_ms: f64,
    /// The latest the device answers a request it answers at all, ms (default 100, or twice
    /// `timeout_ms` if that is longer). After a request goes unanswered the line is held this
    /// long for its reply before the next request goes out, so a late reply is never taken for
    /// a later request's; raised on its own, up to 2000, when a later reply is seen.
    #[serde(default)]
    pub late_reply_ms: Option<f64>,
}

/// Where the valve is.
#[derive(Debug, Clone, PartialEq)]
pub enum Link {
    /// `[valve] kind = "modbus-tcp"`.
    Tcp(TcpLink),
    /// `[valve] kind = "modbus-rtu"`.
    Rtu(RtuLink),
}

impl Link {
    /// The config table of the link, e.g. `valve.modbus-tcp`.
    pub fn section(&self) -> &'static str {
        match self {
            Link::Tcp(_) => "valve.modbus-tcp",
            Link::Rtu(_) => "valve.modbus-rtu",
        }
    }

    /// The unit (TCP) or slave (RTU) id the valve answers at.
    pub fn unit_id(&self) -> u8 {
        match self {
            Link::Tcp(l) => l.unit_id,
            Link::Rtu(l) => l.slave_id,
        }
    }

    /// The configured deadline of a cycle, ms.
    pub fn timeout_ms(&self) -> Option<f64> {
        match self {
            Link::Tcp(l) => l.timeout_ms,
            Link::Rtu(l) => l.timeout_ms,
        }
    }

    /// A short description for the log.
    pub fn describe(&self) -> String {
        match self {
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
}

fn one() -> u8 {
    1
}

fn eight() -> u8 {
    8
}

fn default_baud() -> u32 {
    19200
}

fn default_turnaround() -> f64 {
    1.0
}

impl RtuLink {
    /// Settings for `port` with every other key at its default.
    pub fn new(port: impl Into<String>) -> Self {
        RtuLink {
            port: port.into(),
            baud: default_baud(),
            parity: Parity::Even,
            data_bits: 8,
            stop_bits: 1,
            slave_id: 1,
            timeout_ms: None,
            turnaround_ms: default_turnaround(),
            late_reply_ms: None,
        }
    }

    /// Bits on the wire per character: start + data + parity + stop (11 for 8E1 or 8N2).
    pub fn bits_per_char(&self) -> u32 {
        let parity = if self.parity == Parity::None { 0 } else { 1 };
        1 + u32::from(self.data_bits) + parity + u32::from(self.stop_bits)
    }

    /// The first setting that is not allowed, as (key, message).
    pub fn violation(&self) -> Option<(&'static str, String)> {
        if !(300..=4_000_000).contains(&self.baud) {
            return Some((
                "baud",
                format!("{} is not allowed: a baud rate, 300-4000000", self.baud),
            ));
        }
        if !(7..=8).contains(&self.data_bits) {
            return Some((
                "data_bits",
                format!("{} is not allowed: 7 or 8", self.data_bits),
            ));
        }
        if !(1..=2).contains(&self.stop_bits) {
            return Some((
                "stop_bits",
                format!("{} is not allowed: 1 or 2", self.stop_bits),
            ));
        }
        if !(1..=247).contains(&self.slave_id) {
            return Some((
                "slave_id",
                format!("{} is not allowed: a slave address, 1-247", self.slave_id),
            ));
        }
        if !(self.turnaround_ms.is_finite() && (0.0..=1000.0).contains(&self.turnaround_ms)) {
            return Some((
                "turnaround_ms",
                format!(
                    "{} is not allowed: a response time in ms, 0-1000",
                    self.turnaround_ms
                ),
            ));
        }
        if let Some(ms) = self.late_reply_ms {
            let most = MAX_HORIZON.as_millis() as f64;
            if !(ms.is_finite() && ms >= 1.0 && ms <= most) {
                return Some((
                    "late_reply_ms",
                    format!("{ms} is not allowed: the device's slowest answer in ms, 1-{most}"),
                ));
            }
            if let Some(t) = self.timeout_ms.filter(|&t| t > ms) {
                return Some((
                    "late_reply_ms",
                    format!(
                        "{ms} is shorter than timeout_ms = {t}: a reply within the deadline is not \
                         late; set late_reply_ms to at least {t}"
                    ),
                ));
            }
        }
        timeout_violation(self.timeout_ms)
    }

    /// How long the line is held for an unanswered request's reply, for a cycle deadline of
    /// `timeout`: `late_reply_ms`, or [`DEFAULT_LATE_REPLY`] or twice the deadline.
    pub fn late_reply(&self, timeout: Duration) -> Duration {
        match self.late_reply_ms {
            Some(ms) => Duration::from_secs_f64(ms / 1000.0),
            None => DEFAULT_LATE_REPLY.max(2 * timeout).min(MAX_HORIZON),
        }
    }
}

impl TcpLink {
    /// The socket address of `address` (`host:port`), or why there is none.
    pub fn resolve(&self) -> Result<SocketAddr, String> {
        self.address
            .to_socket_addrs()
            .map_err(|e| e.to_string())?
            .next()
            .ok_or_else(|| "no address found".into())
    }

    /// The first setting that is not allowed, as (key, message).
    pub fn violation(&self) -> Option<(&'static str, String)> {
        timeout_violation(self.timeout_ms)
    }
}

fn timeout_violation(t: Option<f64>) -> Option<(&'static str, String)> {
    match t {
        Some(t) if !(t.is_finite() && t > 0.0 && t <= 60_000.0) => Some((
            "timeout_ms",
            format!("{t} is not allowed: a timeout in ms, > 0 and at most 60000"),
        )),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn character_sizes() {
        let mut l = RtuLink::new("/dev/null");
        assert_eq!(l.bits_per_char(), 11); // 8E1
        l.parity = Parity::None;
        assert_eq!(l.bits_per_char(), 10); // 8N1
        l.stop_bits = 2;
        assert_eq!(l.bits_per_char(), 11); // 8N2
    }

    #[test]
    fn violations_name_the_key() {
        let mut l = RtuLink::new("/dev/null");
        assert_eq!(l.violation(), None);
        l.slave_id = 0;
        assert_eq!(l.violation().map(|v| v.0), Some("slave_id"));
        l.slave_id = 1;
        l.timeout_ms = Some(0.0);
        assert_eq!(l.violation().map(|v| v.0), Some("timeout_ms"));
        l.timeout_ms = Some(20.0);
        l.late_reply_ms = Some(10.0);
        assert_eq!(l.violation().map(|v| v.0), Some("late_reply_ms"));
        l.late_reply_ms = Some(5000.0);
        assert_eq!(l.violation().map(|v| v.0), Some("late_reply_ms"));
        l.late_reply_ms = Some(250.0);
        assert_eq!(l.violation(), None);
        assert_eq!(l.late_reply(Duration::ZERO), Duration::from_millis(250));
    }

    #[test]
    fn late_replies_are_waited_for_at_least_twice_the_deadline() {
        let l = RtuLink::new("/dev/null");
        let ms = |ms| Duration::from_millis(ms);
        assert_eq!(l.late_reply(ms(8)), ms(100));
        assert_eq!(l.late_reply(ms(400)), ms(800));
        assert_eq!(l.late_reply(ms(4000)), MAX_HORIZON);
    }
}
