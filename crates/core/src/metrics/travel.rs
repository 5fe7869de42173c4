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
    let mut counter = TravelCounter::default();
    for &v in x {
        counter.push(v, deadband_pct);
    }
    counter.total()
}

/// The travel accumulator one sample at a time (what [`travel`] runs over a series).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TravelCounter {
    anchor: Option<f64>,
    dir: f64,
    total: Travel,
}

impl TravelCounter {
    /// Adds the position `v` (%), counted through `deadband_pct`; true when it counted a move.
    /// A non-finite sample is skipped.
    pub fn push(&mut self, v: f64, deadband_pct: f64) -> bool {
        if !v.is_finite() {
            return false;
        }
        let Some(a) = self.anchor else {
            self.anchor = Some(v);
            return false;
        };
        let d = v - a;
        if d.abs() < deadband_pct {
            return false;
        }
        if self.dir != 0.0 && d.signum() != self.dir {
            self.total.reversals += 1;
        }
        self.dir = d.signum();
        self.total.travel_pct += d.abs();
        self.anchor = Some(v);
        true
    }

    /// The travel and reversals counted so far.
    pub fn total(&self) -> Travel {
        self.total
    }
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
