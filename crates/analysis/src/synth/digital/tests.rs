use super::*;
use crate::synth::Actuator;

const DT: f64 = 0.01;

/// `p` run from rest at `from` on O_P `to` for `seconds`: (V_P, stem) per sample.
fn run(p: &DigitalParams, from: f64, to: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut valve = DigitalValve::new(p, DT).unwrap();
    valve.reset(from, from);
    to.iter()
        .map(|&u| (valve.step(u), valve.stem_pct()))
        .unzip()
}

fn held(value: f64, seconds: f64) -> Vec<f64> {
    vec![value; (seconds / DT) as usize]
}

#[test]
fn a_healthy_valve_settles_inside_its_tolerance_band_and_stays() {
    let p = DigitalParams::default();
    for (from, to) in [(30.0, 50.0), (50.0, 49.0), (49.0, 49.4), (70.0, 20.0)] {
        let (_, stem) = run(&p, from, &held(to, 3.0));
        let rest = &stem[200..];
        assert!(
            rest.iter()
                .all(|x| (x - to).abs() <= p.tolerance_pct + 0.02),
            "{from} -> {to}: {:?}",
            &rest[..5]
        );
        let moved = rest.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>();
        assert!(moved < 0.01, "{from} -> {to}: still moving ({moved} %)");
    }
}

#[test]
fn a_solenoid_held_open_strokes_at_the_speed_the_orifices_give() {
    // A duty of 100 per % opens a solenoid for the whole sample: the valve strokes at the
    // orifice's speed, which the quasi-static formula gives at half travel.
    let mut p = DigitalParams {
        duty_per_pct: 100.0,
        ..DigitalParams::default()
    };
    p.set_stroke_speeds(40.0, 25.0);
    for (from, to, opening) in [(5.0, 95.0, true), (95.0, 5.0, false)] {
        let (_, stem) = run(&p, from, &held(to, 6.0));
        let at = |x: f64| {
            stem.iter()
                .position(|s| if opening { *s >= x } else { *s <= x })
                .unwrap() as f64
                * DT
        };
        let measured =
            10.0 / (at(if opening { 55.0 } else { 45.0 }) - at(if opening { 45.0 } else { 55.0 }));
        let formula = p.stroke_speed_pct_per_s(50.0, opening);
        assert!(
            (measured / formula - 1.0).abs() < 0.1,
            "opening {opening}: measured {measured:.1} %/s, formula {formula:.1} %/s"
        );
    }
}

#[test]
fn the_linkage_play_is_lost_inside_the_loop_and_the_transmitter_error_shows() {
    let p = DigitalParams {
        play_pct: 2.0,
        gain: 1.02,
        offset_pct: -0.5,
        noise_pct: 0.0,
        ..DigitalParams::default()
    };
    let mut op = held(60.0, 3.0);
    op.extend(held(40.0, 3.0));
    let (vp, stem) = run(&p, 50.0, &op);
    // The positioner brings the arm to the set-point: the stem rests half the play beyond it
    // in the direction it came from, and V_P reads the arm through the transmitter.
    let reading = |arm: f64| 1.02 * arm - 0.5;
    let band = p.tolerance_pct + 0.02;
    for (k, target, beyond) in [(290, 60.0, 1.0), (590, 40.0, -1.0)] {
        assert!((vp[k] - reading(target)).abs() < 1.02 * band, "{}", vp[k]);
        assert!((stem[k] - target - beyond).abs() < band, "{}", stem[k]);
    }
    // On the reversal the reading stands still until the stem has crossed the play.
    let turn = 300
        + stem[300..]
            .iter()
            .position(|x| *x < stem[290] - 0.05)
            .unwrap();
    assert_eq!(vp[turn], vp[290]);
    let seen = 300 + vp[300..].iter().position(|v| *v < vp[290] - 0.05).unwrap();
    assert!(
        stem[seen - 1] < stem[290] - 1.9,
        "{} {}",
        stem[seen - 1],
        stem[290]
    );
}

#[test]
fn a_stop_holds_the_stem_and_a_lattice_holds_the_reading() {
    let p = DigitalParams {
        stop_high_pct: 80.0,
        lattice_pct: 0.25,
        ..DigitalParams::default()
    };
    let (vp, stem) = run(&p, 50.0, &held(90.0, 3.0));
    assert!(stem.iter().all(|x| *x <= 80.0));
    assert!((stem[290] - 80.0).abs() < 1e-12);
    assert!(vp
        .iter()
        .all(|v| ((v / 0.25).round() * 0.25 - v).abs() < 1e-9));
}

#[test]
fn the_set_point_arrives_after_the_input_delay() {
    let p = DigitalParams {
        input_delay_s: 0.5,
        ..DigitalParams::default()
    };
    let (_, stem) = run(&p, 40.0, &held(60.0, 2.0));
    let first = stem.iter().position(|x| *x > 40.05).unwrap() as f64 * DT;
    assert!((0.5..0.58).contains(&first), "moved at {first} s");
}

#[test]
fn a_tolerance_band_lets_the_valve_rest_anywhere_inside_it() {
    let p = DigitalParams {
        tolerance_pct: 0.8,
        ..DigitalParams::default()
    };
    let targets = [53.0, 51.5, 55.0, 54.1, 50.0, 48.7, 52.0];
    let mut op = Vec::new();
    for t in targets {
        op.extend(held(t, 2.0));
    }
    let (_, stem) = run(&p, 50.0, &op);
    let errors: Vec<f64> = (targets.iter().enumerate())
        .map(|(k, t)| {
            let rest = &stem[200 * k + 150..200 * (k + 1)];
            assert!(rest.windows(2).all(|w| w[0] == w[1]), "{t}: moving");
            rest[0] - t
        })
        .collect();
    assert!(errors.iter().all(|e| e.abs() <= 0.8), "{errors:?}");
    let spread = errors.iter().copied().fold(f64::MIN, f64::max)
        - errors.iter().copied().fold(f64::MAX, f64::min);
    assert!(spread > 0.5, "{errors:?}");
}

#[test]
fn runs_repeat_for_a_seed_and_the_seed_moves_the_noise() {
    let p = DigitalParams::default();
    let op = held(55.0, 2.0);
    assert_eq!(run(&p, 50.0, &op), run(&p, 50.0, &op));
    let q = DigitalParams { noise_seed: 2, ..p };
    assert_ne!(run(&p, 50.0, &op).0, run(&q, 50.0, &op).0);
}

#[test]
fn parameters_out_of_range_are_refused_by_name() {
    let bad = [
        DigitalParams {
            supply_bar: 2.0,
            ..DigitalParams::default()
        },
        DigitalParams {
            min_pulse_s: 0.05,
            ..DigitalParams::default()
        },
        DigitalParams {
            static_pct: 0.01,
            ..DigitalParams::default()
        },
        DigitalParams {
            internal_step_s: 0.001,
            ..DigitalParams::default()
        },
    ];
    let names: Vec<&str> = bad
        .iter()
        .map(|p| DigitalValve::new(p, DT).unwrap_err().name)
        .collect();
    assert_eq!(
        names,
        ["supply_bar", "min_pulse_s", "static_pct", "internal_step_s"]
    );
    assert!(DigitalValve::new(&DigitalParams::default(), f64::NAN).is_err());
}
