//! The daemon's log format, written by the logger and read by the recording reader: the row
//! ([`Sample`]), its [`HEADER`], the slot [`Status`] words, and the precision of the numbers.
//!
//! Columns: `t_s,op_pct,vp_pct,status,lateness_us,latency_us,op_sent_pct,utc,op_controller_pct`
//! (the first six as they always were, then each later one added at the end, so readers of
//! older logs read these; the recording reader ignores columns it is not asked for).
//! - `t_s`: the slot's scheduled time, s from the first slot (the grid, k / rate).
//! - `op_pct`: the O_P sent in this slot (with `[valve.compensation]`, the compensated
//!   set-point: what the valve received, which identification must see); in a `skipped` row,
//!   the O_P the valve was holding.
//! - `vp_pct`: the V_P read back; empty when none was read (never repeated or invented).
//! - `status`: see [`Status`] (written with `Display`, read back with `FromStr`).
//! - `lateness_us`: actual start of the cycle minus `t_s`, µs (empty for `skipped`).
//! - `latency_us`: duration of the valve transaction, µs (empty for `skipped`).
//! - `op_sent_pct`: the set-point as the valve received it, % (a positioner gets O_P after its
//!   register's scaling and rounding, e.g. 45.67 % as 457 per mille = 45.7 %); empty when the
//!   write was not acknowledged.
//! - `utc`: the slot's scheduled time as UTC wall-clock time, ms (`2026-11-23T19:27:09.045Z`):
//!   the wall clock read when the loop started plus `t_s`, so it never jumps with the clock. On
//!   the virtual clock (`--as-fast-as-possible`) that is the run's start plus simulated time,
//!   so a long run's later rows and file names lie in the future.
//! - `op_controller_pct`: the O_P the source (the process controller) asked for, before
//!   compensation; equal to `op_pct` without `[valve.compensation]` and in stop-action rows.
//!
//! Numbers are written with a fixed precision, trailing zeros dropped: times to 1 µs (`t_s`),
//! percentages to 0.0001 % ([`PCT_DECIMALS`]; the loop rounds O_P to it before sending, so the
//! logged O_P is the one sent), durations to 1 ns: never `49.400000000000006`.
//!
//! Not here: writing files (`vb_daemon::runtime::logger`), reading them ([`super::read`]).

use std::fmt;
use std::str::FromStr;
use std::time::SystemTime;

use time::OffsetDateTime;

/// The header of every log file.
pub const HEADER: [&str; 9] = [
    "t_s",
    "op_pct",
    "vp_pct",
    "status",
    "lateness_us",
    "latency_us",
    "op_sent_pct",
    "utc",
    "op_controller_pct",
];

/// Decimals of the percentages in the log (0.0001 %).
pub const PCT_DECIMALS: usize = 4;

/// `pct` rounded to the log's precision, so that what the loop sends is what it logs.
pub fn round_pct(pct: f64) -> f64 {
    let scale = 10f64.powi(PCT_DECIMALS as i32);
    (pct * scale).round() / scale
}

/// What happened in a slot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Status {
    /// O_P written and V_P read.
    Ok,
    /// The valve did not answer in time; no V_P.
    Timeout,
    /// The valve answered with an error; no V_P.
    Error,
    /// The link to the valve is down; no V_P.
    Disconnected,
    /// O_P written and V_P read, but the O_P is the safe one: the process controller of the
    /// `modbus-server` source has not written a set-point for `watchdog_s`.
    Watchdog,
    /// The slot was missed because the previous cycle overran; nothing sent, no V_P.
    Skipped,
    /// The stop action `hold`: the last O_P sent once more (V_P empty if that failed).
    SafeHold,
    /// The stop action `go-to`: `go_to_pct` sent (V_P empty if that failed).
    SafeGoTo,
}

impl Status {
    /// Every status, in the order of the summary.
    pub const ALL: [Status; 8] = [
        Status::Ok,
        Status::Timeout,
        Status::Error,
        Status::Disconnected,
        Status::Watchdog,
        Status::Skipped,
        Status::SafeHold,
        Status::SafeGoTo,
    ];

    /// The word written in the `status` column.
    pub fn as_str(self) -> &'static str {
        match self {
            Status::Ok => "ok",
            Status::Timeout => "timeout",
            Status::Error => "error",
            Status::Disconnected => "disconnected",
            Status::Watchdog => "watchdog",
            Status::Skipped => "skipped",
            Status::SafeHold => "safe-hold",
            Status::SafeGoTo => "safe-go-to",
        }
    }

    /// True for the stop action's row.
    pub fn is_stop_action(self) -> bool {
        matches!(self, Status::SafeHold | Status::SafeGoTo)
    }

    /// True when the slot's V_P read failed: such a row has no V_P whatever its cell holds.
    /// (Rows of the other statuses carry the V_P read, if any.)
    pub fn is_failed_read(self) -> bool {
        matches!(self, Status::Timeout | Status::Error | Status::Disconnected)
    }
}

