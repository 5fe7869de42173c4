//! The serial bus budget: how long one loop cycle takes on an RTU line, and whether the loop
//! rate fits.
//!
//! A transaction costs its request and response characters (start, data, parity and stop bits
//! each), the silence that ends each frame (3.5 characters, fixed at 1.75 ms above 19200 baud as
//! the Modbus serial-line guide prescribes), and the device's turnaround (its response time). A
//! cycle is the sum over the plan's transactions. The verdict refuses a rate the link cannot
//! carry and flags a thin margin; it is computed once at start-up, not measured.
//!
//! Several valves on one serial bus ([`BusBudget`]) take turns on the wire within each cycle:
//! the bus's cycle is the sum of theirs, and that sum must fit the period. Each valve's cycle
//! deadline is then a share of the period ([`BusBudget::deadlines`]), so a valve that does not
//! answer costs its own share and never holds the others past the cycle.

use super::link::RtuLink;
use super::plan::Plan;

/// Above this share of the period the margin counts as thin.
pub const THIN_USAGE: f64 = 0.7;
/// Default deadline of a cycle, as a share of the loop period.
pub const DEFAULT_TIMEOUT_SHARE: f64 = 0.8;

/// One transaction's share of the cycle.
#[derive(Debug, Clone, PartialEq)]
pub struct TransactionTime {
    /// Modbus function code.
    pub function_code: u8,
    /// Request characters.
    pub request_chars: usize,
    /// Response characters.
    pub response_chars: usize,
    /// Wire time including both silences and the turnaround, s.
    pub time_s: f64,
}

/// How a cycle's wire time compares with the loop period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Comfortably inside the period.
    Fits,
    /// Fits, but uses more than [`THIN_USAGE`] of the period.
    Thin,
    /// Does not fit.
    TooSlow,
}

impl Verdict {
    /// Logs a budget that fits, `described`: a warning when the margin is thin.
    fn log(self, described: &str) {
        if self == Verdict::Thin {
            tracing::warn!("thin bus margin: {described}");
        } else {
            tracing::info!("bus budget: {described}");
        }
    }

    /// The verdict on a cycle taking `usage` of the period.
    fn of(usage: f64) -> Verdict {
        if usage > 1.0 {
            Verdict::TooSlow
        } else if usage > THIN_USAGE {
            Verdict::Thin
        } else {
            Verdict::Fits
        }
    }
}

/// The wire time of one cycle on an RTU line.
#[derive(Debug, Clone, PartialEq)]
pub struct Budget {
    /// Baud rate.
    pub baud: u32,
    /// Bits per character.
    pub bits_per_char: u32,
    /// Time of one character, s.
    pub char_s: f64,
    /// Inter-frame silence, s.
    pub silence_s: f64,
    /// Device turnaround, s.
    pub turnaround_s: f64,
    /// Per transaction.
    pub transactions: Vec<TransactionTime>,
    /// Whole cycle, s.
    pub cycle_s: f64,
    /// Loop period, s.
    pub period_s: f64,
}

/// A loop rate the serial line cannot carry.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("bus budget: {0}")]
pub struct BudgetError(pub String);

impl Budget {
    /// The budget of `plan` on `link` for a loop of period `period_s`.
    pub fn rtu(link: &RtuLink, plan: &Plan, period_s: f64) -> Budget {
        let bits = link.bits_per_char();
        let char_s = f64::from(bits) / f64::from(link.baud);
        let silence_s = if link.baud > 19200 {
            1.75e-3
        } else {
            3.5 * char_s
        };
        let turnaround_s = link.turnaround_ms / 1000.0;
        let transactions: Vec<TransactionTime> = plan
            .transactions
            .iter()
            .map(|t| {
                let (req, resp) = (t.rtu_request_bytes(), t.rtu_response_bytes());
                TransactionTime {
                    function_code: t.function_code(),
                    request_chars: req,
                    response_chars: resp,
                    time_s: (req + resp) as f64 * char_s + 2.0 * silence_s + turnaround_s,
                }
            })
            .collect();
        let cycle_s = transactions.iter().map(|t| t.time_s).sum();
        Budget {
            baud: link.baud,
            bits_per_char: bits,
            char_s,
            silence_s,
            turnaround_s,
            transactions,
            cycle_s,
            period_s,
        }
    }

    /// Cycle time over period.
    pub fn usage(&self) -> f64 {
        self.cycle_s / self.period_s
    }

    /// The highest loop rate the link carries, Hz.
    pub fn max_rate_hz(&self) -> f64 {
        1.0 / self.cycle_s
    }

    /// Fits, thin or too slow.
    pub fn verdict(&self) -> Verdict {
        Verdict::of(self.usage())
    }

