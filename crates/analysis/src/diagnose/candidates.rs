//! Candidates: for each effect of the vocabulary, which knobs of the composed valve it frees,
//! in which boxes, from which starts; and the refit jobs of a round built from them.
//!
//! An effect that is already in the model, or that the data cannot identify (saturation when
//! V_P never stops short of O_P), has no candidate; nor has quantization, which is named from
//! the sensor lattice itself.
//! Every candidate also refits the positioner gain, the dead time and (while it is a healthy
//! one) the stroke-speed limit, so an effect is judged against the best the rest of the model
//! can do, not against a model fitted without it; the dead time's candidate also refits a slow
//! stroke already named, within a factor of two.
//!
//! Not here: the refit ([`super::refit`]) or the decision ([`super::judge`]).

use super::delay::MAX_DEAD_TIME_S;
use super::facts::Facts;
use super::refit::{
    free_gain, spread_starts, Free, NOMINAL_MIN_SLEW_PCT_PER_S, START_TIME_CONSTANT_S,
};
use vb_core::model::composed::{self, Effect, Knob, FASTEST_PCT_PER_S};
use vb_core::model::ModelSpec;

/// Slowest stroke speed a fit considers, %/s (a full stroke in over half an hour).
const SLOWEST_PCT_PER_S: f64 = 0.05;
/// Share of the speed V_P holds for a second or more each way ([`Facts::sustained_speeds`])
/// below which no fit puts an uneven valve's limit that way ([`uneven_limits`]): the valve was
/// seen moving that fast, so its limit is no slower. The share leaves room for a reading's
/// gain and for a chamber that fills faster near closed than at half travel. A fit whose
/// blocks never ask the valve for its speed one way leaves that limit where nothing holds it,
/// even below what the held-out blocks show the valve doing (seed 48's physical valve 45,
/// closing at 25 %/s in held-out blocks alone, was given a closing limit of 21 %/s, and its
/// opening limit of 9.7 %/s went unnamed). A single limit gets no floor: in a valve whose
/// chamber fills more slowly the more it is open, a limit the same at every opening sits well
/// below the speeds held near closed (`pub_sdd_paper_rs`, 14 times slower fully open, holds
/// 10 %/s near closed and needs a single limit below 6 %/s before its slowdown is named).
const SUSTAINED_SHARE: f64 = 0.6;
/// Shortest time constant a dead time's refit starts the positioner with, s
/// ([`keeping_the_lag`]).
const SHORTEST_START_LAG_S: f64 = 0.05;
/// Longest crossing time of lost motion a fit considers, s: a friction band of 6 % crossed at
/// pin-cart II's pace (0.3-0.8 s per % of band) takes 3 s at mid travel and nearly 5 s fully
/// open, and a fit pinned at the edge of its box is not named.
const LONGEST_CROSSING_S: f64 = 10.0;
/// Span of O_P (5th to 95th percentile) below which a calibration is fitted as an offset
/// alone, % of travel: the sensor's gain shows only across a fifth of the travel or more.
const MIN_GAIN_SPAN_PCT: f64 = 20.0;
/// Largest wind-up past a travel stop a fit of a stop searches, % of travel: a
/// spring-diaphragm chamber winds on to its supply, several spring ranges above the pressure
/// that holds the stem at a stop (a 6 bar supply on a 0.4-2 bar spring is 250 % beyond a stop
/// at half travel), and must vent all that before the valve leaves the stop.
pub(super) const WINDUP_RANGE_PCT: f64 = 400.0;
/// Where the first fit of a stop starts its wind-up, % of travel. A drive winds up most often
/// within a travel, but one that winds on to its supply holds the valve at the stop for
/// seconds after O_P has come back (1.7-1.8 s on seed 30's digital valve 360, up to 10 s on
/// its 279); from a start within a travel the fit moves the stop itself to the end of its box
/// instead, and the stop is not named.
const WINDUP_STARTS_PCT: [f64; 3] = [20.0, 100.0, 320.0];

/// One effect to refit, from several starts (the knobs and boxes are the same in all).
#[derive(Debug, Clone)]
pub(crate) struct Job {
    pub effect: Effect,
    pub starts: Vec<Vec<Free>>,
    /// How many knobs, first in each start, are the effect's own (the rest are the model's
    /// gain, dead time and stroke speed, refitted with it).
    pub own: usize,
}

