//! Warm starts from simple physical estimates: dead time from the cross-correlation of O_P and
//! V_P changes, time constant from the step responses, travel speed from V_P, and pin-cart II's
//! crossing polynomial from the step-delay analysis.
//!
//! The search ([`super::search`]) samples the whole box anyway; the seeds make sure the points
//! an engineer would try first are always among the candidates, which matters most for the
//! seven-parameter pin-cart II.
//!
//! Not here: fitting. Every estimate is read straight off the data.

use serde::Serialize;

use super::params::Layout;
use vb_core::metrics::stats::quantile;
use vb_core::metrics::steps::{travel_speed, CrossingSeed, StepAnalysis};
use vb_core::model::ModelKind;

/// Physical estimates read off a recording.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Physical {
    /// Lag of the peak cross-correlation of ΔO_P and ΔV_P, s (fractional).
    pub dead_time_s: f64,
    /// Median T63 minus the dead time over same-direction steps, s.
    pub time_constant_s: f64,
    /// 99.5th percentile of |V_P speed| over 0.1 s, %/s.
    pub max_speed_pct_per_s: f64,
    /// Mean delay of same-direction steps, s (when there were steps).
    pub same_delay_s: Option<f64>,
    /// Pin-cart II's polynomial from the step delays.
    pub crossing: Option<CrossingSeed>,
}

/// The dead time (s) at which ΔV_P correlates best with ΔO_P, looking up to `max_lag_s`;
/// parabolic interpolation between samples gives a fractional value.
pub fn dead_time_xcorr(op: &[f64], vp: &[f64], dt: f64, max_lag_s: f64) -> f64 {
    let n = op.len().min(vp.len());
    let lags = ((max_lag_s / dt).ceil() as usize).min(n / 4).max(1);
    let mut r = vec![0.0; lags + 1];
    // O_P mostly holds still: summing over its nonzero changes only is exact and fast.
    for k in 1..n {
        let d = op[k] - op[k - 1];
        if d == 0.0 {
            continue;
        }
        for (l, rl) in r.iter_mut().enumerate() {
            let j = k + l;
            if j >= n {
                break;
            }
            // A missing V_P (NaN) adds nothing.
            let dv = vp[j] - vp[j - 1];
            if dv.is_finite() {
                *rl += d * dv;
            }
        }
    }
    let (best, _) =
        r.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |acc, (l, &v)| if v > acc.1 { (l, v) } else { acc },
        );
    let frac = if best > 0 && best < lags {
        let (a, b, c) = (r[best - 1], r[best], r[best + 1]);
        let den = a - 2.0 * b + c;
        if den < 0.0 {
            (0.5 * (a - c) / den).clamp(-0.5, 0.5)
        } else {
            0.0
        }
    } else {
        0.0
    };
    ((best as f64 + frac) * dt).max(0.0)
}

/// Reads the physical estimates off a recording and its step analysis.
pub fn estimate(op: &[f64], vp: &[f64], dt: f64, steps: &StepAnalysis) -> Physical {
    let td = dead_time_xcorr(op, vp, dt, 5.0_f64.max(5.0 * dt));
    let mut t63: Vec<f64> = steps
        .steps
        .iter()
        .filter(|s| s.reversal != Some(true))
        .filter_map(|s| s.t63_s)
        .map(|t| (t - td).max(dt))
        .collect();
    let tau = if t63.is_empty() {
        (5.0 * dt).max(0.3)
    } else {
        quantile(&mut t63, 0.5)
    };
    Physical {
        dead_time_s: td,
        time_constant_s: tau,
        max_speed_pct_per_s: travel_speed(vp, dt, None),
        same_delay_s: (steps.same.count > 0).then_some(steps.same.mean_s),
        crossing: steps.pincart2,
    }
}

/// Physical starting vectors for `layout` (each inside its box once clamped).
pub fn starts(layout: &Layout, p: &Physical) -> Vec<Vec<f64>> {
    let td = p.dead_time_s;
    let td2 = p
        .same_delay_s
        .map_or(td * 0.7, |d| (d - 0.3 * p.time_constant_s).max(0.0));
    let tau = p.time_constant_s;
    let k = 1.0 / tau.max(1e-3);
    let speed = (1.2 * p.max_speed_pct_per_s).max(1.0);
    let cross = p.crossing.map_or([0.3, 0.4, 0.5], |c| c.at_0_50_100_s);
    let raw: Vec<Vec<f64>> = match layout.kind {
        ModelKind::Modelless => vec![vec![]],
        ModelKind::Delayed => vec![vec![td], vec![td2 + 0.5 * tau]],
        ModelKind::Fopdt => vec![vec![td, tau], vec![td2, tau]],
        ModelKind::Stiction => vec![vec![td, 0.5, 0.2], vec![td + 0.5 * tau, 1.0, 0.5]],
        ModelKind::Pincart1 => vec![vec![td, 1.0, k], vec![td2, 0.3, k]],
        ModelKind::Physical => vec![vec![]],
        ModelKind::Pincart2 => vec![
            [vec![td, k, speed, 0.3], cross.to_vec()].concat(),
            [vec![td2, k, speed, 0.1], cross.to_vec()].concat(),
            vec![td2, 2.0 * k, speed, 0.3, 0.0, 0.0, 0.0],
        ],
    };
    raw.into_iter()
        .map(|x| layout.vector(&layout.spec(&x)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, Valve};

    #[test]
    fn dead_time_of_a_delayed_fopdt_is_found() {
        let mut spec = bundled(ModelKind::Fopdt);
        spec.dead_time_s = 0.37;
        let op: Vec<f64> = (0..6000)
            .map(|k| 30.0 + 10.0 * ((k / 300) % 4) as f64)
            .collect();
        let vp = Valve::new(&spec, 0.01).unwrap().simulate(&op, 30.0);
        let td = dead_time_xcorr(&op, &vp, 0.01, 3.0);
        assert!((td - 0.37).abs() < 0.03, "{td}");
    }
}
