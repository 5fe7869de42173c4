//! Evident slips: quick moves of V_P with the stem at rest on both sides, and stuck before.
//!
//! A stem that sticks and then jumps stands still before the jump and after it; a valve that
//! jitters after a noisy command, slews or catches up in steps does not. Counting the slips
//! that show those rests (and only those big enough that noise alone practically never makes
//! one) is what lets [`super::stickslip`] name stick-slip by their number, and the correlation
//! of V_P with the smooth model's V_P just before them tells a stuck stem (noise alone there)
//! from a valve that followed its command right up to a quick move (a pulsing positioner).

use super::facts::{self, Slip};
use super::tuning::Tuning;
use vb_core::metrics::stats;

/// A slip at least this many times the slip threshold is evident: noise alone (five sigmas of
/// the compared means at the threshold) practically never makes one, and the slips a healthy
/// valve's small mismatch with its model makes lie just above the threshold. It must also be
/// larger than a healthy stem's friction band ([`super::tuning::Worth::friction_band_pct`]), whose lost motion
/// a stem can make up in one quick move.
const EVIDENT_FACTOR: f64 = 1.5;
/// Window before each evident slip over which V_P is compared with the current smooth
/// model's V_P, in slip spans (0.2 s at 100 Hz), ending a span before the slip's middle.
const STUCK_SPANS: usize = 2;
/// Median correlation, over the evident slips, of V_P with the smooth model's V_P in the
/// window before them, from which V_P follows the model up to its quick moves rather than
/// sticks: a stuck stem reads noise there (a correlation near 0), a healthy valve following a
/// noisy controller output follows the model (about 0.5 under a 0.1 % sensor).
pub(super) const FOLLOWS: f64 = 0.25;

/// Longest brief stick between a slip past the target and the slip back, in slip spans
/// (0.3 s at 100 Hz): a fast positioner turns a stem round within that.
const BRIEF_STICK_SPANS: usize = 3;
/// Largest ratio of the sizes of a slip out and the slip back.
const LIKE_SIZE: f64 = 1.5;

/// What makes a slip evident: its size, and V_P at rest on both sides of the move.
pub(super) struct Rest {
    /// Samples the move may take (the slip detector's span).
    span: usize,
    /// Noise of the reading, %.
    sigma: f64,
    /// Samples of the initial transient, not counted.
    skip: usize,
    /// Smallest evident slip, % ([`EVIDENT_FACTOR`]).
    least: f64,
}

impl Rest {
    /// Evident slips for a reading of noise `sigma` with the slips of `scale`, the first `skip`
    /// samples not counted.
    pub(super) fn new(scale: &facts::SlipScale, sigma: f64, skip: usize, tuning: &Tuning) -> Rest {
        Rest {
            span: scale.span,
            sigma,
            skip,
            least: (EVIDENT_FACTOR * scale.threshold_pct)
                .max(tuning.worth.friction_band_pct)
                .max(1.5 * sigma),
        }
    }

    /// Number of `slips` of the reading `y` at least `least` in size, outside the initial
    /// transient, with `y` at rest for a span just before and just after the move: within a
    /// quarter of the slip plus what five noise sigmas spread over. A valve that jitters
    /// after a noisy controller output moves all the time; a stuck stem stands still, then
    /// slips. A stem pushed past its target by a fast positioner may stick there only briefly
    /// and slip back ([`BRIEF_STICK_SPANS`]): two slips of opposite sign and like size, at rest
    /// before the first and after the second, count both: a healthy valve on a still command
    /// has no reason to leave its place and come back.
    pub(super) fn evident(&self, slips: &[Slip], y: &[f64]) -> usize {
        let h = self.span;
        let still = |a: usize, b: usize, size: f64| {
            let (lo, hi) = y[a..b]
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), &v| {
                    (l.min(v), u.max(v))
                });
            hi - lo <= 0.25 * size + 5.0 * self.sigma
        };
        let counted = |s: &Slip| {
            s.k >= self.skip.max(2 * h) && s.k + 2 * h <= y.len() && s.size_pct.abs() >= self.least
        };
        let before = |s: &Slip| still(s.k - 2 * h, s.k - h, s.size_pct.abs());
        let after = |s: &Slip| still(s.k + h, s.k + 2 * h, s.size_pct.abs());
        let turned_round = |out: &Slip, back: &Slip| {
            let (a, b) = (out.size_pct, back.size_pct);
            back.k - out.k <= BRIEF_STICK_SPANS * h
                && a * b < 0.0
                && a.abs().max(b.abs()) <= LIKE_SIZE * a.abs().min(b.abs())
        };
        let mut count = 0;
        let mut i = 0;
        while i < slips.len() {
            let s = &slips[i];
            match slips.get(i + 1) {
                Some(b)
                    if counted(s) && counted(b) && turned_round(s, b) && before(s) && after(b) =>
                {
                    count += 2;
                    i += 2;
                }
                _ => {
                    count += usize::from(counted(s) && before(s) && after(s));
                    i += 1;
                }
            }
        }
        count
    }

    /// How closely the reading `y` follows the smooth model's `reference` just before its
    /// evident-sized `slips`: the median, over those slips, of the correlation of `y` with
    /// `reference` over the [`STUCK_SPANS`] before the move (none earlier than a span after
    /// the previous slip; readings without V_P left out; 0 where either stands still). A stem
    /// that sticks and then jumps stands still while the model moves on; a valve whose quick
    /// moves are those of a pulsing positioner following a noisy command follows the model's
    /// every wiggle up to them.
    pub(super) fn follows(&self, slips: &[Slip], y: &[f64], reference: &[f64]) -> f64 {
        let h = self.span;
        let window = STUCK_SPANS * h;
        let mut previous = 0;
        let mut correlations = Vec::new();
        for s in slips.iter().filter(|s| s.size_pct.abs() >= self.least) {
            let (start, end) = (
                (s.k.saturating_sub(h + window)).max(previous),
                s.k.saturating_sub(h),
            );
            previous = s.k + h;
            let pairs: Vec<(f64, f64)> = (start..end.min(y.len()).min(reference.len()))
                .filter(|&j| y[j].is_finite())
                .map(|j| (y[j], reference[j]))
                .collect();
            if pairs.len() * 2 < window {
                continue;
            }
            correlations.push(correlation(&pairs));
        }
        stats::median(&correlations).unwrap_or(0.0)
    }
}

