//! The valve signature of a response test: the slow ramp out, down past the start and back, read
//! as ISA-75.13.01 reads a positioner's input-output curve. At each reversal of the ramp the
//! dead band is the O_P travel from where the set-point the valve received first turned (the
//! reversal itself, unless the set-point register rounds the ramp into steps) until V_P has
//! moved from its extreme since the reversal by the threshold, less the threshold (once moving,
//! V_P follows the ramp: O_P travelled the threshold while V_P crossed it), so neither the
//! register nor the reading's resolution adds to it. Hysteresis plus dead band is how far the falling
//! leg's V_P lies above the rising legs' at the same O_P (the median over bins of O_P, once V_P
//! has left each reversal), and hysteresis is that less the dead band.
//!
//! V_P is read through a centred mean of half a second (the ramp moves O_P by a twentieth of a
//! percent in it at 0.1 %/s), so the threshold is four standard errors of that mean or half a
//! lattice step, whichever is larger.
//!
//! Not here: the resolution (the smallest step resolved comes from the steps, [`super`]).

use std::ops::Range;

use serde::Serialize;

use super::{Direction, Resolution, MIN_THRESHOLD_PCT};
use vb_core::recording::Recording;
use vb_core::response_plan::SignaturePlan;

/// The signature's figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Signature {
    /// The mean dead band of the ramp's two reversals, %.
    pub dead_band_pct: Option<f64>,
    /// The smallest step size every step of it and of the larger sizes resolved, %.
    pub resolution_pct: Option<f64>,
    /// Hysteresis plus dead band less the dead band, %.
    pub hysteresis_pct: Option<f64>,
    /// How far the falling leg's V_P lies above the rising legs' at the same O_P, %.
    pub hysteresis_plus_dead_band_pct: Option<f64>,
    /// The ramp's reversals, top then bottom.
    pub reversals: Vec<Reversal>,
    /// The threshold a move of the smoothed V_P must pass, %.
    pub threshold_pct: Option<f64>,
    /// The rows of the ramp.
    #[serde(skip)]
    pub rows: Range<usize>,
}

/// One reversal of the ramp.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Reversal {
    /// When O_P turned, s from the start of the log.
    pub t_s: f64,
    /// O_P there, %.
    pub at_pct: f64,
    /// The direction O_P turned to.
    pub direction: Direction,
    /// O_P travel until V_P moved, %; `None` when it did not before the leg's end.
    pub dead_band_pct: Option<f64>,
    /// The row of the reversal, the row where V_P moved, and V_P's extreme before it, %.
    #[serde(skip)]
    pub marks: (usize, Option<usize>, f64),
}

/// The half-width of the centred mean, s.
const SMOOTH_HALF_S: f64 = 0.25;
/// Bins of O_P over the ramp's reach for the legs' comparison.
const BINS: f64 = 20.0;

/// The centred mean of the measured values of `vp` over `range`, `half` rows either side.
fn smoothed(vp: &[f64], range: Range<usize>, half: usize) -> Vec<f64> {
    let (mut n, mut s) = (vec![0usize; vp.len() + 1], vec![0.0; vp.len() + 1]);
    for (k, v) in vp.iter().enumerate() {
        let ok = v.is_finite();
        n[k + 1] = n[k] + usize::from(ok);
        s[k + 1] = s[k] + if ok { *v } else { 0.0 };
    }
    range
        .map(|k| {
            let (a, b) = (k.saturating_sub(half), (k + half + 1).min(vp.len()));
            match n[b] - n[a] {
                0 => f64::NAN,
                c => (s[b] - s[a]) / c as f64,
            }
        })
        .collect()
}

/// The first row of `rows` at which `sm` (indexed from `rows.start`) has moved from its extreme
/// since `rows.start`, in the old direction `-dir`, by at least `floor` towards `dir`; and that
/// extreme.
fn departure(
    sm: &[f64],
    rows: Range<usize>,
    offset: usize,
    dir: f64,
    floor: f64,
) -> (Option<usize>, f64) {
    let mut ext = f64::NEG_INFINITY;
    for k in rows {
        let y = -dir * sm[k - offset];
        if !y.is_finite() {
            continue;
        }
        ext = ext.max(y);
        if ext - y >= floor {
            return (Some(k), -dir * ext);
        }
    }
    (None, -dir * ext)
}

