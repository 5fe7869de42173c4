//! Dead time: a delay line of O_P, sized once from T_d and the sample period.
//!
//! The delay may be a fraction of a sample: the output is interpolated linearly between the two
//! stored samples that bracket `t - T_d`, so a fitted dead time is a real number, not a whole count
//! of samples. Whole-sample delays are exact. The buffer is allocated when the line is built and
//! never again; `push` does no allocation.

/// A fixed-length delay line with linear interpolation for the fractional part of the delay.
#[derive(Debug, Clone)]
pub struct DelayLine {
    buf: Vec<f64>,
    head: usize,
    whole: usize,
    frac: f64,
}

impl DelayLine {
    /// A delay of `delay_s` seconds at `sample_period_s`; negative delays count as zero.
    pub fn new(delay_s: f64, sample_period_s: f64) -> Self {
        let samples = (delay_s.max(0.0) / sample_period_s).max(0.0);
        // Round away float noise so that 0.35 s at 10 ms is exactly 35 samples.
        let rounded = samples.round();
        let samples = if (samples - rounded).abs() < 1e-9 {
            rounded
        } else {
            samples
        };
        let whole = samples.floor() as usize;
        let frac = samples - whole as f64;
        DelayLine {
            buf: vec![0.0; whole + 2],
            head: 0,
            whole,
            frac,
        }
    }

    /// A line that can delay by up to `max_delay_s` at `sample_period_s`, starting with no
    /// delay; [`DelayLine::set_samples`] changes the delay without allocating.
    pub fn with_capacity(max_delay_s: f64, sample_period_s: f64) -> Self {
        let mut line = DelayLine::new(max_delay_s, sample_period_s);
        line.whole = 0;
        line.frac = 0.0;
        line
    }

    /// Sets the delay to `samples` whole samples, at most the line's capacity. The stored
    /// history is kept, so a growing delay repeats the last input instead of jumping.
    pub fn set_samples(&mut self, samples: usize) {
        self.whole = samples.min(self.buf.len() - 2);
        self.frac = 0.0;
    }

    /// Fills the history with `value`, as if the input had been constant forever.
    pub fn reset(&mut self, value: f64) {
        self.buf.fill(value);
        self.head = 0;
    }

    /// Pushes the newest input and returns the input of `delay` seconds ago.
    #[inline]
    pub fn push(&mut self, x: f64) -> f64 {
        // Index arithmetic without `%`: a division per sample would dominate the step time.
        let n = self.buf.len();
        self.head = if self.head + 1 == n { 0 } else { self.head + 1 };
        self.buf[self.head] = x;
        // `whole <= n - 2`, so one wrap is enough.
        let mut i0 = self.head + n - self.whole;
        if i0 >= n {
            i0 -= n;
        }
        if self.frac == 0.0 {
            return self.buf[i0];
        }
        let i1 = if i0 == 0 { n - 1 } else { i0 - 1 };
        (1.0 - self.frac) * self.buf[i0] + self.frac * self.buf[i1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whole_sample_delay_is_exact() {
        let mut d = DelayLine::new(0.03, 0.01);
        d.reset(0.0);
        let out: Vec<f64> = (1..=6).map(|k| d.push(k as f64)).collect();
        assert_eq!(out, vec![0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
    }

    #[test]
    fn a_set_delay_stays_within_the_capacity() {
        let mut d = DelayLine::with_capacity(0.03, 0.01);
        d.reset(0.0);
        assert_eq!(d.push(1.0), 1.0);
        d.set_samples(2);
        assert_eq!(d.push(2.0), 0.0);
        assert_eq!(d.push(3.0), 1.0);
        d.set_samples(1);
        assert_eq!(d.push(4.0), 3.0);
        d.set_samples(100);
        assert_eq!(d.push(5.0), 2.0);
    }

    #[test]
    fn zero_delay_passes_through() {
        let mut d = DelayLine::new(0.0, 0.01);
        d.reset(5.0);
        assert_eq!(d.push(7.0), 7.0);
    }

    #[test]
    fn fractional_delay_interpolates() {
        let mut d = DelayLine::new(0.015, 0.01);
        d.reset(0.0);
        let out: Vec<f64> = (1..=4).map(|k| d.push(10.0 * k as f64)).collect();
        // 1.5 samples late: halfway between the inputs one and two samples ago.
        assert_eq!(out, vec![0.0, 5.0, 15.0, 25.0]);
    }
}
