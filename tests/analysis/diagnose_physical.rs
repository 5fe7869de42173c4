//! Diagnosis on the physical valve (`model = "physical"`), whose physics diagnosis does not
//! share (it fits a composed pin-cart II valve): the classes of failure seen on recordings from
//! other simulators, each built from the physics that causes it in a real valve. A travel stop
//! above closed or below open, a coarse sensor lattice on a quiet sensor, a valve that hunts at
//! some holds only, a deadband in the positioner, a dead time hidden behind a travel stop, a
//! healthy valve in closed loop read by a quiet sensor, and a healthy valve whose stem dynamics
//! a slowdown of the open valve could take up (nothing to find in either).
//!
//! The blind benchmark (`cargo bench --bench diagnose_blind`) scores the same method over
//! hundreds of randomised valves; these are the cases that must never regress.

use valve_bridge::diagnose::{self, Diagnosis, Note};
use valve_bridge::model::{ModelSpec, PhysicalParams};
use valve_bridge::synth::{self, physical, Excitation};

use crate::cases;
use crate::common::diagnosis::{names, param};

const DT: f64 = 0.01;
const MINUTES_10: f64 = 600.0;

/// The healthy physical valve read by a sensor of `noise_pct`, with `change` applied.
fn valve(noise_pct: f64, change: impl Fn(&mut ModelSpec, &mut PhysicalParams)) -> ModelSpec {
    let mut spec = physical::healthy();
    let mut p = spec
        .physical
        .expect("the bundled physical valve has [physical]");
    p.sensor_noise_pct = noise_pct;
    change(&mut spec, &mut p);
    spec.physical = Some(p);
    spec
}

fn diagnose(spec: &ModelSpec, excitation: Excitation, seed: u64) -> Diagnosis {
    let rec = synth::generate(spec, excitation, MINUTES_10, DT, 0.0, seed).unwrap();
    diagnose::diagnose(&rec.view(), None, &|_, _| {}).unwrap()
}

#[test]
fn a_stop_below_full_open_is_saturation_and_nothing_else() {
    // The stem stops at 80 % while the paper's random steps ask for up to 97 %.
    let spec = valve(0.1, |s, _| s.travel.max_pct = 80.0);
    let d = diagnose(&spec, Excitation::RandomSteps, 3);
    assert_eq!(names(&d), ["saturation"], "{:?}", d.findings);
    let stop = param(&d, "travel_max_pct");
    assert!((stop - 80.0).abs() < 0.5, "stop at {stop} %");
}

#[test]
fn a_stop_above_closed_is_saturation_too() {
    let spec = valve(0.1, |s, _| s.travel.min_pct = 30.0);
    let d = diagnose(&spec, Excitation::RandomSteps, 4);
    assert_eq!(names(&d), ["saturation"], "{:?}", d.findings);
    let stop = param(&d, "travel_min_pct");
    assert!((stop - 30.0).abs() < 0.5, "stop at {stop} %");
}

#[test]
fn a_coarse_lattice_on_a_quiet_sensor_is_quantization() {
    // 0.4 % steps of the reading, 0.01 % of noise: the lattice itself is the evidence.
    let spec = valve(0.01, |_, p| p.sensor_resolution_pct = 0.4);
    let d = diagnose(&spec, Excitation::SmallSteps { around_pct: 50.0 }, 5);
    assert_eq!(names(&d), ["quantization"], "{:?}", d.findings);
    assert!((param(&d, "quantization_pct") - 0.4).abs() < 1e-6);
    // The noise floor is at least the rounding's, not 0.
    assert!(
        d.noise_floor_pct >= 0.4 / 12f64.sqrt() - 1e-9,
        "{}",
        d.noise_floor_pct
    );
}

#[test]
fn a_valve_that_hunts_at_some_holds_only_is_stiction() {
    // Static friction 1 % above the Coulomb band with a quiet sensor: after a few of the
    // random steps the stem sticks, slips past the target and hunts (25 slips of 0.3 % or
    // more in 10 minutes); after most it settles. Where they fall between the fit and the
    // held-out blocks is chance.
    let spec = valve(0.02, |_, p| {
        (p.positioner_gain_per_s, p.deadband_pct) = (7.5, 0.036);
        (p.coulomb_band_pct, p.static_band_pct) = (0.13, 1.2);
    });
    let d = diagnose(&spec, Excitation::RandomSteps, 3);
    assert_eq!(names(&d), ["stiction"], "{:?}", d.findings);
}