/// The refit jobs of a round: every effect in `effects` with its variants, each from spread
/// starts, with the gain and dead time freed too. `td_max` bounds the dead time of effects
/// other than `dead_time` (the baseline's, until a dead time was found).
pub(crate) fn jobs(
    effects: &[Effect],
    current: &ModelSpec,
    facts: &Facts,
    dt: f64,
    td_max: f64,
) -> Vec<Job> {
    let mut jobs: Vec<Job> = Vec::new();
    let td = composed::get(current, Knob::DeadTime);
    for &effect in effects {
        for variant in variants(effect, current, facts, td_max) {
            let own = variant.len();
            let td_hi = if effect == Effect::DeadTime {
                MAX_DEAD_TIME_S
            } else {
                td_max.max(td)
            };
            for mut free in spread_starts(variant) {
                let mut rest = rest_of_model(current, dt, td_hi, &free);
                let answer = answer_start(&free, facts).filter(|_| effect == Effect::DeadTime);
                for gain in rest.iter_mut().filter(|f| f.knob == Knob::Gain) {
                    if let Some(start) = answer {
                        *gain = keeping_the_lag(*gain, current, start);
                    }
                    if starts_wide(&free, facts) {
                        *gain = gain.from(gain.init.max(1.0 / START_TIME_CONSTANT_S));
                    }
                }
                free.extend(rest);
                if effect == Effect::DeadTime {
                    free.extend(named_slow_stroke(current));
                    free.extend(named_windup(current));
                }
                // Variants that differ only in their own start share the spread starts.
                let same_box = |starts: &[Vec<Free>]| {
                    starts[0].len() == free.len()
                        && starts[0].iter().zip(&free).all(|(a, b)| a.same_box(b))
                };
                match jobs
                    .iter_mut()
                    .find(|j| j.effect == effect && same_box(&j.starts))
                {
                    Some(j) if j.starts.contains(&free) => {}
                    Some(j) => j.starts.push(free),
                    None => jobs.push(Job {
                        effect,
                        starts: vec![free],
                        own,
                    }),
                }
            }
        }
    }
    jobs
}

/// An opening and a closing limit, from the fastest move measured each way and from each side
/// three times faster; neither given less than [`SUSTAINED_SHARE`] of the speed V_P held that
/// way for a second or more.
fn uneven_limits(facts: &Facts) -> Vec<Vec<Free>> {
    let (open, close) = (facts.open_speed.max(0.5), facts.close_speed.max(0.5));
    let (held_open, held_close) = facts.sustained_speeds;
    let limit = |knob, start, held: f64| {
        Free::new(knob, SLOWEST_PCT_PER_S, FASTEST_PCT_PER_S, start)
            .at_least(SUSTAINED_SHARE * held)
    };
    [(open, close), (3.0 * open, close), (open, 3.0 * close)]
        .map(|(o, c)| {
            vec![
                limit(Knob::Slew, o, held_open),
                limit(Knob::ClosingSlew, c, held_close),
            ]
        })
        .to_vec()
}

/// The model's own knobs a candidate refits with those of its effect (`own`): the positioner
/// gain, the dead time up to `td_hi` and, while it is a healthy one, the stroke-speed limit;
/// those `own` frees already are left out.
pub(crate) fn rest_of_model(spec: &ModelSpec, dt: f64, td_hi: f64, own: &[Free]) -> Vec<Free> {
    let mut rest = vec![free_gain(spec, dt)];
    if !own.iter().any(|f| f.knob == Knob::DeadTime) {
        let td = composed::get(spec, Knob::DeadTime);
        rest.push(Free::new(Knob::DeadTime, 0.0, td_hi.max(td), td));
    }
    rest.extend(healthy_slew(spec, own));
    rest
}

/// The first start of a deadband's refit, %.
const BAND_START_PCT: f64 = 0.5;

