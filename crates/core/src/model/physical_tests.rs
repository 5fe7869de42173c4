//! Tests of the physical valve: each parameter produces the behaviour it is named for, and
//! invariants hold for any parameters in the documented ranges (proptest).

use super::*;
use crate::model::{bundled, ModelKind, ModelSpec, Valve};
use proptest::prelude::*;

const DT: f64 = 0.01;

/// A quiet healthy valve (no sensor noise, no dead time) changed by `f`.
fn spec(f: impl FnOnce(&mut PhysicalParams)) -> ModelSpec {
    let mut p = PhysicalParams {
        sensor_noise_pct: 0.0,
        ..PhysicalParams::default()
    };
    f(&mut p);
    ModelSpec {
        physical: Some(p),
        ..ModelSpec::bare(ModelKind::Physical, 0.0)
    }
}

fn valve_at(spec: &ModelSpec, at: f64) -> Valve {
    let mut v = Valve::new(spec, DT).unwrap();
    v.reset(at, at);
    v
}

fn hold(v: &mut Valve, op: f64, seconds: f64) -> Vec<f64> {
    (0..(seconds / DT).round() as usize)
        .map(|_| v.step(op))
        .collect()
}

/// Samples until the reading leaves `from` by more than `by`.
fn moves_after(out: &[f64], from: f64, by: f64) -> usize {
    out.iter()
        .position(|y| (y - from).abs() > by)
        .unwrap_or(out.len())
}

/// Largest speed of the reading over 0.1 s, %/s.
fn top_speed(out: &[f64]) -> f64 {
    out.windows(11)
        .map(|w| (w[10] - w[0]).abs() / (10.0 * DT))
        .fold(0.0, f64::max)
}

#[test]
fn bundled_file_is_the_default_healthy_valve() {
    let spec = bundled(ModelKind::Physical);
    assert_eq!(spec.physical, Some(PhysicalParams::default()));
    let table = toml::Value::try_from(PhysicalParams::default()).unwrap();
    assert_eq!(
        table.as_table().map(|t| t.len()),
        Some(PhysicalParams::COUNT)
    );
    // A healthy valve follows a 10 % step within a second and stops on it.
    let mut v = valve_at(&spec, 40.0);
    let out = hold(&mut v, 50.0, 3.0);
    assert!((out[100] - 50.0).abs() < 0.3, "{}", out[100]);
    assert!((out[299] - 50.0).abs() < 0.2, "{}", out[299]);
}

#[test]
fn coulomb_band_delays_reversals_but_not_same_direction_steps() {
    let s = spec(|p| {
        p.coulomb_band_pct = 3.0;
        p.static_band_pct = 3.0;
        p.deadband_pct = 0.0;
    });
    let mut v = valve_at(&s, 45.0);
    let settled = *hold(&mut v, 50.0, 10.0).last().unwrap();
    let mut same = v.clone();
    let up = hold(&mut same, 52.0, 3.0);
    let down = hold(&mut v, 48.0, 3.0);
    let (t_same, t_rev) = (
        moves_after(&up, settled, 0.05),
        moves_after(&down, settled, 0.05),
    );
    // The chamber must cross the 3 % band first: at most 16 %/s that is about 0.2 s more.
    assert!(
        t_rev >= t_same + 12,
        "same {t_same}, reversal {t_rev} samples"
    );
    // Lost motion on the reversal: an equal and opposite move ends short of where it started.
    assert!((up[299] - 52.0).abs() < 0.3 && (down[299] - 48.0).abs() < 0.3);
}

