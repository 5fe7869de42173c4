//! The digital family of the blind benchmark: a sampled, pulse-width-modulated positioner
//! (Bürkert-style) on a spring-diaphragm actuator filled and vented through orifices, a stem
//! with LuGre friction, and the position feedback through a linkage and an ADC
//! (`valve_bridge::synth::digital`, simulated apart from the project's models). Valves are
//! drawn healthy, given the planned effects, recorded through the bench's excitations and
//! labelled from their physics by the thresholds of `cases.rs`, with their truth.
//!
//! How each label is decided (and its truth, in the unit diagnosis sizes it in):
//!
//! | effect | physics built in | labelled when | truth |
//! |---|---|---|---|
//! | `dead_time` | set-point transport delay | delay + half a sample + line delay >= `DEAD_TIME_S` | that sum, s (the mean wait from O_P to the first flow) |
//! | `backlash` | play of the linkage to the potentiometer, inside the positioner's loop | play >= `BACKLASH_PCT` | the play (the stem's lost motion on a reversal beyond its friction), % |
//! | `stiction` | LuGre static level above Coulomb | the noise-free reading slips by >= `STICTION_PCT` within 0.1 s after 0.2 s still, where the same stem with static = Coulomb moves less than half as much, >= `STICK_SLIPS` times | median slip, % |
//! | `slew_rate` | both orifices small | both stroke speeds at half travel <= `SLEW_PCT_PER_S`, and the valve with its healthy orifices moves 1.5 times faster than the limit at that opening for 3 s | geometric mean of the two speeds at half travel, %/s |
//! | `asymmetry` | one orifice smaller | faster / slower speed at half travel >= `ASYMMETRY_RATIO`, exercised on the slow side as above | that ratio |
//! | `min_speed` | minimum pulse raised | the error below which it takes over, `min_pulse / (duty_per_pct * sample)`, >= `MIN_SPEED_BAND_PCT`, and the noise-free reading with it stands 3 noise sigmas (>= 0.1 %) from the same valve's without it for 3 s, while the valve moves 1.5 times faster than the floor for 3 s | the floor (one minimum pulse a sample at half travel), %/s |
//! | `deadband` | tolerance band | band width (twice the tolerance) >= `DEADBAND_PCT` | the width, % |
//! | `saturation` | stem stop below 100 % or above 0 % | O_P passes it by >= 1 % for >= 10 s | the stop as V_P reads it (the arm half the play short of the stem, through the transmitter), % |
//! | `quantization` | the feedback ADC's lattice | lattice >= `QUANTIZATION_PCT` and >= the noise | the lattice, % |
//! | `calibration` | the feedback transmitter's error | `|(a - 1) x + b| >= CALIBRATION_PCT` at the 5th or 95th percentile of O_P | that error, % |
//!
//! The chamber's volume growth is kept healthy (no `state_dependent_delay`): the family is
//! never drawn with one, and a healthy valve's stroke at 95 % is at most 1.4 times slower than
//! at 5 % (`tests/analysis/diagnose_blind_digital.rs`). Nothing here runs diagnosis.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use valve_bridge::diagnose::Effect;
use valve_bridge::recording::Recording;
use valve_bridge::synth::digital::{DigitalParams, DigitalValve};
use valve_bridge::synth::{self, SynthError};

use super::measures;
use super::physical::split;
use super::*;

/// The effects the family is drawn with: the vocabulary but `state_dependent_delay`.
pub(crate) const EFFECTS: [Effect; 10] = [
    Effect::DeadTime,
    Effect::Backlash,
    Effect::SlewRate,
    Effect::Asymmetry,
    Effect::MinSpeed,
    Effect::Stiction,
    Effect::Deadband,
    Effect::Saturation,
    Effect::Quantization,
    Effect::Calibration,
];

