//! Valve travel and reversals, the wear figures of a positioner's travel accumulator: the
//! distance the stem covered and how often it turned, counted through a deadband so that sensor
//! noise on a resting valve adds nothing.
//!
//! A move is counted once the position has left the last counted point by the deadband; the
//! distance counted is the whole way from that point. A reversal is a counted move against the
//! previous one. Not here: anything about what moved the valve.

/// Travel and reversals of one position series.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Travel {
    /// Distance covered, % of travel (100 = one full stroke).
    pub travel_pct: f64,
    /// Counted moves against the previous counted move.
    pub reversals: usize,
}

/// The travel and reversals of `x` (%), counted through `deadband_pct` (> 0, e.g. a few noise
/// standard deviations). Non-finite samples are skipped.
pub fn travel(x: &[f64], deadband_pct: f64) -> Travel {
    let mut out = Travel::default();
    let mut anchor: Option<f64> = None;
    let mut dir = 0.0;
    for &v in x.iter().filter(|v| v.is_finite()) {
        let Some(a) = anchor else {
            anchor = Some(v);
            continue;
        };
        let d = v - a;
        if d.abs() >= deadband_pct {
            if dir != 0.0 && d.signum() != dir {
                out.reversals += 1;
            }
            dir = d.signum();
            out.travel_pct += d.abs();
            anchor = Some(v);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_strokes_and_turns_not_noise() {
        // Up 10 %, down 4 %, up 2 %: 16 % of travel, two reversals.
        let mut x: Vec<f64> = (0..=100).map(|k| k as f64 * 0.1).collect();
        x.extend((0..=40).map(|k| 10.0 - k as f64 * 0.1));
        x.extend((0..=20).map(|k| 6.0 + k as f64 * 0.1));
        let t = travel(&x, 0.05);
        assert!((t.travel_pct - 16.0).abs() < 1e-9, "{t:?}");
        assert_eq!(t.reversals, 2);
        // Noise of ±0.02 % around a resting valve counts nothing through a 0.1 % deadband.
        let rest: Vec<f64> = (0..1000)
            .map(|k| 50.0 + if k % 2 == 0 { 0.02 } else { -0.02 })
            .collect();
        assert_eq!(travel(&rest, 0.1), Travel::default());
        assert_eq!(travel(&[f64::NAN, 1.0, f64::NAN, 3.0], 0.5).travel_pct, 2.0);
    }
}
