//! What the labels of the blind benchmark measure on noise-free runs of a valve, whatever
//! simulated it: slips of stick-slip, the time a speed limit shapes the run, whether a
//! minimum speed moves the valve away from where it would be without it, and how long O_P
//! asks to pass a travel stop. Each family (`physical.rs`, `digital.rs`) runs its own valve
//! and hands the positions here, so both are labelled by the same rules. Only arithmetic on
//! sampled positions; no simulation, no diagnosis.

use super::{DT, EXPOSED_SPEED_RATIO, SATURATION_MARGIN_PCT, SATURATION_S};

/// Samples a stem must stand still before a slip (0.2 s) and a slip's most samples (0.1 s).
const STILL: usize = 20;
const WITHIN: usize = 10;
/// Stillness before a slip, %.
const STILL_PCT: f64 = 0.01;
/// Window of a speed, samples (0.1 s).
const SPEED_WINDOW: usize = 10;

/// The slips of `x`: moves of at least `jump` within 0.1 s after it stood still (within
/// 0.01 %) for 0.2 s, while `smooth` (the same valve without what makes it slip, on the same
/// O_P) moved less than half as much (a move a command starts is no slip). Each slip's size.
pub(crate) fn slips(x: &[f64], smooth: &[f64], jump: f64) -> Vec<f64> {
    let mut out = Vec::new();
    let mut k = STILL;
    while k + WITHIN < x.len().min(smooth.len()) {
        let (lo, hi) = x[k - STILL..=k]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let moved = (x[k + WITHIN] - x[k]).abs();
        if hi - lo <= STILL_PCT
            && moved >= jump
            && (smooth[k + WITHIN] - smooth[k]).abs() < moved / 2.0
        {
            out.push(moved);
            k += WITHIN + STILL;
        } else {
            k += 1;
        }
    }
    out
}

/// Seconds over which `x` moves faster than [`EXPOSED_SPEED_RATIO`] times `top(at, closing)`
/// (the limit at the opening `at` the window starts from, in the direction it moves), over
/// 0.1 s windows: both ways for `None`, closing only for `Some(true)`, opening only for
/// `Some(false)`.
pub(crate) fn exposed_s(x: &[f64], which: Option<bool>, top: impl Fn(f64, bool) -> f64) -> f64 {
    let w = SPEED_WINDOW;
    let fast = x
        .windows(w + 1)
        .filter(|s| {
            let speed = (s[w] - s[0]) / (w as f64 * DT);
            let along = match which {
                None => speed.abs(),
                Some(true) => -speed,
                Some(false) => speed,
            };
            along > EXPOSED_SPEED_RATIO * top(s[0], speed < 0.0)
        })
        .count();
    fast as f64 * DT
}

/// Seconds over which `with` (a valve with a minimum speed `floor`, %/s) stands at least
/// `least` away from `without` (the same valve without it), and seconds over which `with`
/// moves at least [`EXPOSED_SPEED_RATIO`] times the floor (0.1 s windows).
pub(crate) fn floor_seconds(with: &[f64], without: &[f64], least: f64, floor: f64) -> (f64, f64) {
    let apart = with
        .iter()
        .zip(without)
        .filter(|(x, y)| (*x - *y).abs() >= least)
        .count();
    let w = SPEED_WINDOW;
    let faster = with
        .windows(w + 1)
        .filter(|s| (s[w] - s[0]).abs() / (w as f64 * DT) >= EXPOSED_SPEED_RATIO * floor)
        .count();
    (apart as f64 * DT, faster as f64 * DT)
}

/// True when `op` asks to pass a stop at `high` below 100 % (or at `low` above 0 %) by
/// [`SATURATION_MARGIN_PCT`] for [`SATURATION_S`] in total.
pub(crate) fn saturation_asked(low: f64, high: f64, op: &[f64]) -> bool {
    let over = op
        .iter()
        .filter(|&&u| {
            (high < 100.0 && u >= high + SATURATION_MARGIN_PCT)
                || (low > 0.0 && u <= low - SATURATION_MARGIN_PCT)
        })
        .count();
    over as f64 * DT >= SATURATION_S
}

/// The `q` quantile of the finite values of `x` (NaN when there are none).
pub(crate) fn quantile(x: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.get(((v.len().max(1) - 1) as f64 * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// The median of `x` (NaN when empty).
pub(crate) fn median(x: &[f64]) -> f64 {
    quantile(x, 0.5)
}

/// The largest reading error `|(gain - 1) x + offset|` at the 5th and 95th percentiles of
/// `op`, %: where the valve is operated.
pub(crate) fn reading_error_pct(gain: f64, offset: f64, op: &[f64]) -> f64 {
    let err = |x: f64| ((gain - 1.0) * x + offset).abs();
    err(quantile(op, 0.05)).max(err(quantile(op, 0.95)))
}
