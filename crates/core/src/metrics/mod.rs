//! The paper's Table 1 metrics (Bram et al.): how well a simulated V_P matches the measured one,
//! plus the information criteria for comparing models with different numbers of parameters.
//!
//! - [`scores`] / [`scores_masked`]: MAE, MAE filtered, R², SSE and Rel. SSE in one pass over
//!   the data, as a [`Scores`]; [`table1_header`] and [`table1_row`] print them like Table 1.
//! - [`sse`], [`mae`], [`r2`]: the single metrics on whole slices.
//! - [`filtfilt_butter_lowpass`]: the zero-phase Butterworth filter of "MAE filtered".
//! - [`aic`], [`bic`]: Gaussian-likelihood information criteria from an SSE.
//! - [`stats`]: quantiles, mean and spread, robust noise and a residual's correlation length.
//! - [`travel`]: a valve's travel and reversals through a deadband (wear figures).
//! - [`steps`]: the step delays and stroke speeds a recording shows, shared by identification,
//!   diagnosis and the daemon's health check.
//!
//! Units: MAE in the units of the data (percent of travel for V_P); SSE in those units squared
//! (%²). The paper's SSE column is on fractions of full travel: its modelless row (MAE 1.106 %,
//! 41,300 samples, SSE 14.37) only fits that reading, so a paper SSE is ours / 10⁴. R² and
//! Rel. SSE are ratios, the same in any unit.
//!
//! Not here: choosing the windows to score (pass a mask), fitting, or any I/O.

mod filter;
pub mod stats;
pub mod steps;
mod travel;

pub use filter::{filtfilt_butter_lowpass, PAPER_FILTER_CUTOFF_HZ, PAPER_FILTER_ORDER};
pub use travel::{travel, Travel, TravelCounter};

/// One row of Table 1.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Scores {
    /// Mean |measured − simulated|, in the data's units (%).
    pub mae: f64,
    /// Mean |filtered(measured) − simulated|, with the paper's filter ([`PAPER_FILTER_ORDER`],
    /// [`PAPER_FILTER_CUTOFF_HZ`], zero phase) run over each stretch of measured samples, on
    /// the scored samples of the stretches long enough to filter; equal to `mae` when
    /// `filtered` is false.
    pub mae_filtered: f64,
    /// 1 − SSE / SST, SST taken around the mean of the measured samples scored; NaN when their
    /// spread is below [`R2_MIN_SPREAD_PCT`] (nothing moved for a model to explain).
    pub r2: f64,
    /// Σ (measured − simulated)², in the data's units squared (%²).
    pub sse: f64,
    /// SSE relative to the modelless prediction (simulated = O_P): SSE / Σ (measured − O_P)².
    pub rel_sse: f64,
    /// Number of samples scored.
    pub n: usize,
    /// Whether the measurement could be filtered: false when 1.25 Hz is at or above the
    /// Nyquist frequency (data at 2.5 Hz or slower) or every stretch of measured samples is too
    /// short (≤ 18 samples).
    pub filtered: bool,
    /// Standard deviation of the measured samples scored, in the data's units (%).
    #[serde(default)]
    pub spread_pct: f64,
}

/// Least spread (standard deviation) of the measured V_P over the scored samples for which R²
/// is given, %: one step of a per-mille position register. Below it nothing moved that a model
/// could explain, and 1 − SSE / SST divides by the rounding of the reading (a valve at rest for
/// 20 s gave R² = −7 × 10²⁵ %).
pub const R2_MIN_SPREAD_PCT: f64 = 0.1;

/// Table 1 metrics over all samples. `sample_period` (s) sets the filter's sample rate.
///
/// # Panics
/// If the three slices differ in length (a caller bug, not a data problem).
pub fn scores(measured: &[f64], simulated: &[f64], op: &[f64], sample_period: f64) -> Scores {
    score(measured, simulated, op, sample_period, |_| true)
}

/// Table 1 metrics over the samples where `mask` is true, e.g. the paper's windows where the
/// valve is not saturated. The filter runs over the whole contiguous measurement first (so the
/// window edges see real neighbours, not padding); then only masked samples are scored.
///
/// With no sample masked, `n` is 0 and the averages and ratios are NaN.
///
/// # Panics
/// If the four slices differ in length.
pub fn scores_masked(
    measured: &[f64],
    simulated: &[f64],
    op: &[f64],
    sample_period: f64,
    mask: &[bool],
) -> Scores {
    assert_eq!(mask.len(), measured.len(), "mask and measured V_P lengths");
    score(measured, simulated, op, sample_period, |i| mask[i])
}

