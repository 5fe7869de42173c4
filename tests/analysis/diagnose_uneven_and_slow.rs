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
//!   held-out blocks about as well. So too seed 32 valve 324 (digital, ramps): opening at
//!   9.5 %/s was named `slew_rate` in the first round, where the unevenness fitted with a
//!   closing limit at the top of its box was not plausible; once the unevenness is named
//!   the limit named first is its slower side, and the valve given a healthy speed on its
//!   faster side (37 %/s closing) fits as well.
//! - seed 17 valve 0 and seed 18 valve 117 (physical, busy closed loops, sensor noise 0.02 %):
//!   both sides slow (0.3-0.8 %/s), one up to 2.6 times faster. The valve turns back long
//!   before it reaches its faster limit, so its fastest moves each way differ by less than a
//!   fifth; where it rests (below O_P when it closes faster) shows the unevenness. Both are
//!   named, the ratio's interval holding the drawn one, rather than a calibration offset.
//! - seed 19 valve 69 as logged (physical, closed loop, sensor noise 0.1 %, read per mille):
//!   even at 0.48 %/s both ways, read 0.07 % high. An unevenness of 1.46 fits the held-out
//!   blocks barely better than the offset, and the valve's fastest moves each way are alike:
//!   the offset is put in first and no unevenness is named. The two limits go in as a trace,
//!   and the valve is named slow (0.50 %/s).
//! - seed 45 valve 129 as logged (physical, closed loop, sensor noise 0.1 %, read per
//!   mille): closing 43.5 times slower than opening. The median second difference of a
//!   reading rounded to 0.1 % made its noise 0.12 %; taken out of V_P's fastest moves, that
//!   left the valve closing at under half its closing limit, the unevenness was not plausible
//!   and a calibration offset went in first. Measured by a trimmed mean square, the noise is
//!   0.106 % (sqrt(0.1² + 0.1²/12) = 0.104), and the unevenness is named, its interval
//!   holding the drawn ratio.
//! - seed 22 valve 126 (physical, quiet closed loop, sensor noise 0.02 %): even at 0.38 %/s.
//!   The valve never holds a speed long enough for one limit to be plausible; two limits
//!   alike, uneven by too little to name, go in the model as a trace. Both are slower than a
//!   valve in good order strokes: `slew_rate` is named, its interval holding the drawn speed.
//!   Not so seed 22 valve 219 (physical, busy closed loop, sensor noise 0.1 %), healthy but
//!   with a creep floor of 6.8 %/s: it answers the controller's noise at about 6 %/s both ways,
//!   ten times faster than a valve in good order is asked to move there; nor valve 9 (random
//!   steps), fast closed and slow open by its growing chamber only: the slowdown is named,
//!   not a slow stroke.
//! - seed 18 valves 24 and 144 (physical): a healthy flow limit (about 50 %/s closed) behind
//!   a chamber that makes the valve three or four times slower fully open. The slow stroke at
//!   half travel is listed after the slowdown (and the dead time of valve 24) that causes it.
//! - seed 23 valve 48 (physical, random steps, sensor noise 0.02 %): a stroke of 4.2 %/s that
//!   starts 0.48 s late. The stroke is named first, fitted beside the baseline's short dead
//!   time; the dead time's candidate refits it within a factor of two, so the late start is
//!   named too, each interval holding the drawn value.
//! - seed 48 valve 45 (physical, ramps, sensor noise 0.1 %): opening at 9.7 %/s, closing ten
//!   times faster. The two ramps of O_P that ask it to open faster, and its fastest closes
//!   (up to 26 %/s), all fall in held-out blocks; fitted on blocks that never ask for more
//!   than about 10 %/s either way, the closing limit fell to 21 %/s and the unevenness made
//!   the held-out blocks worse. No limit of an unevenness is fitted below 0.6 of the speed
//!   V_P held for a second that way (24 %/s closing): the unevenness is named, its interval
//!   holding the drawn ratio.
//! - seed 59 valve 9 (physical, random steps, sensor noise 0.1 %): 2.6 times slower fully open,
//!   read 1.9 % low by a sensor whose gain is 1.9 % short. Taken as a true reading, V_P rests
//!   1.9-3.7 % from O_P, and the model with the calibration alone answered faster low in the
//!   travel than the recording (8.6 times against 4.0), so the slowdown was not seen and
//!   `slew_rate` was named instead. Read back through the calibration (1.5 times against
//!   1.0), the slowdown is named beside the calibration, its interval holding the drawn ratio,
//!   and no slow stroke.

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
    for (seed, index) in [(17, 39), (17, 280), (32, 324)] {
        let (case, d) = diagnosed_as(seed, index, false);
        assert_eq!(case.labels, [Effect::Asymmetry], "{seed}/{index}");
        assert_eq!(named(&d), [Effect::Asymmetry], "{seed}/{index}");
    }
}

