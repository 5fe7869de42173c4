//! Whether the valve strokes slower than a valve in good order, measured on the recording
//! rather than read off a model.
//!
//! A planner needs to hear that a valve is slow whether or not the model needed a new term
//! for it: a baseline whose time constant stretches to the valve's slowness fits a
//! rate-limited valve well enough that no speed limit is worth adding, and its figures then
//! say nothing about the stroke. The recording says it directly when O_P asked for speed, and
//! V_P's fastest move in that direction ([`Facts::open_speed`], noise taken out) is the
//! valve's stroke speed or less:
//!
//! - a step of [`ASKED_STEP_PCT`] or more asks a valve in good order (positioner gain 2 /s or
//!   more) for at least the stroke speed worth maintenance: slower than that is slow;
//! - any O_P (ramps, smaller steps) asks for what a valve in good order would do with it: a
//!   first-order follower of O_P at [`GOOD_GAIN_PER_S`] and no speed limit, its fastest move
//!   each way measured like V_P's. Where that is at least [`LEAST_ASKED_PCT_PER_S`], a valve
//!   that moves less than [`SLOW_SHARE`] of it (or of the speed worth maintenance, if lower)
//!   could not keep up: a ramp of 10 %/s followed at 1 %/s.
//!
//! A valve whose model holds a speed limit each way (an asymmetry finding, or a trace of one)
//! is slow too when the faster of them is: [`slow_both_ways`] names the slew-rate limit that
//! model already has. A valve whose model moves it at a gain below a valve in good order's,
//! and no faster than that gain allows, is slow through its positioner: [`slow_gain`] names it
//! with the stroke speed the recording bounds.
//! A valve slow at half travel only because its opening slows it has the slowdown named first
//! ([`slowdown_first`]).
//!
//! Not here: the speed limits a model is given (`candidates`) or judged by (`judge`).

use super::diagnosis::{self, Note, Support, Trace};
use super::evidence::{Detail, Evidence};
use super::facts::Facts;
use super::judge::{beyond_chance, bic_change, blocks_helped, shares};
use super::rounds::Data;
use super::size;
use super::speeds::{speeds, WINDOWS_S};
use super::{Finding, Measure};
use vb_core::model::composed::{self, Effect, Knob, Size};
use vb_core::model::{bundled, FopdtParams, ModelKind, ModelSpec, Valve};

/// Smallest O_P step, %, that asks a valve in good order for the stroke speed worth
/// maintenance: the slowest healthy positioner gain (2 /s) times this is 40 %/s.
pub(super) const ASKED_STEP_PCT: f64 = 20.0;
/// The slowest positioner gain of a valve in good order, 1/s.
const GOOD_GAIN_PER_S: f64 = 2.0;
/// Least speed, %/s, a valve in good order must reach on O_P for it to ask anything (a
/// controller's noise moves such a valve by a fraction of this).
const LEAST_ASKED_PCT_PER_S: f64 = 4.0;
/// Share of what a valve in good order reaches below which a valve could not keep up.
const SLOW_SHARE: f64 = 0.5;
/// Share of the slowest gain of a valve in good order below which a valve is slow through its
/// gain: twice as slow as the slowest in good order (a physical valve on small steps whose
/// chamber slows it when open was fitted at 1.2 /s with no slowdown named).
const SLOW_GAIN_SHARE: f64 = 0.5;
/// Largest error, %, at which a positioner in good order drives its valve at full speed (its
/// proportional band): a valve whose speed stays proportional to its error strokes at most its
/// gain times this.
const FULL_DRIVE_ERROR_PCT: f64 = 10.0;