impl fmt::Display for Status {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A `status` cell that is none of the daemon's words.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a status of the daemon's log (ok, timeout, error, disconnected, watchdog, skipped, safe-hold, safe-go-to)")]
pub struct UnknownStatus(pub String);

impl FromStr for Status {
    type Err = UnknownStatus;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Status::ALL
            .into_iter()
            .find(|st| st.as_str() == s)
            .ok_or_else(|| UnknownStatus(s.to_string()))
    }
}

/// One row of the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Scheduled time, s from the first slot.
    pub t_s: f64,
    /// O_P, % (empty only if no O_P was ever sent before a skipped slot).
    pub op_pct: Option<f64>,
    /// V_P, % (empty when not read).
    pub vp_pct: Option<f64>,
    /// What happened.
    pub status: Status,
    /// Start of the cycle minus `t_s`, µs.
    pub lateness_us: Option<f64>,
    /// Valve transaction time, µs.
    pub latency_us: Option<f64>,
    /// The set-point as the valve received it, % (empty when no write was acknowledged).
    pub op_sent_pct: Option<f64>,
    /// The scheduled time as wall-clock time.
    pub utc: SystemTime,
    /// The O_P the source asked for, before compensation, %.
    pub op_controller_pct: Option<f64>,
}

impl Sample {
    /// The row's cells, as written.
    pub fn cells(&self) -> [String; HEADER.len()] {
        let opt = |v: Option<f64>, decimals| v.map_or(String::new(), |v| fixed(v, decimals));
        [
            fixed(self.t_s, 6),
            opt(self.op_pct, PCT_DECIMALS),
            opt(self.vp_pct, PCT_DECIMALS),
            self.status.to_string(),
            opt(self.lateness_us, 3),
            opt(self.latency_us, 3),
            opt(self.op_sent_pct, PCT_DECIMALS),
            utc_stamp(self.utc),
            opt(self.op_controller_pct, PCT_DECIMALS),
        ]
    }
}

/// `v` with `decimals` decimals, trailing zeros dropped but one kept (`50.0`, `0.07`, `12.5`).
pub fn fixed(v: f64, decimals: usize) -> String {
    let text = format!("{v:.decimals$}");
    let text = match text.find('.') {
        Some(dot) => {
            let trimmed = text.trim_end_matches('0');
            if trimmed.len() == dot + 1 {
                format!("{trimmed}0")
            } else {
                trimmed.to_string()
            }
        }
        None => text,
    };
    // -0.0 after rounding reads as 0.0.
    if text
        .trim_start_matches('-')
        .trim_matches(['0', '.'])
        .is_empty()
    {
        "0.0".to_string()
    } else {
        text
    }
}

/// `2026-11-23T19:27:09.045Z` (UTC, ms).
pub fn utc_stamp(t: SystemTime) -> String {
    let format = time::macros::format_description!(
        "[year]-[month]-[day]T[hour]:[minute]:[second].[subsecond digits:3]Z"
    );
    OffsetDateTime::from(t)
        .format(&format)
        .unwrap_or_else(|_| "unknown-time".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_status_reads_back_as_written() {
        for st in Status::ALL {
            assert_eq!(st.to_string().parse::<Status>(), Ok(st));
        }
        assert_eq!(
            "gap".parse::<Status>(),
            Err(UnknownStatus("gap".to_string()))
        );
    }

    #[test]
    fn numbers_have_a_fixed_precision_without_artefacts() {
        assert_eq!(fixed(49.400000000000006, PCT_DECIMALS), "49.4");
        assert_eq!(fixed(0.1 + 0.2, 6), "0.3");
        assert_eq!(fixed(50.9913961021933, PCT_DECIMALS), "50.9914");
        assert_eq!(fixed(40.0, PCT_DECIMALS), "40.0");
        assert_eq!(fixed(-0.00001, PCT_DECIMALS), "0.0");
        assert_eq!(fixed(-0.3, PCT_DECIMALS), "-0.3");
        assert_eq!(fixed(1234.5678, 3), "1234.568");
        // What the loop sends is what the log shows, to the last digit.
        let op = round_pct(50.9913961021933);
        assert_eq!(fixed(op, PCT_DECIMALS).parse::<f64>().unwrap(), op);
    }
}
