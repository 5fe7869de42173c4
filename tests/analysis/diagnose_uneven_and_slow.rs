//! A valve slower one way than the other is named `asymmetry`; when even its faster side is
//! slower than a valve in good order strokes, it is slow both ways and `slew_rate` is named
//! too, sized as the stroke speed at half travel (the geometric mean of the two limits). On
//! valves of the blind bench, recorded intact:
//!
//! - seed 17 valve 348 (digital, random steps, sensor noise 0.25 %): both orifices small,
//!   a stroke speed of 1.4 %/s, closing four times slower than opening.
//!   Both are named, each interval holding the drawn size.
//! - seed 17 valve 39 (physical, closed loop) and valve 280 (digital, small steps): one side
//!   slow, the other at a healthy speed the recording never asks for in full. Only the
//!   unevenness is named: the valve given a healthy speed on its faster side fits the
//!   held-out blocks about as well.

use valve_bridge::diagnose::Effect;

use crate::diagnose_stiction_or_not::{diagnosed_as, holds, named};

#[test]
fn a_valve_slow_both_ways_is_named_uneven_and_slow() {
    let (case, d) = diagnosed_as(17, 348, false);
    assert_eq!(case.labels, [Effect::SlewRate, Effect::Asymmetry]);
    let found = named(&d);
    assert!(found.contains(&Effect::Asymmetry), "{found:?}");
    assert!(found.contains(&Effect::SlewRate), "{found:?}");
    assert!(holds(&case, &d, Effect::SlewRate), "{:?}", d.findings);
    assert!(holds(&case, &d, Effect::Asymmetry), "{:?}", d.findings);
}

#[test]
fn a_valve_slow_one_way_only_is_not_named_slow() {
    for index in [39, 280] {
        let (case, d) = diagnosed_as(17, index, false);
        assert_eq!(case.labels, [Effect::Asymmetry], "valve {index}");
        assert_eq!(named(&d), [Effect::Asymmetry], "valve {index}");
    }
}
