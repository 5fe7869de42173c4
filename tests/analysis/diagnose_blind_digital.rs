//! The blind benchmark's digital family (`benches/blind/digital.rs`) on short recordings: its
//! labels follow the physics. A healthy valve has none and rests without jumps; a tolerance
//! band above the label's threshold is a `deadband`, and the valve rests anywhere inside it,
//! without jumps; a LuGre static level well above the Coulomb one is a `stiction`, and the
//! valve slips; each label's truth is the physics it was built from. Healthy chambers hold no
//! state-dependent delay, and the plans cover every effect of the family under every
//! excitation. Diagnosis is not run here.

use crate::cases;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use valve_bridge::diagnose::Effect;
use valve_bridge::synth::digital::{DigitalParams, DigitalValve};

use crate::cases::{build, digital, plans, Case, Family, Physics, Plan, DT, EXCITATIONS};

const SHORT_S: f64 = 240.0;

fn plan(seed: u64, effects: Vec<Effect>, excitation: &'static str) -> Plan {
    Plan {
        index: 0,
        seed,
        family: Family::Digital,
        effects,
        excitation,
    }
}

fn params(case: &Case) -> DigitalParams {
    match case.physics {
        Physics::Digital(p) => p,
        Physics::Physical(_) => panic!("case {} is physical", case.plan.index),
    }
}

/// The case re-run on its O_P with a noise-free, continuous feedback (which the positioner does
/// not use, so the stem is the recording's): the stem's positions when `stem`, else the reading
/// (the potentiometer's arm, beyond the linkage's play).
fn replay(case: &Case, stem: bool) -> Vec<f64> {
    let p = DigitalParams {
        noise_pct: 0.0,
        lattice_pct: 0.0,
        ..params(case)
    };
    let vp0 = case.rec.vp[0];
    DigitalValve::new(&p, DT)
        .unwrap()
        .simulate(&case.rec.op, vp0, stem)
}

/// Jumps of `x`: moves of at least `size` within 0.1 s after 0.2 s still (within 0.01 %),
/// O_P unchanged all the while.
fn jumps(op: &[f64], x: &[f64], size: f64) -> usize {
    (20..x.len() - 10)
        .filter(|&k| {
            let still = x[k - 20..=k].iter().all(|v| (v - x[k]).abs() <= 0.01);
            let held = op[k - 20..=k + 10].iter().all(|u| *u == op[k]);
            still && held && (x[k + 10] - x[k]).abs() >= size
        })
        .count()
}

/// How far the stem rests from O_P at the end of every hold of at least 2 s.
fn rest_errors(op: &[f64], x: &[f64]) -> Vec<f64> {
    (200..x.len())
        .filter(|&k| op[k - 200..=k].iter().all(|u| *u == op[k]) && op.get(k + 1) != Some(&op[k]))
        .map(|k| x[k] - op[k])
        .collect()
}

#[test]
fn a_healthy_valve_has_no_label_and_rests_without_jumps() {
    for (seed, excitation) in [(11, "small_steps"), (12, "random_steps")] {
        let case = build(&plan(seed, Vec::new(), excitation), SHORT_S).unwrap();
        assert!(case.labels.is_empty(), "{excitation}: {:?}", case.labels);
        let x = replay(&case, true);
        assert_eq!(jumps(&case.rec.op, &x, 0.1), 0, "{excitation}");
        let p = params(&case);
        let errors = rest_errors(&case.rec.op, &x);
        assert!(errors.len() > 5, "{excitation}: {} holds", errors.len());
        assert!(
            errors
                .iter()
                .all(|e| e.abs() <= p.tolerance_pct + p.play_pct / 2.0 + 0.02),
            "{excitation}: tolerance {}, {errors:?}",
            p.tolerance_pct
        );
    }
}

#[test]
fn a_tolerance_band_is_a_deadband_and_the_valve_rests_anywhere_inside_it() {
    let case = build(&plan(21, vec![Effect::Deadband], "small_steps"), SHORT_S).unwrap();
    assert_eq!(case.labels, [Effect::Deadband]);
    let p = params(&case);
    assert!(2.0 * p.tolerance_pct >= cases::DEADBAND_PCT);
    assert_eq!(case.truth[0].name, "deadband_pct");
    assert_eq!(case.truth[0].value, 2.0 * p.tolerance_pct);
    let x = replay(&case, true);
    assert_eq!(jumps(&case.rec.op, &x, 0.1), 0);
    let errors = rest_errors(&case.rec.op, &x);
    assert!(
        errors
            .iter()
            .all(|e| e.abs() <= p.tolerance_pct + p.play_pct / 2.0 + 0.02),
        "tolerance {}, {errors:?}",
        p.tolerance_pct
    );
    // Not at one edge: the valve stops wherever the last pulse leaves it.
    let spread = errors.iter().copied().fold(f64::MIN, f64::max)
        - errors.iter().copied().fold(f64::MAX, f64::min);
    assert!(
        spread >= p.tolerance_pct,
        "tolerance {}, {errors:?}",
        p.tolerance_pct
    );
}

#[test]
fn a_static_level_above_the_coulomb_one_is_stiction_and_the_valve_slips() {
    let case = build(&plan(31, vec![Effect::Stiction], "small_steps"), SHORT_S).unwrap();
    assert_eq!(case.labels, [Effect::Stiction], "{} draws", case.draws);
    let p = params(&case);
    let excess = p.static_pct - p.coulomb_pct;
    assert!(excess > digital::HEALTHY_STATIC_EXCESS_PCT.1, "{excess}");
    let slip = case.truth[0].value;
    assert!(slip >= cases::STICTION_PCT, "{slip}");
    // The stem creeps on its bristles while it sticks, inside the linkage's play: the reading
    // stands still, then jumps.
    let x = replay(&case, false);
    assert!(
        jumps(&case.rec.op, &x, cases::STICTION_PCT) >= 3,
        "excess {excess}, slip {slip}"
    );
}

#[test]
fn healthy_chambers_hold_no_state_dependent_delay() {
    // Over healthy draws, a full stroke at 95 % is at most 1.4 times slower than at 5 %, either
    // way (state_dependent_delay is labelled from 1.5 times over the openings visited).
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    for k in 0..300 {
        let p = digital::healthy_params(&mut rng, 0.1, 0.0, k, k % 2 == 0);
        p.validate().unwrap();
        for opening in [true, false] {
            let slower =
                p.stroke_speed_pct_per_s(5.0, opening) / p.stroke_speed_pct_per_s(95.0, opening);
            assert!(slower <= 1.4, "draw {k}, opening {opening}: {slower}");
        }
    }
}

#[test]
fn the_plans_cover_every_effect_of_the_family_under_every_excitation() {
    let all: Vec<Plan> = plans(1, 220)
        .into_iter()
        .filter(|p| p.family == Family::Digital)
        .collect();
    assert_eq!(all.len(), 110 + 16);
    assert_eq!(all[0].index, 253);
    assert!(!all
        .iter()
        .any(|p| p.effects.contains(&Effect::StateDependentDelay)));
    for e in digital::EFFECTS {
        let n = all.iter().filter(|p| p.effects.contains(&e)).count();
        assert!(n >= 9, "{}: {n}", e.name());
        for x in EXCITATIONS {
            let m = all
                .iter()
                .filter(|p| p.effects.first() == Some(&e) && p.excitation == x)
                .count();
            assert!(m >= 1, "{} never under {x}", e.name());
        }
    }
}