/// The metrics over the samples `keep` accepts, the filter having run over all of `measured`.
fn score(
    measured: &[f64],
    simulated: &[f64],
    op: &[f64],
    sample_period: f64,
    keep: impl Fn(usize) -> bool,
) -> Scores {
    assert_eq!(
        simulated.len(),
        measured.len(),
        "simulated and measured V_P lengths"
    );
    assert_eq!(op.len(), measured.len(), "O_P and measured V_P lengths");
    let smooth = filtered_runs(measured, sample_period);
    // Samples without a measurement (NaN) or a simulation are never scored.
    let kept =
        || (0..measured.len()).filter(|&i| keep(i) && (measured[i] - simulated[i]).is_finite());
    let n = kept().count();
    let sum = |f: &dyn Fn(usize) -> f64| kept().map(f).sum::<f64>();
    let mean = sum(&|i| measured[i]) / n as f64;
    let sse = sum(&|i| (measured[i] - simulated[i]).powi(2));
    let sst = sum(&|i| (measured[i] - mean).powi(2));
    let spread_pct = (sst / n as f64).sqrt();
    let smoothed = || kept().filter(|&i| smooth[i].is_finite());
    let n_smooth = smoothed().count();
    Scores {
        mae: sum(&|i| (measured[i] - simulated[i]).abs()) / n as f64,
        mae_filtered: if n_smooth > 0 {
            smoothed()
                .map(|i| (smooth[i] - simulated[i]).abs())
                .sum::<f64>()
                / n_smooth as f64
        } else {
            sum(&|i| (measured[i] - simulated[i]).abs()) / n as f64
        },
        r2: if spread_pct >= R2_MIN_SPREAD_PCT {
            1.0 - sse / sst
        } else {
            f64::NAN
        },
        sse,
        rel_sse: sse / sum(&|i| (measured[i] - op[i]).powi(2)),
        n,
        filtered: n_smooth > 0,
        spread_pct,
    }
}

/// The measurement filtered run by run: each maximal run of measured (finite) samples on its
/// own, NaN where a run is too short to filter or not measured. At absurd sample rates the
/// filter's coefficients lose all precision: a run whose result is not finite stays NaN.
fn filtered_runs(measured: &[f64], sample_period: f64) -> Vec<f64> {
    let mut out = vec![f64::NAN; measured.len()];
    let mut k = 0;
    while k < measured.len() {
        if !measured[k].is_finite() {
            k += 1;
            continue;
        }
        let a = k;
        while k < measured.len() && measured[k].is_finite() {
            k += 1;
        }
        let run = filter::filtfilt(
            &measured[a..k],
            PAPER_FILTER_ORDER,
            PAPER_FILTER_CUTOFF_HZ,
            1.0 / sample_period,
        );
        if let Some(f) = run.filter(|f| f.iter().all(|v| v.is_finite())) {
            out[a..k].copy_from_slice(&f);
        }
    }
    out
}

/// Σ (a − b)² over the common length.
pub fn sse(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
}

/// Mean |a − b| over the common length (NaN when empty).
pub fn mae(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).sum::<f64>() / n as f64
}

/// 1 − SSE / SST of a prediction, SST around the mean of `measured` (not finite when
/// `measured` is constant or empty). Both slices must have the same length.
pub fn r2(measured: &[f64], simulated: &[f64]) -> f64 {
    let mean = measured.iter().sum::<f64>() / measured.len() as f64;
    let sst: f64 = measured.iter().map(|m| (m - mean).powi(2)).sum();
    1.0 - sse(measured, simulated) / sst
}

/// Akaike information criterion of a least-squares fit with Gaussian errors:
/// n ln(SSE / n) + 2k, for n samples and k free parameters. Lower is better; only differences
/// between models on the same data mean anything (the SSE unit only shifts all by a constant).
pub fn aic(sse: f64, n: usize, k: usize) -> f64 {
    n as f64 * (sse / n as f64).ln() + 2.0 * k as f64
}

/// Bayesian information criterion: n ln(SSE / n) + k ln n. Penalises parameters more than
/// [`aic`] once n > 7.
pub fn bic(sse: f64, n: usize, k: usize) -> f64 {
    n as f64 * (sse / n as f64).ln() + k as f64 * (n as f64).ln()
}

/// The column titles matching [`table1_row`].
pub fn table1_header() -> String {
    format!(
        "{:<20} {:>8} {:>12} {:>8} {:>12} {:>9} {:>8}",
        "model", "MAE", "MAE filtered", "R²", "SSE (%²)", "Rel. SSE", "samples"
    )
}