// Healthy ranges of the family: a positioner tuned to its actuator (X.TUNE), in good order.
/// Set-point transport delay, s (with half a sample and the line, at most 0.1 s).
pub(crate) const HEALTHY_INPUT_DELAY_S: (f64, f64) = (0.02, 0.08);
/// Line delay from the solenoids to the chamber, s.
pub(crate) const HEALTHY_LINE_DELAY_S: (f64, f64) = (0.0, 0.005);
/// Positioner's sampling period, s.
pub(crate) const SAMPLE_S: (f64, f64) = (0.005, 0.02);
/// Tolerance band, % (a band of twice this, at most 0.12 %).
pub(crate) const HEALTHY_TOLERANCE_PCT: (f64, f64) = (0.02, 0.06);
/// Positioner gain at half travel, 1/s, and its largest product with the sampling period (a
/// faster loop overshoots and hunts with the stem's dynamics).
pub(crate) const HEALTHY_GAIN_PER_S: (f64, f64) = (12.0, 22.0);
pub(crate) const GAIN_TIMES_SAMPLE: f64 = 0.3;
/// The broadened class's gain, 1/s.
pub(crate) const BROAD_GAIN_PER_S: (f64, f64) = (6.0, 22.0);
/// Error below which the minimum pulse takes over, %: so short a pulse moves the valve by
/// less than a third of the tolerance band.
pub(crate) const HEALTHY_PULSE_BAND_PCT: (f64, f64) = (0.03, 0.12);
/// Stroke speed at half travel with the fill solenoid open, %/s (venting within 10 %).
pub(crate) const HEALTHY_STROKE_PCT_PER_S: (f64, f64) = (45.0, 80.0);
/// Volume growth over the stroke.
pub(crate) const HEALTHY_GROWTH: (f64, f64) = (0.03, 0.15);
/// LuGre Coulomb level, % of travel, and the static level's excess over it. A reversal has to
/// cross twice the Coulomb level, so the stem's friction band is 0.04-0.2 %: like the physical
/// family's healthy band (at most 0.15 %), below the 0.3 % `diagnose` calls worth maintenance
/// and well below the 0.5-0.8 % bands that are faults.
pub(crate) const HEALTHY_COULOMB_PCT: (f64, f64) = (0.02, 0.1);
pub(crate) const HEALTHY_STATIC_EXCESS_PCT: (f64, f64) = (0.0, 0.02);
/// Linkage play, %.
pub(crate) const HEALTHY_PLAY_PCT: (f64, f64) = (0.0, 0.1);
/// Largest step of one minimum pulse for a valve with a minimum speed, %: the tolerance band
/// is widened to hold it (at most 0.135 %, still no deadband), so the valve settles.
const FLOOR_STEP_PCT: f64 = 0.22;

/// The fastest floor of a valve with a minimum speed under the excitation named `name`, %/s:
/// small steps move at a few %/s, ramps at 5-30 %/s for seconds. (In closed loop a valve
/// seldom moves at 1 %/s and no floor shows: such a valve is drawn as under the other
/// excitations and stays too faint to label.)
fn floor_cap(name: &str) -> f64 {
    match name {
        "small_steps" => 3.0,
        "ramps" => 6.0,
        _ => f64::INFINITY,
    }
}

/// One draw: healthy physics, the planned effects, the recording, its labels and truth.
pub(crate) fn draw_case(
    plan: &Plan,
    duration_s: f64,
    rng: &mut ChaCha8Rng,
    draws: usize,
) -> Result<Case, SynthError> {
    let broad = plan.excitation == NOISY_LOOP;
    let (noise, lattice) = draw_sensor(rng, broad);
    let healthy = healthy_params(rng, noise, lattice, plan.seed, broad);
    let excitation = excitation(plan.excitation, rng);
    let op_seed: u64 = rng.gen();
    let mut params = healthy;
    let mut sizes = Vec::new();
    for &effect in &plan.effects {
        let size = if effect == Effect::Saturation {
            let low = rng.gen_bool(0.5);
            let op = record(&params, excitation, duration_s, op_seed)?.op;
            let size = stop_size(&op, low, rng);
            if low {
                params.stop_low_pct = size;
            } else {
                params.stop_high_pct = 100.0 - size;
            }
            size
        } else {
            let size = log_uniform(rng, size_range(effect, noise, plan.excitation));
            build_effect(&mut params, effect, size, plan.excitation, rng);
            size
        };
        sizes.push((effect, size));
    }
    let rec = record(&params, excitation, duration_s, op_seed)?;
    let (labels, truth) = labels(&params, &healthy, &rec)?;
    Ok(Case {
        plan: plan.clone(),
        physics: Physics::Digital(params),
        excitation,
        op_seed,
        noise_pct: noise,
        lattice_pct: lattice,
        sizes,
        labels,
        truth,
        draws,
        rec,
    })
}