/// A positioner band twice as wide as the distance from O_P the valve rests at
/// ([`Facts::rest_distance_pct`], the band's half width), when that is wider than twice
/// [`BAND_START_PCT`]. In a closed loop (no holds) a slow positioner explains a wide band's
/// waits as well, and the baseline fits one; a refit from a narrow band keeps that slow gain
/// (seed 56's physical 75, a band of 2.19 % at a gain of 9.9 /s: fitted 0.78 % at 0.66 /s, and
/// named a slow stroke).
fn wide_band(facts: &Facts) -> Option<f64> {
    let band = 2.0 * facts.rest_distance_pct;
    (band > 2.0 * BAND_START_PCT).then_some(band.min(10.0))
}

/// Whether `own` is the positioner band from where the valve rests ([`wide_band`]): the gain
/// then starts no slower than a healthy positioner's ([`START_TIME_CONSTANT_S`]), so the band
/// and not a slow positioner explains the waits.
fn starts_wide(own: &[Free], facts: &Facts) -> bool {
    let wide = wide_band(facts);
    own.iter()
        .any(|f| f.knob == Knob::PositionerDeadband && Some(f.init) == wide)
}

/// The dead time `own` starts from, when that is where V_P's increments answer O_P's
/// ([`Facts::answer_delay_s`]).
fn answer_start(own: &[Free], facts: &Facts) -> Option<f64> {
    let answer = facts.answer_delay_s?;
    let at = |f: &Free| f.knob == Knob::DeadTime && f.init == answer;
    own.iter().any(at).then_some(answer)
}

/// The gain `gain` (of `spec`) starting fast enough that a dead time starting at `start`
/// leaves the model's whole lag (dead time and time constant) as it was, down to a time
/// constant of [`SHORTEST_START_LAG_S`]: where V_P's answer starts, what is left of the lag is
/// the positioner's, and a longer delay with the same positioner would lag twice; the simplex
/// from there seldom finds a delay whose valley is narrow (a loop's chatter repeated late).
/// Never slower than `gain` starts.
fn keeping_the_lag(gain: Free, spec: &ModelSpec, start: f64) -> Free {
    let lag = composed::get(spec, Knob::DeadTime) + 1.0 / gain.init.max(gain.def.lo);
    let fast = 1.0 / (lag - start).max(SHORTEST_START_LAG_S);
    gain.from(fast.clamp(gain.init, gain.def.hi))
}

/// The stroke-speed limit of `spec` free within a healthy positioner's range, when it lies
/// there and `free` does not free it already: the baseline fitted it next to a missing effect
/// (a dead time too short, no travel stop), where it may have settled on a compromise that
/// only the effect's refit can undo.
fn healthy_slew(spec: &ModelSpec, free: &[Free]) -> Option<Free> {
    let slew = composed::get(spec, Knob::Slew);
    let taken = free
        .iter()
        .any(|f| matches!(f.knob, Knob::Slew | Knob::ClosingSlew));
    let healthy = (NOMINAL_MIN_SLEW_PCT_PER_S..=FASTEST_PCT_PER_S).contains(&slew)
        && spec.effects.closing_slew_pct_per_s == 0.0;
    (healthy && !taken).then(|| {
        Free::new(
            Knob::Slew,
            NOMINAL_MIN_SLEW_PCT_PER_S,
            FASTEST_PCT_PER_S,
            slew,
        )
    })
}

/// The stroke-speed limits of `spec` when they are a slow stroke already named (or put in as
/// a trace), each free within a factor of two of where it is: they were fitted beside the
/// baseline's short dead time, and a slow stroke that starts late reaches its target late too,
/// so a longer delay only fits together with the stroke it shifts. Freed for the dead time's
/// candidate only: beside lost motion a refitted stroke also takes over part of a reversal's
/// wait, which only the crossing time should.
fn named_slow_stroke(spec: &ModelSpec) -> Vec<Free> {
    let slew = composed::get(spec, Knob::Slew);
    let uneven = spec.effects.closing_slew_pct_per_s > 0.0;
    if slew >= NOMINAL_MIN_SLEW_PCT_PER_S && !uneven {
        return Vec::new();
    }
    let around = |knob| {
        let v = composed::get(spec, knob);
        Free::new(
            knob,
            (0.5 * v).max(SLOWEST_PCT_PER_S),
            (2.0 * v).min(FASTEST_PCT_PER_S),
            v,
        )
    };
    let mut free = vec![around(Knob::Slew)];
    if uneven {
        free.push(around(Knob::ClosingSlew));
    }
    free
}

