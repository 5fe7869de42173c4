//! One step of a response test measured on the logged V_P (ISA-75.25.01's figures): the dead
//! time until V_P has moved a tenth of the step (the paper's step delay, measured as `steps`
//! measures it, [`time_to_move`]), T63 and T86 until it has covered 63.2 % and 86.5 % of its
//! final change, the overshoot past that final value, the error left at the end of the hold and
//! whether the valve resolved the step at all. V_P before the step is its mean over the half
//! second before; its final value the mean over the hold's last `still_s`. Rows without V_P are
//! passed over; a time whose crossing follows more than three of them in a row is left out (the
//! crossing could lie anywhere in the gap), and so is an overshoot with such a gap within twice
//! T86 of the step.
//!
//! Not here: finding the step in the log ([`super::align`]), the signature.

use super::{Direction, Found, Resolution, StepResult};
use vb_core::metrics::steps::{longest_missing, time_to_move, MAX_MISSING_ROWS};
use vb_core::recording::Recording;

/// Share of the step V_P must have moved for the dead time to end.
pub const DEAD_TIME_SHARE: f64 = 0.1;
/// Share of the final change at T63: 1 - 1/e.
pub const T63_SHARE: f64 = 0.632_120_558_828_557_7;
/// Share of the final change at T86: 1 - 1/e².
pub const T86_SHARE: f64 = 0.864_664_716_763_387_3;
/// The time before a step over which V_P is averaged for where it started, s.
const BEFORE_S: f64 = 0.5;

/// Where V_P crossed a level after a step.
#[derive(Debug, Clone, Copy)]
enum Crossed {
    /// At this row.
    At(usize),
    /// Somewhere in a gap of more than three rows without V_P.
    Hidden,
    /// Not within the hold.
    Never,
}

/// The mean of the measured values of `x` (NaN when none is).
fn mean_measured(x: &[f64]) -> f64 {
    let (n, sum) =
        (x.iter().filter(|v| v.is_finite())).fold((0usize, 0.0), |(n, s), v| (n + 1, s + v));
    if n == 0 {
        f64::NAN
    } else {
        sum / n as f64
    }
}

/// The step `found` of `rec` measured through `res`; its final V_P is the mean of the hold's
/// last `still_rows` rows (at most half of it).
pub(super) fn measure(
    rec: &Recording,
    found: &Found,
    res: &Resolution,
    still_rows: usize,
) -> StepResult {
    let (vp, op, dt) = (&rec.vp, &rec.op, rec.sample_period);
    let (a, end) = (found.row, found.end.min(vp.len()));
    let before = a.saturating_sub(((BEFORE_S / dt).round() as usize).max(1));
    let tail = end - still_rows.min((end - a) / 2).max(1);
    let (v0, v_end) = (mean_measured(&vp[before..a]), mean_measured(&vp[tail..end]));
    let (from, to) = (op[a - 1], op[a]);
    let direction = Direction::of(to - from);
    let dir = direction.sign();
    let sent = res.sent(to) - res.sent(from);
    let measured = v0.is_finite() && v_end.is_finite();
    let mut r = StepResult {
        t_s: rec.t[a] - rec.t[0],
        start_pct: from,
        opening_pct: found.step.opening_pct,
        size_pct: found.step.size_pct,
        sent_size_pct: sent,
        direction,
        reversal: found.reversal,
        dead_time_s: None,
        t63_s: None,
        t86_s: None,
        overshoot_pct: None,
        final_error_pct: None,
        moved_pct: None,
        resolved: false,
        answered: false,
        hidden_by_gap: false,
        hold_s: (end - a) as f64 * dt,
        missing_rows: vp[before..end].iter().filter(|v| !v.is_finite()).count(),
        measured,
        rows: (a, end),
        levels: (v0, v_end),
    };
    if !measured {
        return r;
    }
    let floor = res.threshold_pct;
    let moved = (v_end - v0) * dir;
    // The first row that has moved `need`; hidden when more than three rows without V_P came
    // just before it: the crossing could lie anywhere in that gap.
    let crossing = |need: f64| match time_to_move(vp, a..end, (v0, dir), need, dt) {
        None => Crossed::Never,
        Some(t) => {
            let j = a + (t / dt).round() as usize;
            let gap = vp[a..j].iter().rev().take_while(|v| !v.is_finite()).count();
            if gap <= MAX_MISSING_ROWS {
                Crossed::At(j)
            } else {
                Crossed::Hidden
            }
        }
    };
    let mut time = |c: Crossed| match c {
        Crossed::At(j) => Some((j - a) as f64 * dt),
        Crossed::Hidden => {
            r.hidden_by_gap = true;
            None
        }
        Crossed::Never => None,
    };
    let dead = crossing((DEAD_TIME_SHARE * sent.abs()).max(floor));
    let answered = !matches!(dead, Crossed::Never);
    let dead_time_s = time(dead);
    r.dead_time_s = dead_time_s;
    r.answered = answered;
    r.moved_pct = Some(moved);
    // Plus 0: a valve exactly on target has no error, not -0.
    r.final_error_pct = Some((res.sent(to) - v_end) * dir + 0.0);
    r.resolved = moved >= (0.5 * sent.abs()).max(floor);
    // The times and the overshoot of a change the threshold cannot split into parts are noise.
    if !(r.resolved && moved >= 2.0 * floor) {
        return r;
    }
    let t86 = crossing(T86_SHARE * moved);
    let t86_row = match t86 {
        Crossed::At(j) => Some(j),
        _ => None,
    };
    r.t63_s = time(crossing(T63_SHARE * moved));
    r.t86_s = time(t86);
    // An overshoot peaks within twice T86; a gap there could hide it.
    let Some(window) = t86_row.map(|j| (2 * j - a + 1).clamp(j + 1, end)) else {
        return r;
    };
    if longest_missing(&vp[a..window]) > MAX_MISSING_ROWS {
        r.hidden_by_gap = true;
        return r;
    }
    let highest = |rows: std::ops::Range<usize>| {
        (vp[rows].iter().filter(|v| v.is_finite()))
            .map(|v| (v - v0) * dir)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    // Past the final value by more than the threshold and than the hold's end reaches (a valve
    // still creeping in at the end has not overshot).
    let past = highest(a..end) - moved;
    let over = highest(a..end) - highest(tail..end) > floor && past > floor;
    r.overshoot_pct = Some(if over { 100.0 * past / moved } else { 0.0 });
    r
}