/// The fastest opening and closing moves of a valve in good order following `op` (sampled
/// every `dt` s), %/s: the project's first-order model at [`GOOD_GAIN_PER_S`] (a time
/// constant of its inverse), no dead time, no speed limit.
fn good_speeds(op: &[f64], dt: f64) -> (f64, f64) {
    let spec = ModelSpec {
        dead_time_s: 0.0,
        fopdt: Some(FopdtParams {
            time_constant_s: 1.0 / GOOD_GAIN_PER_S,
        }),
        ..bundled(ModelKind::Fopdt)
    };
    let Ok(mut valve) = Valve::new(&spec, dt) else {
        return (0.0, 0.0);
    };
    let follower = valve.simulate(op, op.first().copied().unwrap_or(0.0));
    speeds(&follower, dt, 0.0, &WINDOWS_S)
}

/// The note that the valve strokes slower than a valve in good order in a direction the
/// recording (`facts`, on `op`) asked it to go fast in, with the fastest speed measured each
/// way (`None` where nothing asked); `None` when no asked direction is slow. `worth_pct_per_s`
/// is the stroke speed worth maintenance.
pub(super) fn slow_strokes(facts: &Facts, op: &[f64], worth_pct_per_s: f64) -> Option<Note> {
    let largest = |sign: f64| {
        (facts.steps.iter())
            .map(|s| sign * s.size_pct)
            .fold(0.0f64, f64::max)
    };
    let (up, down) = (largest(1.0), largest(-1.0));
    let (good_up, good_down) = good_speeds(op, facts.dt);
    // What O_P asked for that way (0: nothing), and the least speed that keeps up with it.
    let asked = |step: f64, good: f64| {
        if step >= ASKED_STEP_PCT {
            (worth_pct_per_s, worth_pct_per_s)
        } else if good >= LEAST_ASKED_PCT_PER_S {
            let asked = good.min(worth_pct_per_s);
            (asked, SLOW_SHARE * asked)
        } else {
            (0.0, 0.0)
        }
    };
    let ((ask_up, need_up), (ask_down, need_down)) = (asked(up, good_up), asked(down, good_down));
    let (open, close) = (facts.open_speed, facts.close_speed);
    if open >= need_up && close >= need_down {
        return None;
    }
    // A speed is told where a step asked for it, or where the valve fell short.
    let told = |step: f64, speed: f64, need: f64| {
        (step >= ASKED_STEP_PCT || speed < need).then_some(speed)
    };
    let (slow_up, slow_down) = (open < need_up, close < need_down);
    let asked_pct_per_s = match (slow_up, slow_down) {
        (true, false) => ask_up,
        (false, true) => ask_down,
        _ => ask_up.max(ask_down),
    };
    Some(Note::SlowStrokes {
        opening_pct_per_s: told(up, open, need_up),
        closing_pct_per_s: told(down, close, need_down),
        largest_step_pct: up.max(down),
        asked_pct_per_s,
        worth_pct_per_s,
    })
}

/// Adds to `findings` the slew-rate finding of a valve slow both ways: uneven and slow at its
/// faster side too ([`slow_both_ways`], after the others), or slow through its positioner's
/// gain ([`slow_gain`], first).
pub(super) fn slow_findings(
    (findings, traces): (&mut Vec<Finding>, &[Trace]),
    spec: &ModelSpec,
    data: Data,
    noise: (f64, f64),
) {
    if findings.iter().any(|f| f.effect == Effect::Asymmetry) {
        findings.retain(|f| f.effect != Effect::SlewRate);
    }
    if let Some(slow) = slow_both_ways((findings, traces), spec, data, noise) {
        findings.push(slow);
    } else if let Some(slow) = slow_gain(findings, spec, data, noise) {
        // The baseline took the slowness in before any round ran: what was named since was
        // fitted around it.
        findings.insert(0, slow);
    }
}