/// The wind-up of `spec`'s travel stop when it has one, free over its whole range: it was
/// fitted beside the baseline's short dead time, where a drive that must come back from past
/// the stop also stood in for the valve leaving it late; with the delay that takes over, the
/// wind-up must shrink or grow with it (seed 57's physical 81, a dead time of 0.52 s beside a
/// stop on ramps: refitted without its wind-up, the drawn delay made the held-out error twice
/// as large, and an unevenness of 12.5 times was named in its place).
fn named_windup(spec: &ModelSpec) -> Option<Free> {
    has_stop(spec).then(|| windup_from(composed::get(spec, Knob::Windup)))
}

/// Whether `spec` has a travel stop short of 0 or 100 %.
fn has_stop(spec: &ModelSpec) -> bool {
    spec.travel.min_pct > 0.0 || spec.travel.max_pct < 100.0
}

/// A stop's wind-up, free over its whole range ([`WINDUP_RANGE_PCT`]) from `start`, %.
pub(super) fn windup_from(start: f64) -> Free {
    Free::new(Knob::Windup, 0.0, WINDUP_RANGE_PCT, start)
}

/// The variants to try for `effect` on top of `spec`, or none when it is already there or the
/// data cannot identify it.
pub(crate) fn variants(
    effect: Effect,
    spec: &ModelSpec,
    facts: &Facts,
    td_max: f64,
) -> Vec<Vec<Free>> {
    let get = |k| composed::get(spec, k);
    let f = Free::new;
    let slew = get(Knob::Slew);
    let speed = facts.open_speed.max(facts.close_speed).max(0.5);
    match effect {
        // From the baseline's dead time, and from its whole lag (dead time and time
        // constant): a baseline that took a long delay for a slow positioner has the lag
        // right and its parts wrong, and a simplex from its dead time does not find the delay.
        // And from where V_P's increments answer O_P's, when longer: a loop's chatter repeated
        // late leaves a valley too narrow for a simplex from the lag ([`super::delay`]).
        Effect::DeadTime if td_max < MAX_DEAD_TIME_S => {
            let td = get(Knob::DeadTime);
            let lag = td + 1.0 / get(Knob::Gain).max(0.05);
            let answer = facts.answer_delay_s.filter(|&d| d > td.max(0.3));
            [td.max(0.3), lag.clamp(0.3, 0.9 * MAX_DEAD_TIME_S)]
                .into_iter()
                .chain(answer)
                .map(|start| vec![f(Knob::DeadTime, 0.0, MAX_DEAD_TIME_S, start)])
                .collect()
        }
        // Lost motion either as pin-cart II's crossing time (eq. 7) or as a friction band the
        // positioner crosses at its own speed (the lost time then depends on the move); the
        // error surface of either has many valleys, so each starts from several sizes.
        Effect::Backlash if get(Knob::Crossing) == 0.0 && get(Knob::FrictionBand) == 0.0 => vec![
            vec![f(Knob::Crossing, 0.02, LONGEST_CROSSING_S, 0.2)],
            vec![f(Knob::Crossing, 0.02, LONGEST_CROSSING_S, 0.8)],
            vec![f(Knob::FrictionBand, 0.05, 20.0, 0.3)],
            vec![f(Knob::FrictionBand, 0.05, 20.0, 1.0)],
            vec![f(Knob::FrictionBand, 0.05, 20.0, 3.0)],
        ],
        Effect::StateDependentDelay
            if get(Knob::Slowdown) == 0.0 && get(Knob::CrossingSlope) == 0.0 =>
        {
            slowdown_variants(spec)
        }
        Effect::SlewRate
            if slew >= NOMINAL_MIN_SLEW_PCT_PER_S && spec.effects.closing_slew_pct_per_s == 0.0 =>
        {
            vec![vec![f(
                Knob::Slew,
                SLOWEST_PCT_PER_S,
                slew.min(FASTEST_PCT_PER_S),
                speed.min(slew),
            )]]
        }
        // From the fastest move measured each way, and from each side three times faster: a
        // valve in a busy loop never moves far enough either way to show its limits, and how
        // much faster one side is shows only in where the valve rests (below O_P when it
        // closes faster, and by more the faster it closes).
        Effect::Asymmetry if spec.effects.closing_slew_pct_per_s == 0.0 => uneven_limits(facts),
        // A positioner's creep floor can be as fast as a slow stroke: up to the slew limit.
        // Where the floor is slower than the valve closes its small errors it does nothing and
        // a fit feels no slope, so it also starts from a tenth and three tenths of the limit
        // (from 1 %/s alone, seed 31's physical valve 204, a floor of 1.9 %/s beside an uneven
        // stroke, was named `slew_rate`).
        Effect::MinSpeed if get(Knob::MinSpeed) == 0.0 => {
            let top = slew.clamp(1.0, 100.0);
            [1.0, 0.1 * top, 0.3 * top]
                .map(|start| vec![f(Knob::MinSpeed, 0.05, top, start.clamp(0.05, top))])
                .to_vec()
        }
        // Stick-slip either on the valve's input (Choudhury) or inside the positioner loop
        // (breakaway: sticks when slow, slips past the target, hunts).
        Effect::Stiction if get(Knob::Stickband) == 0.0 && get(Knob::Breakaway) == 0.0 => vec![
            vec![
                f(Knob::Stickband, 0.05, 10.0, 0.5),
                f(Knob::JumpFraction, 0.0, 1.0, 0.5),
            ],
            vec![
                f(Knob::Stickband, 0.05, 10.0, 2.0),
                f(Knob::JumpFraction, 0.0, 1.0, 0.5),
            ],
            vec![f(Knob::Breakaway, 0.05, 10.0, 0.5)],
        ],
        // A band either on the input (the target moves only once O_P leaves it; the valve
        // then closes in on it ever more slowly) or in the positioner (no action inside it,
        // full action outside: the valve arrives still moving and stops at once). The
        // positioner's band also from where the valve rests ([`wide_band`]).
        Effect::Deadband if get(Knob::Deadband) == 0.0 && get(Knob::PositionerDeadband) == 0.0 => {
            let wide = wide_band(facts).map(|b| vec![f(Knob::PositionerDeadband, 0.02, 10.0, b)]);
            [
                vec![f(Knob::Deadband, 0.02, 10.0, BAND_START_PCT)],
                vec![f(Knob::PositionerDeadband, 0.02, 10.0, BAND_START_PCT)],
            ]
            .into_iter()
            .chain(wide)
            .collect()
        }
        Effect::Saturation if !has_stop(spec) => travel_limits(facts),
        // The sensor lattice is named from its evidence, not refitted (see `rounds`).
        Effect::Calibration if get(Knob::CalGain) == 1.0 && get(Knob::CalOffset) == 0.0 => {
            let (g, o) = steady_gain_offset(facts);
            let (lo, hi) = facts.op_span_pct;
            if hi - lo < MIN_GAIN_SPAN_PCT {
                // Held near one opening, a gain trades against the offset: only the reading
                // error there is seen, and a gain fitted to it would be applied far beyond.
                let at_mid = (g - 1.0) * (lo + hi) / 2.0 + o;
                vec![vec![f(Knob::CalOffset, -15.0, 15.0, at_mid)]]
            } else {
                vec![vec![
                    f(Knob::CalGain, 0.7, 1.3, g),
                    f(Knob::CalOffset, -15.0, 15.0, o),
                ]]
            }
        }
        _ => vec![],
    }
}

