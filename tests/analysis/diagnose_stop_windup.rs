//! A travel stop on a spring-diaphragm actuator, as the daemon logs it: while the stem sits on
//! the stop and O_P asks for more, the chamber fills on towards the supply, several spring
//! ranges beyond the pressure that holds the stem there, and must vent all that before the
//! valve leaves the stop. Four valves of the bench's digital family (seed 9: stops at 46, 80,
//! 71 and 88 %, random steps and mixed excitation, sensor noise 0.1-0.25 %) are named a travel
//! stop and nothing else: with the drive's wind-up bounded at one travel the delay of leaving
//! the stop was left over, and a slowdown of the open valve (and in one a stroke-speed limit)
//! was named to cover it.

use valve_bridge::diagnose::Effect;

use crate::diagnose_stiction_or_not::{diagnosed, named};

#[test]
fn a_stop_whose_chamber_winds_up_to_the_supply_is_a_travel_stop_alone() {
    for index in [316, 345, 346, 350] {
        let (case, d) = diagnosed(9, index);
        assert!(case.labels.contains(&Effect::Saturation), "valve {index}");
        let found = named(&d);
        assert!(
            found.iter().all(|e| case.labels.contains(e)),
            "valve {index}: labels {:?}, found {found:?}",
            case.labels
        );
        let f = d.findings.iter().find(|f| f.effect == Effect::Saturation);
        let truth = case.truth.iter().find(|t| t.effect == Effect::Saturation);
        let (Some(f), Some(truth)) = (f, truth) else {
            panic!("valve {index}: no travel stop in {found:?}");
        };
        assert!(
            (f.size.low..=f.size.high).contains(&truth.value),
            "valve {index}: stop at {:.1} %, {}",
            truth.value,
            f.size.words()
        );
    }
}
