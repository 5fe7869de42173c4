//! Effects several times worth maintenance under a noisy sensor (0.25 %), where the noise is
//! most of the held-out error and an effect removes little of it. On valves of the blind
//! bench, recorded intact:
//!
//! - seed 60 valve 171 (physical, ramps): lost motion of 1.0 %. The fit removes 0.87 % of the
//!   held-out error, under the 1 % a finding removes, at 3.4 times what is worth maintenance:
//!   an effect 3 times worth or more is asked for half that share, and the band is named.
//! - seed 61 valve 45 (physical, closed loop): a stroke of 0.54 %/s. Its limit is fitted at
//!   0.58 %/s, 69 times worth, but a minimum speed fits the busy loop nearly as well, so it
//!   is not named; it stays in the model and the report as a trace, not dropped.

use valve_bridge::diagnose::Effect;

use crate::diagnose_stiction_or_not::{diagnosed_as, holds, named};

#[test]
fn lost_motion_three_times_worth_maintenance_under_a_noisy_sensor_is_named() {
    let (case, d) = diagnosed_as(60, 171, false);
    assert_eq!(case.labels, [Effect::Backlash]);
    assert_eq!(named(&d), [Effect::Backlash]);
    assert!(holds(&case, &d, Effect::Backlash), "{:?}", d.findings);
}

#[test]
fn a_slow_stroke_a_floor_fits_as_well_stays_a_trace() {
    let (case, d) = diagnosed_as(61, 45, false);
    assert_eq!(case.labels, [Effect::SlewRate]);
    assert!(named(&d).is_empty(), "{:?}", named(&d));
    let trace = d.traces.iter().find(|t| t.effect == Effect::SlewRate);
    let speed = trace.map(|t| t.size.value);
    assert!(speed.is_some_and(|v| (0.5..0.7).contains(&v)), "{speed:?}");
}