/// The slew-rate finding of a valve uneven and slow both ways. A
/// `slew_rate` named in a round before the unevenness is, in the final model, the
/// unevenness's slower side: it is taken out and judged so too (seed 32's digital valve 324:
/// opening at 9.5 %/s named slow before its unevenness, closing at 37 %/s).
///
/// An asymmetry puts a speed limit each way in the model (`spec`, the final one): as a finding,
/// or as a trace (uneven by too little to name) that the rounds put in unnamed. The rounds
/// never try a slew-rate limit on a model that has one each way already; when the faster of
/// the two is itself slower than the speed worth maintenance, the valve is slow whichever way
/// it moves, not only uneven, and a planner needs to hear it. A valve in a quiet loop that
/// never holds its speed long enough for a slew-rate limit of its own to be plausible may
/// still be fitted best by two limits alike. Its size is the
/// stroke speed at half travel (the geometric mean of the two limits), with its interval. It
/// is named when the recording shows it: the asymmetry's ratio is bounded above (the recording
/// asked the faster side for its speed), and on the held-out blocks `spec` beats the valve
/// slow one way only (the faster limit raised to the speed worth maintenance, the slower as
/// it is) by what a finding must ([`judged`]).
fn slow_both_ways(
    (findings, traces): (&[Finding], &[Trace]),
    spec: &ModelSpec,
    data: Data,
    noise: (f64, f64),
) -> Option<Finding> {
    let (scorer, tuning) = (data.scorer, data.tuning);
    let (uneven, traced) = match findings.iter().find(|f| f.effect == Effect::Asymmetry) {
        Some(f) => (f.size, false),
        None => {
            let t = traces.iter().find(|t| t.effect == Effect::Asymmetry)?;
            (
                size::open_ended(Effect::Asymmetry, t.size, spec, scorer, tuning),
                true,
            )
        }
    };
    let named = findings.iter().any(|f| f.effect == Effect::SlewRate);
    if named || !uneven.high.is_finite() {
        return None;
    }
    let worth_speed = tuning.worth_speed();
    let faster = size::faster_limit(spec) / composed::half_open(spec);
    if composed::get(spec, Knob::ClosingSlew) <= 0.0 || faster >= worth_speed {
        return None;
    }
    // A trace's limits are the valve's stroke only where it is slow even closed (where it is
    // fastest: not its slowdown's doing) and where O_P asked a valve in good order for more
    // than that: a valve in a busy loop that answers the controller's noise at its
    // positioner's creep floor moves at one speed both ways, faster than a valve in good
    // order would ever have been asked to move there.
    if traced {
        let closed = size::faster_limit(spec);
        let (up, down) = good_speeds(data.rec.op, data.facts.dt);
        if closed >= worth_speed || up.max(down) <= closed {
            return None;
        }
    }
    let mut not_slow = spec.clone();
    let fast = size::speed_knobs(spec).1;
    composed::set(&mut not_slow, fast, worth_speed * composed::half_open(spec));
    let sized = (data.facts, data.rec.op, tuning);
    let now = size::size(Effect::SlewRate, spec, data.facts, data.rec.op, tuning);
    let size = size::interval(now, Effect::SlewRate, spec, scorer, sized);
    judged(
        (spec, &not_slow),
        size,
        vec![Knob::Slew, Knob::ClosingSlew],
        data,
        noise,
    )
}

