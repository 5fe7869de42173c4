//! Compensation built from a model `diagnose` identified on the valve's own log, on physical
//! valves it was not built from (`model = "physical"`): what the compensation bench reports,
//! on shorter runs.
//!
//! - a 1.5 % friction band: small reversing steps track the healthy twin with at least 30 %
//!   less error and no more than 20 % more travel; the noisy level loop is left as it was;
//! - a healthy valve: its model has nothing to compensate, and nothing changes.

use valve_bridge::compensate::trial::{self, Figures, Scenario};
use valve_bridge::compensate::{CompensationConfig, Compensator};
use valve_bridge::diagnose::{self, Effect};
use valve_bridge::model::ModelSpec;
use valve_bridge::synth::{self, physical, Excitation};

const DT: f64 = 0.01;

/// The compensator of the model diagnose finds on 10 minutes of the valve's mixed log.
fn compensator(valve: &ModelSpec) -> Compensator {
    let rec = synth::generate(
        valve,
        Excitation::Mixed { low_pct: 40.0 },
        600.0,
        DT,
        0.0,
        1000,
    )
    .unwrap();
    let model = diagnose::diagnose(&rec.view(), None, &|_, _| {})
        .unwrap()
        .final_model
        .spec;
    let cfg = CompensationConfig {
        model_file: Some("model.toml".into()),
        ..CompensationConfig::default()
    };
    Compensator::new(&cfg, &model, DT, (0.0, 100.0)).unwrap()
}

/// Figures without and with compensation over 5 minutes.
fn trial(valve: &ModelSpec, comp: &Compensator, scenario: Scenario) -> (Figures, Figures) {
    let nominal = trial::nominal(valve);
    let plain = trial::run(valve, None, scenario, 300.0, DT, 1).unwrap();
    let comped = trial::run(valve, Some(comp.clone()), scenario, 300.0, DT, 1).unwrap();
    assert_eq!(comped.switched_off_s, None, "{}", scenario.name());
    (
        trial::figures(&plain, &nominal, DT).unwrap(),
        trial::figures(&comped, &nominal, DT).unwrap(),
    )
}

#[test]
fn a_friction_band_is_compensated_on_small_steps_and_the_level_loop_is_left_alone() {
    let valve = physical::with_effect(Effect::Backlash, 1.5);
    let comp = compensator(&valve);
    assert!(
        comp.describe().starts_with("backlash (friction band 1."),
        "{}",
        comp.describe()
    );
    let (plain, comped) = trial(&valve, &comp, Scenario::SmallSteps);
    assert!(
        comped.tracking_pct <= 0.7 * plain.tracking_pct,
        "{plain:?} -> {comped:?}"
    );
    assert!(comped.travel.travel_pct <= 1.2 * plain.travel.travel_pct);
    let (plain, comped) = trial(&valve, &comp, Scenario::LevelLoop);
    assert!(
        (comped.tracking_pct / plain.tracking_pct - 1.0).abs() < 0.02,
        "{plain:?} -> {comped:?}"
    );
    let iae = |f: &Figures| f.pv_iae.unwrap();
    assert!((iae(&comped) / iae(&plain) - 1.0).abs() < 0.01);
}

#[test]
fn a_healthy_valve_is_left_as_it_is() {
    let valve = physical::healthy();
    let comp = compensator(&valve);
    for scenario in Scenario::ALL {
        let (plain, comped) = trial(&valve, &comp, scenario);
        assert_eq!(plain, comped, "{}: {}", scenario.name(), comp.describe());
    }
}