#[test]
fn a_slow_uneven_valve_in_a_busy_loop_is_named_uneven_and_slow() {
    for (seed, index) in [(17, 0), (18, 117)] {
        let (case, d) = diagnosed_as(seed, index, false);
        assert_eq!(case.labels, [Effect::SlewRate, Effect::Asymmetry]);
        let found = named(&d);
        assert!(
            found.contains(&Effect::Asymmetry),
            "{seed}/{index}: {found:?}"
        );
        assert!(
            found.contains(&Effect::SlewRate),
            "{seed}/{index}: {found:?}"
        );
        assert!(
            !found.contains(&Effect::Calibration),
            "{seed}/{index}: {found:?}"
        );
        assert!(holds(&case, &d, Effect::Asymmetry), "{:?}", d.findings);
    }
}

#[test]
fn a_slow_valve_whose_two_limits_are_a_trace_is_named_slow() {
    let (case, d) = diagnosed_as(22, 126, false);
    assert_eq!(case.labels, [Effect::SlewRate]);
    assert!(d.traces.iter().any(|t| t.effect == Effect::Asymmetry));
    assert_eq!(named(&d), [Effect::SlewRate]);
    assert!(holds(&case, &d, Effect::SlewRate), "{:?}", d.findings);
}

#[test]
fn a_trace_of_limits_at_a_creep_floor_or_from_a_slowdown_is_not_named_slow() {
    let (case, d) = diagnosed_as(22, 219, false);
    assert!(case.labels.is_empty());
    assert_eq!(named(&d), []);
    let (case, d) = diagnosed_as(22, 9, false);
    assert_eq!(case.labels, [Effect::StateDependentDelay]);
    assert_eq!(named(&d), [Effect::StateDependentDelay]);
}

#[test]
fn an_even_valve_read_off_is_not_named_uneven() {
    let (case, d) = diagnosed_as(19, 69, true);
    assert_eq!(case.labels, [Effect::SlewRate]);
    assert_eq!(named(&d), [Effect::SlewRate]);
}

#[test]
fn a_valve_slow_only_through_its_slowdown_has_the_slowdown_named_first() {
    for (index, first) in [(24, Effect::DeadTime), (144, Effect::StateDependentDelay)] {
        let (case, d) = diagnosed_as(18, index, false);
        assert!(case.labels.contains(&first), "valve {index}");
        assert!(!case.labels.contains(&Effect::SlewRate), "valve {index}");
        let found = named(&d);
        assert_eq!(found.first(), Some(&first), "valve {index}: {found:?}");
        assert!(
            found.contains(&Effect::StateDependentDelay),
            "valve {index}: {found:?}"
        );
        if let Some(at) = found.iter().position(|&e| e == Effect::SlewRate) {
            assert_eq!(at, found.len() - 1, "valve {index}: {found:?}");
        }
    }
}

#[test]
fn a_dead_time_beside_a_slow_stroke_is_named_with_it() {
    let (case, d) = diagnosed_as(23, 48, false);
    assert_eq!(case.labels, [Effect::DeadTime, Effect::SlewRate]);
    assert_eq!(named(&d), [Effect::SlewRate, Effect::DeadTime]);
    assert!(holds(&case, &d, Effect::DeadTime), "{:?}", d.findings);
    assert!(holds(&case, &d, Effect::SlewRate), "{:?}", d.findings);
}

#[test]
fn an_uneven_valve_logged_in_per_mille_is_uneven() {
    let (case, d) = diagnosed_as(45, 129, true);
    assert_eq!(case.labels, [Effect::Asymmetry]);
    assert!(
        (d.noise_floor_pct - 0.104).abs() < 0.005,
        "{}",
        d.noise_floor_pct
    );
    assert_eq!(named(&d), [Effect::Asymmetry], "{:?}", d.findings);
    assert!(holds(&case, &d, Effect::Asymmetry), "{:?}", d.findings);
}

#[test]
fn an_uneven_valve_whose_fast_side_shows_in_held_out_blocks_alone_is_named_uneven() {
    let (case, d) = diagnosed_as(48, 45, false);
    assert_eq!(case.labels, [Effect::Asymmetry]);
    assert_eq!(named(&d), [Effect::Asymmetry]);
    assert!(holds(&case, &d, Effect::Asymmetry), "{:?}", d.findings);
}

#[test]
fn a_slowdown_read_by_an_offset_sensor_is_named_beside_the_calibration() {
    let (case, d) = diagnosed_as(59, 9, false);
    assert_eq!(
        case.labels,
        [Effect::StateDependentDelay, Effect::Calibration]
    );
    assert_eq!(
        named(&d),
        [Effect::Calibration, Effect::StateDependentDelay]
    );
    assert!(
        holds(&case, &d, Effect::StateDependentDelay),
        "{:?}",
        d.findings
    );
}

/// Seed 60's digital valve 312 in a closed loop opens 51 times slower than it closes; its
/// chamber fills more slowly the fuller it is, so the opening limit a fit gives it (0.35 %/s)
/// sits below the 0.61 %/s it held for a second, on the floor the held speed sets a fit. A
/// limit there was taken as pinned, and the valve was named `calibration` and `stiction`.
#[test]
fn an_uneven_valve_whose_slower_limit_sits_on_the_held_speed_s_floor_is_named() {
    let (case, d) = diagnosed_as(60, 312, false);
    assert_eq!(case.labels, [Effect::Asymmetry]);
    assert_eq!(named(&d), [Effect::Asymmetry]);
    assert!(holds(&case, &d, Effect::Asymmetry), "{:?}", d.findings);
}
