//! When stick-slip is named and when its look-alikes are, on valves of the blind bench
//! (its digital family unless said) as the daemon logs them.
//!
//! - A pulsing positioner under a noisy controller output rests and steps; that is not
//!   stick-slip. Three healthy valves in level loops under a noisy controller (seed 5 valve
//!   372, seed 6 valve 378, seed 7 valve 369): V_P rests while the error is inside the
//!   tolerance band and then moves in a quick step, dozens of times, which a smooth model
//!   without a band never does; a friction band or a tolerance band makes such steps too, so
//!   no stiction is named.
//! - A fast positioner following a noisy controller output in a closed loop moves in quick
//!   steps too (seed 9: valve 264, healthy, and valve 269, a dead time of 0.63 s): a fitted
//!   stick-slip comes closer to those steps than the current model, and on the fit blocks a
//!   little closer than the smooth rival, but on the held-out pieces the rival matches them
//!   better as often as not, so no stiction is named.
//! - Linkage play inside the positioner's loop makes a closed loop hunt in quick steps too
//!   (seed 37: valves 258 and 339; seed 38: valve 354): the stem crosses the play unseen on
//!   each reversal and the reading catches up in one go. A friction band crossed by a
//!   positioner as fast as the one stick-slip is given matches those steps as closely, so no
//!   stiction is named.
//! - A valve that does stick and jump in a closed loop (seed 5 valve 270, stiction alone),
//!   whose slips a fitted stick-slip matches only in part, is still named stiction by their
//!   number: its evident slips outnumber the smooth rival's many times over. One whose slips
//!   stick-slip matches (seed 9 valve 205, of the physical family) is named by the match.
//! - A valve that sticks and jumps at the steps it is given (seed 13 valve 55, of the physical
//!   family, on random steps; seed 11 valve 309 on small steps; both recorded intact), whose
//!   slip histograms a friction band matches about as closely as stick-slip, by slips without
//!   rests: under a command that holds still between moves, the valve rests and jumps dozens
//!   of times, five times as often as that rival and more, so the rival is none and stiction
//!   is named, with the slip's interval holding the drawn one. As logged (sensor noise 0.1 %,
//!   read per mille) neither is: the stick-slip grid's best fits make 3 to 6 slips on the
//!   held-out blocks where the valve makes 31 and 60, and which of them the free-run error
//!   picks decides whether the slips come closer over the whole recording. With the noise
//!   read 0.121 % (the median of a per-mille reading) they did; read 0.106 % they do not.
//! - A valve that hunts in slips the sensor's noise hides one by one (seed 12 valve 270: slips
//!   of 0.51 % on small steps under 0.25 % of noise) shows too few evident slips to be judged
//!   by them, but the current model misses hundreds in the fit and the held-out blocks alike:
//!   it is named stiction, and the slip's interval holds the drawn one.
//! - A tolerance band that stick-slip explains as well is named a deadband (seed 5 valve 285,
//!   a 0.94 % band alone, random steps, sensor noise 0.25 %): stick-slip on the valve's input
//!   (a band and a jump) and a positioner deadband remove the same half of the held-out error;
//!   with as much support from the held-out blocks, the one with fewer parameters wins on BIC,
//!   the other is named its look-alike, and the deadband's interval holds the band.
//! - A healthy stem in a noisy level loop stops short by its lost motion, which looks like a
//!   deadband (seed 12 valve 222, of the physical family: Coulomb band 0.12 %, positioner
//!   deadband 0.006 %, fitted as a deadband of 0.26 %): a deadband no larger than a healthy
//!   friction band is not worth maintenance, so nothing is named.
//! - A tolerance band whose stick-slip look-alike removes a little more of the held-out error
//!   is named a deadband when V_P never sticks and then jumps (seed 11 valves 321 and 330,
//!   bands of 0.55 % beside a 1 % sensor lattice on random steps and 0.75 % on mixed
//!   excitation): neither shows one evident slip, so stick-slip is only its look-alike.
//! - A digital positioner that waits 1.8 s before it acts on a noisy controller output (seed 17
//!   valve 312, a level loop) moves in quick steps long after O_P did; a baseline that took
//!   the delay for a slow positioner misses hundreds of them. The dead time, fitted from the
//!   baseline's whole lag, explains them: dead time is named with an interval holding the
//!   drawn delay, and stiction is not.
//! - A valve that hunts by 0.6 % beside a travel stop, recorded intact (seed 17 valve 309,
//!   mixed excitation): once the stop is in the model, the free-run error is least with a
//!   stick-slip trace of 0.05 %, which goes in the model unnamed. Judged by its slips against
//!   the model without that trace, stiction is named, its interval holding the drawn slip.
//! - Stick-slip that wins a round by the held-out error must stick and jump too: seed 33's
//!   physical valve 78 (an unevenness of 1.8 on random steps, a static excess of 0.009 %) was
//!   named `stiction` 0.36 % beside the unevenness, for 7 % of the held-out error left, while
//!   V_P made not one evident slip. The unevenness alone is named, intact and as logged.
//! - A digital positioner with a wide tolerance band leaves it with a pulse and rests at its
//!   edge again: on ramps V_P climbs a staircase of equal steps, which sticks and then jumps
//!   like stick-slip (seed 43 valve 312: a 2.9 % band on ramps, steps of 0.30 %; seed 37 valve
//!   330: 2.2 % in a closed loop, steps of 0.34 %). Steps of a quarter of the band or less are
//!   the band's: deadband alone is named, intact and as logged. Stick-slip inside a band,
//!   with slips of a third of it or more (seed 40 valve 198: 0.71 % in 2.9 %; seed 42 valve
//!   177: 0.86 % in 1.6 %, both of the physical family), is still named beside it.