#[test]
fn a_deadband_in_the_positioner_is_a_deadband_alone() {
    // No action inside 1.5 %, full action outside it: the valve arrives still moving and
    // stops at the band's edge. That is no minimum speed.
    let spec = valve(0.1, |_, p| p.deadband_pct = 1.5);
    let d = diagnose(&spec, Excitation::Mixed { low_pct: 30.0 }, 7);
    assert_eq!(names(&d), ["deadband"], "{:?}", d.findings);
    let band = param(&d, "positioner_deadband_pct").max(param(&d, "deadband_pct"));
    assert!((1.0..2.0).contains(&band), "deadband {band} %");
}

#[test]
fn a_dead_time_behind_a_travel_stop_is_found_beside_it() {
    // The stop takes most of the error; the dead time must still be named after it.
    let spec = valve(0.02, |s, _| {
        s.travel.max_pct = 75.0;
        s.dead_time_s = 0.7;
    });
    let d = diagnose(&spec, Excitation::Ramps, 8);
    let found = names(&d);
    assert!(
        found.starts_with(&["saturation", "dead_time"]),
        "{:?}",
        d.findings
    );
    // The joint refits after the stop's wind-up recover the whole dead time.
    let td = d.final_model.spec.dead_time_s;
    assert!((td - 0.7).abs() < 0.1, "dead time {td} s");
}

#[test]
fn a_healthy_valve_in_closed_loop_read_by_a_quiet_sensor_has_nothing_missing() {
    // A noisy controller output through a healthy positioner with its small friction band:
    // neither a rate limit, nor a floor, nor stick-slip.
    let spec = valve(0.02, |_, p| {
        p.coulomb_band_pct = 0.12;
        p.static_band_pct = 0.14;
    });
    for seed in [9, 10] {
        let d = diagnose(&spec, Excitation::ClosedLoop { level_pct: 45.0 }, seed);
        assert!(d.findings.is_empty(), "seed {seed}: {:?}", d.findings);
    }
}

#[test]
fn a_healthy_valve_is_not_called_slower_when_open_than_it_shows() {
    // A healthy valve of the blind benchmark (seed 424242, case 104): a chamber only 1.14 times
    // slower fully open, fill and vent 95 and 86 %/s, a 12 Hz stem, the noisiest sensor, the
    // mixed excitation. A slowdown of 1.65 times fully open took up a quarter of its held-out
    // error (stem dynamics, the small asymmetry); the recording shows the upper third of its
    // travel answering only 1.10 times slower than the model without it does.
    healthy_blind_case(424242, 104);
}

#[test]
fn a_healthy_valve_under_a_jittery_controller_output_is_given_no_band() {
    // Seed 44's valves 225 and 246, healthy (positioner bands of 0.08 and 0.01 %, friction
    // bands under 0.2 %) in level loops whose controller output has a noise of 1.50 and 1.34 %
    // (sd): their chambers filter that jitter, and a deadband of 0.35 % (on 246 also a friction
    // band of 0.31 %) took the filtering up, intact and as logged.
    for index in [225, 246] {
        for as_logged in [false, true] {
            let (case, d) = crate::diagnose_stiction_or_not::diagnosed_as(44, index, as_logged);
            assert!(case.labels.is_empty(), "valve {index}: {:?}", case.labels);
            assert!(
                d.findings.is_empty(),
                "valve {index}, as logged {as_logged}: {:?}",
                names(&d)
            );
        }
    }
}

/// The diagnosis of a healthy valve of the blind benchmark (seed `seed`, case `index`), which
/// must have no finding.
fn healthy_blind_case(seed: u64, index: usize) -> Diagnosis {
    let plan = cases::plans(seed, 220)
        .into_iter()
        .find(|p| p.index == index)
        .unwrap();
    let case = cases::build(&plan, MINUTES_10).unwrap();
    assert!(case.labels.is_empty(), "{:?}", case.labels);
    let d = diagnose::diagnose(&case.rec.view(), None, &|_, _| {}).unwrap();
    assert!(d.findings.is_empty(), "{:?}", names(&d));
    d
}

#[test]
fn a_healthy_valve_read_a_little_off_is_not_called_asymmetric() {
    // A healthy valve of the blind benchmark (seed 777001, case 101): a slow positioner
    // (3.5 /s) in closed loop under a noisy controller output, its sensor reading 0.026 % high
    // on a 0.025 % lattice. Its errors are hundredths of a percent, so the offset is most of
    // them: without it in the model, an asymmetric speed limit (5.8 %/s opening, 1.6 %/s
    // closing) made the model lag one way and removed 58 % of the held-out error.
    let d = healthy_blind_case(777001, 101);
    let offset = d.notes.iter().find_map(|n| match n {
        Note::SensorCalibration { offset_pct, .. } => Some(*offset_pct),
        _ => None,
    });
    assert!(
        matches!(offset, Some(o) if (0.01..0.1).contains(&o)),
        "{:?}",
        d.notes
    );
}
