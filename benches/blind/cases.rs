//! The valves of the blind diagnosis benchmark: two families, each seeded and labelled from
//! its physics by the thresholds below (never from what diagnosis finds).
//!
//! - **physical** (`physical.rs`): the project's physical model (`model = "physical"`, not
//!   the composed pin-cart valve diagnosis fits).
//! - **digital** (`digital.rs`): a sampled, pulse-width-modulated digital positioner on a
//!   spring-diaphragm actuator with LuGre friction and a position feedback through a linkage,
//!   simulated apart from the project's models (`valve_bridge::synth::digital`).
//!
//! A plan fixes a case's family, what it is meant to hold (nothing, one effect, or two) and
//! its excitation; [`build`] draws a healthy valve of its family (every parameter inside its
//! healthy range), builds the planned effects in at sizes from just above their label
//! threshold to large, records it, and labels it. Effects that only show when the excitation
//! exercises them (a slew limit the valve never reaches, a stop O_P never asks to pass) are
//! labelled only when it does; a draw whose labels differ from the plan is drawn again with
//! the next sub-seed, so a case's labels are exactly the effects whose physics is outside the
//! healthy ranges. Each label comes with the physical truth of its size, in the unit diagnosis
//! sizes it in (`Truth`), so the intervals diagnosis reports can be checked against it.
//!
//! Used by `benches/diagnose_blind.rs` and, on short recordings, by
//! `tests/analysis/diagnose_blind_cases.rs`. Nothing here runs diagnosis.

#![allow(dead_code)]

#[path = "digital.rs"]
pub(crate) mod digital;
#[path = "measures.rs"]
pub(crate) mod measures;
#[path = "physical.rs"]
pub(crate) mod physical;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use valve_bridge::diagnose::Effect;
use valve_bridge::model::ModelSpec;
use valve_bridge::recording::Recording;
use valve_bridge::synth::digital::DigitalParams;
use valve_bridge::synth::{Excitation, SynthError};

/// Sample period of every recording, s (100 Hz).
pub(crate) const DT: f64 = 0.01;
/// Length of every recording of the bench, s.
pub(crate) const DURATION_S: f64 = 600.0;
/// Share of the rows a logged recording lacks V_P in (`--as-logged`).
pub(crate) const LOST_SHARE: f64 = 0.005;
/// Valves of the physical family a seed's plan draws (the digital family: half as many).
pub(crate) const PLAN_VALVES: usize = 220;

// Label thresholds: an effect is labelled when its physics reaches these (how each family
// measures it: `physical.rs` and `digital.rs`).
/// Transport delay before the positioner acts, s: more than twice the slowest healthy one and
/// above the 0.2 s a healthy positioner may have.
pub(crate) const DEAD_TIME_S: f64 = 0.25;
/// Lost motion on a reversal, % (the physical family's Coulomb band, the digital family's
/// linkage play): a reversal loses at least 0.6 % of travel, several times the largest
/// healthy band and above the noisiest sensor (0.25 %).
pub(crate) const BACKLASH_PCT: f64 = 0.6;
/// Static band above the Coulomb band, %: slips of about this size stand above the noise (the
/// digital family counts slips of at least this size)...
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
/// Positioner deadband (the digital family's tolerance band, both sides), %: the valve stops
/// short by 0.15 % or more.
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

// Healthy ranges of the physical family (the digital family's are in `digital.rs`; every
// case's physics starts inside all of them): the imperfections of a
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

/// A family of valves: which simulator a case comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Family {
    /// The project's physical model (`physical.rs`).
    Physical,
    /// The digital positioner simulated apart from the project's models (`digital.rs`).
    Digital,
}

impl Family {
    pub(crate) const ALL: [Family; 2] = [Family::Physical, Family::Digital];

    pub(crate) fn name(self) -> &'static str {
        match self {
            Family::Physical => "physical",
            Family::Digital => "digital",
        }
    }
}

/// What a case is meant to hold.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Plan {
    pub index: usize,
    pub seed: u64,
    pub family: Family,
    pub effects: Vec<Effect>,
    pub excitation: &'static str,
}

/// What a case's valve is.
#[derive(Debug, Clone)]
pub(crate) enum Physics {
    Physical(ModelSpec),
    Digital(DigitalParams),
}

/// The physical size of a labelled effect, named and in the unit diagnosis sizes it in
/// (`valve_bridge::diagnose::size`: `dead_time_s`, `friction_band_pct`, ...).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Truth {
    pub effect: Effect,
    pub name: &'static str,
    pub value: f64,
}

/// A generated, labelled case.
#[derive(Debug, Clone)]
pub(crate) struct Case {
    pub plan: Plan,
    pub physics: Physics,
    pub excitation: Excitation,
    /// Seed of the excitation's O_P (and of a closed loop's controller noise).
    pub op_seed: u64,
    pub noise_pct: f64,
    pub lattice_pct: f64,
    /// Each planned effect with the size it was drawn at (its family's units).
    pub sizes: Vec<(Effect, f64)>,
    /// The effects the physics holds, by the thresholds above.
    pub labels: Vec<Effect>,
    /// The physical size of each label.
    pub truth: Vec<Truth>,
    /// Draws needed until the labels matched the plan.
    pub draws: usize,
    pub rec: Recording,
}