/// Pearson's correlation of the pairs; 0 when either member stands still.
fn correlation(pairs: &[(f64, f64)]) -> f64 {
    let n = pairs.len() as f64;
    let (mx, my) = pairs
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (sxy, sxx, syy) = pairs.iter().fold((0.0, 0.0, 0.0), |(c, a, b), (x, y)| {
        let (dx, dy) = (x - mx, y - my);
        (c + dx * dy, a + dx * dx, b + dy * dy)
    });
    if sxx > 0.0 && syy > 0.0 {
        sxy / (sxx * syy).sqrt()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slip_counts_as_evident_with_rests_around_it_or_around_a_brief_stick_and_back() {
        // 100 Hz, a quiet reading: slips take 10 samples, evident ones are 0.3 % or more.
        let scale = facts::SlipScale::new(0.01, 0.01, 0.0);
        let rest = Rest::new(&scale, 0.01, 0, &Tuning::default());
        let h = scale.span;
        // Level 50; a move of `first` % at 1000 and one of `second` % `dwell` samples later.
        let reading = |first: f64, second: f64, dwell: usize| -> Vec<f64> {
            (0..3000)
                .map(|k| match k {
                    _ if k < 1000 => 50.0,
                    _ if k < 1000 + dwell => 50.0 + first,
                    _ => 50.0 + first + second,
                })
                .collect()
        };
        let slips = |y: &[f64]| facts::slips(&vec![50.0; y.len()], y, &scale);
        // A stem that stays where it slipped to: one evident slip.
        let stays = reading(0.5, 0.0, 0);
        assert_eq!(rest.evident(&slips(&stays), &stays), 1);
        // Out and back after a brief stick, too brief for a span's rest after the first slip
        // (between one and a half and two spans: the slip detector sees both): both evident.
        for dwell in [3 * h / 2, 2 * h - 1] {
            let y = reading(0.5, -0.5, dwell);
            assert_eq!(slips(&y).len(), 2, "dwell {dwell}");
            assert_eq!(rest.evident(&slips(&y), &y), 2, "dwell {dwell}");
        }
        // On in two moves as close together (a valve catching up in steps): neither.
        let on = reading(0.5, 0.5, 2 * h - 1);
        assert_eq!(slips(&on).len(), 2);
        assert_eq!(rest.evident(&slips(&on), &on), 0);
    }

    #[test]
    fn a_stuck_stem_does_not_follow_the_model_before_its_slips_a_pulsing_one_does() {
        let scale = facts::SlipScale::new(0.01, 0.01, 0.0);
        let rest = Rest::new(&scale, 0.02, 0, &Tuning::default());
        // The smooth model wiggles by 0.2 % (a noisy command); the reading moves by 0.5 % at
        // every 500th sample.
        let reference: Vec<f64> = (0..5000)
            .map(|k| 50.0 + 0.2 * (k as f64 * std::f64::consts::TAU / 40.0).sin())
            .collect();
        let offset = |k: usize| 0.5 * (k / 500) as f64;
        let slips: Vec<Slip> = (1..10)
            .map(|i| Slip {
                k: 500 * i,
                size_pct: 0.5,
            })
            .collect();
        let e = vb_core::testkit::noise(5000, 0.02);
        // Following the model up to each quick move: correlated, about 1.
        let follows: Vec<f64> = (0..5000).map(|k| reference[k] + offset(k) + e[k]).collect();
        assert!(rest.follows(&slips, &follows, &reference) > 0.9);
        // Stuck between the moves, its reading noise alone: about 0.
        let stuck: Vec<f64> = (0..5000).map(|k| 50.0 + offset(k) + e[k]).collect();
        assert!(rest.follows(&slips, &stuck, &reference).abs() < FOLLOWS);
        // Readings lost (NaN) are left out, and slips too small to be evident count for nothing.
        let mut holes = follows.clone();
        holes.iter_mut().step_by(3).for_each(|v| *v = f64::NAN);
        assert!(rest.follows(&slips, &holes, &reference) > 0.9);
        let small: Vec<Slip> = slips
            .iter()
            .map(|s| Slip {
                k: s.k,
                size_pct: 0.05,
            })
            .collect();
        assert_eq!(rest.follows(&small, &follows, &reference), 0.0);
    }
}