/// An opening-dependent slowdown, and (with a crossing time) a crossing time that grows with
/// opening. The slowdown lowers the stroke speed with opening too, so the speed limit (at the
/// closed end, where the valve is fastest) is refitted with it. Until a slow stroke has been
/// found on its own, that limit stays a healthy one: a valve that is slow even when closed is
/// `slew_rate`, judged on its own.
fn slowdown_variants(spec: &ModelSpec) -> Vec<Vec<Free>> {
    let f = Free::new;
    let slew = composed::get(spec, Knob::Slew);
    let limit = if slew >= NOMINAL_MIN_SLEW_PCT_PER_S {
        f(
            Knob::Slew,
            NOMINAL_MIN_SLEW_PCT_PER_S,
            FASTEST_PCT_PER_S,
            slew.min(FASTEST_PCT_PER_S),
        )
    } else {
        f(
            Knob::Slew,
            SLOWEST_PCT_PER_S,
            FASTEST_PCT_PER_S,
            (1.5 * slew).min(FASTEST_PCT_PER_S),
        )
    };
    let mut v = vec![vec![f(Knob::Slowdown, 0.0, 20.0, 1.0), limit]];
    let c = composed::get(spec, Knob::Crossing);
    if c > 0.0 {
        v.push(vec![
            f(Knob::Crossing, 0.0, LONGEST_CROSSING_S, c * 0.5),
            f(Knob::CrossingSlope, -c / 100.0, 0.05, c / 100.0),
        ]);
    }
    v
}