/// One line of Table 1 for `model`, percentages as in the paper; a figure that does not exist
/// (MAE filtered of data that could not be filtered, R² of a constant measurement, anything of
/// no samples) is `n/a`.
pub fn table1_row(model: &str, s: &Scores) -> String {
    let [mae, filtered, r2, sse, rel, n] = table1_cells(s);
    format!("{model:<20} {mae:>8} {filtered:>12} {r2:>8} {sse:>12} {rel:>9} {n:>8}")
}

/// Why a figure of `s` that [`table1_cells`] gives as `n/a` cannot be given, one sentence per
/// figure (none when every figure is there).
pub fn not_given(s: &Scores) -> Vec<String> {
    let mut why = Vec::new();
    if s.n == 0 {
        return vec!["no samples were scored".into()];
    }
    if !s.r2.is_finite() {
        why.push(format!(
            "R² n/a: the measured V_P spreads by {:.4} % (standard deviation) over the {} samples \
             scored, less than {R2_MIN_SPREAD_PCT} % (one step of a per-mille reading): nothing \
             moved for a model to explain",
            s.spread_pct, s.n
        ));
    }
    if !s.rel_sse.is_finite() {
        why.push(
            "Rel. SSE n/a: V_P equals O_P on every sample scored, so the modelless prediction \
             it is relative to has no error"
                .into(),
        );
    }
    why
}

/// Why the `n/a` figures of the Table 1 `rows` are not given ([`not_given`]), each reason once,
/// as lines to print under the table.
pub fn table1_notes<'a>(rows: impl IntoIterator<Item = &'a Scores>) -> String {
    let mut all: Vec<String> = Vec::new();
    for why in rows.into_iter().flat_map(not_given) {
        if !all.contains(&why) {
            all.push(why);
        }
    }
    all.iter().map(|w| format!("  ({w})\n")).collect()
}

