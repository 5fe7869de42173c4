//! Small statistics shared by identification and diagnosis: quantiles, the median, mean and
//! spread, a robust noise estimate, the correlation length of a residual and Wilcoxon's
//! signed-rank test.
//!
//! Written here rather than taken from a crate because each is a few lines over `f64` slices
//! with the exact conventions the analysis relies on (a quantile is an order statistic found
//! in linear time, an empty input gives 0), and the statistics crates bring matrices and
//! distributions this code does not need.
//!
//! Not here: the Table 1 metrics ([`super::scores`]) or anything that reads a model.

/// The `q` quantile of `x` (0-1) as the order statistic at `round((len - 1) q)`, found in
/// linear time (reorders `x`); 0 for an empty slice.
pub fn quantile(x: &mut [f64], q: f64) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    let k = ((x.len() - 1) as f64 * q).round() as usize;
    let (_, v, _) = x.select_nth_unstable_by(k, f64::total_cmp);
    *v
}

/// The median of `x` (the upper one for an even count), or `None` when empty.
pub fn median(x: &[f64]) -> Option<f64> {
    if x.is_empty() {
        return None;
    }
    let mut v = x.to_vec();
    Some(quantile(&mut v, 0.5))
}

/// Mean, sample standard deviation and count (`(0, 0, 0)` when empty; the spread of one value
/// is 0).
pub fn mean_sd(x: impl Iterator<Item = f64>) -> (f64, f64, usize) {
    let v: Vec<f64> = x.collect();
    if v.is_empty() {
        return (0.0, 0.0, 0);
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len().max(2) - 1) as f64).sqrt();
    (m, s, v.len())
}

/// How many times differenced a signal is before its noise is measured ([`noise_sd`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Differences {
    /// Sample-to-sample differences: white noise of σ gives σ√2. Steps barely move the median.
    First,
    /// Second differences: white noise of σ gives σ√6; steps and smooth moves (ramps, slewing)
    /// barely move the median either.
    Second,
}

/// Robust standard deviation of the white measurement noise of `x`: the median absolute
/// difference of the chosen order, divided by what a Gaussian of σ = 1 gives (0.6745 times the
/// difference's standard deviation). Movements are rare enough not to move the median.
/// 0 for fewer than five samples.
pub fn noise_sd(x: &[f64], order: Differences) -> f64 {
    if x.len() < 5 {
        return 0.0;
    }
    let mut d = abs_differences(x, order);
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    let (_, med, _) = d.select_nth_unstable_by(mid, f64::total_cmp);
    match order {
        Differences::First => *med / (0.6745 * std::f64::consts::SQRT_2),
        Differences::Second => *med / 0.6745 / 6f64.sqrt(),
    }
}

/// The absolute differences of `x` of the chosen order; those that touch a missing sample
/// (NaN) are left out.
fn abs_differences(x: &[f64], order: Differences) -> Vec<f64> {
    match order {
        Differences::First => (x.windows(2))
            .map(|w| (w[1] - w[0]).abs())
            .filter(|d| d.is_finite())
            .collect(),
        Differences::Second => (x.windows(3))
            .map(|w| (w[2] - 2.0 * w[1] + w[0]).abs())
            .filter(|d| d.is_finite())
            .collect(),
    }
}

/// Share of the squared second differences [`noise_sd_trimmed`] keeps (the smallest ones).
const TRIM_KEEP: f64 = 0.75;
/// Mean square of a standard Gaussian within the quantile that keeps [`TRIM_KEEP`] of it
/// (|z| < 1.1503): (0.75 − 2 · 1.1503 · φ(1.1503)) / 0.75.
const TRIMMED_MEAN_SQUARE: f64 = 0.368_6;

