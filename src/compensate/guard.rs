//! The guard of compensation: is the valve, with compensation, tracking the controller worse
//! than it would without it?
//!
//! Both cannot be measured at once, so "without" is the identified model itself driven by the
//! controller's O_P: what the model says the uncompensated valve does. Each window of
//! `window_s`, the RMS of O_P - V_P over the rows that read a V_P (with compensation, measured)
//! is compared with the RMS of O_P - the model's V_P over the same rows (without, predicted).
//! Compensation is judged worse when the measured error exceeds the predicted one by more
//! than the margin and by more than [`FLOOR_PCT`] (a resting valve's noise against a
//! noise-free model is no verdict). The verdict is the caller's to act on.
//!
//! Allocation-free: sums over the window, nothing kept per sample.

/// The smallest excess of the measured over the predicted RMS that counts, %: about a sensor's
/// noise (0.02-0.1 %), which the measured V_P carries and the model does not.
pub const FLOOR_PCT: f64 = 0.05;

/// One window's verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Window {
    /// RMS of O_P - V_P, measured with compensation, %.
    pub with_pct: f64,
    /// RMS of O_P - V_P of the model without compensation, over the same rows, %.
    pub without_pct: f64,
    /// Rows that read a V_P.
    pub rows: usize,
    /// The measured error is worse than the predicted one beyond the margin.
    pub worse: bool,
}

/// The running window.
#[derive(Debug, Clone)]
pub(super) struct Guard {
    window_samples: u64,
    margin: f64,
    samples: u64,
    rows: usize,
    with_sq: f64,
    without_sq: f64,
}

impl Guard {
    /// A guard judging every `window_samples` samples with the relative `margin`.
    pub(super) fn new(window_samples: u64, margin: f64) -> Self {
        Guard {
            window_samples: window_samples.max(1),
            margin,
            samples: 0,
            rows: 0,
            with_sq: 0.0,
            without_sq: 0.0,
        }
    }

    /// Adds a sample: the controller's O_P, the model's V_P without compensation and the
    /// measured V_P (None when none was read); returns the verdict when a window ends.
    pub(super) fn add(&mut self, op: f64, predicted: f64, measured: Option<f64>) -> Option<Window> {
        self.samples += 1;
        if let Some(vp) = measured {
            self.rows += 1;
            self.with_sq += (op - vp).powi(2);
            self.without_sq += (op - predicted).powi(2);
        }
        if self.samples < self.window_samples {
            return None;
        }
        let n = self.rows;
        let (with_sq, without_sq) = (self.with_sq, self.without_sq);
        *self = Guard::new(self.window_samples, self.margin);
        if n == 0 {
            return None;
        }
        let with_pct = (with_sq / n as f64).sqrt();
        let without_pct = (without_sq / n as f64).sqrt();
        Some(Window {
            with_pct,
            without_pct,
            rows: n,
            worse: with_pct > without_pct * (1.0 + self.margin)
                && with_pct - without_pct > FLOOR_PCT,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_window_is_judged_on_the_rows_that_read_a_v_p() {
        let mut g = Guard::new(4, 0.1);
        assert_eq!(g.add(50.0, 49.0, Some(49.0)), None);
        assert_eq!(g.add(50.0, 49.0, None), None);
        assert_eq!(g.add(50.0, 49.0, Some(49.0)), None);
        let w = g.add(50.0, 49.0, Some(48.0)).unwrap();
        assert_eq!(w.rows, 3);
        assert!((w.without_pct - 1.0).abs() < 1e-12);
        assert!((w.with_pct - 2.0f64.sqrt()).abs() < 1e-12);
        assert!(w.worse);
        // The next window starts afresh; a small excess within the margin is no verdict.
        for _ in 0..3 {
            assert_eq!(g.add(50.0, 49.0, Some(48.95)), None);
        }
        assert!(!g.add(50.0, 49.0, Some(48.95)).unwrap().worse);
    }

    #[test]
    fn noise_on_a_resting_valve_is_no_verdict() {
        // Predicted 0 error, measured 0.03 % of noise: far beyond 10 % in ratio, not in size.
        let mut g = Guard::new(2, 0.1);
        g.add(50.0, 50.0, Some(50.03));
        assert!(!g.add(50.0, 50.0, Some(49.97)).unwrap().worse);
        // No V_P in a whole window: nothing to judge.
        let mut g = Guard::new(2, 0.1);
        g.add(50.0, 50.0, None);
        assert_eq!(g.add(50.0, 50.0, None), None);
    }
}
