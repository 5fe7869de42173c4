//! Diagnosis on recordings with an effect hidden on purpose, and on healthy valves (null cases).
//!
//! Each case is a closed level loop (gentle moves, many small reversals, no clean steps) or the
//! paper's random steps through a healthy valve (FOPDT-like, 0.1 s dead time, 60 %/s stroke)
//! with one small effect added, with sensor noise. The effect must be named, its size recovered,
//! and the held-out error lowered; a healthy valve must get no finding, and a coarse sensor
//! must not be taken for stiction. Stick-slip that hunts in the loop is found by its slips.

use valve_bridge::diagnose::{self, Diagnosis, Effect, Outcome};
use valve_bridge::model::composed::{self, Knob};
use valve_bridge::model::{bundled, ModelKind, ModelSpec};
use valve_bridge::synth::{self, Excitation};

use crate::common::diagnosis::{names, param};

const DT: f64 = 0.01;

fn healthy() -> ModelSpec {
    let mut spec = composed::compose(&bundled(ModelKind::Fopdt), DT);
    spec.dead_time_s = 0.1;
    composed::set(&mut spec, Knob::Slew, 60.0);
    spec
}

fn run(spec: &ModelSpec, excitation: Excitation, noise: f64, seed: u64) -> Diagnosis {
    let rec = synth::generate(spec, excitation, 900.0, DT, noise, seed).unwrap();
    diagnose::diagnose(&rec.view(), None, &|_, _| {}).unwrap()
}

const LOOP: Excitation = Excitation::ClosedLoop { level_pct: 50.0 };

#[test]
fn healthy_valve_in_closed_loop_gets_no_finding() {
    let d = run(&healthy(), LOOP, 0.1, 11);
    assert!(d.findings.is_empty(), "{:?}: {:?}", names(&d), d.outcome);
    assert!(
        matches!(d.outcome, Outcome::Noise | Outcome::NotSignificant { .. }),
        "{:?}",
        d.outcome
    );
}

#[test]
fn healthy_valve_under_random_steps_gets_no_finding() {
    let d = run(&healthy(), Excitation::RandomSteps, 0.1, 12);
    assert!(d.findings.is_empty(), "{:?}: {:?}", names(&d), d.outcome);
}

#[test]
fn small_backlash_hidden_in_closed_loop_is_found() {
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Crossing, 0.4);
    let d = run(&spec, LOOP, 0.1, 7);
    assert_eq!(names(&d), ["backlash"], "{:?}", d.outcome);
    // The 0.4 s crossing is quoted as the friction band it means at the loop's reversals (0.49 %
    // when this was written), inside its interval.
    let band = &d.findings[0].size;
    assert_eq!(band.name, "friction_band_pct");
    assert!(
        (0.3..0.8).contains(&band.value) && band.low <= band.value && band.value <= band.high,
        "{band:?}"
    );
    let f = &d.findings[0];
    assert!(f.heldout_sse_after < f.heldout_sse_before && f.delta_bic < 0.0);
}

#[test]
fn deadband_hidden_in_closed_loop_is_found() {
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Deadband, 0.4);
    let d = run(&spec, LOOP, 0.1, 7);
    assert_eq!(names(&d), ["deadband"], "{:?}", d.outcome);
    assert!((param(&d, "deadband_pct") - 0.4).abs() < 0.1);
}

/// A stickband of 0.8 % (jump 0.4 %) on the valve's input, behind a positioner that passes
/// its jumps on over more than 0.1 s: V_P never jumps, so the recording cannot tell it from a
/// positioner deadband (a valve in a deadband rests within its band and never jumps). The
/// band is found, named a deadband with stiction as its look-alike (the response test's slow
/// ramp out and back tells them apart).
#[test]
fn stiction_hidden_in_closed_loop_is_found_as_a_band_with_stiction_its_look_alike() {
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Stickband, 0.8);
    let d = run(&spec, LOOP, 0.1, 7);
    assert_eq!(names(&d), ["deadband"], "{:?}", d.outcome);
    assert_eq!(d.findings[0].alternatives, [Effect::Stiction]);
}

#[test]
fn extra_dead_time_is_found_with_its_size() {
    let mut spec = healthy();
    spec.dead_time_s = 0.6;
    let d = run(&spec, LOOP, 0.1, 7);
    assert_eq!(names(&d), ["dead_time"], "{:?}", d.outcome);
    assert!((param(&d, "dead_time_s") - 0.6).abs() < 0.05);
}