use valve_bridge::diagnose::{self, Diagnosis, Effect, Note};
use valve_bridge::synth::logged;

use crate::cases::{self, Case};

/// Valve `index` of the bench's `seed` and its diagnosis as the daemon logs it.
pub(crate) fn diagnosed(seed: u64, index: usize) -> (Case, Diagnosis) {
    diagnosed_as(seed, index, true)
}

/// Valve `index` of the bench's `seed` and its diagnosis, as the daemon logs it or intact.
pub(crate) fn diagnosed_as(seed: u64, index: usize, as_logged: bool) -> (Case, Diagnosis) {
    let plan = (cases::plans(seed, 220).into_iter())
        .find(|p| p.index == index)
        .unwrap();
    let case = cases::build(&plan, 600.0).unwrap();
    let d = if as_logged {
        let rec = logged::as_logged(&case.rec, 0.005, plan.seed);
        diagnose::diagnose(&rec.view(), None, &|_, _| {})
    } else {
        diagnose::diagnose(&case.rec.view(), None, &|_, _| {})
    };
    (case, d.unwrap())
}

/// Whether the finding of `effect` in `d` has a 90 % interval holding the truth of `case`.
pub(crate) fn holds(case: &Case, d: &Diagnosis, effect: Effect) -> bool {
    let finding = d.findings.iter().find(|f| f.effect == effect);
    let truth = case.truth.iter().find(|t| t.effect == effect);
    match (finding, truth) {
        (Some(f), Some(t)) => {
            f.size.name == t.name && (f.size.low..=f.size.high).contains(&t.value)
        }
        _ => false,
    }
}

pub(crate) fn named(d: &Diagnosis) -> Vec<Effect> {
    d.findings.iter().map(|f| f.effect).collect()
}

#[test]
fn a_pulsing_positioner_in_a_noisy_loop_is_not_named_stiction() {
    for (seed, index) in [(5, 372), (6, 378), (7, 369)] {
        let (case, d) = diagnosed(seed, index);
        assert!(case.labels.is_empty(), "seed {seed} valve {index}");
        assert!(
            !named(&d).contains(&Effect::Stiction),
            "seed {seed} valve {index}: {:?}",
            named(&d)
        );
    }
}

#[test]
fn slips_a_valve_makes_following_the_model_are_not_hunting_by_their_number() {
    // Seed 46's digital 363, healthy, in a noisy loop read under 0.4 % of noise, recorded
    // intact: 35 evident slips of about 1.2 %, V_P following the model before them (0.46), and
    // the model missed 78 and 75 slips in the two halves, fifteen a minute. That count was
    // taken for hunting the noise hides, and stiction of 1.13 % was named.
    let (case, d) = diagnosed_as(46, 363, false);
    assert!(case.labels.is_empty());
    assert!(d.findings.is_empty(), "{:?}", named(&d));
}