/// `params` recorded under `excitation` for `duration_s` (O_P seeded by `seed`).
pub(crate) fn record(
    params: &DigitalParams,
    excitation: Excitation,
    duration_s: f64,
    seed: u64,
) -> Result<Recording, SynthError> {
    let mut valve = DigitalValve::new(params, DT)?;
    synth::record(&mut valve, excitation, duration_s, DT, 0.0, seed)
}

fn within(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    rng.gen_range(lo..=hi)
}

/// A valve with every parameter inside its healthy range (the broadened class's gain when
/// `broad`), read by a feedback of `noise` and `lattice`.
pub(crate) fn healthy_params(
    rng: &mut ChaCha8Rng,
    noise: f64,
    lattice: f64,
    seed: u64,
    broad: bool,
) -> DigitalParams {
    let mut p = DigitalParams {
        sample_s: within(rng, SAMPLE_S),
        tolerance_pct: within(rng, HEALTHY_TOLERANCE_PCT),
        derivative_s: within(rng, (0.0, 0.02)),
        input_delay_s: within(rng, HEALTHY_INPUT_DELAY_S),
        line_delay_s: within(rng, HEALTHY_LINE_DELAY_S),
        travel_noise_pct: within(rng, (0.002, 0.005)),
        travel_lattice_pct: within(rng, (0.0, 0.01)),
        supply_bar: within(rng, (5.0, 7.0)),
        spring_start_bar: within(rng, (0.4, 1.2)),
        critical_ratio: within(rng, (0.3, 0.5)),
        volume_growth: within(rng, HEALTHY_GROWTH),
        natural_freq_hz: within(rng, (12.0, 25.0)),
        coulomb_pct: within(rng, HEALTHY_COULOMB_PCT),
        stribeck_pct_per_s: within(rng, (0.3, 2.0)),
        bristle_stiffness: within(rng, (100.0, 300.0)),
        play_pct: within(rng, HEALTHY_PLAY_PCT),
        gain: 1.0 + within(rng, (-0.001, 0.001)),
        offset_pct: within(rng, (-0.05, 0.05)),
        noise_pct: noise,
        lattice_pct: lattice,
        noise_seed: seed >> 1,
        ..DigitalParams::default()
    };
    p.spring_end_bar = p.spring_start_bar + within(rng, (1.0, 2.0));
    // Supply well above the spring's end: the fill orifice stays near choked over the stroke.
    p.supply_bar = p.supply_bar.max(p.spring_end_bar + 2.5);
    p.static_pct = p.coulomb_pct + within(rng, HEALTHY_STATIC_EXCESS_PCT);
    p.damp(within(rng, (0.6, 1.0)), within(rng, (0.3, 0.8)));
    let fill = within(rng, HEALTHY_STROKE_PCT_PER_S);
    p.set_stroke_speeds(fill, fill * within(rng, (0.9, 1.1)));
    let fastest = (GAIN_TIMES_SAMPLE / p.sample_s).min(HEALTHY_GAIN_PER_S.1);
    let lowest = if broad {
        BROAD_GAIN_PER_S.0
    } else {
        HEALTHY_GAIN_PER_S.0
    };
    let gain = within(rng, (lowest.min(fastest), fastest));
    set_gain(&mut p, gain);
    let band = within(rng, HEALTHY_PULSE_BAND_PCT);
    p.min_pulse_s = band * p.duty_per_pct * p.sample_s;
    p
}

/// Sets the PD law's duty per % so the positioner's gain at half travel is `gain` 1/s.
fn set_gain(p: &mut DigitalParams, gain: f64) {
    let speed =
        0.5 * (p.stroke_speed_pct_per_s(50.0, true) + p.stroke_speed_pct_per_s(50.0, false));
    p.duty_per_pct = gain / speed;
}

