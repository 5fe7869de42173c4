//! The zero-phase Butterworth low-pass behind Table 1's "MAE filtered", as SciPy computes it.
//!
//! The design (`butter`) and the forward-backward run (`sosfiltfilt`) come from the `sci-rs`
//! crate, which ports SciPy's code: second-order sections, odd padding of 3 × (2 × sections + 1)
//! samples (minus one per section pair with a trailing zero coefficient, as SciPy counts
//! them) at both ends, and steady-state initial conditions. The test in this file checks it
//! against SciPy's output stored in `tests/data/filter/` (max difference ~1e-12).
//!
//! Not here: other filter types, or choosing the cut-off (the paper fixes 5th order, 1.25 Hz).

use sci_rs::signal::filter::design::{
    butter_dyn, DigitalFilter, FilterBandType, FilterOutputType, Sos, SosFormatFilter,
};
use sci_rs::signal::filter::sosfiltfilt_dyn;

/// Order of the paper's filter.
pub const PAPER_FILTER_ORDER: usize = 5;
/// Half-power frequency of the paper's filter, Hz.
pub const PAPER_FILTER_CUTOFF_HZ: f64 = 1.25;

/// `x` filtered forward and backward (zero phase) by a Butterworth low-pass of `order` with
/// half-power frequency `cutoff_hz`, at `sample_rate_hz`.
///
/// This is SciPy's `sosfiltfilt(butter(order, cutoff_hz, fs=sample_rate_hz, output="sos"), x)`
/// with its default padding. As there, `order` and `cutoff_hz` describe the filter of one pass:
/// run twice, its magnitude response is squared, so the result is attenuated by 6 dB at
/// `cutoff_hz` and by 3 dB a little lower (≈ 0.92 × `cutoff_hz` for order 5), with twice the
/// roll-off. This is how the paper's "zero-phase 5th order Butterworth filter with a half-power
/// frequency of 1.25 Hz" is read.
///
/// Returns `x` unchanged when it cannot filter: `order` is 0, `cutoff_hz` is not strictly
/// between 0 and a finite Nyquist frequency (e.g. 1.25 Hz on 1 Hz data), or `x` is not longer than
/// the padding (18 samples for order 5; SciPy raises an error there).
pub fn filtfilt_butter_lowpass(
    x: &[f64],
    order: usize,
    cutoff_hz: f64,
    sample_rate_hz: f64,
) -> Vec<f64> {
    filtfilt(x, order, cutoff_hz, sample_rate_hz).unwrap_or_else(|| x.to_vec())
}

/// [`filtfilt_butter_lowpass`], or `None` where that returns `x` unchanged.
pub(super) fn filtfilt(
    x: &[f64],
    order: usize,
    cutoff_hz: f64,
    sample_rate_hz: f64,
) -> Option<Vec<f64>> {
    if order == 0
        || !(cutoff_hz > 0.0 && cutoff_hz < sample_rate_hz / 2.0 && sample_rate_hz.is_finite())
    {
        return None;
    }
    let DigitalFilter::Sos(SosFormatFilter { sos }) = butter_dyn(
        order,
        vec![cutoff_hz],
        Some(FilterBandType::Lowpass),
        Some(false),
        Some(FilterOutputType::Sos),
        Some(sample_rate_hz),
    ) else {
        return None;
    };
    // sci-rs asserts (panics) where SciPy raises: check the length first.
    (x.len() > padding(&sos)).then(|| sosfiltfilt_dyn(x.iter(), &sos))
}

/// SciPy's default `padlen` for `sosfiltfilt`.
fn padding(sos: &[Sos<f64>]) -> usize {
    let b_zeros = sos.iter().filter(|s| s.b[2] == 0.0).count();
    let a_zeros = sos.iter().filter(|s| s.a[2] == 0.0).count();
    3 * (2 * sos.len() + 1 - b_zeros.min(a_zeros))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Columns `x,y_fs100,y_fs10` written by `tests/data/filter/make_filter_vectors.py`.
    fn scipy_vectors() -> Vec<[f64; 3]> {
        let path = concat!(
            concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
            "/tests/data/filter/butter5_1p25hz.csv"
        );
        let text = std::fs::read_to_string(path).unwrap();
        text.lines()
            .skip(1)
            .map(|line| {
                let v: Vec<f64> = line.split(',').map(|c| c.parse().unwrap()).collect();
                [v[0], v[1], v[2]]
            })
            .collect()
    }

    #[test]
    fn matches_scipy_sosfiltfilt_at_100_and_10_hz() {
        let rows = scipy_vectors();
        assert_eq!(rows.len(), 1000);
        let x: Vec<f64> = rows.iter().map(|r| r[0]).collect();
        for (fs, col) in [(100.0, 1), (10.0, 2)] {
            let y = filtfilt_butter_lowpass(&x, PAPER_FILTER_ORDER, PAPER_FILTER_CUTOFF_HZ, fs);
            let worst = y
                .iter()
                .zip(&rows)
                .map(|(a, r)| (a - r[col]).abs())
                .fold(0.0, f64::max);
            assert!(worst < 1e-9, "fs {fs}: max |rust - scipy| = {worst:e}");
        }
    }

    #[test]
    fn passes_through_where_it_cannot_filter() {
        let x: Vec<f64> = (0..100).map(|k| (k % 7) as f64).collect();
        // 1.25 Hz is above the Nyquist frequency of 1 Hz data.
        assert_eq!(filtfilt_butter_lowpass(&x, 5, 1.25, 1.0), x);
        assert_eq!(filtfilt_butter_lowpass(&x, 5, 1.25, 2.5), x);
        assert_eq!(filtfilt_butter_lowpass(&x, 0, 1.25, 100.0), x);
        assert_eq!(filtfilt_butter_lowpass(&x, 5, 1.25, f64::INFINITY), x);
        assert_eq!(filtfilt_butter_lowpass(&x, 5, f64::NAN, 100.0), x);
        // Not longer than the padding of 18 samples.
        assert_eq!(filtfilt_butter_lowpass(&x[..18], 5, 1.25, 100.0), &x[..18]);
        assert_ne!(filtfilt_butter_lowpass(&x[..19], 5, 1.25, 100.0), &x[..19]);
        assert!(filtfilt_butter_lowpass(&[], 5, 1.25, 100.0).is_empty());
    }

    #[test]
    fn keeps_a_constant_and_removes_fast_noise() {
        let c = filtfilt_butter_lowpass(&[42.0; 200], 5, 1.25, 100.0);
        assert!(c.iter().all(|v| (v - 42.0).abs() < 1e-9));
        // 20 Hz at 100 Hz is far in the stop band: away from the ends (the slowest pole decays
        // with about 0.4 s, 40 samples), only the mean -0.2 is left.
        let x: Vec<f64> = (0..2000)
            .map(|k| if k % 5 < 2 { 1.0 } else { -1.0 })
            .collect();
        let y = filtfilt_butter_lowpass(&x, 5, 1.25, 100.0);
        assert!(y[500..1500].iter().all(|v| (v + 0.2).abs() < 1e-4));
    }
}