/// The travel stops to fit, in a box of ±2 % around where the recording shows them, each
/// with the drive's wind-up past it: each stop the recording shows on its own and, when it
/// shows both, both together (an offset sensor can make V_P look held at the bottom when the
/// stop is only at the top).
fn travel_limits(facts: &Facts) -> Vec<Vec<Free>> {
    let high = facts.stop_high_pct.map(|hi| {
        Free::new(
            Knob::TravelMax,
            (hi - 2.0).max(1.0),
            (hi + 2.0).min(100.0),
            hi,
        )
    });
    let low = facts.stop_low_pct.map(|lo| {
        Free::new(
            Knob::TravelMin,
            (lo - 2.0).max(0.0),
            (lo + 2.0).min(99.0),
            lo,
        )
    });
    let mut stops: Vec<Vec<Free>> = [high, low].into_iter().flatten().map(|f| vec![f]).collect();
    if let (Some(h), Some(l)) = (high, low) {
        stops.push(vec![h, l]);
    }
    // The drive winds up past the stop while O_P asks for more, and must come back first.
    let windup = windup_from(20.0);
    (stops.iter())
        .flat_map(|set| {
            WINDUP_STARTS_PCT.map(|start| {
                let mut set = set.clone();
                set.push(windup.from(start));
                set
            })
        })
        .collect()
}

/// Least-squares line through the settled holds: V_P = g O_P + o (1, 0 with too few holds).
fn steady_gain_offset(facts: &Facts) -> (f64, f64) {
    let h = &facts.holds;
    if h.len() < 3 {
        return (1.0, 0.0);
    }
    let n = h.len() as f64;
    let mx = h.iter().map(|x| x.op_pct).sum::<f64>() / n;
    let my = h.iter().map(|x| x.vp_pct).sum::<f64>() / n;
    let sxx: f64 = h.iter().map(|x| (x.op_pct - mx).powi(2)).sum();
    if sxx < 1.0 {
        return (1.0, my - mx);
    }
    let g = h
        .iter()
        .map(|x| (x.op_pct - mx) * (x.vp_pct - my))
        .sum::<f64>()
        / sxx;
    (g.clamp(0.7, 1.3), my - g.clamp(0.7, 1.3) * mx)
}

#[cfg(test)]
mod tests {
    use super::*;
    use vb_core::model::{bundled, ModelKind};
    use vb_core::testkit::{steps, Columns};

    /// The knobs the calibration candidate frees on O_P stepping through `levels`, read 0.5 %
    /// high, and the start of the offset.
    fn calibration_knobs(levels: &[f64]) -> (Vec<Knob>, f64) {
        let dt = 0.01;
        let op = steps(20_000, 500, levels);
        let vp: Vec<f64> = op.iter().map(|x| x + 0.5).collect();
        let rec = Columns::new(op, vp, dt);
        let facts = super::super::facts::measure(&rec.view(), 0.05, 0.0);
        let spec = composed::compose(&bundled(ModelKind::Fopdt), dt);
        let variants = variants(Effect::Calibration, &spec, &facts, 1.0);
        assert_eq!(variants.len(), 1);
        let offset = (variants[0].iter())
            .find(|f| f.knob == Knob::CalOffset)
            .map_or(f64::NAN, |f| f.init);
        (variants[0].iter().map(|f| f.knob).collect(), offset)
    }