#[test]
fn calibration_offset_is_found() {
    let mut spec = healthy();
    composed::set(&mut spec, Knob::CalOffset, 0.8);
    let d = run(&spec, LOOP, 0.1, 7);
    assert_eq!(names(&d), ["calibration"], "{:?}", d.outcome);
    assert!((param(&d, "calibration_offset_pct") - 0.8).abs() < 0.1);
}

#[test]
fn slow_stroke_under_random_steps_is_a_slew_rate() {
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Slew, 12.0);
    let d = run(&spec, Excitation::RandomSteps, 0.1, 5);
    assert_eq!(names(&d), ["slew_rate"], "{:?}", d.outcome);
    assert!((param(&d, "slew_pct_per_s") - 12.0).abs() < 1.0);
}

#[test]
fn quantized_sensor_on_a_healthy_valve_is_not_stiction() {
    // A smooth valve read on a 0.5 % lattice moves in sudden steps with rests between, like a
    // sticking one, but one lattice step at a time: that is the sensor, not stick-slip.
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Quantum, 0.5);
    let d = run(&spec, LOOP, 0.0, 3);
    assert_eq!(names(&d), ["quantization"], "{:?}", d.outcome);
}

#[test]
fn hunting_by_stick_slip_in_closed_loop_is_found_by_its_slips() {
    // Stick-slip inside the positioner loop: the valve hunts with a phase O_P does not set, so
    // the free-run error cannot credit it; the slips of V_P do, with the breakaway's size.
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Breakaway, 1.5);
    let d = run(&spec, LOOP, 0.1, 3);
    assert_eq!(names(&d), ["stiction"], "{:?}", d.outcome);
    assert!((param(&d, "breakaway_pct") - 1.5).abs() < 0.2);
    assert!(
        matches!(d.outcome, Outcome::Missing { by_slips: true, .. }),
        "{:?}",
        d.outcome
    );
}

#[test]
fn a_slow_stroke_and_a_deadband_are_both_found() {
    // Two effects at once: the slow stroke dominates the large steps, the deadband only shows
    // in where the valve settles, so it is found second.
    let mut spec = healthy();
    composed::set(&mut spec, Knob::Slew, 15.0);
    composed::set(&mut spec, Knob::Deadband, 0.8);
    let d = run(&spec, Excitation::RandomSteps, 0.1, 21);
    let mut found = names(&d);
    found.sort();
    assert_eq!(found, ["deadband", "slew_rate"], "{:?}", d.outcome);
    assert!((param(&d, "slew_pct_per_s") - 15.0).abs() < 1.0);
    assert!((param(&d, "deadband_pct") - 0.8).abs() < 0.1);
    let last = d.findings.last().map_or(f64::NAN, |f| f.heldout_sse_after);
    assert!(last < 0.1 * d.baseline.heldout_sse, "{:?}", d.outcome);
}

#[test]
fn slow_venting_behind_a_long_signal_line_is_asymmetry_dead_time_and_a_slow_stroke() {
    let mut spec = healthy();
    spec.dead_time_s = 0.6;
    composed::set(&mut spec, Knob::Slew, 30.0);
    composed::set(&mut spec, Knob::ClosingSlew, 12.0);
    let d = run(&spec, Excitation::RandomSteps, 0.1, 22);
    let mut found = names(&d);
    found.sort();
    // Opening at 30 %/s is itself slower than the 40 %/s worth maintenance: the valve is slow
    // both ways, not only uneven.
    assert_eq!(
        found,
        ["asymmetry", "dead_time", "slew_rate"],
        "{:?}",
        d.outcome
    );
    // The joint refit after the second finding recovers both sizes.
    let fin = &d.final_model.spec;
    assert!((fin.dead_time_s - 0.6).abs() < 0.05, "{}", fin.dead_time_s);
    assert!((composed::get(fin, Knob::ClosingSlew) - 12.0).abs() < 1.0);
    // The stroke speed is the geometric mean of the two limits, 19 %/s.
    let slow = d.findings.iter().find(|f| f.effect == Effect::SlewRate);
    let speed = slow.map_or(f64::NAN, |f| f.size.value);
    assert!((speed - 360f64.sqrt()).abs() < 1.5, "{speed}");
}