#[test]
fn static_above_coulomb_makes_the_stem_slip_at_rest() {
    let sticky = spec(|p| {
        p.coulomb_band_pct = 0.5;
        p.static_band_pct = 2.0;
        p.deadband_pct = 0.0;
    });
    let mut v = valve_at(&sticky, 45.0);
    let out = hold(&mut v, 50.0, 60.0);
    let tail = &out[2000..];
    let slips = tail
        .windows(5)
        .filter(|w| (w[4] - w[0]).abs() > 0.5)
        .count();
    assert!(slips >= 4, "{slips} slips at a steady O_P");
    // Without the static excess the stem comes to rest.
    let calm = spec(|p| {
        p.coulomb_band_pct = 0.5;
        p.static_band_pct = 0.5;
        p.deadband_pct = 0.0;
    });
    let out = hold(&mut valve_at(&calm, 45.0), 50.0, 60.0);
    assert!(out[2000..].iter().all(|y| (y - 50.0).abs() < 0.01));
}

#[test]
fn fill_and_vent_limits_set_opening_and_closing_speeds() {
    let s = spec(|p| {
        p.fill_rate_pct_per_s = 40.0;
        p.vent_rate_pct_per_s = 10.0;
    });
    let mut v = valve_at(&s, 20.0);
    let open = top_speed(&hold(&mut v, 80.0, 8.0));
    let close = top_speed(&hold(&mut v, 20.0, 8.0));
    assert!((open - 40.0).abs() < 2.0, "opening {open} %/s");
    assert!((close - 10.0).abs() < 0.5, "closing {close} %/s");
}

#[test]
fn volume_growth_slows_the_open_valve() {
    let s = spec(|p| p.volume_growth = 3.0);
    let rise = |at: f64| {
        let mut v = valve_at(&s, at);
        let out = hold(&mut v, at + 2.0, 3.0);
        out.iter().position(|y| *y > at + 2.0 * 0.63).unwrap_or(300)
    };
    let (closed, open) = (rise(5.0), rise(90.0));
    assert!(
        open as f64 > 2.5 * closed as f64,
        "T63 {closed} near closed, {open} near open"
    );
    let mut v = valve_at(&s, 10.0);
    let fast = top_speed(&hold(&mut v, 30.0, 3.0));
    let mut v = valve_at(&s, 70.0);
    let slow = top_speed(&hold(&mut v, 90.0, 3.0));
    assert!(
        fast > 2.0 * slow,
        "stroke {fast} %/s near closed, {slow} %/s open"
    );
}

#[test]
fn deadband_stops_the_valve_short() {
    let s = spec(|p| p.deadband_pct = 2.0);
    let mut v = valve_at(&s, 50.0);
    let last = *hold(&mut v, 55.0, 5.0).last().unwrap();
    assert!(last > 53.9 && last < 54.4, "stopped at {last}");
    // Inside half the band nothing happens at all.
    let mut v = valve_at(&s, 50.0);
    assert!(hold(&mut v, 50.9, 3.0).iter().all(|&y| y == 50.0));
}

#[test]
fn min_rate_closes_small_errors_at_a_constant_speed() {
    let slow = |floor: f64| {
        spec(move |p| {
            p.positioner_gain_per_s = 0.5;
            p.min_rate_pct_per_s = floor;
            p.deadband_pct = 0.2;
        })
    };
    let mut v = valve_at(&slow(3.0), 50.0);
    let out = hold(&mut v, 51.0, 3.0);
    // 1 % at 3 %/s: a third of a second, at the same speed early and late in the move.
    let at = |level: f64| out.iter().position(|y| *y > level).unwrap_or(300);
    let (a, b, c) = (at(50.2), at(50.5), at(50.8));
    assert!(c < 45, "reached 50.8 after {c} samples");
    assert!(((b - a) as i64 - (c - b) as i64).abs() <= 2, "{a} {b} {c}");
    // Without the floor the same valve creeps exponentially (0.5 /s).
    let mut v = valve_at(&slow(0.0), 50.0);
    let out = hold(&mut v, 51.0, 3.0);
    assert!(out[299] < 50.8, "{}", out[299]);
}