/// Builds `effect` at `size` (the units of `cases::size_range`) into `p`, for a recording
/// under the excitation named `excitation`.
fn build_effect(
    p: &mut DigitalParams,
    effect: Effect,
    size: f64,
    excitation: &str,
    rng: &mut ChaCha8Rng,
) {
    let (open, close) = (
        p.stroke_speed_pct_per_s(50.0, true),
        p.stroke_speed_pct_per_s(50.0, false),
    );
    match effect {
        Effect::DeadTime => p.input_delay_s = size,
        Effect::Backlash => p.play_pct = size,
        Effect::Stiction => p.static_pct = p.coulomb_pct + size,
        // The positioner keeps its tuning (its pulses, its duty per %): its gain falls with
        // the speed.
        Effect::SlewRate => p.set_stroke_speeds(size, size * close / open),
        Effect::Asymmetry => {
            // Slow venting or slow filling with equal odds; the slow side keeps 0.3 %/s.
            let ratio = size.min(open.min(close) / 0.3).max(1.0);
            if rng.gen_bool(0.5) {
                p.set_stroke_speeds(open, open / ratio);
            } else {
                p.set_stroke_speeds(close / ratio, close);
            }
        }
        Effect::MinSpeed => {
            // The floor is the band times the gain. Under gentle excitations the valve seldom
            // moves faster than a few %/s, where a faster floor is a slew limit to any
            // recording: there the positioner is detuned (a lower duty per %), so the floor
            // stays below what the excitation exceeds. One minimum pulse must not step past a
            // tolerance band widened to hold it (else the valve hunts).
            let floor = (size * p.gain_per_s())
                .min(floor_cap(excitation))
                .min(FLOOR_STEP_PCT / p.sample_s);
            let mean = 0.5 * (open + close);
            p.min_pulse_s = (floor * p.sample_s / mean).min(p.sample_s);
            set_gain(p, floor / size);
            let step = mean * p.min_pulse_s;
            p.tolerance_pct = p.tolerance_pct.max(0.6 * step);
        }
        Effect::Deadband => p.tolerance_pct = size / 2.0,
        Effect::Quantization => p.lattice_pct = size,
        Effect::Calibration => {
            p.offset_pct = if rng.gen_bool(0.5) { size } else { -size };
            p.gain = 1.0 + rng.gen_range(-0.02..=0.02);
        }
        Effect::StateDependentDelay | Effect::Saturation => {}
    }
}

/// `p` with a noise-free, continuous, calibrated feedback (the play kept): what V_P would be
/// without its sensor's own errors.
fn quiet(p: &DigitalParams) -> DigitalParams {
    DigitalParams {
        noise_pct: 0.0,
        lattice_pct: 0.0,
        gain: 1.0,
        offset_pct: 0.0,
        ..*p
    }
}

/// `p` run on the recorded O_P from its first V_P: the stem's positions (`stem`) or V_P.
fn replay(p: &DigitalParams, rec: &Recording, stem: bool) -> Result<Vec<f64>, SynthError> {
    let vp0 = rec.vp.first().copied().unwrap_or(0.0);
    Ok(DigitalValve::new(p, DT)?.simulate(&rec.op, vp0, stem))
}

