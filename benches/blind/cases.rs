//! The valves of the blind diagnosis benchmark: drawn from the physical model, seeded, and
//! labelled from their physics by the thresholds below (never from what diagnosis finds).
//!
//! A plan fixes what a case is meant to hold (nothing, one effect, or two) and its excitation;
//! [`build`] draws a healthy valve (every physical parameter inside its healthy range), builds
//! the planned effects in at sizes from just above their label threshold to large, records
//! it, and labels it. Effects that only show when the excitation exercises them (a slew limit
//! the valve never reaches, a stop O_P never asks to pass) are labelled only when it does; a
//! draw whose labels differ from the plan is drawn again with the next sub-seed, so a case's
//! labels are exactly the effects whose physics is outside the healthy ranges.
//!
//! Used by `benches/diagnose_blind.rs` and, on short recordings, by
//! `tests/diagnose_blind_cases.rs`. Nothing here runs diagnosis.

#![allow(dead_code)]

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use valve_bridge::diagnose::Effect;
use valve_bridge::model::{ModelSpec, PhysicalParams, Valve};
use valve_bridge::recording::Recording;
use valve_bridge::synth::{self, physical, Excitation, SynthError};

/// Sample period of every recording, s (100 Hz).
pub(crate) const DT: f64 = 0.01;

// Label thresholds: an effect is labelled when its physics reaches these.
/// Transport delay, s: more than twice the slowest healthy one and above the 0.2 s a healthy
/// positioner may have.
pub(crate) const DEAD_TIME_S: f64 = 0.25;
/// Coulomb band, %: a reversal loses at least 0.6 % of travel, several times the largest
/// healthy band and above the noisiest sensor (0.25 %).
pub(crate) const BACKLASH_PCT: f64 = 0.6;
/// Static band above the Coulomb band, %: slips of about this size stand above the noise...
pub(crate) const STICTION_PCT: f64 = 0.4;
/// ...and the excitation makes the stem stick and slip at least this often (a stem that only
/// breaks away at the start of large moves, and settles smoothly, shows no stick-slip).
pub(crate) const STICK_SLIPS: usize = 10;
/// Chamber volume growth g: the open valve is at least twice as slow as the closed one...
pub(crate) const GROWTH: f64 = 1.0;
/// ...and between the openings the recording visits (5th to 95th percentile of V_P) the
/// response slows by at least half: a valve kept near one opening shows no dependence on it.
pub(crate) const GROWTH_EXPOSED_RATIO: f64 = 1.5;
/// Both flow limits at most this, %/s: a full stroke takes at least 4 s, well below the 40 %/s
/// a healthy positioner strokes at...
pub(crate) const SLEW_PCT_PER_S: f64 = 25.0;
/// Ratio of the faster to the slower flow limit: opening and closing speeds differ by half.
pub(crate) const ASYMMETRY_RATIO: f64 = 1.5;
/// ...and a limit (or the slower side of an asymmetry) counts only when the same valve without
/// it would have moved this many times faster than the limit...
pub(crate) const EXPOSED_SPEED_RATIO: f64 = 1.5;
/// ...for this long in total, s: the limit then shapes the recording.
pub(crate) const EXPOSED_S: f64 = 3.0;
/// Error below which the minimum flow takes over from proportional action (q_min / K), %:
/// small moves are visibly constant-rate at this size...
pub(crate) const MIN_SPEED_BAND_PCT: f64 = 0.4;
/// ...and the floor moves V_P (noise-free) away from where the same valve without it would
/// be, by three sensor-noise sigmas (at least 0.1 %) for this long in total, s.
pub(crate) const MIN_SPEED_SHOWN_S: f64 = 3.0;
/// Positioner deadband, %: the valve stops short by 0.15 % or more.
pub(crate) const DEADBAND_PCT: f64 = 0.3;
/// A stop below 100 % counts when O_P asks to pass it by at least this much, %...
pub(crate) const SATURATION_MARGIN_PCT: f64 = 1.0;
/// ...for this long in total, s.
pub(crate) const SATURATION_S: f64 = 10.0;
/// Sensor resolution, %: at least this and at least the sensor noise (a finer lattice is
/// dithered into the noise).
pub(crate) const QUANTIZATION_PCT: f64 = 0.15;
/// Largest sensor error |(a - 1) x + b| over the openings O_P visits (5th-95th percentile), %.
pub(crate) const CALIBRATION_PCT: f64 = 0.5;