#[test]
fn travel_stop_holds_the_stem_while_op_asks_for_more() {
    let mut s = spec(|_| {});
    s.travel.max_pct = 80.0;
    let mut v = valve_at(&s, 70.0);
    let out = hold(&mut v, 90.0, 5.0);
    assert!(out[150..].iter().all(|&y| y == 80.0));
    // The chamber wound up past the stop, so coming back takes longer than a plain step.
    let back = hold(&mut v, 70.0, 5.0);
    let t_back = moves_after(&back, 80.0, 0.05);
    let mut w = valve_at(&spec(|_| {}), 80.0);
    let t_plain = moves_after(&hold(&mut w, 70.0, 5.0), 80.0, 0.05);
    assert!(t_back > t_plain + 10, "{t_back} vs {t_plain} samples");
}

#[test]
fn sensor_gain_offset_resolution_and_noise() {
    let s = spec(|p| {
        p.sensor_gain = 1.1;
        p.sensor_offset_pct = 1.0;
    });
    let mut v = valve_at(&spec(|_| {}), 50.0);
    let mut w = Valve::new(&s, DT).unwrap();
    w.reset(50.0, 1.1 * 50.0 + 1.0);
    // The positioner holds the true position at O_P; the sensor reads it off by gain and offset.
    assert!((hold(&mut v, 50.0, 1.0)[99] - 50.0).abs() < 1e-9);
    let read = hold(&mut w, 50.0, 1.0)[99];
    assert!((read - 56.0).abs() < 1e-9, "{read}");
    // The reading is not clamped to the travel.
    let mut top = Valve::new(&s, DT).unwrap();
    top.reset(100.0, 111.0);
    assert!((top.step(100.0) - 111.0).abs() < 1e-9);

    let lattice = spec(|p| p.sensor_resolution_pct = 0.5);
    let mut v = valve_at(&lattice, 40.0);
    let out = hold(&mut v, 43.3, 3.0);
    assert!(out
        .iter()
        .all(|y| ((y / 0.5).round() * 0.5 - y).abs() < 1e-9));
    assert_eq!(out[299], 43.5);

    let noisy = spec(|p| p.sensor_noise_pct = 0.2);
    let mut v = valve_at(&noisy, 50.0);
    let out = hold(&mut v, 50.0, 20.0);
    let mean = out.iter().sum::<f64>() / out.len() as f64;
    let sd = (out.iter().map(|y| (y - mean).powi(2)).sum::<f64>() / out.len() as f64).sqrt();
    assert!(
        (sd - 0.2).abs() < 0.02 && (mean - 50.0).abs() < 0.02,
        "{mean} {sd}"
    );
    // Re-seeded on reset: the same noise again.
    v.reset(50.0, 50.0);
    assert_eq!(hold(&mut v, 50.0, 20.0), out);
}

#[test]
fn dead_time_delays_the_start() {
    let mut s = spec(|_| {});
    s.dead_time_s = 0.5;
    let mut v = valve_at(&s, 30.0);
    let out = hold(&mut v, 40.0, 2.0);
    assert_eq!(moves_after(&out, 30.0, 1e-6), 50);
}

