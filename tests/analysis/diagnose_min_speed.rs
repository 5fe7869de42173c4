//! A positioner's minimum speed (a creep floor: small errors close at a constant rate instead
//! of exponentially), found where it is and not where the model cannot use it. On valves of
//! the blind bench's physical family, seed 31, recorded intact:
//!
//! - valve 204 (small steps, sensor noise 0.02 %): opening 28 times slower than closing and a
//!   floor of 1.9 %/s. With the floor fitted from 1 %/s alone a slow stroke was named in its
//!   place (`slew_rate` 3.3 %/s); fitted also from a tenth and three tenths of the
//!   stroke-speed limit, the floor is named beside the unevenness, its interval holding the
//!   drawn floor.
//! - valve 132 (mixed excitation, sensor noise 0.1 %): a deadband of 1.9 %, no floor. From
//!   those starts a floor of 4.3 %/s took 7 % of the held-out error after the deadband; put
//!   back at none, with the gain and dead time it was refitted with kept, it lost nothing:
//!   the gain was the refit's, and the floor (below the speed at which the positioner
//!   reaches the deadband's edge) never acted. Only the deadband is named.
//!
//! And on seed 60's digital valve 324 (mixed excitation, sensor noise 0.1 %), a floor of
//! 29.8 %/s, fitted as 29.3: its step tails read 19.0 %/s 0.26-0.53 % from rest, less than
//! 0.7 of the floor, as a speed taken over 0.1 s reads any stem that stops within it. Judged
//! against the floor itself it went unnamed; judged against how the model's own tails read,
//! it is named.

use valve_bridge::diagnose::Effect;

use crate::diagnose_stiction_or_not::{diagnosed_as, holds, named};

#[test]
fn a_minimum_speed_beside_an_uneven_stroke_is_named_not_a_slow_stroke() {
    let (case, d) = diagnosed_as(31, 204, false);
    assert_eq!(case.labels.len(), 2, "{:?}", case.labels);
    let found = named(&d);
    assert!(
        case.labels.iter().all(|e| found.contains(e)) && found.len() == 2,
        "labels {:?}, found {found:?}",
        case.labels
    );
    let sizes: Vec<String> = d.findings.iter().map(|f| f.size.words()).collect();
    assert!(
        holds(&case, &d, Effect::MinSpeed),
        "truth {:?}, found {sizes:?}",
        case.truth
    );
}

#[test]
fn a_minimum_speed_whose_knob_does_nothing_is_not_named() {
    let (case, d) = diagnosed_as(31, 132, false);
    assert_eq!(case.labels, vec![Effect::Deadband]);
    assert_eq!(named(&d), vec![Effect::Deadband]);
}

#[test]
fn a_fast_floor_is_judged_by_how_the_model_s_own_step_tails_read() {
    let (case, d) = diagnosed_as(60, 324, false);
    assert_eq!(case.labels, vec![Effect::MinSpeed]);
    assert_eq!(named(&d), vec![Effect::MinSpeed]);
    assert!(holds(&case, &d, Effect::MinSpeed), "{:?}", d.findings);
}
