//! Numbers meant for people: a value with at most six significant digits and no binary
//! floating-point artefacts (`0.1`, never `0.09999999999999999`; `1.823494`, never
//! `1.8234943590000001`), and `n/a` for a value that does not exist (NaN), never `NaN%`.
//!
//! Files meant to be read back (recordings, model files) keep full round-trip precision; this is
//! for messages, warnings and tables. An effect's size is worded here too (`friction band
//! 1.40 % (1.10-1.80)`), the same in a diagnosis report and in a live alarm.

/// `x` rounded to six significant digits, shortest form (`0.01`, `3600`, `1.5e-9`), `inf`,
/// `-inf`, or `n/a` for NaN.
pub fn num(x: f64) -> String {
    if x.is_nan() {
        return "n/a".into();
    }
    if x.is_infinite() || x == 0.0 {
        return format!("{x}");
    }
    // Shortest round trip of the value rounded to six significant digits: `{:e}` with a
    // precision rounds in decimal, and parsing it back gives the double nearest to that decimal.
    let rounded: f64 = format!("{x:.5e}").parse().unwrap_or(x);
    if (1e-4..1e15).contains(&rounded.abs()) {
        format!("{rounded}")
    } else {
        format!("{rounded:e}")
    }
}

/// `n` and `noun`, with an `s` unless `n` is 1: `1 alarm`, `2 alarms`, `0 alarms`.
pub fn count(n: u64, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// What a size's name means to a person, and the unit it is printed in.
pub fn size_label(name: &str) -> (&'static str, &'static str) {
    match name {
        "dead_time_s" => ("dead time", " s"),
        "friction_band_pct" => ("friction band", " %"),
        "crossing_half_open_s" => ("crossing time at half travel", " s"),
        "open_vs_closed" => ("fully open slower than closed by", " times"),
        "crossing_open_s" => ("crossing time fully open", " s"),
        "stroke_speed_pct_per_s" => ("stroke speed at half travel", " %/s"),
        "speed_ratio" => ("one direction faster than the other by", " times"),
        "min_speed_pct_per_s" => ("minimum speed", " %/s"),
        "slip_pct" => ("slip", " %"),
        "deadband_pct" => ("deadband", " %"),
        "stop_pct" => ("travel stop at", " %"),
        "lattice_pct" => ("sensor lattice", " %"),
        "reading_error_pct" => ("reading error", " %"),
        _ => ("size", ""),
    }
}

/// A number with three significant figures (at least two decimals below 1).
pub fn sig3(x: f64) -> String {
    let a = x.abs();
    let decimals = if a >= 100.0 {
        0
    } else if a >= 10.0 {
        1
    } else if a >= 0.1 || a == 0.0 {
        2
    } else {
        3
    };
    format!("{x:.decimals$}")
}

/// The size named `name` (as in the `--json` document) of `value` within `low`-`high`, as
/// `Size::words` words it.
pub fn size_text(name: &str, value: f64, low: f64, high: f64) -> String {
    let (what, unit) = size_label(name);
    format!("{what} {}{unit}{}", sig3(value), interval_text(low, high))
}

/// The interval `low`-`high` of a size, as its words follow the value: ` (1.38-1.46)`,
/// ` (1.92 or more)` without an upper end, nothing when none was computed.
pub fn interval_text(low: f64, high: f64) -> String {
    if high == f64::INFINITY {
        format!(" ({} or more)", sig3(low))
    } else if low < high {
        format!(" ({}-{})", sig3(low), sig3(high))
    } else {
        String::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interval_without_an_upper_end_is_a_lower_bound() {
        assert_eq!(
            size_text("speed_ratio", 5.37, 1.92, f64::INFINITY),
            "one direction faster than the other by 5.37 times (1.92 or more)"
        );
        assert_eq!(interval_text(1.38, 1.46), " (1.38-1.46)");
        assert_eq!(interval_text(2.0, 2.0), "");
    }

    #[test]
    fn three_figures() {
        assert_eq!(sig3(0.05), "0.050");
        assert_eq!(sig3(123.4), "123");
    }

    #[test]
    fn counts_take_their_plural() {
        assert_eq!(count(1, "connection attempt"), "1 connection attempt");
        assert_eq!(count(0, "alarm"), "0 alarms");
        assert_eq!(count(12, "hold"), "12 holds");
    }
    use proptest::prelude::*;

    #[test]
    fn no_artefacts_and_no_nan() {
        assert_eq!(num(0.09999999999999999), "0.1");
        assert_eq!(num(1.8234943590000001), "1.82349");
        assert_eq!(num(49.400000000000006), "49.4");
        assert_eq!(num(0.009999999999990905), "0.01");
        assert_eq!(num(3600.0), "3600");
        assert_eq!(num(-2.5), "-2.5");
        assert_eq!(num(1.5e-9), "1.5e-9");
        assert_eq!(num(1e300), "1e300");
        assert_eq!(num(f64::NAN), "n/a");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(f64::INFINITY), "inf");
    }

    proptest! {
        /// Never more than six significant digits, and the text reads back close to the value.
        #[test]
        fn short_and_close(x in -1e12f64..1e12) {
            let s = num(x);
            let digits = s.trim_start_matches('-').split('e').next().unwrap_or("")
                .chars().filter(char::is_ascii_digit).collect::<String>();
            prop_assert!(digits.trim_start_matches('0').trim_end_matches('0').len() <= 6, "{s}");
            let back: f64 = s.parse().unwrap();
            prop_assert!((back - x).abs() <= 1e-5 * x.abs() + 1e-300, "{x} -> {s}");
        }
    }
}