// Healthy ranges (every case's physics starts inside all of them): the imperfections of a
// valve in good order, as large as the shared healthy case's (0.1 % friction band, 0.05 s
// transport delay) and a little more. They may be visible at the lowest sensor noise; they are
// not what a valve engineer would call a fault.
/// Transport delay, s.
pub(crate) const HEALTHY_DEAD_TIME_S: (f64, f64) = (0.02, 0.1);
/// Coulomb band, %.
pub(crate) const HEALTHY_COULOMB_PCT: (f64, f64) = (0.0, 0.15);
/// Static band above Coulomb, %.
pub(crate) const HEALTHY_STATIC_EXCESS_PCT: (f64, f64) = (0.0, 0.03);
/// Volume growth.
pub(crate) const HEALTHY_GROWTH: (f64, f64) = (0.0, 0.2);
/// Fill limit, %/s (the vent limit is within 10 % of it).
pub(crate) const HEALTHY_FILL_PCT_PER_S: (f64, f64) = (50.0, 100.0);
/// Positioner deadband, %.
pub(crate) const HEALTHY_DEADBAND_PCT: (f64, f64) = (0.0, 0.1);
/// Sensor lattice when there is one, %.
pub(crate) const HEALTHY_LATTICE_PCT: (f64, f64) = (0.005, 0.05);
/// Sensor noise levels, %.
pub(crate) const NOISE_LEVELS_PCT: [f64; 3] = [0.02, 0.1, 0.25];

// The broadened healthy class: valves in good order as they look in closed loop under a noisy
// controller with slow reversals (the level loop's inflow turns over minutes), wider than the
// ranges above where a healthy valve in service can be.
/// The excitation of the broadened healthy class.
pub(crate) const NOISY_LOOP: &str = "noisy_loop";
/// Coulomb band, %.
pub(crate) const BROAD_COULOMB_PCT: (f64, f64) = (0.0, 0.2);
/// Positioner gain, 1/s (the other healthy valves: 3-10).
pub(crate) const BROAD_GAIN_PER_S: (f64, f64) = (2.0, 10.0);
/// Sensor noise levels, %.
pub(crate) const BROAD_NOISE_LEVELS_PCT: [f64; 4] = [0.02, 0.1, 0.25, 0.4];
/// Noise of the loop's level sensor, %: the controller's output moves three times as much
/// (the default loop's is 0.15 %).
pub(crate) const BROAD_LEVEL_NOISE_PCT: (f64, f64) = (0.1, 0.5);

/// The excitations cycled over the cases.
pub(crate) const EXCITATIONS: [&str; 5] = [
    "random_steps",
    "closed_loop",
    "small_steps",
    "ramps",
    "mixed",
];

/// Sizes each effect is drawn at (log-uniform): from just above its threshold to large. A
/// flow limit only shows where the excitation asks for more speed than it allows, so under
/// gentle excitations (closed loop: a healthy valve rarely moves faster than 2 %/s; small
/// steps: 8 %/s; ramps: 12 %/s but for a few seconds) limits are drawn lower and ratios higher.
pub(crate) fn size_range(effect: Effect, noise_pct: f64, excitation: &str) -> (f64, f64) {
    let gentle = match excitation {
        "closed_loop" => 2,
        "small_steps" | "ramps" => 1,
        _ => 0,
    };
    match effect {
        Effect::DeadTime => (0.3, 2.0),
        Effect::Backlash => (0.7, 6.0),
        Effect::Stiction => (0.5, 3.0),
        Effect::StateDependentDelay => (1.2, 8.0),
        Effect::SlewRate => [(2.0, 20.0), (0.8, 6.0), (0.3, 1.5)][gentle],
        Effect::Asymmetry => [(1.7, 6.0), (5.0, 30.0), (40.0, 150.0)][gentle],
        Effect::MinSpeed => (0.5, 2.0),
        Effect::Deadband => (0.4, 3.0),
        // Drawn as the quantile of O_P the stop sits at (1 - it for a stop above closed); the
        // size is how far the stop lies from its end of travel.
        Effect::Saturation => (0.6, 0.97),
        Effect::Quantization => (1.2 * QUANTIZATION_PCT.max(noise_pct), 1.5),
        Effect::Calibration => (0.6, 4.0),
    }
}

/// What a case is meant to hold.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Plan {
    pub index: usize,
    pub seed: u64,
    pub effects: Vec<Effect>,
    pub excitation: &'static str,
}

