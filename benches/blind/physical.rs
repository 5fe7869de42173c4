//! The physical family of the blind benchmark: valves of the project's physical model
//! (`model = "physical"`, `valve_bridge::synth::physical`), drawn healthy, given the planned
//! effects and labelled by the thresholds of `cases.rs`. Its draws and labels are those the
//! bench had before the digital family (the same valves for the same seed).
//!
//! Each label's truth: the transport delay (s), the Coulomb band (the stem's lost motion on a
//! reversal, %), the stroke speed at half travel (the flow limits over the chamber's volume
//! there, their geometric mean, %/s), the ratio of the faster flow limit to the slower, the
//! minimum flow at half travel (%/s), the median slip measured (%), the deadband (%), the
//! chamber's slowdown fully open (1 + g), the stop as the sensor reads it (%), the lattice (%)
//! and the reading's error where O_P operates the valve (%). Nothing here runs diagnosis.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use valve_bridge::diagnose::Effect;
use valve_bridge::model::{ModelSpec, PhysicalParams, Valve};
use valve_bridge::recording::Recording;
use valve_bridge::synth::{self, physical, SynthError};

use super::measures::{self, quantile};
use super::*;

/// One draw: healthy physics, the planned effects, the recording, its labels and truth.
pub(crate) fn draw_case(
    plan: &Plan,
    duration_s: f64,
    rng: &mut ChaCha8Rng,
    draws: usize,
) -> Result<Case, SynthError> {
    let broad = plan.excitation == NOISY_LOOP;
    let (noise, lattice) = draw_sensor(rng, broad);
    let mut healthy = healthy_spec(rng, noise, lattice, plan.seed);
    if broad {
        broaden(&mut healthy, rng);
    }
    let excitation = excitation(plan.excitation, rng);
    // Each draw its own O_P sequence, so a redraw is not stuck with one that never exercises
    // the planned effect.
    let op_seed: u64 = rng.gen();
    let mut spec = healthy.clone();
    let mut sizes = Vec::new();
    for &effect in &plan.effects {
        let size = if effect == Effect::Saturation {
            // A stop short of open or, as often, above closed.
            let low = rng.gen_bool(0.5);
            let op = synth::generate(&spec, excitation, duration_s, DT, 0.0, op_seed)?.op;
            let size = stop_size(&op, low, rng);
            if low {
                spec.travel.min_pct = size;
            } else {
                physical::apply(&mut spec, effect, size);
            }
            size
        } else {
            let size = log_uniform(rng, size_range(effect, noise, plan.excitation));
            build_effect(&mut spec, effect, size, rng);
            size
        };
        sizes.push((effect, size));
    }
    let rec = synth::generate(&spec, excitation, duration_s, DT, 0.0, op_seed)?;
    let (labels, truth) = labels(&spec, &healthy, &rec)?;
    Ok(Case {
        plan: plan.clone(),
        physics: Physics::Physical(spec),
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

/// A valve with every physical parameter inside its healthy range.
fn healthy_spec(rng: &mut ChaCha8Rng, noise: f64, lattice: f64, seed: u64) -> ModelSpec {
    let mut spec = physical::healthy();
    spec.dead_time_s = rng.gen_range(HEALTHY_DEAD_TIME_S.0..=HEALTHY_DEAD_TIME_S.1);
    let coulomb = rng.gen_range(HEALTHY_COULOMB_PCT.0..=HEALTHY_COULOMB_PCT.1);
    let fill = rng.gen_range(HEALTHY_FILL_PCT_PER_S.0..=HEALTHY_FILL_PCT_PER_S.1);
    spec.physical = Some(PhysicalParams {
        positioner_gain_per_s: rng.gen_range(3.0..=10.0),
        deadband_pct: rng.gen_range(HEALTHY_DEADBAND_PCT.0..=HEALTHY_DEADBAND_PCT.1),
        fill_rate_pct_per_s: fill,
        vent_rate_pct_per_s: fill * rng.gen_range(0.9..=1.1),
        min_rate_pct_per_s: 0.0,
        volume_growth: rng.gen_range(HEALTHY_GROWTH.0..=HEALTHY_GROWTH.1),
        natural_freq_hz: rng.gen_range(8.0..=25.0),
        damping_ratio: rng.gen_range(0.6..=1.0),
        coulomb_band_pct: coulomb,
        static_band_pct: coulomb
            + rng.gen_range(HEALTHY_STATIC_EXCESS_PCT.0..=HEALTHY_STATIC_EXCESS_PCT.1),
        sensor_gain: 1.0 + rng.gen_range(-0.001..=0.001),
        sensor_offset_pct: rng.gen_range(-0.05..=0.05),
        sensor_noise_pct: noise,
        sensor_resolution_pct: lattice,
        // A TOML integer is signed: the seed keeps 63 bits.
        noise_seed: seed >> 1,
        internal_step_s: 0.001,
    });
    spec
}

/// A healthy valve of the broadened class: its friction band and positioner gain drawn from
/// the wider ranges.
fn broaden(spec: &mut ModelSpec, rng: &mut ChaCha8Rng) {
    if let Some(p) = spec.physical.as_mut() {
        let excess = p.static_band_pct - p.coulomb_band_pct;
        p.coulomb_band_pct = rng.gen_range(BROAD_COULOMB_PCT.0..=BROAD_COULOMB_PCT.1);
        p.static_band_pct = p.coulomb_band_pct + excess;
        p.positioner_gain_per_s = rng.gen_range(BROAD_GAIN_PER_S.0..=BROAD_GAIN_PER_S.1);
    }
}

/// Builds `effect` at `size` into `spec`, with what the physics needs around it.
fn build_effect(spec: &mut ModelSpec, effect: Effect, size: f64, rng: &mut ChaCha8Rng) {
    match effect {
        Effect::Asymmetry => {
            // Slow venting or slow filling with equal odds; the slow side keeps at least
            // 0.3 %/s (after a slew limit, the ratio may have to be smaller than drawn).
            let fast = spec
                .physical
                .map_or(60.0, |p| p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s));
            let size = size.min(fast / 0.3).max(1.0);
            let ratio = if rng.gen_bool(0.5) { size } else { 1.0 / size };
            physical::apply(spec, effect, ratio);
        }
        Effect::MinSpeed => {
            if let Some(p) = spec.physical.as_mut() {
                let floor = (size * p.positioner_gain_per_s)
                    .min(16.0)
                    .min(p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s));
                p.min_rate_pct_per_s = floor;
                // A floor makes the stem overshoot by about 2 z q_min / w after the positioner
                // stops; a stiff stem (overshoot <= 0.05 %) with a deadband and a friction band
                // in the upper half of their healthy ranges lets the valve settle instead of
                // hunting.
                let needed = 2.0 * p.damping_ratio * floor / (std::f64::consts::TAU * 0.05);
                p.natural_freq_hz = p.natural_freq_hz.max(needed).min(100.0);
                p.internal_step_s = p.internal_step_s.min(0.07 / p.natural_freq_hz);
                let (db, c) = (HEALTHY_DEADBAND_PCT.1, HEALTHY_COULOMB_PCT.1);
                p.deadband_pct = p.deadband_pct.max(rng.gen_range(0.6 * db..=db));
                let excess = p.static_band_pct - p.coulomb_band_pct;
                p.coulomb_band_pct = p.coulomb_band_pct.max(rng.gen_range(0.4 * c..=c));
                p.static_band_pct = p.coulomb_band_pct + excess;
            }
        }
        Effect::Calibration => {
            let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
            physical::apply(spec, effect, sign * size);
            if let Some(p) = spec.physical.as_mut() {
                p.sensor_gain = 1.0 + rng.gen_range(-0.02..=0.02);
            }
        }
        _ => physical::apply(spec, effect, size),
    }
}

/// The effects `spec` holds by the thresholds, `healthy` being the same valve before any
/// effect was built in (for the limits that must be exercised to count), each with its truth.
pub(crate) fn labels(
    spec: &ModelSpec,
    healthy: &ModelSpec,
    rec: &Recording,
) -> Result<(Vec<Effect>, Vec<Truth>), SynthError> {
    let (Some(p), Some(h)) = (spec.physical, healthy.physical) else {
        return Ok((Vec::new(), Vec::new()));
    };
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
    let dead = spec.dead_time_s;
    add(dead >= DEAD_TIME_S, Effect::DeadTime, "dead_time_s", dead);
    let band = p.coulomb_band_pct;
    add(
        band >= BACKLASH_PCT,
        Effect::Backlash,
        "friction_band_pct",
        band,
    );
    let slipped = if p.static_band_pct - p.coulomb_band_pct >= STICTION_PCT {
        stick_slips(spec, rec)?
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
    let (lo, hi) = (quantile(&rec.vp, 0.05), quantile(&rec.vp, 0.95));
    let slower = (1.0 + p.volume_growth * hi / 100.0) / (1.0 + p.volume_growth * lo / 100.0);
    add(
        p.volume_growth >= GROWTH && slower >= GROWTH_EXPOSED_RATIO,
        Effect::StateDependentDelay,
        "open_vs_closed",
        1.0 + p.volume_growth,
    );
    let (fast, slow) = (
        p.fill_rate_pct_per_s.max(p.vent_rate_pct_per_s),
        p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s),
    );
    let half = 1.0 + p.volume_growth / 2.0;
    let slew = fast <= SLEW_PCT_PER_S && limit_exercised(spec, &h, rec, None)?;
    let speed = (fast * slow).sqrt() / half;
    add(slew, Effect::SlewRate, "stroke_speed_pct_per_s", speed);
    let closing = p.vent_rate_pct_per_s < p.fill_rate_pct_per_s;
    let asym = fast / slow >= ASYMMETRY_RATIO && limit_exercised(spec, &h, rec, Some(closing))?;
    add(asym, Effect::Asymmetry, "speed_ratio", fast / slow);
    let floor = p.min_rate_pct_per_s;
    add(
        floor / p.positioner_gain_per_s >= MIN_SPEED_BAND_PCT && floor_shown(spec, rec)?,
        Effect::MinSpeed,
        "min_speed_pct_per_s",
        floor / half,
    );
    let db = p.deadband_pct;
    add(db >= DEADBAND_PCT, Effect::Deadband, "deadband_pct", db);
    let (low, high) = (spec.travel.min_pct, spec.travel.max_pct);
    let stop = if 100.0 - high >= low { high } else { low };
    let asked = measures::saturation_asked(low, high, &rec.op);
    let read = p.sensor_gain * stop + p.sensor_offset_pct;
    add(asked, Effect::Saturation, "stop_pct", read);
    let q = p.sensor_resolution_pct;
    add(
        q >= QUANTIZATION_PCT.max(p.sensor_noise_pct),
        Effect::Quantization,
        "lattice_pct",
        q,
    );
    let err = measures::reading_error_pct(p.sensor_gain, p.sensor_offset_pct, &rec.op);
    add(
        err >= CALIBRATION_PCT,
        Effect::Calibration,
        "reading_error_pct",
        err,
    );
    Ok(split(out))
}

/// The labels of `truth`, in the vocabulary's order, and the truth in the same order.
pub(crate) fn split(mut truth: Vec<Truth>) -> (Vec<Effect>, Vec<Truth>) {
    truth.sort_by_key(|t| t.effect as usize);
    (truth.iter().map(|t| t.effect).collect(), truth)
}

/// Whether the flow limits of `spec` shape the recording: the same valve with the healthy
/// limits `h`, run noise-free on the recorded O_P, moves faster than `EXPOSED_SPEED_RATIO`
/// times the limit (over the chamber's volume at the opening) for `EXPOSED_S` in total (both ways for `None`, closing only for
/// `Some(true)`, opening only for `Some(false)`).
fn limit_exercised(
    spec: &ModelSpec,
    h: &PhysicalParams,
    rec: &Recording,
    closing: Option<bool>,
) -> Result<bool, SynthError> {
    let Some(p) = spec.physical else {
        return Ok(false);
    };
    let limit = match closing {
        None => p.fill_rate_pct_per_s.max(p.vent_rate_pct_per_s),
        Some(true) => p.vent_rate_pct_per_s,
        Some(false) => p.fill_rate_pct_per_s,
    };
    let mut free = spec.clone();
    free.physical = Some(PhysicalParams {
        fill_rate_pct_per_s: h.fill_rate_pct_per_s,
        vent_rate_pct_per_s: h.vent_rate_pct_per_s,
        sensor_noise_pct: 0.0,
        sensor_resolution_pct: 0.0,
        ..p
    });
    let vp0 = rec.vp.first().copied().unwrap_or(0.0);
    let sim = Valve::new(&free, DT)?.simulate(&rec.op, vp0);
    // The chamber's volume grows with the opening, so the stem's top speed there is the flow
    // limit over the volume (as in the model's chamber).
    let top = |x: f64, _| limit / (1.0 + p.volume_growth * (x / 100.0).clamp(0.0, 1.0));
    Ok(measures::exposed_s(&sim, closing, top) >= EXPOSED_S)
}

/// `spec` with a noise-free, continuous sensor, run on the recorded O_P: the true position.
fn true_position(spec: &ModelSpec, rec: &Recording) -> Result<Vec<f64>, SynthError> {
    let mut quiet = spec.clone();
    if let Some(p) = quiet.physical.as_mut() {
        (p.sensor_noise_pct, p.sensor_resolution_pct) = (0.0, 0.0);
        (p.sensor_gain, p.sensor_offset_pct) = (1.0, 0.0);
    }
    let vp0 = rec.vp.first().copied().unwrap_or(0.0);
    Ok(Valve::new(&quiet, DT)?.simulate(&rec.op, vp0))
}

/// The stem's slips ([`measures::slips`]) of at least half the static excess, against the
/// same stem without the excess (static band = Coulomb band).
fn stick_slips(spec: &ModelSpec, rec: &Recording) -> Result<Vec<f64>, SynthError> {
    let Some(p) = spec.physical else {
        return Ok(Vec::new());
    };
    let mut smooth = spec.clone();
    if let Some(q) = smooth.physical.as_mut() {
        q.static_band_pct = q.coulomb_band_pct;
    }
    let (x, y) = (true_position(spec, rec)?, true_position(&smooth, rec)?);
    let jump = (p.static_band_pct - p.coulomb_band_pct) / 2.0;
    Ok(measures::slips(&x, &y, jump))
}

/// Whether the minimum flow shows: the noise-free position with it stands away from the same
/// valve's without it by three sensor-noise sigmas (at least 0.1 %) for [`MIN_SPEED_SHOWN_S`],
/// and the valve also moves faster than the floor ([`EXPOSED_SPEED_RATIO`] times it, over
/// 0.1 s, for [`EXPOSED_S`]): a valve that only ever moves at its floor is a slew-limited valve
/// as far as any recording can tell.
fn floor_shown(spec: &ModelSpec, rec: &Recording) -> Result<bool, SynthError> {
    let Some(p) = spec.physical else {
        return Ok(false);
    };
    let mut without = spec.clone();
    if let Some(q) = without.physical.as_mut() {
        q.min_rate_pct_per_s = 0.0;
    }
    let (a, b) = (true_position(spec, rec)?, true_position(&without, rec)?);
    let least = (3.0 * p.sensor_noise_pct).max(0.1);
    let (apart, faster) = measures::floor_seconds(&a, &b, least, p.min_rate_pct_per_s);
    Ok(apart >= MIN_SPEED_SHOWN_S && faster >= EXPOSED_S)
}

/// The effects whose physics in `spec` lies outside the healthy ranges (whatever the
/// excitation did with them).
pub(crate) fn outside_healthy(spec: &ModelSpec) -> Vec<Effect> {
    let Some(p) = spec.physical else {
        return Vec::new();
    };
    let out_of = |x: f64, (lo, hi): (f64, f64)| x < lo - 1e-12 || x > hi + 1e-12;
    let fill = HEALTHY_FILL_PCT_PER_S;
    let slow = (fill.0 * 0.9, fill.1 * 1.1);
    let ratio = p.fill_rate_pct_per_s.max(p.vent_rate_pct_per_s)
        / p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s);
    let checks = [
        (
            Effect::DeadTime,
            out_of(spec.dead_time_s, HEALTHY_DEAD_TIME_S),
        ),
        (
            Effect::Backlash,
            out_of(p.coulomb_band_pct, HEALTHY_COULOMB_PCT),
        ),
        (
            Effect::Stiction,
            out_of(
                p.static_band_pct - p.coulomb_band_pct,
                HEALTHY_STATIC_EXCESS_PCT,
            ),
        ),
        (
            Effect::StateDependentDelay,
            out_of(p.volume_growth, HEALTHY_GROWTH),
        ),
        (
            Effect::SlewRate,
            out_of(p.fill_rate_pct_per_s, slow) && out_of(p.vent_rate_pct_per_s, slow),
        ),
        (Effect::Asymmetry, ratio > 1.1 / 0.9 + 1e-9),
        (Effect::MinSpeed, p.min_rate_pct_per_s > 0.0),
        (
            Effect::Deadband,
            out_of(p.deadband_pct, HEALTHY_DEADBAND_PCT),
        ),
        (
            Effect::Saturation,
            spec.travel.max_pct < 100.0 || spec.travel.min_pct > 0.0,
        ),
        (
            Effect::Quantization,
            p.sensor_resolution_pct > HEALTHY_LATTICE_PCT.1,
        ),
        (
            Effect::Calibration,
            (p.sensor_gain - 1.0).abs() > 0.001 + 1e-12 || p.sensor_offset_pct.abs() > 0.05,
        ),
    ];
    checks
        .into_iter()
        .filter_map(|(e, out)| out.then_some(e))
        .collect()
}