#[test]
fn a_fast_positioner_following_a_noisy_controller_is_not_named_stiction() {
    for index in [264, 269] {
        let (case, d) = diagnosed(9, index);
        assert!(!case.labels.contains(&Effect::Stiction), "valve {index}");
        assert!(
            named(&d).iter().all(|e| case.labels.contains(e)),
            "valve {index}: labels {:?}, found {:?}",
            case.labels,
            named(&d)
        );
    }
}

#[test]
fn linkage_play_a_closed_loop_hunts_across_is_not_named_stiction() {
    // Linkage play of 3.98 % (seed 37's 258, 0.02 % sensor), 1.45 % (seed 37's 339, 0.25 %)
    // and 2.06 % (seed 38's 354, 0.1 %) inside the positioner's loop: the stem crosses the
    // play unseen on every reversal of the controller's output and the reading catches up in
    // one quick step. A friction band as fast as stick-slip's positioner makes those steps
    // as closely as stick-slip does.
    for (seed, index) in [(37, 258), (37, 339), (38, 354)] {
        let (case, d) = diagnosed(seed, index);
        assert_eq!(case.labels, [Effect::Backlash], "seed {seed} valve {index}");
        assert!(
            !named(&d).contains(&Effect::Stiction),
            "seed {seed} valve {index}: {:?}",
            named(&d)
        );
    }
}

#[test]
fn stick_slip_in_a_closed_loop_is_still_named_by_its_slips() {
    for (seed, index) in [(5, 270), (9, 205)] {
        let (case, d) = diagnosed(seed, index);
        assert_eq!(case.labels, [Effect::Stiction], "seed {seed} valve {index}");
        assert_eq!(
            named(&d).first(),
            Some(&Effect::Stiction),
            "seed {seed} valve {index}: {:?}",
            named(&d)
        );
    }
}

#[test]
fn a_smooth_rival_without_the_valves_rests_cannot_veto_stick_slip() {
    for (seed, index) in [(13, 55), (11, 309)] {
        let (case, d) = diagnosed_as(seed, index, false);
        stick_slip_alone_named_and_sized(&case, &d, &format!("seed {seed} valve {index}"));
    }
}

/// `case` holds stick-slip alone, and `d` names it alone with an interval holding its slip.
fn stick_slip_alone_named_and_sized(case: &Case, d: &Diagnosis, which: &str) {
    assert_eq!(case.labels, [Effect::Stiction], "{which}");
    assert_eq!(named(d), [Effect::Stiction], "{which}");
    assert!(
        holds(case, d, Effect::Stiction),
        "{which}: {:?}, drawn {:?}",
        d.findings[0].size,
        case.truth
    );
}

#[test]
fn stick_slip_that_hunts_at_some_set_points_and_rests_at_others_is_named() {
    // Seed 50's physical valve 45 (static band 0.97 %, Coulomb 0.10 %, a slow positioner at
    // 3.3 /s): it hunts around a steady O_P until a slip lands inside its tolerance band. Stick-
    // slip without a band hunts at every set-point (over 300 slips where the valve makes 87
    // evident ones), so it was never named.
    let (case, d) = diagnosed_as(50, 45, false);
    stick_slip_alone_named_and_sized(&case, &d, "seed 50 valve 45");
}

#[test]
fn a_deadband_named_before_stick_slip_stays_as_named() {
    // Seed 50's digital valve 258 (a tolerance band of 2.8 % and stick-slip of 0.71 %, on
    // ramps): the deadband is named first, and stick-slip's fit puts no band of its own in the
    // model beside it (it once added one of 1.13 %).
    let (case, d) = diagnosed_as(50, 258, false);
    assert_eq!(case.labels, [Effect::Stiction, Effect::Deadband]);
    assert_eq!(named(&d), [Effect::Deadband, Effect::Stiction]);
    let stick = &d.findings[1].params;
    assert!(!stick.contains_key("positioner_deadband_pct"), "{stick:?}");
}

#[test]
fn stick_slip_the_noise_hides_one_slip_at_a_time_is_named_by_their_number() {
    let (case, d) = diagnosed(12, 270);
    stick_slip_alone_named_and_sized(&case, &d, "seed 12 valve 270 as logged");
}

#[test]
fn a_healthy_stem_in_a_noisy_loop_is_not_named_a_deadband() {
    let (case, d) = diagnosed(12, 222);
    assert!(case.labels.is_empty());
    assert_eq!(named(&d), []);
}