/// A generated, labelled case.
#[derive(Debug, Clone)]
pub(crate) struct Case {
    pub plan: Plan,
    pub spec: ModelSpec,
    pub excitation: Excitation,
    pub noise_pct: f64,
    pub lattice_pct: f64,
    /// Each planned effect with its size (units of [`synth::physical`]).
    pub sizes: Vec<(Effect, f64)>,
    /// The effects the physics holds, by the thresholds above.
    pub labels: Vec<Effect>,
    /// Draws needed until the labels matched the plan.
    pub draws: usize,
    pub rec: Recording,
}

/// `n` plans from `seed`: a fifth healthy (at least 40 when `n` >= 200), 15 % with two
/// effects, the rest with one, every effect equally often, shuffled; then `n` * 3 / 20 more
/// healthy valves of the broadened class ([`NOISY_LOOP`]).
pub(crate) fn plans(seed: u64, n: usize) -> Vec<Plan> {
    let mut out = plans_of_effects(seed, n);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xb20ad);
    for _ in 0..n * 3 / 20 {
        out.push(Plan {
            index: out.len(),
            seed: rng.gen(),
            effects: Vec::new(),
            excitation: NOISY_LOOP,
        });
    }
    out
}

/// The `n` plans of [`plans`] before the broadened healthy class.
fn plans_of_effects(seed: u64, n: usize) -> Vec<Plan> {
    let healthy = if n >= 200 {
        40.max(n / 5)
    } else {
        n.div_ceil(5)
    };
    let doubles = (n * 15) / 100;
    let singles = n.saturating_sub(healthy + doubles);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut kinds: Vec<Vec<Effect>> = vec![Vec::new(); healthy.min(n)];
    for j in 0..singles {
        kinds.push(vec![Effect::ALL[j % Effect::ALL.len()]]);
    }
    for j in 0..doubles.min(n - kinds.len()) {
        let a = Effect::ALL[(j * 3) % Effect::ALL.len()];
        let b = Effect::ALL[(j * 3 + 1 + j / Effect::ALL.len()) % Effect::ALL.len()];
        kinds.push(if a == b { vec![a] } else { vec![a, b] });
    }
    // The k-th case of a kind gets the k-th excitation (shifted per kind), so every effect
    // meets every excitation.
    let mut seen: Vec<(Vec<Effect>, usize)> = Vec::new();
    let mut out: Vec<Plan> = kinds
        .into_iter()
        .map(|effects| {
            let key = effects.first().copied();
            let k = match seen.iter_mut().find(|(e, _)| e.first().copied() == key) {
                Some((_, c)) => {
                    *c += 1;
                    *c
                }
                None => {
                    seen.push((effects.clone(), 0));
                    0
                }
            };
            let shift = key.map_or(0, |e| e as usize);
            Plan {
                index: 0,
                seed: 0,
                excitation: EXCITATIONS[(k + shift) % EXCITATIONS.len()],
                effects,
            }
        })
        .collect();
    out.shuffle(&mut rng);
    for (i, p) in out.iter_mut().enumerate() {
        p.index = i;
        p.seed = rng.gen();
    }
    out
}

/// Most draws of one case; the last one is kept, labelled as it is, if none matched the plan.
pub(crate) const MAX_DRAWS: usize = 200;

/// Generates and labels the case of `plan`, `duration_s` long.
pub(crate) fn build(plan: &Plan, duration_s: f64) -> Result<Case, SynthError> {
    let mut draw = 1;
    loop {
        let mut rng = ChaCha8Rng::seed_from_u64(plan.seed.wrapping_add(draw as u64));
        let case = draw_case(plan, duration_s, &mut rng, draw)?;
        if same_set(&case.labels, &plan.effects) || draw == MAX_DRAWS {
            return Ok(case);
        }
        draw += 1;
    }
}

fn same_set(a: &[Effect], b: &[Effect]) -> bool {
    a.len() == b.len() && a.iter().all(|e| b.contains(e))
}

fn log_uniform(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    (rng.gen_range(lo.ln()..=hi.ln())).exp()
}