/// The slew-rate finding of a valve slow through its positioner: `spec` (the final model)
/// moves at its gain times the error, below the slowest gain of a valve in good order
/// ([`GOOD_GAIN_PER_S`]), and never reaches a speed limit. A digital positioner drives its
/// pilots with a duty proportional to the error up to its full-drive error, so a valve whose
/// stroke is slow (small orifices, a low supply) keeps that proportion at every error a
/// closed loop makes and is fitted as a slow valve without a speed limit, at a gain below
/// [`SLOW_GAIN_SHARE`] of the good one (seed 42's digital valve 297: a stroke of 0.56 %/s in
/// a level loop, fitted at 0.23 /s, with a dead time of 0.50 s named instead). Its stroke
/// speed (the geometric mean of the two directions') is then at least the geometric mean of
/// the fastest speeds V_P shows each way ([`Facts::open_speed`], noise taken out; the faster
/// one where only one is measured) and at most the gain times [`FULL_DRIVE_ERROR_PCT`] (or the
/// model's speed limit, if lower): the size is the geometric mean of those ends, which are its
/// interval. Named when no speed
/// finding is, the fastest speed shown lies below that upper end (a valve seen moving faster
/// is not slow through its gain), and `spec` beats the same model at the good gain by what a
/// finding must ([`judged`]).
fn slow_gain(
    findings: &[Finding],
    spec: &ModelSpec,
    data: Data,
    noise: (f64, f64),
) -> Option<Finding> {
    let speed_named =
        (findings.iter()).any(|f| matches!(f.effect, Effect::SlewRate | Effect::Asymmetry));
    let gain = composed::get(spec, Knob::Gain);
    let half = composed::half_open(spec);
    let (open, close) = (data.facts.open_speed, data.facts.close_speed);
    let shown = open.max(close);
    let most = (gain * FULL_DRIVE_ERROR_PCT).min(size::faster_limit(spec)) / half;
    if speed_named || gain >= SLOW_GAIN_SHARE * GOOD_GAIN_PER_S || !(shown > 0.0 && shown < most) {
        return None;
    }
    let least = if open.min(close) > 0.0 {
        (open * close).sqrt()
    } else {
        shown
    };
    let mut not_slow = spec.clone();
    composed::set(&mut not_slow, Knob::Gain, GOOD_GAIN_PER_S);
    let worth_speed = data.tuning.worth_speed();
    let value = (least * most).sqrt();
    let size = Size {
        name: "stroke_speed_pct_per_s",
        unit: "%/s",
        value,
        low: least,
        high: most,
        worth: worth_speed / value,
        worth_low: worth_speed / most,
    };
    let mut found = judged((spec, &not_slow), size, vec![Knob::Gain], data, noise)?;
    if let Detail::SlewRate { gain_per_s, .. } = &mut found.facts.detail {
        *gain_per_s = Some(gain);
    }
    Some(found)
}

/// A slew-rate finding of `size` on the knobs `knobs` of `spec`, when the recording shows the
/// valve as slow as `spec` has it: on the held-out blocks `spec` beats `not_slow` (the same
/// valve faster) beyond noise in enough blocks, by a real share of the error above the noise
/// floor, BIC agreeing (`noise`: what noise alone leaves on the held-out blocks, and the
/// residual's correlation length), and the size is worth maintenance at its less material end.
fn judged(
    (spec, not_slow): (&ModelSpec, &ModelSpec),
    size: Size,
    knobs: Vec<Knob>,
    data: Data,
    (held_noise, corr_len): (f64, f64),
) -> Option<Finding> {
    let (scorer, tuning) = (data.scorer, data.tuning);
    let (sim_before, sim_after) = (scorer.simulate(not_slow), scorer.simulate(spec));
    let (before, after) = (scorer.errors_of(&sim_before), scorer.errors_of(&sim_after));
    let helped = blocks_helped(
        &scorer.paired(&sim_before, &sim_after),
        data.sigma,
        tuning.block_z,
    );
    let (excess_share, heldout_share) = shares(before.held, after.held, held_noise);
    let delta_bic = bic_change(&before, &after, 0, scorer.n_scored(), corr_len);
    tracing::debug!(
        size = size.value,
        held_before = before.held,
        held_after = after.held,
        helped,
        excess_share,
        delta_bic,
        worth_low = size.worth_low,
        "slow valve"
    );
    let shown = beyond_chance(helped, excess_share, delta_bic, size.worth_low, tuning)
        && heldout_share >= tuning.share_asked(size.worth_low)
        && size.worth_low >= tuning.materiality;
    shown.then(|| Finding {
        effect: Effect::SlewRate,
        facts: Evidence::of(
            Effect::SlewRate,
            spec,
            not_slow,
            data.facts,
            data.windows,
            data.sigma,
        ),
        params: diagnosis::params(spec, knobs.iter().copied()),
        knobs,
        alternatives: Vec::new(),
        heldout_sse_before: before.held,
        heldout_sse_after: after.held,
        delta_bic,
        support: Some(Support {
            excess_share,
            blocks_helped: helped,
        }),
        size,
        measure: Measure::HeldoutSse {
            before: before.held,
            after: after.held,
        },
    })
}