/// The figures of a Table 1 row as [`table1_row`] prints them: MAE, MAE filtered, R², SSE,
/// Rel. SSE, samples.
pub fn table1_cells(s: &Scores) -> [String; 6] {
    let pct = |x: f64, decimals: usize| {
        if x.is_finite() {
            format!("{x:.decimals$}%")
        } else {
            "n/a".into()
        }
    };
    let sse = if s.sse.is_finite() && s.n > 0 {
        format!("{:.3}", s.sse)
    } else {
        "n/a".into()
    };
    [
        pct(s.mae, 3),
        pct(if s.filtered { s.mae_filtered } else { f64::NAN }, 3),
        pct(100.0 * s.r2, 2),
        sse,
        pct(100.0 * s.rel_sse, 2),
        s.n.to_string(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-12 * b.abs().max(1.0)
    }

    #[test]
    fn helpers_match_hand_computed_values() {
        let m = [1.0, 2.0, 3.0, 4.0];
        let s = [1.5, 2.0, 2.0, 4.0];
        // Errors -0.5, 0, 1, 0.
        assert!(close(sse(&m, &s), 1.25));
        assert!(close(mae(&m, &s), 0.375));
        // Mean 2.5, SST = 2.25 + 0.25 + 0.25 + 2.25 = 5.
        assert!(close(r2(&m, &s), 1.0 - 1.25 / 5.0));
        assert!(close(r2(&m, &m), 1.0));
        assert!(!r2(&[2.0, 2.0], &[1.0, 3.0]).is_finite());
        assert!(mae(&[], &[]).is_nan());
    }

    #[test]
    fn information_criteria() {
        // n = 10, SSE = 10: ln 1 = 0.
        assert!(close(aic(10.0, 10, 3), 6.0));
        assert!(close(bic(10.0, 10, 3), 3.0 * 10f64.ln()));
        assert!(close(aic(10.0 * std::f64::consts::E, 10, 0), 10.0));
        assert!(bic(1.0, 100, 3) - bic(1.0, 100, 2) > aic(1.0, 100, 3) - aic(1.0, 100, 2));
    }

    #[test]
    fn scores_by_hand_on_short_data_are_unfiltered() {
        let measured = [1.0, 2.0, 3.0, 4.0];
        let simulated = [1.5, 2.0, 2.0, 4.0];
        let op = [0.0, 2.0, 3.0, 6.0]; // modelless errors 1, 0, 0, -2: SSE 5
        let s = scores(&measured, &simulated, &op, 0.01);
        assert_eq!(s.n, 4);
        assert!(!s.filtered, "4 samples are too few to filter");
        assert!(close(s.mae, 0.375) && close(s.mae_filtered, 0.375));
        assert!(close(s.sse, 1.25));
        assert!(close(s.r2, 0.75));
        assert!(close(s.rel_sse, 0.25));
        // Modelless against itself: Rel. SSE is 100 %.
        assert!(close(scores(&measured, &op, &op, 0.01).rel_sse, 1.0));
    }

    #[test]
    fn masked_scores_count_only_masked_samples() {
        let measured = [1.0, 2.0, 3.0, 4.0, 100.0];
        let simulated = [1.5, 2.0, 2.0, 4.0, 0.0];
        let op = [0.0, 2.0, 3.0, 6.0, 0.0];
        let s = scores_masked(
            &measured,
            &simulated,
            &op,
            1.0,
            &[true, true, true, true, false],
        );
        assert_eq!(s, scores(&measured[..4], &simulated[..4], &op[..4], 1.0));
        // Mean of the masked samples only: {2, 3}, SST 0.5, SSE 1.
        let s = scores_masked(
            &measured,
            &simulated,
            &op,
            1.0,
            &[false, true, true, false, false],
        );
        assert_eq!(s.n, 2);
        assert!(close(s.r2, 1.0 - 1.0 / 0.5));
        let s = scores_masked(&measured, &simulated, &op, 1.0, &[false; 5]);
        assert_eq!(s.n, 0);
        assert!(s.mae.is_nan() && s.r2.is_nan());
    }

    #[test]
    fn a_valve_at_rest_gets_no_r2_and_says_why() {
        // Still to the last bit but for rounding: R² would be a ratio of rounding errors.
        let measured = vec![52.0 + 1e-13, 52.0, 52.0 - 1e-13, 52.0];
        let simulated = vec![51.5; 4];
        let s = scores(&measured, &simulated, &measured, 0.01);
        assert!(s.r2.is_nan() && s.spread_pct < 1e-12, "{s:?}");
        assert_eq!(table1_cells(&s)[2], "n/a");
        let why = not_given(&s);
        assert!(
            why[0].starts_with("R² n/a: the measured V_P spreads by 0.0000 %"),
            "{why:?}"
        );
        assert!(why[1].starts_with("Rel. SSE n/a"), "{why:?}");
        // Moving by a step or more, it has one.
        let moving = [52.0, 52.3, 52.0, 52.3];
        let s = scores(&moving, &simulated, &simulated, 0.01);
        assert!(s.r2.is_finite() && not_given(&s).is_empty(), "{s:?}");
    }

    #[test]
    fn filtered_mae_uses_the_filter_over_all_data_then_the_mask() {
        // 100 Hz: a 0.2 Hz sine plus 25 Hz noise; the model predicts the sine exactly.
        let clean: Vec<f64> = (0..3000)
            .map(|k| 50.0 + 10.0 * (0.4 * std::f64::consts::PI * k as f64 * 0.01).sin())
            .collect();
        let noisy: Vec<f64> = (0..3000)
            .map(|k| clean[k] + if k % 4 < 2 { 0.5 } else { -0.5 })
            .collect();
        let s = scores(&noisy, &clean, &clean, 0.01);
        assert!(s.filtered);
        assert!(close(s.mae, 0.5));
        // The ends carry the filter's start-up transient; the middle is clean.
        assert!(s.mae_filtered < 0.05, "{}", s.mae_filtered);
        let mask: Vec<bool> = (0..3000).map(|k| (1000..1200).contains(&k)).collect();
        let m = scores_masked(&noisy, &clean, &clean, 0.01, &mask);
        assert_eq!(m.n, 200);
        assert!(m.mae_filtered < 1e-5, "{}", m.mae_filtered);
        // The filter ran over all the data, not over the window alone.
        let full = filtfilt_butter_lowpass(&noisy, 5, 1.25, 100.0);
        assert!(close(
            m.mae_filtered,
            mae(&full[1000..1200], &clean[1000..1200])
        ));
        let alone = filtfilt_butter_lowpass(&noisy[1000..1200], 5, 1.25, 100.0);
        assert!(mae(&alone, &clean[1000..1200]) > 10.0 * m.mae_filtered);
        // 1 Hz data: no filtering, and the table says so.
        let s = scores(&noisy, &clean, &clean, 1.0);
        assert!(!s.filtered && s.mae_filtered == s.mae);
        assert!(table1_row("FOPDT", &s).contains(" n/a "));
    }

    #[test]
    fn table_row_reads_like_the_paper() {
        let s = Scores {
            mae: 0.731,
            mae_filtered: 0.711,
            r2: 0.9989,
            sse: 42840.0,
            rel_sse: 0.298,
            n: 41300,
            filtered: true,
            spread_pct: 20.0,
        };
        let row = table1_row("Pin-cart II", &s);
        assert_eq!(
            row,
            "Pin-cart II            0.731%       0.711%   99.89%    42840.000    29.80%    41300"
        );
        assert_eq!(table1_header().chars().count(), row.chars().count());
    }
}