    #[test]
    fn a_calibration_seen_near_one_opening_is_an_offset_alone() {
        let (knobs, offset) = calibration_knobs(&[48.0, 51.0, 49.5, 52.0, 47.0]);
        assert_eq!(knobs, [Knob::CalOffset]);
        assert!((offset - 0.5).abs() < 1e-9, "{offset}");
        let (knobs, _) = calibration_knobs(&[20.0, 70.0, 45.0, 85.0, 30.0]);
        assert_eq!(knobs, [Knob::CalGain, Knob::CalOffset]);
    }

    /// The facts of a valve that follows O_P stepping between 40 and 60 % exactly, and the
    /// bundled FOPDT model (at 100 Hz).
    fn following_steps() -> (Facts, ModelSpec) {
        let op = steps(20_000, 500, &[40.0, 60.0]);
        let rec = Columns::new(op.clone(), op, 0.01);
        let facts = super::super::facts::measure(&rec.view(), 0.05, 0.0);
        (facts, composed::compose(&bundled(ModelKind::Fopdt), 0.01))
    }

    #[test]
    fn an_uneven_valve_is_also_tried_with_each_side_three_times_faster_than_measured() {
        let (facts, spec) = following_steps();
        let starts: Vec<(f64, f64)> = variants(Effect::Asymmetry, &spec, &facts, 1.0)
            .iter()
            .map(|v| (v[0].init, v[1].init))
            .collect();
        let (open, close) = (facts.open_speed.max(0.5), facts.close_speed.max(0.5));
        assert_eq!(
            starts,
            [(open, close), (3.0 * open, close), (open, 3.0 * close)]
        );
    }

    #[test]
    fn an_uneven_valve_is_never_fitted_below_what_it_held_each_way() {
        let (mut facts, mut spec) = following_steps();
        composed::set(&mut spec, Knob::Slew, 100.0);
        facts.sustained_speeds = (20.0, 12.0);
        let floors = |effect| {
            (variants(effect, &spec, &facts, 1.0).iter())
                .map(|v| v.iter().map(|f| (f.knob, f.floor)).collect::<Vec<_>>())
                .collect::<Vec<_>>()
        };
        // Opening held at 20 %/s and closing at 12 %/s: each limit from 0.6 of its own; a
        // single limit anywhere in its box.
        let uneven = vec![(Knob::Slew, 0.6 * 20.0), (Knob::ClosingSlew, 0.6 * 12.0)];
        assert_eq!(floors(Effect::Asymmetry), vec![uneven; 3]);
        assert_eq!(
            floors(Effect::SlewRate),
            [[(Knob::Slew, SLOWEST_PCT_PER_S)]]
        );
    }

    #[test]
    fn only_the_dead_time_refits_a_slow_stroke_already_named() {
        let (facts, mut spec) = following_steps();
        let boxes = |spec: &ModelSpec, effect| {
            let jobs = jobs(&[effect], spec, &facts, 0.01, 1.0);
            let free = &jobs[0].starts[0];
            (free.iter())
                .filter(|f| matches!(f.knob, Knob::Slew | Knob::ClosingSlew))
                .map(|f| (f.knob, f.def.lo, f.def.hi))
                .collect::<Vec<_>>()
        };
        // A healthy stroke is refitted with every effect, in a healthy positioner's range.
        composed::set(&mut spec, Knob::Slew, 100.0);
        let healthy = [(Knob::Slew, NOMINAL_MIN_SLEW_PCT_PER_S, FASTEST_PCT_PER_S)];
        assert_eq!(boxes(&spec, Effect::DeadTime), healthy);
        assert_eq!(boxes(&spec, Effect::Backlash), healthy);
        // A slow stroke, uneven: both limits within a factor of two, for the dead time only.
        composed::set(&mut spec, Knob::Slew, 3.0);
        composed::set(&mut spec, Knob::ClosingSlew, 4.0);
        assert_eq!(
            boxes(&spec, Effect::DeadTime),
            [(Knob::Slew, 1.5, 6.0), (Knob::ClosingSlew, 2.0, 8.0)]
        );
        assert!(boxes(&spec, Effect::Backlash).is_empty());
    }

