//! Linkage play inside a digital positioner's loop is lost motion, not a deadband: two valves
//! of the blind bench's digital family (seed 5: valve 309 on ramps, 330 on small steps), each
//! with linkage play alone, intact and as the daemon logs them. The positioner closes its loop
//! on the potentiometer behind the play, so V_P comes to rest at the set-point and a reversal
//! waits while the stem crosses the play; `diagnose` names `backlash` first, no `deadband`,
//! and its 90 % interval holds the stem's lost motion (the play; `friction_band_pct`).

use valve_bridge::diagnose::{self, Effect};
use valve_bridge::synth::logged;

use crate::cases;

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
