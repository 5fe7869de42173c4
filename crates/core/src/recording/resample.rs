//! [`resample_zoh`]: a piecewise-constant signal (such as the O_P command) put onto a new,
//! regular sample grid by zero-order hold. No interpolation, no filtering.

/// The values of `x` (sampled at times `t`, increasing) held onto the grid
/// `t[0] + k * period`, k = 0, 1, ..., up to and including `t`'s last time.
///
/// Each grid point takes the last sample at or before it (zero-order hold: a command keeps its
/// value until the next one). A sample counts as "at" a grid point when it lies within a
/// millionth of `period` after it, so rounding in the times does not shift a change by one
/// step. Returns an empty vector when `t` is empty, `period` is not positive and finite, or the
/// lengths differ.
pub fn resample_zoh(t: &[f64], x: &[f64], period: f64) -> Vec<f64> {
    let (Some(&t0), Some(&t_end)) = (t.first(), t.last()) else {
        return Vec::new();
    };
    if t.len() != x.len() || !(period > 0.0 && period.is_finite()) {
        return Vec::new();
    }
    let tolerance = period * 1e-6;
    let steps = ((t_end - t0 + tolerance) / period).floor() as usize;
    let mut out = Vec::with_capacity(steps + 1);
    let mut i = 0;
    for k in 0..=steps {
        let tk = t0 + k as f64 * period;
        while i + 1 < t.len() && t[i + 1] <= tk + tolerance {
            i += 1;
        }
        out.push(x[i]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_each_value_until_the_next() {
        // 1 Hz steps onto 0.25 s.
        let y = resample_zoh(&[0.0, 1.0, 2.0], &[10.0, 20.0, 30.0], 0.25);
        assert_eq!(y, [10.0, 10.0, 10.0, 10.0, 20.0, 20.0, 20.0, 20.0, 30.0]);
        // Down-sampling keeps the value at or before each grid point.
        let t: Vec<f64> = (0..10).map(|k| k as f64 * 0.1).collect();
        let x: Vec<f64> = (0..10).map(f64::from).collect();
        assert_eq!(resample_zoh(&t, &x, 0.3), [0.0, 3.0, 6.0, 9.0]);
        // Irregular times: a change lands on the first grid point at or after it.
        let y = resample_zoh(&[0.0, 0.013, 0.03], &[1.0, 2.0, 3.0], 0.01);
        assert_eq!(y, [1.0, 1.0, 2.0, 3.0]);
        // Same period: identity, despite rounding in the times.
        let t: Vec<f64> = (0..100).map(|k| k as f64 * 0.01 + 5.0).collect();
        assert_eq!(resample_zoh(&t, &x.repeat(10), 0.01), x.repeat(10));
    }

    #[test]
    fn degenerate_inputs_give_nothing() {
        assert!(resample_zoh(&[], &[], 0.1).is_empty());
        assert!(resample_zoh(&[0.0, 1.0], &[1.0], 0.1).is_empty());
        assert!(resample_zoh(&[0.0, 1.0], &[1.0, 2.0], 0.0).is_empty());
        assert_eq!(resample_zoh(&[3.0], &[7.0], 0.1), [7.0]);
    }
}
