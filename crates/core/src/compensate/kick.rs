//! The reversal kick: how much to add to the set-point so that a positioner crosses its
//! friction band sooner, and lands on the band's far side instead of carrying the stem past
//! its target.
//!
//! While the valve's pin (the positioner's chamber pressure) crosses the band, the stem stands
//! still and the pin moves at the positioner's speed for the error it sees. A kick `k` on top
//! of the error `|e|` speeds the crossing up; but once the pin reaches the far side, whatever
//! the kick still adds moves the stem beyond where it was asked to go. So the kick is planned
//! each sample as the largest one that, if it were ramped down from now at the rate limit,
//! would bring the pin at most to the far side: it rises while the band is wide, falls as the
//! pin closes in, and is zero when the pin lands. It never goes beyond the kick at which the
//! positioner's speed saturates (a larger one crosses no sooner on the model, and sooner than
//! planned on a valve faster than the model).
//!
//! Pure arithmetic over a pin-speed function: no state, no allocation. The model state it
//! reads and the rate limit it assumes belong to the caller ([`super::Compensator`]).

/// One sample's planning problem, in % and seconds at the valve's core.
pub(super) struct Plan<F: Fn(f64) -> f64> {
    /// |e|: how far the wanted core input is from the cart, % (> 0).
    pub error_pct: f64,
    /// How far the pin may still travel before it must stop kicking, %.
    pub room_pct: f64,
    /// The pin's speed for an error of this size (% → %/s), non-decreasing.
    pub speed: F,
    /// Sample period, s.
    pub dt: f64,
    /// How much the kick may change per sample, %.
    pub step_pct: f64,
    /// The largest kick allowed, %.
    pub max_pct: f64,
}

/// Bisection steps: the kick to 2⁻³⁰ of its cap.
const BISECTIONS: usize = 30;

impl<F: Fn(f64) -> f64> Plan<F> {
    /// The kick for this sample, % (>= 0; 0 when the pin lands without one).
    pub(super) fn kick(&self) -> f64 {
        if self.room_pct <= 0.0 || self.error_pct <= 0.0 || self.max_pct <= 0.0 {
            return 0.0;
        }
        let cap = self.saturation();
        if self.advance(cap) <= self.room_pct {
            return cap;
        }
        let (mut lo, mut hi) = (0.0, cap);
        if self.advance(lo) > self.room_pct {
            return 0.0;
        }
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if self.advance(mid) <= self.room_pct {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo
    }

    /// The smallest kick (up to `max_pct`) at which the pin is as fast as at `max_pct`.
    fn saturation(&self) -> f64 {
        let top = (self.speed)(self.error_pct + self.max_pct);
        if (self.speed)(self.error_pct) >= top {
            return 0.0;
        }
        let (mut lo, mut hi) = (0.0, self.max_pct);
        for _ in 0..BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if (self.speed)(self.error_pct + mid) >= top {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        hi
    }

    /// How far the pin moves with the kick `k` now, ramped down by `step_pct` a sample after,
    /// until the sample in which it is zero, %.
    fn advance(&self, k: f64) -> f64 {
        let mut moved = (self.speed)(self.error_pct + k) * self.dt;
        let mut rest = k - self.step_pct;
        while rest > 0.0 {
            moved += (self.speed)(self.error_pct + rest) * self.dt;
            rest -= self.step_pct;
        }
        moved
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A positioner of gain 8 /s saturating at 60 %/s.
    fn plan(error_pct: f64, room_pct: f64) -> Plan<impl Fn(f64) -> f64> {
        Plan {
            error_pct,
            room_pct,
            speed: |e: f64| (8.0 * e).min(60.0),
            dt: 0.01,
            step_pct: 5.0,
            max_pct: 10.0,
        }
    }

    #[test]
    fn a_wide_band_gets_the_kick_that_saturates_the_positioner() {
        // 60 %/s needs an error of 7.5 %: 0.5 % of it is the controller's, 7 % the kick's.
        let k = plan(0.5, 1.5).kick();
        assert!((k - 7.0).abs() < 1e-6, "{k}");
    }

    #[test]
    fn the_kick_shrinks_as_the_pin_closes_in_and_lands_it() {
        // Step the pin with the planned kicks (rate limited as the caller does): it reaches the
        // side, never beyond, and the kick is zero by then.
        let (e, band) = (0.3, 1.5);
        let (mut pin, mut kick) = (0.0, 0.0);
        let speed = |x: f64| (8.0f64 * x).min(60.0);
        let mut samples = 0;
        while band - pin > 1e-9 && samples < 1000 {
            let want = plan(e, band - pin).kick();
            kick = want.clamp(kick - 5.0, kick + 5.0);
            pin += (speed(e + kick) * 0.01).min(band - pin);
            samples += 1;
            assert!(pin <= band + 1e-12);
        }
        // Without a kick: 1.5 / (8 * 0.3) = 0.625 s; with it, a few samples, and once the pin
        // has landed there is nothing more to add.
        assert!(samples <= 6, "{samples}");
        assert_eq!(plan(e, band - pin).kick(), 0.0);
    }

    #[test]
    fn no_room_or_no_error_means_no_kick() {
        assert_eq!(plan(0.5, 0.0).kick(), 0.0);
        assert_eq!(plan(0.0, 1.0).kick(), 0.0);
        // The error alone crosses what is left in this sample.
        assert_eq!(plan(5.0, 0.1).kick(), 0.0);
    }
}