/// Robust standard deviation of the white measurement noise of `x` read on a lattice: the mean
/// of the smallest [`TRIM_KEEP`] of its squared second differences, over what a Gaussian of
/// σ = 1 gives (6 times [`TRIMMED_MEAN_SQUARE`]). On a reading rounded to steps about as large
/// as its noise, the median difference ([`noise_sd`]) is itself a multiple of the step and
/// errs by a fifth (noise of 0.1 % read in steps of 0.1 % gives over 0.115 %, for a read
/// noise of sqrt(0.1² + 0.1²/12) = 0.104 %); a mean of the differences' squares takes in how
/// often each multiple occurs and, trimmed, still ignores moves. On an unrounded reading the
/// two agree. 0 for fewer than five samples.
pub fn noise_sd_trimmed(x: &[f64]) -> f64 {
    if x.len() < 5 {
        return 0.0;
    }
    let mut d = abs_differences(x, Differences::Second);
    let keep = (d.len() as f64 * TRIM_KEEP) as usize;
    if keep == 0 {
        return 0.0;
    }
    d.select_nth_unstable_by(keep - 1, f64::total_cmp);
    let mean_square = d[..keep].iter().map(|d| d * d).sum::<f64>() / keep as f64;
    (mean_square / (6.0 * TRIMMED_MEAN_SQUARE)).sqrt()
}

/// Number of samples over which `r` stays correlated, from its lag-1 autocorrelation ρ:
/// `(1 + ρ) / (1 - ρ)` (1 for white noise; ρ is clamped to 0-0.999). Information criteria count
/// a residual's independent samples as its length over this. Missing samples (NaN) are left
/// out, and so are the pairs that touch one.
pub fn correlation_length(r: &[f64]) -> f64 {
    let measured = || r.iter().filter(|x| x.is_finite());
    let n = measured().count().max(1) as f64;
    let m = measured().sum::<f64>() / n;
    let var = measured().map(|x| (x - m).powi(2)).sum::<f64>() / n;
    if var <= 0.0 {
        return 1.0;
    }
    let (c1, pairs): (f64, f64) = (r.windows(2))
        .map(|w| (w[0] - m) * (w[1] - m))
        .filter(|c| c.is_finite())
        .fold((0.0, 0.0), |(s, k), c| (s + c, k + 1.0));
    let rho = (c1 / pairs.max(1.0) / var).clamp(0.0, 0.999);
    (1.0 + rho) / (1.0 - rho)
}