/// The effects `p` holds by the thresholds, `healthy` being the same valve before any effect
/// was built in, each with its truth (module doc).
pub(crate) fn labels(
    p: &DigitalParams,
    healthy: &DigitalParams,
    rec: &Recording,
) -> Result<(Vec<Effect>, Vec<Truth>), SynthError> {
    let mut out = Vec::new();
    let mut add = |yes: bool, effect: Effect, name: &'static str, value: f64| {
        if yes {
            out.push(Truth {
                effect,
                name,
                value,
            });
        }
    };
    let dead = p.input_delay_s + p.sample_s / 2.0 + p.line_delay_s;
    add(dead >= DEAD_TIME_S, Effect::DeadTime, "dead_time_s", dead);
    add(
        p.play_pct >= BACKLASH_PCT,
        Effect::Backlash,
        "friction_band_pct",
        p.play_pct,
    );
    let slipped = if p.static_pct - p.coulomb_pct > HEALTHY_STATIC_EXCESS_PCT.1 {
        let smooth = DigitalParams {
            static_pct: p.coulomb_pct,
            ..quiet(p)
        };
        let (x, y) = (replay(&quiet(p), rec, false)?, replay(&smooth, rec, false)?);
        measures::slips(&x, &y, STICTION_PCT)
    } else {
        Vec::new()
    };
    let slip = measures::median(&slipped);
    add(
        slipped.len() >= STICK_SLIPS,
        Effect::Stiction,
        "slip_pct",
        slip,
    );
    let (open, close) = (
        p.stroke_speed_pct_per_s(50.0, true),
        p.stroke_speed_pct_per_s(50.0, false),
    );
    let (fast, slow) = (open.max(close), open.min(close));
    let slew = fast <= SLEW_PCT_PER_S && limit_exercised(p, healthy, rec, None)?;
    add(
        slew,
        Effect::SlewRate,
        "stroke_speed_pct_per_s",
        (fast * slow).sqrt(),
    );
    let asym =
        fast / slow >= ASYMMETRY_RATIO && limit_exercised(p, healthy, rec, Some(close < open))?;
    add(asym, Effect::Asymmetry, "speed_ratio", fast / slow);
    let floor = p.floor_speed_pct_per_s();
    let shown = p.min_pulse_band_pct() >= MIN_SPEED_BAND_PCT && floor_shown(p, rec)?;
    add(shown, Effect::MinSpeed, "min_speed_pct_per_s", floor);
    let width = 2.0 * p.tolerance_pct;
    add(
        width >= DEADBAND_PCT,
        Effect::Deadband,
        "deadband_pct",
        width,
    );
    let (low, high) = (p.stop_low_pct, p.stop_high_pct);
    // As V_P reads the stem there: the arm trails it by half the play on the way in.
    let half = p.play_pct / 2.0;
    let stop = if 100.0 - high >= low {
        high - half
    } else {
        low + half
    };
    let asked = measures::saturation_asked(low, high, &rec.op);
    let read = p.gain * stop + p.offset_pct;
    add(asked, Effect::Saturation, "stop_pct", read);
    let q = p.lattice_pct;
    let coarse = q >= QUANTIZATION_PCT.max(p.noise_pct);
    add(coarse, Effect::Quantization, "lattice_pct", q);
    let err = measures::reading_error_pct(p.gain, p.offset_pct, &rec.op);
    add(
        err >= CALIBRATION_PCT,
        Effect::Calibration,
        "reading_error_pct",
        err,
    );
    Ok(split(out))
}

/// Whether the orifices of `p` shape the recording: the same valve with the healthy orifices
/// of `h`, run noise-free on the recorded O_P, moves its stem faster than
/// [`EXPOSED_SPEED_RATIO`] times what `p` strokes at there for [`EXPOSED_S`] (both ways for
/// `None`, closing only for `Some(true)`, opening only for `Some(false)`).
fn limit_exercised(
    p: &DigitalParams,
    h: &DigitalParams,
    rec: &Recording,
    closing: Option<bool>,
) -> Result<bool, SynthError> {
    let free = DigitalParams {
        fill_per_s: h.fill_per_s,
        vent_per_s: h.vent_per_s,
        ..quiet(p)
    };
    let stem = replay(&free, rec, true)?;
    let top = |x: f64, down: bool| p.stroke_speed_pct_per_s(x, !down);
    Ok(measures::exposed_s(&stem, closing, top) >= EXPOSED_S)
}

/// Whether the minimum pulse shows: the noise-free reading with it stands three noise sigmas
/// (at least 0.1 %) away from the same valve's without it (pulses as short as the error asks)
/// for [`MIN_SPEED_SHOWN_S`], and the valve also moves [`EXPOSED_SPEED_RATIO`] times faster
/// than the floor for [`EXPOSED_S`].
fn floor_shown(p: &DigitalParams, rec: &Recording) -> Result<bool, SynthError> {
    let without = DigitalParams {
        min_pulse_s: 0.0,
        ..quiet(p)
    };
    let (a, b) = (
        replay(&quiet(p), rec, false)?,
        replay(&without, rec, false)?,
    );
    let least = (3.0 * p.noise_pct).max(0.1);
    let (apart, faster) = measures::floor_seconds(&a, &b, least, p.floor_speed_pct_per_s());
    Ok(apart >= MIN_SPEED_SHOWN_S && faster >= EXPOSED_S)
}