/// Salt of the digital family's plans: its own stream, so the physical family's plans and
/// seeds are those of a seed before the family was added.
const DIGITAL_SALT: u64 = 0xd1617a1;
/// Salt of a family's broadened healthy class.
const BROAD_SALT: u64 = 0xb20ad;

/// The plans of `seed` for `n` physical valves: first the physical family ([`family_plans`]
/// of `n`), then the digital family (of `n` / 2), numbered on.
pub(crate) fn plans(seed: u64, n: usize) -> Vec<Plan> {
    let mut out = family_plans(Family::Physical, seed, n, &Effect::ALL);
    let digital = family_plans(
        Family::Digital,
        seed ^ DIGITAL_SALT,
        n / 2,
        &digital::EFFECTS,
    );
    let first = out.len();
    out.extend(digital.into_iter().map(|p| Plan {
        index: first + p.index,
        ..p
    }));
    out
}

/// `n` plans of `family` from `seed` over `effects`: a fifth healthy (at least 40 when `n` >=
/// 200), 15 % with two effects, the rest with one, every effect equally often, shuffled; then
/// `n` * 3 / 20 more healthy valves of the broadened class ([`NOISY_LOOP`]).
fn family_plans(family: Family, seed: u64, n: usize, effects: &[Effect]) -> Vec<Plan> {
    let mut out = plans_of_effects(family, seed, n, effects);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ BROAD_SALT);
    for _ in 0..n * 3 / 20 {
        out.push(Plan {
            index: out.len(),
            seed: rng.gen(),
            family,
            effects: Vec::new(),
            excitation: NOISY_LOOP,
        });
    }
    out
}

/// The `n` plans of [`family_plans`] before the broadened healthy class.
fn plans_of_effects(family: Family, seed: u64, n: usize, all: &[Effect]) -> Vec<Plan> {
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
        kinds.push(vec![all[j % all.len()]]);
    }
    for j in 0..doubles.min(n - kinds.len()) {
        let a = all[(j * 3) % all.len()];
        let b = all[(j * 3 + 1 + j / all.len()) % all.len()];
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
                family,
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

/// Most draws of one case; the last one is kept, labelled as it is, if none matched the plan
/// (a planned effect the excitation never shows). A digital valve takes seconds to draw and
/// label, so its family gives up sooner.
pub(crate) const MAX_DRAWS: usize = 200;
pub(crate) const MAX_DIGITAL_DRAWS: usize = 30;

/// Generates and labels the case of `plan`, `duration_s` long.
pub(crate) fn build(plan: &Plan, duration_s: f64) -> Result<Case, SynthError> {
    let mut draw = 1;
    loop {
        let mut rng = ChaCha8Rng::seed_from_u64(plan.seed.wrapping_add(draw as u64));
        let case = match plan.family {
            Family::Physical => physical::draw_case(plan, duration_s, &mut rng, draw)?,
            Family::Digital => digital::draw_case(plan, duration_s, &mut rng, draw)?,
        };
        let most = match plan.family {
            Family::Physical => MAX_DRAWS,
            Family::Digital => MAX_DIGITAL_DRAWS,
        };
        if same_set(&case.labels, &plan.effects) || draw == most {
            return Ok(case);
        }
        draw += 1;
    }
}

/// The bench's case of `plan` ([`DURATION_S`] long), recorded intact or as the daemon logs it
/// (per mille, [`LOST_SHARE`] of the rows without V_P in bursts).
pub(crate) fn build_as(plan: &Plan, as_logged: bool) -> Result<Case, SynthError> {
    let mut case = build(plan, DURATION_S)?;
    if as_logged {
        case.rec = valve_bridge::synth::logged::as_logged(&case.rec, LOST_SHARE, plan.seed);
    }
    Ok(case)
}

fn same_set(a: &[Effect], b: &[Effect]) -> bool {
    a.len() == b.len() && a.iter().all(|e| b.contains(e))
}

pub(crate) fn log_uniform(rng: &mut ChaCha8Rng, (lo, hi): (f64, f64)) -> f64 {
    (rng.gen_range(lo.ln()..=hi.ln())).exp()
}

/// The sensor of a case: its noise (the broadened class's levels when `broad`) and, half the
/// time, a fine lattice.
pub(crate) fn draw_sensor(rng: &mut ChaCha8Rng, broad: bool) -> (f64, f64) {
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
    (noise, lattice)
}

pub(crate) fn excitation(name: &str, rng: &mut ChaCha8Rng) -> Excitation {
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

/// Where a travel stop goes for the O_P `op` of the valve without it: how far it lies from its
/// end of travel, `100 - stop` for a stop short of open at a quantile of `op` drawn from
/// [`size_range`] (less the margin O_P must pass it by), or the stop itself for one above
/// closed (`low`) at the complementary quantile.
pub(crate) fn stop_size(op: &[f64], low: bool, rng: &mut ChaCha8Rng) -> f64 {
    let (lo, hi) = size_range(Effect::Saturation, 0.0, "");
    let q = rng.gen_range(lo..=hi);
    if low {
        (measures::quantile(op, 1.0 - q) + SATURATION_MARGIN_PCT).clamp(1.0, 95.0)
    } else {
        100.0 - (measures::quantile(op, q) - SATURATION_MARGIN_PCT).clamp(5.0, 99.0)
    }
}