    #[test]
    fn only_the_dead_time_refits_a_named_stop_s_wind_up() {
        let (facts, mut spec) = following_steps();
        let windup = |spec: &ModelSpec, effect| {
            let jobs = jobs(&[effect], spec, &facts, 0.01, 1.0);
            (jobs[0].starts[0].iter())
                .filter(|f| f.knob == Knob::Windup)
                .map(|f| (f.def.lo, f.def.hi, f.init))
                .collect::<Vec<_>>()
        };
        assert!(
            windup(&spec, Effect::DeadTime).is_empty(),
            "no stop, no wind-up"
        );
        spec.travel.max_pct = 70.0;
        composed::set(&mut spec, Knob::Windup, 13.0);
        assert_eq!(
            windup(&spec, Effect::DeadTime),
            [(0.0, WINDUP_RANGE_PCT, 13.0)]
        );
        assert!(windup(&spec, Effect::Backlash).is_empty());
    }

    #[test]
    fn the_dead_time_also_starts_where_the_increments_answer_keeping_the_whole_lag() {
        let (mut facts, mut spec) = following_steps();
        composed::set(&mut spec, Knob::DeadTime, 0.1);
        composed::set(&mut spec, Knob::Gain, 0.5);
        let starts = |facts: &Facts, effect| {
            let at = |free: &[Free], knob| free.iter().find(|f| f.knob == knob).map(|f| f.init);
            (jobs(&[effect], &spec, facts, 0.01, 0.2)[0].starts.iter())
                .map(|free| (at(free, Knob::DeadTime), at(free, Knob::Gain)))
                .collect::<Vec<_>>()
        };
        // The increments answer 1.5 s late: a start there, besides the floor, a share of the
        // box and the whole lag (2.1 s), with a time constant of what its dead time leaves of
        // that lag; the other starts keep the model's gain.
        facts.answer_delay_s = Some(1.5);
        let with = starts(&facts, Effect::DeadTime);
        let mut tds: Vec<f64> = (with.iter())
            .filter_map(|s| s.0.map(|td| (td * 1e3).round() / 1e3))
            .collect();
        tds.sort_by(f64::total_cmp);
        tds.dedup();
        assert_eq!(tds, [0.3, 1.2, 1.5, 2.1]);
        for (td, gain) in &with {
            let expected = if *td == Some(1.5) { 1.0 / 0.6 } else { 0.5 };
            assert!(
                gain.is_some_and(|g| (g - expected).abs() < 1e-9),
                "{with:?}"
            );
        }
        facts.answer_delay_s = None;
        assert_eq!(starts(&facts, Effect::DeadTime).len(), with.len() - 1);
        // Another effect's starts leave the dead time and the gain where the model has them.
        for (td, gain) in starts(&facts, Effect::Backlash) {
            assert_eq!((td, gain), (Some(0.1), Some(0.5)));
        }
    }

    #[test]
    fn a_valve_resting_far_from_o_p_also_starts_a_wide_positioner_band_at_a_healthy_gain() {
        let (mut facts, mut spec) = following_steps();
        composed::set(&mut spec, Knob::Gain, 0.5);
        let starts = |facts: &Facts| {
            let at = |free: &[Free], knob| free.iter().find(|f| f.knob == knob).map(|f| f.init);
            (jobs(&[Effect::Deadband], &spec, facts, 0.01, 0.2).iter())
                .flat_map(|j| j.starts.iter())
                .map(|free| (at(free, Knob::PositionerDeadband), at(free, Knob::Gain)))
                .collect::<Vec<_>>()
        };
        // Resting 1.1 % from O_P: a band of 2.2 % too, its gain no slower than 1 / 0.3 s;
        // every other start keeps the model's gain.
        facts.rest_distance_pct = 1.1;
        let with = starts(&facts);
        assert!(
            with.contains(&(Some(2.2), Some(1.0 / START_TIME_CONSTANT_S))),
            "{with:?}"
        );
        for (band, gain) in &with {
            assert!(*band == Some(2.2) || *gain == Some(0.5), "{with:?}");
        }
        // Resting within twice the narrow start's half width: no wide start.
        facts.rest_distance_pct = 0.4;
        let without = starts(&facts);
        assert_eq!(without.len(), with.len() - 1);
        assert!(without.iter().all(|s| s.1 == Some(0.5)), "{without:?}");
    }
}