/// One draw: healthy physics, the planned effects, the recording and its labels.
fn draw_case(
    plan: &Plan,
    duration_s: f64,
    rng: &mut ChaCha8Rng,
    draws: usize,
) -> Result<Case, SynthError> {
    let broad = plan.excitation == NOISY_LOOP;
    let noise = if broad {
        BROAD_NOISE_LEVELS_PCT[rng.gen_range(0..BROAD_NOISE_LEVELS_PCT.len())]
    } else {
        NOISE_LEVELS_PCT[rng.gen_range(0..NOISE_LEVELS_PCT.len())]
    };
    let lattice = if rng.gen_bool(0.5) {
        rng.gen_range(HEALTHY_LATTICE_PCT.0..=HEALTHY_LATTICE_PCT.1)
    } else {
        0.0
    };
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
            let size = saturation_size(&spec, excitation, duration_s, op_seed, low, rng)?;
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
    let labels = labels(&spec, &healthy, &rec)?;
    Ok(Case {
        plan: plan.clone(),
        spec,
        excitation,
        noise_pct: noise,
        lattice_pct: lattice,
        sizes,
        labels,
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

fn excitation(name: &str, rng: &mut ChaCha8Rng) -> Excitation {
    match name {
        NOISY_LOOP => Excitation::NoisyLoop {
            level_pct: rng.gen_range(30.0..=70.0),
            level_noise_pct: rng.gen_range(BROAD_LEVEL_NOISE_PCT.0..=BROAD_LEVEL_NOISE_PCT.1),
        },
        "closed_loop" => Excitation::ClosedLoop {
            level_pct: rng.gen_range(30.0..=70.0),
        },
        "small_steps" => Excitation::SmallSteps {
            around_pct: rng.gen_range(20.0..=70.0),
        },
        "ramps" => Excitation::Ramps,
        "mixed" => Excitation::Mixed {
            low_pct: rng.gen_range(20.0..=40.0),
        },
        _ => Excitation::RandomSteps,
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

/// How far a stop lies from its end of travel: 100 - the stop for a stop short of open at
/// quantile `q` of the O_P the healthy valve gets, or the stop itself for one above closed
/// (`low`) at quantile 1 - `q`.
fn saturation_size(
    spec: &ModelSpec,
    excitation: Excitation,
    duration_s: f64,
    seed: u64,
    low: bool,
    rng: &mut ChaCha8Rng,
) -> Result<f64, SynthError> {
    let (lo, hi) = size_range(Effect::Saturation, 0.0, "");
    let q = rng.gen_range(lo..=hi);
    let rec = synth::generate(spec, excitation, duration_s, DT, 0.0, seed)?;
    Ok(if low {
        (quantile(&rec.op, 1.0 - q) + SATURATION_MARGIN_PCT).clamp(1.0, 95.0)
    } else {
        100.0 - (quantile(&rec.op, q) - SATURATION_MARGIN_PCT).clamp(5.0, 99.0)
    })
}

fn quantile(x: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v.get(((v.len().max(1) - 1) as f64 * q).round() as usize)
        .copied()
        .unwrap_or(f64::NAN)
}

/// The effects `spec` holds by the thresholds, `healthy` being the same valve before any
/// effect was built in (for the limits that must be exercised to count).
pub(crate) fn labels(
    spec: &ModelSpec,
    healthy: &ModelSpec,
    rec: &Recording,
) -> Result<Vec<Effect>, SynthError> {
    let (Some(p), Some(h)) = (spec.physical, healthy.physical) else {
        return Ok(Vec::new());
    };
    let mut out = Vec::new();
    let mut add = |yes: bool, e: Effect| {
        if yes {
            out.push(e);
        }
    };
    add(spec.dead_time_s >= DEAD_TIME_S, Effect::DeadTime);
    add(p.coulomb_band_pct >= BACKLASH_PCT, Effect::Backlash);
    add(
        p.static_band_pct - p.coulomb_band_pct >= STICTION_PCT
            && stick_slips(spec, rec)? >= STICK_SLIPS,
        Effect::Stiction,
    );
    let (lo, hi) = (quantile(&rec.vp, 0.05), quantile(&rec.vp, 0.95));
    let slower = (1.0 + p.volume_growth * hi / 100.0) / (1.0 + p.volume_growth * lo / 100.0);
    add(
        p.volume_growth >= GROWTH && slower >= GROWTH_EXPOSED_RATIO,
        Effect::StateDependentDelay,
    );
    let (fast, slow) = (
        p.fill_rate_pct_per_s.max(p.vent_rate_pct_per_s),
        p.fill_rate_pct_per_s.min(p.vent_rate_pct_per_s),
    );
    let slew = fast <= SLEW_PCT_PER_S;
    add(
        slew && limit_exercised(spec, &h, rec, None)?,
        Effect::SlewRate,
    );
    let asym = fast / slow >= ASYMMETRY_RATIO;
    let closing = p.vent_rate_pct_per_s < p.fill_rate_pct_per_s;
    add(
        asym && limit_exercised(spec, &h, rec, Some(closing))?,
        Effect::Asymmetry,
    );
    add(
        p.min_rate_pct_per_s / p.positioner_gain_per_s >= MIN_SPEED_BAND_PCT
            && floor_shown(spec, rec)?,
        Effect::MinSpeed,
    );
    add(p.deadband_pct >= DEADBAND_PCT, Effect::Deadband);
    add(saturation_asked(spec, rec), Effect::Saturation);
    add(
        p.sensor_resolution_pct >= QUANTIZATION_PCT.max(p.sensor_noise_pct),
        Effect::Quantization,
    );
    let (lo, hi) = (quantile(&rec.op, 0.05), quantile(&rec.op, 0.95));
    let err = |x: f64| ((p.sensor_gain - 1.0) * x + p.sensor_offset_pct).abs();
    add(err(lo).max(err(hi)) >= CALIBRATION_PCT, Effect::Calibration);
    out.sort_by_key(|e| *e as usize);
    Ok(out)
}

/// True when O_P asks to pass a stop below 100 % (or above 0 %) by the margin long enough.
fn saturation_asked(spec: &ModelSpec, rec: &Recording) -> bool {
    let (lo, hi) = (spec.travel.min_pct, spec.travel.max_pct);
    let over = rec
        .op
        .iter()
        .filter(|&&u| {
            (hi < 100.0 && u >= hi + SATURATION_MARGIN_PCT)
                || (lo > 0.0 && u <= lo - SATURATION_MARGIN_PCT)
        })
        .count();
    over as f64 * DT >= SATURATION_S
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
    let w = 10;
    // The chamber's volume grows with the opening, so the stem's top speed there is the flow
    // limit over the volume (as in the model's chamber).
    let top = |x: f64| limit / (1.0 + p.volume_growth * (x / 100.0).clamp(0.0, 1.0));
    let fast = sim
        .windows(w + 1)
        .filter(|s| {
            let speed = (s[w] - s[0]) / (w as f64 * DT);
            let along = match closing {
                None => speed.abs(),
                Some(true) => -speed,
                Some(false) => speed,
            };
            along > EXPOSED_SPEED_RATIO * top(s[0])
        })
        .count();
    Ok(fast as f64 * DT >= EXPOSED_S)
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

/// How often the stem sticks and slips: moves of at least half the static excess within 0.1 s
/// after it stood still (within 0.01 %) for 0.2 s, while the same stem without the excess
/// (static band = Coulomb band) moved less than half as much (a move a command starts is no
/// slip).
fn stick_slips(spec: &ModelSpec, rec: &Recording) -> Result<usize, SynthError> {
    let Some(p) = spec.physical else {
        return Ok(0);
    };
    let mut smooth = spec.clone();
    if let Some(q) = smooth.physical.as_mut() {
        q.static_band_pct = q.coulomb_band_pct;
    }
    let (x, y) = (true_position(spec, rec)?, true_position(&smooth, rec)?);
    let jump = (p.static_band_pct - p.coulomb_band_pct) / 2.0;
    let (still, within) = (20, 10);
    let mut count = 0;
    let mut k = still;
    while k + within < x.len() {
        let (lo, hi) = x[k - still..=k]
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        let moved = (x[k + within] - x[k]).abs();
        if hi - lo <= 0.01 && moved >= jump && (y[k + within] - y[k]).abs() < moved / 2.0 {
            count += 1;
            k += within + still;
        } else {
            k += 1;
        }
    }
    Ok(count)
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
    let apart = a
        .iter()
        .zip(&b)
        .filter(|(x, y)| (*x - *y).abs() >= least)
        .count();
    let w = 10;
    let faster = a
        .windows(w + 1)
        .filter(|s| {
            let speed = (s[w] - s[0]).abs() / (w as f64 * DT);
            speed >= EXPOSED_SPEED_RATIO * p.min_rate_pct_per_s
        })
        .count();
    Ok(apart as f64 * DT >= MIN_SPEED_SHOWN_S && faster as f64 * DT >= EXPOSED_S)
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
