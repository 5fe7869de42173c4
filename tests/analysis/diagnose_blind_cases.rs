//! The blind benchmark's physical family (`benches/blind/cases.rs`, `physical.rs`) on
//! recordings as long as the bench's: one valve per effect and a healthy one are labelled with
//! exactly the planned effects, only the planned physics leaves the healthy ranges, generation
//! is deterministic, and the full plan holds every effect often enough. Diagnosis is not run
//! here (the digital family: `tests/analysis/diagnose_blind_digital.rs`).

use crate::cases;

use crate::cases::physical::outside_healthy;
use crate::cases::{build, plans, Family, Physics, Plan, EXCITATIONS, NOISY_LOOP};
use valve_bridge::diagnose::Effect;

const SHORT_S: f64 = 600.0;

/// The physical valve of a case of the physical family.
fn spec(case: &cases::Case) -> &valve_bridge::model::ModelSpec {
    match &case.physics {
        Physics::Physical(spec) => spec,
        Physics::Digital(_) => panic!("case {} is digital", case.plan.index),
    }
}

fn plan(i: usize, effects: Vec<Effect>) -> Plan {
    Plan {
        index: i,
        seed: 1000 + i as u64,
        family: Family::Physical,
        effects,
        excitation: EXCITATIONS[i % EXCITATIONS.len()],
    }
}

#[test]
fn one_valve_per_effect_is_labelled_with_it_alone() {
    let mut all: Vec<Vec<Effect>> = Effect::ALL.iter().map(|e| vec![*e]).collect();
    all.push(Vec::new());
    all.push(vec![Effect::SlewRate, Effect::Asymmetry]);
    for (i, effects) in all.into_iter().enumerate() {
        let case = build(&plan(i, effects.clone()), SHORT_S).unwrap();
        let mut want = effects.clone();
        want.sort_by_key(|e| *e as usize);
        assert_eq!(case.labels, want, "plan {effects:?}, {} draws", case.draws);
        let mut outside = outside_healthy(spec(&case));
        outside.sort_by_key(|e| *e as usize);
        assert_eq!(outside, want, "{:?}", spec(&case));
        spec(&case).validate().unwrap();
        assert_eq!(case.rec.len(), (SHORT_S / cases::DT) as usize);
    }
}

#[test]
fn generation_is_deterministic() {
    let p = plan(3, vec![Effect::Backlash]);
    let (a, b) = (build(&p, 60.0).unwrap(), build(&p, 60.0).unwrap());
    assert_eq!(spec(&a), spec(&b));
    assert_eq!((&a.rec.op, &a.rec.vp), (&b.rec.op, &b.rec.vp));
    let other = build(&plan(4, vec![Effect::Backlash]), 60.0).unwrap();
    assert_ne!(a.rec.vp, other.rec.vp);
    assert_eq!(plans(5, 220), plans(5, 220));
}

#[test]
fn a_healthy_valve_of_the_broadened_class_has_no_label() {
    // A noisy controller and slow reversals, a friction band up to 0.2 %, a positioner gain
    // down to 2 /s and sensor noise up to 0.4 %: none of it is an effect.
    for i in 0..4 {
        let p = Plan {
            excitation: NOISY_LOOP,
            ..plan(i, Vec::new())
        };
        let case = build(&p, SHORT_S).unwrap();
        assert!(case.labels.is_empty(), "{:?}", case.labels);
        let ph = spec(&case).physical.unwrap();
        assert!(ph.coulomb_band_pct <= 0.2 && ph.positioner_gain_per_s >= 2.0);
    }
}

#[test]
fn the_full_plan_covers_every_effect_and_excitation() {
    let all: Vec<Plan> = plans(1, 200)
        .into_iter()
        .filter(|p| p.family == Family::Physical)
        .collect();
    assert_eq!(all.len(), 230);
    let broad = all.iter().filter(|p| p.excitation == NOISY_LOOP).count();
    assert_eq!(broad, 30);
    assert!(all[200..]
        .iter()
        .all(|p| p.effects.is_empty() && p.excitation == NOISY_LOOP));
    let healthy = all.iter().filter(|p| p.effects.is_empty()).count() - broad;
    let doubles = all.iter().filter(|p| p.effects.len() == 2).count();
    assert!(healthy >= 40, "{healthy}");
    assert!((25..=35).contains(&doubles), "{doubles}");
    for e in Effect::ALL {
        let n = all.iter().filter(|p| p.effects.contains(&e)).count();
        assert!(n >= 15, "{}: {n}", e.name());
        for x in EXCITATIONS {
            let m = all
                .iter()
                .filter(|p| p.effects.first() == Some(&e) && p.excitation == x)
                .count();
            assert!(m >= 1, "{} never under {x}", e.name());
        }
    }
}
