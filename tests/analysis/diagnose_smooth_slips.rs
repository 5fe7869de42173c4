//! Slips that smooth friction makes are not stick-slip: a healthy valve of the blind bench's
//! digital family (seed 4, valve 372: a level loop under a noisy controller, LuGre Coulomb
//! friction of a 0.79 % band and static friction no higher), as the daemon logs it. Its
//! positioner's pulses move the stem in jerks after it rests, which a friction band crossed at
//! the positioner's speed reproduces as closely as stick-slip does, so `diagnose` names no
//! stiction.

use valve_bridge::diagnose::{self, Effect};
use valve_bridge::synth::logged;

use crate::cases;

#[test]
fn slips_a_smooth_friction_band_makes_are_not_named_stiction() {
    let plan = (cases::plans(4, 220).into_iter())
        .find(|p| p.index == 372)
        .unwrap();
    let mut case = cases::build(&plan, 600.0).unwrap();
    assert!(case.labels.is_empty(), "{:?}", case.labels);
    case.rec = logged::as_logged(&case.rec, 0.005, plan.seed);
    let d = diagnose::diagnose(&case.rec.view(), None, &|_, _| {}).unwrap();
    let named: Vec<Effect> = d.findings.iter().map(|f| f.effect).collect();
    assert!(!named.contains(&Effect::Stiction), "{named:?}");
}