/// Puts a `slew_rate` finding after the others when the valve is slow at half travel only
/// because its opening slows it: the model's speed limit where the valve is fastest (closed,
/// the faster way) is as fast as a valve in good order (`worth_pct_per_s`), and an
/// opening-dependent slowdown (`state_dependent_delay`, a slowdown in `spec`) is among the
/// `findings`. The growing chamber, not the air supply, then makes the stroke slow, and the
/// finding that names it comes first.
pub(super) fn slowdown_first(findings: &mut [Finding], spec: &ModelSpec, worth_pct_per_s: f64) {
    let slowdown = composed::get(spec, Knob::Slowdown) > 0.0
        && (findings.iter()).any(|f| f.effect == Effect::StateDependentDelay);
    let limit = size::faster_limit(spec);
    if slowdown && limit >= worth_pct_per_s {
        findings.sort_by_key(|f| f.effect == Effect::SlewRate);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::facts;
    use vb_core::testkit::{noise, steps, Columns};

    const DT: f64 = 0.01;

    /// V_P of a valve following `op` at `gain` /s, no faster than `limit` %/s, read with
    /// 0.1 % of noise: a rate limiter written here, apart from the project's models.
    fn follow(op: &[f64], gain: f64, limit: f64) -> Vec<f64> {
        let e = noise(op.len(), 0.1);
        let mut x = op[0];
        (op.iter().zip(e))
            .map(|(&u, e)| {
                x += (gain * (u - x)).clamp(-limit, limit) * DT;
                x + e
            })
            .collect()
    }

    /// V_P of a valve driven at `full` %/s times its error over `band` % (at full speed beyond),
    /// read with 0.1 % of noise: a pulse-width-modulated positioner written here, apart from
    /// the project's models.
    fn driven(op: &[f64], full: f64, band: f64) -> Vec<f64> {
        let e = noise(op.len(), 0.1);
        let mut x = op[0];
        (op.iter().zip(e))
            .map(|(&u, e)| {
                x += full * ((u - x) / band).clamp(-1.0, 1.0) * DT;
                x + e
            })
            .collect()
    }

    /// `n` samples of O_P from a level loop: slow swings of a few % and the controller's
    /// chatter.
    fn level_loop(n: usize) -> Vec<f64> {
        let chatter = noise(2 * n, 0.3);
        (0..n)
            .map(|k| {
                let t = k as f64 * DT;
                let swing = 2.0 * (t / 70.0 * std::f64::consts::TAU).sin()
                    + 1.5 * (t / 23.0 * std::f64::consts::TAU + 1.0).sin();
                50.0 + swing + chatter[n + k]
            })
            .collect()
    }

    #[test]
    fn a_valve_moving_at_a_slow_gain_over_every_error_is_named_slow_first() {
        let op = level_loop(30_000);
        let diagnosed = |full: f64| {
            let rec = Columns::new(op.clone(), driven(&op, full, 2.5), DT);
            crate::diagnose::diagnose(&rec.view(), None, &|_, _| {}).unwrap()
        };
        // 0.6 %/s at full drive: a gain of 0.24 /s over every error of the loop.
        let slow = diagnosed(0.6);
        let first = &slow.findings[0];
        assert_eq!(first.effect, Effect::SlewRate, "{:?}", slow.findings);
        assert!(
            first.size.low <= 0.6 && 0.6 <= first.size.high,
            "{:?}",
            first.size
        );
        // 50 %/s at full drive, a gain of 20 /s: in good order.
        let fast = diagnosed(50.0);
        assert!(
            fast.findings.iter().all(|f| f.effect != Effect::SlewRate),
            "{:?}",
            fast.findings
        );
    }

    /// The note on a valve following `op` at `gain` /s, no faster than `limit` %/s.
    fn note_on(op: &[f64], gain: f64, limit: f64) -> Option<Note> {
        let rec = Columns::new(op.to_vec(), follow(op, gain, limit), DT);
        let f = facts::measure(&rec.view(), 0.1, 0.0);
        slow_strokes(&f, op, 40.0)
    }

    fn note(levels: &[f64], gain: f64, limit: f64) -> Option<Note> {
        note_on(&steps(12_000, 1_000, levels), gain, limit)
    }

    #[test]
    fn a_valve_asked_for_speed_and_stroking_slowly_is_slow_each_way_it_was_asked() {
        // Steps of 30 % both ways at 8 %/s: slow, at about 8 %/s each way.
        let Some(Note::SlowStrokes {
            opening_pct_per_s: Some(open),
            closing_pct_per_s: Some(close),
            largest_step_pct,
            asked_pct_per_s,
            worth_pct_per_s,
        }) = note(&[30.0, 60.0], 10.0, 8.0)
        else {
            panic!("a valve stroking at 8 %/s on 30 % steps is slow");
        };
        assert!((open - 8.0).abs() < 0.8, "{open}");
        assert!((close - 8.0).abs() < 0.8, "{close}");
        assert!((largest_step_pct - 30.0).abs() < 1e-9);
        assert_eq!((asked_pct_per_s, worth_pct_per_s), (40.0, 40.0));
        // Opening by 25 % but closing in 5 % steps: only the opening speed is measured.
        let up = note(&[50.0, 75.0, 70.0, 65.0, 60.0, 55.0, 50.0], 10.0, 8.0);
        assert!(
            matches!(
                up,
                Some(Note::SlowStrokes {
                    opening_pct_per_s: Some(_),
                    closing_pct_per_s: None,
                    ..
                })
            ),
            "{up:?}"
        );
    }

    #[test]
    fn a_fast_valve_or_one_never_asked_for_speed_is_not_slow() {
        // 30 % steps at 60 %/s.
        assert_eq!(note(&[30.0, 60.0], 10.0, 60.0), None);
        // 5 % steps never ask for 40 %/s: a slow valve is not told from a healthy one.
        assert_eq!(note(&[50.0, 55.0], 10.0, 8.0), None);
    }

    /// O_P ramping between 30 % and 60 % at `rate` %/s, held 5 s at each end, for 120 s.
    fn ramps(rate: f64) -> Vec<f64> {
        let ramp = (30.0 / rate / DT) as usize;
        let hold = (5.0 / DT) as usize;
        let cycle: Vec<f64> = (0..ramp)
            .map(|k| 30.0 + rate * k as f64 * DT)
            .chain(std::iter::repeat_n(60.0, hold))
            .chain((0..ramp).map(|k| 60.0 - rate * k as f64 * DT))
            .chain(std::iter::repeat_n(30.0, hold))
            .collect();
        cycle.iter().copied().cycle().take(12_000).collect()
    }

    fn ramp_note(rate: f64, limit: f64) -> Option<Note> {
        note_on(&ramps(rate), 10.0, limit)
    }

    #[test]
    fn a_valve_that_cannot_keep_up_with_a_ramp_is_slow() {
        // Ramps of 10 %/s (no step at all) followed at 2 %/s: slow each way, where a valve in
        // good order moves at about 10 %/s.
        let Some(Note::SlowStrokes {
            opening_pct_per_s: Some(open),
            closing_pct_per_s: Some(close),
            asked_pct_per_s,
            ..
        }) = ramp_note(10.0, 2.0)
        else {
            panic!("a valve stroking at 2 %/s on ramps of 10 %/s is slow");
        };
        assert!(
            (open - 2.0).abs() < 0.6 && (close - 2.0).abs() < 0.6,
            "{open} {close}"
        );
        assert!((9.0..=10.5).contains(&asked_pct_per_s), "{asked_pct_per_s}");
        // The same ramps followed at up to 60 %/s, or at 6 %/s (more than half of 10 %/s).
        assert_eq!(ramp_note(10.0, 60.0), None);
        assert_eq!(ramp_note(10.0, 6.0), None);
        // Ramps of 2 %/s ask too little to tell a 0.5 %/s valve from a healthy one.
        assert_eq!(ramp_note(2.0, 0.5), None);
    }
}