#[test]
fn effects_and_out_of_range_parameters_are_refused_with_the_key() {
    let mut s = spec(|_| {});
    s.effects.deadband_pct = 1.0;
    let e = s.validate().unwrap_err().to_string();
    assert!(e.contains("effects") && e.contains("[physical]"), "{e}");
    let e = spec(|p| p.static_band_pct = 0.05).validate().unwrap_err();
    assert!(e.to_string().contains("physical.static_band_pct"), "{e}");
    let e = spec(|p| p.positioner_gain_per_s = 80.0)
        .validate()
        .unwrap_err();
    assert!(e.to_string().contains("oscillates"), "{e}");
    let text = "model = \"physical\"\n[physical]\nvolume_growth = 30.0\n";
    let e = ModelSpec::from_toml(text, std::path::Path::new("p.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.starts_with("p.toml:3: physical.volume_growth: 30 is not allowed"),
        "{e}"
    );
}

/// Any parameters within the documented ranges.
fn any_params() -> impl Strategy<Value = PhysicalParams> {
    let positioner = (
        0.0f64..1.0,
        0.0f64..10.0,
        0.1f64..1000.0,
        0.1f64..1000.0,
        0.0f64..1.0,
        0.0f64..20.0,
    );
    let stem = (
        1.0f64..100.0,
        0.3f64..5.0,
        0.0f64..20.0,
        0.0f64..1.0,
        0.0f64..1.0,
    );
    let sensor = (
        0.5f64..1.5,
        -10.0f64..10.0,
        0.0f64..5.0,
        0.0f64..10.0,
        0u64..=i64::MAX as u64,
    );
    (positioner, stem, sensor).prop_map(|((k, db, fill, vent, floor, g), stem, sensor)| {
        let (f_n, z, c, s_share, step_share) = stem;
        let damped = (z * std::f64::consts::TAU * f_n).min(100.0);
        PhysicalParams {
            positioner_gain_per_s: 1e-3 + k * (damped - 1e-3),
            deadband_pct: db,
            fill_rate_pct_per_s: fill,
            vent_rate_pct_per_s: vent,
            min_rate_pct_per_s: floor * fill.min(vent),
            volume_growth: g,
            natural_freq_hz: f_n,
            damping_ratio: z,
            coulomb_band_pct: c,
            static_band_pct: c + s_share * (20.0 - c),
            sensor_gain: sensor.0,
            sensor_offset_pct: sensor.1,
            sensor_noise_pct: sensor.2,
            sensor_resolution_pct: sensor.3,
            noise_seed: sensor.4,
            internal_step_s: 1e-5 + step_share * ((0.08 / f_n).min(0.01) - 1e-5),
        }
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn stem_stays_within_the_stops_and_output_is_finite(
        p in any_params(), lo in 0.0f64..30.0, hi in 70.0f64..100.0,
        ops in prop::collection::vec(-20.0f64..120.0, 1..60),
    ) {
        let travel = Travel { min_pct: lo, max_pct: hi };
        let spec = ModelSpec { physical: Some(p), travel, ..ModelSpec::bare(ModelKind::Physical, 0.0) };
        prop_assert!(spec.validate().is_ok(), "{:?}", spec.validate().err());
        let mut core = Physical::new(&p, &travel, DT);
        core.reset(50.0);
        for &u in &ops {
            for _ in 0..5 {
                let y = core.step(u);
                prop_assert!(y.is_finite());
                let x = core.position();
                prop_assert!(x >= lo && x <= hi, "{x} outside [{lo}, {hi}]");
                prop_assert!(core.pressure().is_finite());
            }
        }
    }

    #[test]
    fn same_seed_same_run(p in any_params(), ops in prop::collection::vec(0.0f64..100.0, 1..200)) {
        let spec = ModelSpec { physical: Some(p), ..ModelSpec::bare(ModelKind::Physical, 0.1) };
        let a = Valve::new(&spec, DT).unwrap().simulate(&ops, 50.0);
        let mut v = Valve::new(&spec, DT).unwrap();
        v.simulate(&ops, 20.0);
        prop_assert_eq!(v.simulate(&ops, 50.0), a);
    }

    #[test]
    fn at_rest_on_target_without_noise_it_stays_put(p in any_params(), at in 0.0f64..100.0) {
        let p = PhysicalParams { sensor_noise_pct: 0.0, ..p };
        let travel = Travel::default();
        let mut core = Physical::new(&p, &travel, DT);
        core.reset(p.sensor_gain * at + p.sensor_offset_pct);
        let x0 = core.position();
        let first = core.step(x0);
        for _ in 0..200 {
            prop_assert_eq!(core.step(x0), first);
            prop_assert_eq!(core.position(), x0);
        }
    }
}
