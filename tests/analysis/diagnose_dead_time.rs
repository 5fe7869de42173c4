//! A dead time where O_P never steps: a digital positioner waiting 1.85 s before it acts, in
//! a level loop whose controller output chatters every sample (seed 40 valve 318, sensor
//! noise 0.25 %). V_P repeats the chatter 1.85 s late; the baseline takes the delay for a
//! slow positioner (0.16 s and a time constant of 1.8 s), which fits the slow swing as well as
//! any delay a few samples off the true one, so the free-run error has a valley only a few
//! samples wide. The dead time's refit starts where the increments of V_P answer those of O_P
//! most closely, with a positioner fast enough to keep the baseline's whole lag, and finds it,
//! intact and as the daemon logs it.

use valve_bridge::diagnose::Effect;

use crate::diagnose_stiction_or_not::{diagnosed_as, holds, named};

#[test]
fn a_long_delay_under_a_chattering_controller_is_dead_time() {
    for as_logged in [false, true] {
        let (case, d) = diagnosed_as(40, 318, as_logged);
        assert_eq!(case.labels, [Effect::DeadTime]);
        assert_eq!(named(&d), [Effect::DeadTime], "as logged: {as_logged}");
        assert!(
            holds(&case, &d, Effect::DeadTime),
            "as logged: {as_logged}: {:?}",
            d.findings
        );
    }
}