/// One-sided p-value of Wilcoxon's signed-rank test that the paired differences `x` lean
/// positive: zeros are dropped, tied magnitudes share their mean rank, and the p-value is exact
/// (the share of the 2^n sign patterns whose positive rank sum reaches the observed one).
pub fn signed_rank_p(x: &[f64]) -> f64 {
    let tie = 1e-9;
    let mut v: Vec<f64> = x.iter().copied().filter(|d| d.abs() > tie).collect();
    v.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Twice the mean ranks, so they stay integers.
    let n = v.len();
    let mut rank2 = vec![0usize; n];
    let mut i = 0;
    while i < n {
        let mut j = i;
        while j + 1 < n && v[j + 1].abs() - v[i].abs() <= tie {
            j += 1;
        }
        rank2[i..=j].fill(i + j + 2);
        i = j + 1;
    }
    let observed: usize = v
        .iter()
        .zip(&rank2)
        .filter(|(d, _)| **d > 0.0)
        .map(|(_, r)| r)
        .sum();
    let total: usize = rank2.iter().sum();
    // ways[s]: sign patterns whose positive ranks sum to s.
    let mut ways = vec![0.0f64; total + 1];
    ways[0] = 1.0;
    for &r in &rank2 {
        for s in (r..=total).rev() {
            ways[s] += ways[s - r];
        }
    }
    let all: f64 = ways.iter().sum();
    ways[observed..].iter().sum::<f64>() / all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testkit::noise;

    #[test]
    fn quantiles_are_order_statistics() {
        let mut x = vec![5.0, 1.0, 4.0, 2.0, 3.0];
        assert_eq!(quantile(&mut x, 0.0), 1.0);
        assert_eq!(quantile(&mut x, 0.5), 3.0);
        assert_eq!(quantile(&mut x, 1.0), 5.0);
        assert_eq!(quantile(&mut [], 0.5), 0.0);
        assert_eq!(median(&[2.0, 1.0]), Some(2.0));
        assert_eq!(median(&[]), None);
        let (m, s, n) = mean_sd([1.0, 2.0, 3.0].into_iter());
        assert_eq!((m, s, n), (2.0, 1.0, 3));
        assert_eq!(mean_sd([7.0].into_iter()), (7.0, 0.0, 1));
    }

    #[test]
    fn noise_is_recovered_and_steps_and_ramps_are_ignored() {
        let e = noise(20000, 0.1);
        let step: Vec<f64> = e
            .iter()
            .enumerate()
            .map(|(k, e)| if k < 10000 { 30.0 } else { 60.0 } + e)
            .collect();
        for order in [Differences::First, Differences::Second] {
            let s = noise_sd(&step, order);
            assert!((s - 0.1).abs() < 0.01, "{order:?}: {s}");
        }
        // A ramp of 0.3 % a sample (far above the noise) shifts every first difference, not
        // the second ones.
        let ramp: Vec<f64> = e
            .iter()
            .enumerate()
            .map(|(k, e)| 0.3 * k as f64 + e)
            .collect();
        assert!((noise_sd(&ramp, Differences::Second) - 0.1).abs() < 0.01);
        assert!(noise_sd(&ramp, Differences::First) > 0.2);
        assert_eq!(noise_sd(&[1.0, 2.0], Differences::First), 0.0);
    }

    #[test]
    fn noise_read_on_a_lattice_is_recovered_where_the_median_errs() {
        let e = noise(60000, 0.1);
        // Levels held 5 s at 100 Hz, as a valve on steps rests between them.
        let level = |k: usize| 20.0 + 7.3 * ((k / 500) % 9) as f64 + 0.001 * (k % 500) as f64;
        let raw: Vec<f64> = e.iter().enumerate().map(|(k, e)| level(k) + e).collect();
        let rounded: Vec<f64> = raw.iter().map(|v| (v * 10.0).round() / 10.0).collect();
        let trimmed = noise_sd_trimmed(&raw);
        assert!((trimmed - 0.1).abs() < 0.005, "{trimmed}");
        // Rounded to 0.1 %: the read noise is sqrt(0.1² + 0.1²/12) = 0.104 %.
        let on_lattice = noise_sd_trimmed(&rounded);
        assert!((on_lattice - 0.104).abs() < 0.006, "{on_lattice}");
        let median = noise_sd(&rounded, Differences::Second);
        assert!(median > 0.115, "{median}");
        assert_eq!(noise_sd_trimmed(&[1.0, 2.0, 3.0]), 0.0);
    }

    #[test]
    fn correlation_length_is_one_for_white_noise_and_long_for_a_random_walk() {
        let e = noise(20000, 1.0);
        let white = correlation_length(&e);
        assert!((white - 1.0).abs() < 0.05, "{white}");
        // AR(1) with rho = 0.9: (1 + 0.9) / (1 - 0.9) = 19.
        let mut x = 0.0;
        let ar: Vec<f64> = e
            .iter()
            .map(|v| {
                x = 0.9 * x + v;
                x
            })
            .collect();
        let l = correlation_length(&ar);
        assert!((l - 19.0).abs() < 2.0, "{l}");
        assert_eq!(correlation_length(&[3.0; 10]), 1.0);
        // Missing samples change next to nothing.
        let mut holed = ar.clone();
        holed.iter_mut().step_by(10).for_each(|v| *v = f64::NAN);
        let h = correlation_length(&holed);
        assert!((h - l).abs() < 0.05 * l, "{h} {l}");
    }

    #[test]
    fn signed_rank_test_is_exact() {
        // All five positive: 1 pattern in 32.
        assert!((signed_rank_p(&[1.0, 2.0, 3.0, 4.0, 5.0]) - 1.0 / 32.0).abs() < 1e-12);
        // Zeros are dropped; nothing left means no evidence.
        assert_eq!(signed_rank_p(&[0.0, 0.0]), 1.0);
        // Ranks 1-4, only rank 1 negative: W+ = 9 of 10; patterns with W+ >= 9: {2,3,4}, all.
        assert!((signed_rank_p(&[-1.0, 2.0, 3.0, 4.0]) - 2.0 / 16.0).abs() < 1e-12);
        // Ties share a rank: |1|, |1| -> 1.5 each; W+ = 1.5 + 3 of 6; patterns reaching it: {1, 2}, {1', 2}, all.
        assert!((signed_rank_p(&[1.0, -1.0, 2.0]) - 3.0 / 8.0).abs() < 1e-12);
        // Leaning negative: large p.
        assert!(signed_rank_p(&[-3.0, -2.0, -1.0, 0.5]) > 0.9);
    }
}