/// The signature of `rec`, whose ramp of `plan` started at row `start`.
pub(super) fn measure(
    rec: &Recording,
    start: usize,
    plan: &SignaturePlan,
    res: &Resolution,
) -> Signature {
    let (op, dt) = (&rec.op, rec.sample_period);
    let n = op.len();
    let leg_rows = |pct: f64| pct / plan.rate_pct_per_s / dt;
    // The ramp keeps the plan's timing: each leg ends near its predicted row, at the extreme.
    let mut ends = Vec::with_capacity(3);
    let mut at = start as f64;
    for (len, dir) in [
        (plan.span_pct, 1.0),
        (2.0 * plan.span_pct, -1.0),
        (plan.span_pct, 1.0),
    ] {
        at += leg_rows(len);
        // The plan's last slot may be the log's last row.
        let guess = at.round() as usize;
        let near = guess.saturating_sub(3)..(guess + 4).min(n);
        let Some(end) = near.max_by(|&a, &b| (dir * op[a]).total_cmp(&(dir * op[b]))) else {
            break;
        };
        if guess > n {
            break;
        }
        ends.push(end);
    }
    let stop = ends.last().copied().unwrap_or(n).min(n);
    let half = ((SMOOTH_HALF_S / dt).round() as usize).max(1);
    let sm = smoothed(&rec.vp, start..stop, half);
    let floor = (4.0 * res.noise_pct / ((2 * half + 1) as f64).sqrt())
        .max(0.5 * res.lattice_pct)
        .max(MIN_THRESHOLD_PCT);
    // Each leg from its start (the ramp's start, then each reversal) to the next.
    let starts: Vec<usize> = std::iter::once(start).chain(ends.iter().copied()).collect();
    let mut reversals = Vec::new();
    let mut moving: Vec<(Range<usize>, f64)> = Vec::new();
    for (i, (&a, &b)) in starts.iter().zip(starts.iter().skip(1)).enumerate() {
        let dir = if i == 1 { -1.0 } else { 1.0 };
        let (moved, extreme) = departure(&sm, a..b, start, dir, floor);
        if let Some(m) = moved {
            moving.push((m..b, dir));
        }
        if i > 0 {
            // The last row before the set-point the valve received moved off the reversal's.
            let turned = (a + 1..b)
                .find(|&k| res.sent(op[k]) != res.sent(op[a]))
                .map_or(a, |k| k - 1);
            reversals.push(Reversal {
                t_s: rec.t[a] - rec.t[0],
                at_pct: op[a],
                direction: Direction::of(dir),
                dead_band_pct: moved.map(|m| ((op[m] - op[turned]).abs() - floor).max(0.0)),
                marks: (a, moved, extreme),
            });
        }
    }
    let bands: Vec<f64> = reversals.iter().filter_map(|r| r.dead_band_pct).collect();
    let dead_band_pct = (bands.len() == 2).then(|| bands.iter().sum::<f64>() / 2.0);
    let hd = separation(rec, &moving, plan);
    Signature {
        dead_band_pct,
        resolution_pct: None,
        hysteresis_pct: hd.zip(dead_band_pct).map(|(hd, d)| (hd - d).max(0.0)),
        hysteresis_plus_dead_band_pct: hd,
        reversals,
        threshold_pct: Some(floor),
        rows: start..stop,
    }
}

/// How far V_P on the falling leg lies above V_P on the rising legs at the same O_P: the median
/// over bins of O_P (a twentieth of the ramp's reach each) that both cover of the difference of
/// their means; `moving` holds each leg's rows after V_P left its start, and its direction.
fn separation(
    rec: &Recording,
    moving: &[(Range<usize>, f64)],
    plan: &SignaturePlan,
) -> Option<f64> {
    let lo = plan.opening_pct - plan.span_pct;
    let width = 2.0 * plan.span_pct / BINS;
    let bins = BINS as usize;
    // Per bin: (sum, count) rising, then falling.
    let mut acc = vec![[(0.0, 0usize); 2]; bins];
    for (rows, dir) in moving {
        let side = usize::from(*dir < 0.0);
        for k in rows.clone() {
            let (o, v) = (rec.op[k], rec.vp[k]);
            let bin = ((o - lo) / width).floor();
            if v.is_finite() && bin >= 0.0 && (bin as usize) < bins {
                let cell = &mut acc[bin as usize][side];
                cell.0 += v;
                cell.1 += 1;
            }
        }
    }
    let mut diffs: Vec<f64> = (acc.iter())
        .filter(|[up, down]| up.1 > 0 && down.1 > 0)
        .map(|[up, down]| down.0 / down.1 as f64 - up.0 / up.1 as f64)
        .collect();
    if diffs.is_empty() {
        return None;
    }
    diffs.sort_by(f64::total_cmp);
    Some(diffs[diffs.len() / 2])
}