#[test]
fn a_tolerance_band_stick_slip_explains_as_well_is_named_deadband() {
    let (case, d) = diagnosed(5, 285);
    assert_eq!(case.labels, [Effect::Deadband]);
    assert_eq!(named(&d), [Effect::Deadband]);
    assert_eq!(d.findings[0].alternatives, [Effect::Stiction]);
    assert!(
        holds(&case, &d, Effect::Deadband),
        "band {:?}, {}",
        case.truth,
        d.findings[0].size.words()
    );
}

#[test]
fn a_tolerance_band_that_never_jumps_is_named_deadband() {
    for index in [321, 330] {
        let (case, d) = diagnosed(11, index);
        assert!(
            case.labels.contains(&Effect::Deadband) && !case.labels.contains(&Effect::Stiction),
            "valve {index}: {:?}",
            case.labels
        );
        let found = named(&d);
        assert!(
            found.contains(&Effect::Deadband) && !found.contains(&Effect::Stiction),
            "valve {index}: {found:?}"
        );
        let band = d
            .findings
            .iter()
            .find(|f| f.effect == Effect::Deadband)
            .unwrap();
        assert_eq!(band.alternatives, [Effect::Stiction], "valve {index}");
    }
}

#[test]
fn a_long_input_delay_under_a_noisy_controller_is_dead_time_not_stiction() {
    let (case, d) = diagnosed(17, 312);
    assert_eq!(case.labels, [Effect::DeadTime]);
    assert_eq!(named(&d), [Effect::DeadTime], "{:?}", d.findings);
    assert!(holds(&case, &d, Effect::DeadTime), "{:?}", d.findings);
}

#[test]
fn a_valve_hunting_beside_a_travel_stop_is_named_stiction_by_its_slips() {
    let (case, d) = diagnosed_as(17, 309, false);
    assert_eq!(case.labels, [Effect::Stiction, Effect::Saturation]);
    assert!(named(&d).contains(&Effect::Stiction), "{:?}", named(&d));
    assert!(holds(&case, &d, Effect::Stiction), "{:?}", d.findings);
    assert!(holds(&case, &d, Effect::Saturation), "{:?}", d.findings);
}

#[test]
fn a_smooth_mismatch_without_one_evident_slip_is_not_named_stiction() {
    for as_logged in [false, true] {
        let (case, d) = diagnosed_as(33, 78, as_logged);
        assert_eq!(case.labels, [Effect::Asymmetry]);
        assert_eq!(named(&d), [Effect::Asymmetry], "as logged: {as_logged}");
    }
}

#[test]
fn a_tolerance_band_left_in_small_pulsed_steps_is_named_deadband_not_stiction() {
    for (seed, index) in [(43, 312), (37, 330)] {
        for as_logged in [false, true] {
            let (case, d) = diagnosed_as(seed, index, as_logged);
            let at = format!("seed {seed} valve {index}, as logged: {as_logged}");
            assert_eq!(case.labels, [Effect::Deadband], "{at}");
            assert_eq!(named(&d), [Effect::Deadband], "{at}: {:?}", d.findings);
            // The report says the steps were the band's, and how to tell small stick-slip.
            let steps = d.notes.iter().find_map(|n| match *n {
                Note::StepsInBand { step_pct, band_pct } => Some((step_pct, band_pct)),
                _ => None,
            });
            let (step, band) = steps.unwrap_or_else(|| panic!("{at}: {:?}", d.notes));
            assert!(
                (0.25..0.4).contains(&step) && step <= band / 4.0,
                "{at}: {step} in {band}"
            );
        }
    }
}

#[test]
fn stick_slip_inside_a_band_with_slips_of_a_third_of_it_is_still_named() {
    for (seed, index) in [(40, 198), (42, 177)] {
        for as_logged in [false, true] {
            let (case, d) = diagnosed_as(seed, index, as_logged);
            let at = format!("seed {seed} valve {index}, as logged: {as_logged}");
            assert_eq!(case.labels, [Effect::Stiction, Effect::Deadband], "{at}");
            let found = named(&d);
            assert!(
                found.contains(&Effect::Stiction) && found.contains(&Effect::Deadband),
                "{at}: {found:?}"
            );
            assert!(holds(&case, &d, Effect::Stiction), "{at}: {:?}", d.findings);
        }
    }
}
