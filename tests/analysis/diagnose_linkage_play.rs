//! Linkage play inside a digital positioner's loop is lost motion, not a deadband: two valves
//! of the blind bench's digital family (seed 5: valve 309 on ramps, 330 on small steps), each
//! with linkage play alone, intact and as the daemon logs them. The positioner closes its loop
//! on the potentiometer behind the play, so V_P comes to rest at the set-point and a reversal
//! waits while the stem crosses the play; `diagnose` names `backlash` first, no `deadband`,
//! and its 90 % interval holds the stem's lost motion (the play; `friction_band_pct`).
//!
//! Play beside a slow stroke (seed 22 valve 309: 1.14 % of play at 3.37 %/s; seed 23 valve
//! 342: 4.15 % at 2.73 %/s; both digital, mixed excitation, sensor noise 0.25 %, intact): the
//! slow stroke is named first, at a limit slow enough to take up part of the reversals'
//! waits. The play is named beside it only because its candidates refit that limit too, and
//! both intervals then hold the drawn values.

use valve_bridge::diagnose::{self, Effect};
use valve_bridge::synth::logged;

use crate::cases;
use crate::diagnose_stiction_or_not::{diagnosed_as, holds, named};

#[test]
fn play_inside_the_loop_is_named_backlash_and_sized() {
    let plans = cases::plans(5, 220);
    for index in [309, 330] {
        let plan = (plans.iter()).find(|p| p.index == index).unwrap();
        let case = cases::build(plan, 600.0).unwrap();
        assert_eq!(case.labels, [Effect::Backlash], "valve {index}");
        let truth = &case.truth[0];
        assert_eq!(truth.name, "friction_band_pct");
        let logged = logged::as_logged(&case.rec, 0.005, plan.seed);
        for (how, rec) in [("intact", &case.rec), ("as logged", &logged)] {
            let d = diagnose::diagnose(&rec.view(), None, &|_, _| {}).unwrap();
            let named: Vec<Effect> = d.findings.iter().map(|f| f.effect).collect();
            assert_eq!(
                named.first(),
                Some(&Effect::Backlash),
                "{index} {how}: {named:?}"
            );
            assert!(
                !named.contains(&Effect::Deadband),
                "{index} {how}: {named:?}"
            );
            let size = &d.findings[0].size;
            assert_eq!(size.name, truth.name);
            assert!(
                (size.low..=size.high).contains(&truth.value),
                "{index} {how}: play {:.2} %, {}",
                truth.value,
                size.words()
            );
        }
    }
}

#[test]
fn play_beside_a_slow_stroke_is_named_and_both_are_sized() {
    for (seed, index) in [(22, 309), (23, 342)] {
        let (case, d) = diagnosed_as(seed, index, false);
        assert_eq!(case.labels, [Effect::Backlash, Effect::SlewRate]);
        let found = named(&d);
        for effect in [Effect::Backlash, Effect::SlewRate] {
            assert!(found.contains(&effect), "{seed}/{index}: {found:?}");
            assert!(holds(&case, &d, effect), "{seed}/{index}: {:?}", d.findings);
        }
    }
}