    /// The figures in one line.
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self
            .transactions
            .iter()
            .map(|t| {
                format!(
                    "FC {} {}+{} chars",
                    t.function_code, t.request_chars, t.response_chars
                )
            })
            .collect();
        let n = self.transactions.len();
        format!(
            "one cycle takes {:.1} ms on the wire at {} baud, {} bits/char ({}; {} silences of {:.2} ms; {} turnaround{} of {:.1} ms) \
             = {:.0} % of the {:.1} ms loop period; the link carries at most {:.1} Hz",
            self.cycle_s * 1e3,
            self.baud,
            self.bits_per_char,
            parts.join(", "),
            2 * n,
            self.silence_s * 1e3,
            n,
            if n == 1 { "" } else { "s" },
            self.turnaround_s * 1e3,
            self.usage() * 100.0,
            self.period_s * 1e3,
            self.max_rate_hz(),
        )
    }

    /// `Ok` (with the budget) unless the cycle does not fit the period; logs a warning when the
    /// margin is thin.
    pub fn check(self) -> Result<Budget, BudgetError> {
        match self.verdict() {
            Verdict::TooSlow => {
                // FC 23 only helps a plan of more than one transaction.
                let fc23 = if self.transactions.len() > 1 {
                    ", set [valve.registers] fc23 = true"
                } else {
                    ""
                };
                Err(BudgetError(format!(
                    "{}: refusing {:.1} Hz (raise [valve.modbus-rtu] baud{fc23}, or lower [loop] rate_hz to {:.0} or less)",
                    self.describe(),
                    1.0 / self.period_s,
                    self.max_rate_hz().floor()
                )))
            }
            fits => {
                fits.log(&self.describe());
                Ok(self)
            }
        }
    }
}

/// One cycle of every valve on one serial bus.
#[derive(Debug, Clone, PartialEq)]
pub struct BusBudget {
    /// The serial port.
    pub port: String,
    /// Each valve's name and budget, in the order they transact.
    pub valves: Vec<(String, Budget)>,
    /// The whole bus's cycle, s.
    pub cycle_s: f64,
    /// Loop period, s.
    pub period_s: f64,
}

impl BusBudget {
    /// The bus on `port` carrying `valves` (name and budget, for one loop period) in turn.
    pub fn new(port: &str, valves: Vec<(String, Budget)>) -> BusBudget {
        let cycle_s = valves.iter().map(|(_, b)| b.cycle_s).sum();
        let period_s = valves.first().map_or(1.0, |(_, b)| b.period_s);
        BusBudget {
            port: port.to_string(),
            valves,
            cycle_s,
            period_s,
        }
    }

    /// Bus cycle over period.
    pub fn usage(&self) -> f64 {
        self.cycle_s / self.period_s
    }

    /// The figures in one line.
    pub fn describe(&self) -> String {
        let parts: Vec<String> = (self.valves.iter())
            .map(|(name, b)| {
                let fcs: Vec<String> = (b.transactions.iter())
                    .map(|t| format!("FC {}", t.function_code))
                    .collect();
                format!("{name} {:.1} ms ({})", b.cycle_s * 1e3, fcs.join(" + "))
            })
            .collect();
        let (baud, bits) = self
            .valves
            .first()
            .map_or((0, 0), |(_, b)| (b.baud, b.bits_per_char));
        format!(
            "{} valves on {} take {} = {:.1} ms on the wire per cycle at {baud} baud, {bits} \
             bits/char = {:.0} % of the {:.1} ms loop period; the bus carries at most {:.1} Hz",
            self.valves.len(),
            self.port,
            parts.join(" + "),
            self.cycle_s * 1e3,
            self.usage() * 100.0,
            self.period_s * 1e3,
            1.0 / self.cycle_s,
        )
    }

    /// `Ok` unless the bus's cycle does not fit the period, with what to change; logs the
    /// budget (a warning when the margin is thin).
    pub fn check(self) -> Result<BusBudget, BudgetError> {
        match Verdict::of(self.usage()) {
            Verdict::TooSlow => {
                let several: Vec<&str> = (self.valves.iter())
                    .filter(|(_, b)| b.transactions.len() > 1)
                    .map(|(name, _)| name.as_str())
                    .collect();
                let fc23 = if several.is_empty() {
                    String::new()
                } else {
                    format!(
                        ", set [valve.registers] fc23 = true for {}",
                        several.join(", ")
                    )
                };
                Err(BudgetError(format!(
                    "{}: refusing {:.1} Hz (raise [valve.modbus-rtu] baud of every valve on {}{fc23}, lower [loop] rate_hz to {:.0} or less, or put fewer valves on this bus)",
                    self.describe(),
                    1.0 / self.period_s,
                    self.port,
                    (1.0 / self.cycle_s).floor()
                )))
            }
            fits => {
                fits.log(&self.describe());
                Ok(self)
            }
        }
    }

    /// Each valve's cycle deadline, s, from its `timeout_ms` (None: not given). The valves
    /// transact one after the other, so their deadlines add up: a valve with `timeout_ms`
    /// keeps it, and the others share what is left of 80 % of the period (all of it when the
    /// bus needs more than 80 %) in proportion to their wire time, so each can finish a normal
    /// cycle and all of them together, every one timing out, still end within the period.
    /// Refused when the given deadlines add up to more than the period, or leave another valve
    /// less than its wire time.
    pub fn deadlines(&self, timeouts_ms: &[Option<f64>]) -> Result<Vec<f64>, String> {
        let given: f64 = timeouts_ms.iter().flatten().sum::<f64>() / 1e3;
        let period_ms = self.period_s * 1e3;
        if given > self.period_s {
            return Err(format!(
                "the timeout_ms of the valves on {} add up to {:.1} ms, more than the {period_ms:.1} ms loop period: a valve that does not answer would hold the others past the cycle; lower them, or leave them out to share the period",
                self.port,
                given * 1e3
            ));
        }
        let share = if self.usage() <= DEFAULT_TIMEOUT_SHARE {
            DEFAULT_TIMEOUT_SHARE
        } else {
            1.0
        };
        let wire: Vec<f64> = self.valves.iter().map(|(_, b)| b.cycle_s).collect();
        let open: f64 = (wire.iter().zip(timeouts_ms))
            .filter(|(_, t)| t.is_none())
            .map(|(w, _)| w)
            .sum();
        let left = share * self.period_s - given;
        if open > 0.0 && left < open {
            return Err(format!(
                "the timeout_ms given on {} leave {:.1} ms of the {period_ms:.1} ms loop period to the valves without one, which need {:.1} ms on the wire: lower the timeouts given, or give every valve its own",
                self.port,
                left.max(0.0) * 1e3,
                open * 1e3
            ));
        }
        Ok((wire.iter().zip(timeouts_ms))
            .map(|(w, t)| match t {
                Some(ms) => ms / 1e3,
                None => left * w / open,
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::RegisterMap;

    fn link(baud: u32) -> RtuLink {
        RtuLink {
            baud,
            ..RtuLink::new("/dev/null")
        }
    }

    fn fc23() -> Plan {
        Plan::new(&RegisterMap {
            fc23: true,
            ..RegisterMap::default()
        })
    }

    #[test]
    fn nineteen_k_two_transactions() {
        // 8E1: 11 bits/char, 11/19200 s = 0.5729 ms; silence 3.5 chars = 2.0052 ms.
        // FC16 11+8 chars, FC3 8+7 chars: 34 chars = 19.479 ms, 4 silences = 8.021 ms,
        // 2 turnarounds of 1 ms: 29.500 ms.
        let b = Budget::rtu(&link(19200), &Plan::new(&RegisterMap::default()), 0.01);
        assert!((b.char_s - 11.0 / 19200.0).abs() < 1e-15);
        assert!((b.silence_s - 3.5 * 11.0 / 19200.0).abs() < 1e-15);
        assert!((b.cycle_s - 0.029_500).abs() < 1e-6, "{}", b.cycle_s);
        assert_eq!(b.verdict(), Verdict::TooSlow);
        let err = b.check().unwrap_err().to_string();
        assert!(
            err.contains("29.5 ms") && err.contains("refusing 100.0 Hz") && err.contains("33.9 Hz"),
            "{err}"
        );
        assert!(
            err.ends_with("(raise [valve.modbus-rtu] baud, set [valve.registers] fc23 = true, or lower [loop] rate_hz to 33 or less)"),
            "{err}"
        );
    }

    #[test]
    fn nineteen_k_cannot_carry_100_hz_even_with_fc23() {
        // FC23 15+7 = 22 chars = 12.604 ms + 2 silences 4.010 ms + 1 ms = 17.615 ms.
        let b = Budget::rtu(&link(19200), &fc23(), 0.01);
        assert!((b.cycle_s - 0.017_615).abs() < 1e-6, "{}", b.cycle_s);
        assert_eq!(b.verdict(), Verdict::TooSlow);
        // Already one transaction: the fix is the baud rate or the loop rate, not fc23.
        let err = b.clone().check().unwrap_err().to_string();
        assert!(
            err.ends_with("(raise [valve.modbus-rtu] baud, or lower [loop] rate_hz to 56 or less)"),
            "{err}"
        );
        // ... but carries 50 Hz with a thin margin (88 %).
        let b = Budget::rtu(&link(19200), &fc23(), 0.02);
        assert_eq!(b.verdict(), Verdict::Thin);
    }

    #[test]
    fn fast_line_uses_fixed_silence() {
        // 115200 8E1: 0.09549 ms/char; silence fixed 1.75 ms. FC23: 22 chars = 2.1007 ms
        // + 3.5 ms + 1 ms = 6.6007 ms: fits 100 Hz at 66 %.
        let b = Budget::rtu(&link(115200), &fc23(), 0.01);
        assert_eq!(b.silence_s, 1.75e-3);
        assert!((b.cycle_s - 0.006_600_7).abs() < 1e-6, "{}", b.cycle_s);
        assert_eq!(b.verdict(), Verdict::Fits);
        // Two transactions: 34 chars = 3.2465 ms + 7 ms + 2 ms = 12.25 ms: too slow.
        let b = Budget::rtu(&link(115200), &Plan::new(&RegisterMap::default()), 0.01);
        assert!((b.cycle_s - 0.012_246_5).abs() < 1e-6, "{}", b.cycle_s);
        assert_eq!(b.verdict(), Verdict::TooSlow);
    }

    #[test]
    fn thin_margin_is_flagged() {
        let b = Budget::rtu(
            &RtuLink {
                turnaround_ms: 2.0,
                ..link(115200)
            },
            &fc23(),
            0.01,
        );
        assert!((b.usage() - 0.76).abs() < 0.01);
        assert_eq!(b.verdict(), Verdict::Thin);
        assert!(b.check().is_ok());
    }

    fn bus(baud: u32, period_s: f64, plans: &[&Plan]) -> BusBudget {
        let valves = (plans.iter().enumerate())
            .map(|(i, p)| (format!("v{i}"), Budget::rtu(&link(baud), p, period_s)))
            .collect();
        BusBudget::new("/dev/ttyS9", valves)
    }

    #[test]
    fn a_bus_adds_its_valves_up_and_names_what_to_change() {
        let default = Plan::new(&RegisterMap::default());
        // An FC 23 valve and an FC 16 + FC 3 one at 115200 8E1: 6.6 + 12.2 ms, too slow.
        let b = bus(115200, 0.01, &[&fc23(), &default]);
        assert!(
            (b.cycle_s - 0.006_600_7 - 0.012_246_5).abs() < 1e-6,
            "{}",
            b.cycle_s
        );
        let e = b.check().unwrap_err().to_string();
        assert!(
            e.starts_with("bus budget: 2 valves on /dev/ttyS9 take v0 6.6 ms (FC 23) + v1 12.2 ms (FC 16 + FC 3) = 18.8 ms on the wire per cycle at 115200 baud, 11 bits/char = 188 % of the 10.0 ms loop period; the bus carries at most 53.1 Hz: refusing 100.0 Hz"),
            "{e}"
        );
        assert!(
            e.ends_with("(raise [valve.modbus-rtu] baud of every valve on /dev/ttyS9, set [valve.registers] fc23 = true for v1, lower [loop] rate_hz to 53 or less, or put fewer valves on this bus)"),
            "{e}"
        );
        // One FC 23 valve fits 100 Hz, two do not even at 460800 baud (the fixed 1.75 ms
        // silences and the turnarounds take 9 ms of the 10), two fit 50 Hz at 115200.
        assert!(bus(115200, 0.01, &[&fc23()]).check().is_ok());
        assert!(bus(460800, 0.01, &[&fc23(), &fc23()]).check().is_err());
        assert!(bus(115200, 0.02, &[&fc23(), &fc23()]).check().is_ok());
    }

    #[test]
    fn deadlines_share_the_period_by_wire_time() {
        // Two FC 23 valves at 115200 baud and 50 Hz: 6.6 ms each of the 20 ms (66 %), so
        // they share 80 % of the period, 8 ms each.
        let b = bus(115200, 0.02, &[&fc23(), &fc23()]);
        let d = b.deadlines(&[None, None]).unwrap();
        assert!(
            (d[0] - 0.008).abs() < 1e-9 && (d[1] - 0.008).abs() < 1e-9,
            "{d:?}"
        );
        // A given deadline is kept; the other gets what is left of 16 ms.
        let d = b.deadlines(&[Some(9.0), None]).unwrap();
        assert!(
            (d[0] - 0.009).abs() < 1e-9 && (d[1] - 0.007).abs() < 1e-9,
            "{d:?}"
        );
        let e = b.deadlines(&[Some(12.0), Some(9.0)]).unwrap_err();
        assert!(
            e.contains("add up to 21.0 ms, more than the 20.0 ms loop period"),
            "{e}"
        );
        let e = b.deadlines(&[Some(12.0), None]).unwrap_err();
        assert!(e.contains("leave 4.0 ms of the 20.0 ms loop period to the valves without one, which need 6.6 ms"), "{e}");
        // A bus that needs more than 80 % shares the whole period.
        let thin = bus(115200, 0.015, &[&fc23(), &fc23()]);
        let d = thin.deadlines(&[None, None]).unwrap();
        assert!((d[0] - 0.0075).abs() < 1e-9, "{d:?}");
    }
}
