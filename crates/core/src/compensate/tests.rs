//! The compensator on valves whose model it knows: what each part does, the guard rails and
//! the guard.

use proptest::prelude::*;
use rand::SeedableRng;
use rand_distr::Distribution;

use super::*;
use crate::model::{bundled, PinCart2Params};

const DT: f64 = 0.01;

/// A valve whose stem must cross a friction band of `band` % on reversals, pushed by a
/// positioner of gain 8 /s up to 60 %/s, 0.05 s of dead time (the form diagnose fits).
fn band_valve(band: f64) -> ModelSpec {
    ModelSpec {
        pincart2: Some(PinCart2Params {
            p_gain_per_s: 8.0,
            dy_max_pct_per_s: 60.0,
            dy_min_pct_per_s: 0.0,
            a_p: 0.0,
            b_p: 0.0,
            c_p: 0.0,
            backlash_pct: 0.0,
        }),
        effects: Effects {
            friction_band_pct: band,
            ..Effects::default()
        },
        ..ModelSpec::bare(ModelKind::Pincart2, 0.05)
    }
}

fn compensator(model: &ModelSpec) -> Compensator {
    let cfg = CompensationConfig {
        model_file: Some("m.toml".into()),
        ..CompensationConfig::default()
    };
    Compensator::new(&cfg, model, DT, (0.0, 100.0)).unwrap()
}

/// Runs `valve` on `op` (one value per sample), through `comp` when given; returns the sent
/// set-points and V_P.
fn run(valve: &ModelSpec, comp: Option<&mut Compensator>, op: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut v = Valve::new(valve, DT).unwrap();
    v.reset(op[0], op[0]);
    let mut comp = comp;
    let mut sent = Vec::with_capacity(op.len());
    let mut vp = Vec::with_capacity(op.len());
    for (k, &u) in op.iter().enumerate() {
        let s = match comp.as_deref_mut() {
            Some(c) => c.setpoint(u, k as f64 * DT),
            None => u,
        };
        let y = v.step(s);
        if let Some(c) = comp.as_deref_mut() {
            c.observe(Some(y));
        }
        sent.push(s);
        vp.push(y);
    }
    (sent, vp)
}

/// `a` for `n_a` samples, then `b` for `n_b`, then `c` for `n_c`.
fn levels(a: (f64, usize), b: (f64, usize), c: (f64, usize)) -> Vec<f64> {
    [a, b, c]
        .iter()
        .flat_map(|&(x, n)| std::iter::repeat_n(x, n))
        .collect()
}

#[test]
fn a_kick_crosses_the_band_sooner_and_the_valve_does_not_overshoot() {
    let valve = band_valve(1.5);
    // Up to 50 %, then a reversal of 0.3 %: without a kick the positioner needs
    // 1.5 / (8 * 0.3) = 0.625 s to cross the band.
    let op = levels((49.0, 200), (50.0, 300), (49.7, 300));
    let halfway = |vp: &[f64]| vp[500..].iter().position(|&v| v < 49.85).unwrap();
    let (_, plain) = run(&valve, None, &op);
    let mut comp = compensator(&valve);
    let (sent, kicked) = run(&valve, Some(&mut comp), &op);
    let (slow, fast) = (halfway(&plain), halfway(&kicked));
    assert!(slow >= 65 && fast + 40 <= slow, "{slow} -> {fast} samples");
    // A 20 % share of the band is left to the positioner, so it lands short of the side.
    assert!(kicked[500..].iter().all(|&v| v >= 49.7 - 1e-9), "overshoot");
    let most = sent[500..].iter().map(|s| 49.7 - s).fold(0.0, f64::max);
    assert!(most > 1.0 && most <= 10.0, "kick {most}");
    // It ends: the set-point is the controller's once the band is crossed.
    assert_eq!(sent[799], 49.7);
}

#[test]
fn the_inverse_calibration_and_deadband_bring_the_valve_to_the_target() {
    let mut valve = bundled(ModelKind::Fopdt);
    valve.effects.calibration_gain = 0.9;
    valve.effects.calibration_offset_pct = 3.0;
    valve.effects.deadband_pct = 0.6;
    let op = levels((40.0, 300), (45.0, 600), (44.5, 600));
    let (_, plain) = run(&valve, None, &op);
    let mut comp = compensator(&valve);
    let (_, comped) = run(&valve, Some(&mut comp), &op);
    // Without: 0.9 * 45 + 3 - 0.3 = 43.2 %, and the 0.5 % step back stays inside the band.
    assert!((plain[899] - 43.2).abs() < 0.02, "{}", plain[899]);
    assert!((plain[1499] - 43.2).abs() < 0.02, "{}", plain[1499]);
    assert!((comped[899] - 45.0).abs() < 0.02, "{}", comped[899]);
    assert!((comped[1499] - 44.5).abs() < 0.02, "{}", comped[1499]);
    assert!(
        comp.describe().contains("deadband (0.60 %)"),
        "{}",
        comp.describe()
    );
}

#[test]
fn a_deadband_trace_smaller_than_twice_the_smallest_move_is_left_alone() {
    // A band model with a deadband trace of 0.04 % (a fit's, on a valve without one): a step
    // of 0.02 % would hold the valve that far off every target. It is not sent, and the
    // description says so; a deadband of twice the smallest move is stepped for.
    let op = levels((50.0, 300), (49.5, 600), (50.2, 600));
    let mut traced = band_valve(1.5);
    traced.effects.positioner_deadband_pct = 0.04;
    let mut comp = compensator(&traced);
    let (sent, _) = run(&band_valve(1.5), Some(&mut comp), &op);
    assert_eq!((sent[899], sent[1499]), (49.5, 50.2));
    assert!(
        comp.describe()
            .contains("its deadband of 0.040 % is left alone"),
        "{}",
        comp.describe()
    );
    let mut stepped = band_valve(1.5);
    stepped.effects.positioner_deadband_pct = 0.2;
    let mut comp = compensator(&stepped);
    let (sent, _) = run(&band_valve(1.5), Some(&mut comp), &op);
    assert!((sent[899] - 49.4).abs() < 1e-9 && (sent[1499] - 50.3).abs() < 1e-9);
    assert!(
        comp.describe().contains("deadband (0.20 %)"),
        "{}",
        comp.describe()
    );
}

#[test]
fn a_tolerance_band_fitted_with_a_breakaway_is_not_stepped_across() {
    // Stick-slip inside the loop with a band of 0.2 %, where its hunting ends: no deadband
    // step (it would start the next slip); the same band without the breakaway is stepped for.
    let op = levels((50.0, 300), (49.5, 600), (50.2, 600));
    let mut hunting = band_valve(1.5);
    hunting.effects.positioner_deadband_pct = 0.2;
    hunting.effects.breakaway_pct = 0.2;
    let mut comp = compensator(&hunting);
    let (sent, _) = run(&band_valve(1.5), Some(&mut comp), &op);
    assert_eq!((sent[899], sent[1499]), (49.5, 50.2));
    assert!(!comp.describe().contains("deadband"), "{}", comp.describe());
}

#[test]
fn the_deadband_step_is_on_the_side_of_the_move_closing_as_well_as_opening() {
    // A band on the input (the form diagnose writes for a positioner deadband seen through a
    // log) and one in the positioner, each compensated with its own model; and a valve with a
    // friction band and a positioner deadband of 0.5 % compensated with a model of that band on
    // the input, whose kicks pull the model's input target past the wish. Steps both ways, each
    // held 3 s.
    let levels = [50.0, 49.0, 51.0, 49.5, 48.0, 49.0];
    let op: Vec<f64> = levels
        .iter()
        .flat_map(|&x| std::iter::repeat_n(x, 300))
        .collect();
    let with = |friction: f64, positioner: bool| {
        let mut valve = band_valve(friction);
        if positioner {
            valve.effects.positioner_deadband_pct = 0.5;
        } else {
            valve.effects.deadband_pct = 0.744;
        }
        valve
    };
    let cases = [
        (with(0.0, false), with(0.0, false)),
        (with(0.0, true), with(0.0, true)),
        (with(1.0, true), {
            let mut m = band_valve(1.0);
            m.effects.deadband_pct = 0.5;
            m
        }),
    ];
    for (valve, model) in cases {
        let (friction, positioner) = (
            valve.effects.friction_band_pct,
            valve.effects.positioner_deadband_pct > 0.0,
        );
        let (_, plain) = run(&valve, None, &op);
        let mut comp = compensator(&model);
        let (sent, comped) = run(&valve, Some(&mut comp), &op);
        for (i, w) in levels.windows(2).enumerate() {
            let (from, to) = (w[0], w[1]);
            let dir = (to - from).signum();
            let hold = 300 * (i + 1)..300 * (i + 2);
            // Every set-point the step adds is beyond the target on the side of the move.
            assert!(
                sent[hold.clone()].iter().all(|&s| dir * (s - to) >= -1e-9),
                "{friction} {positioner} {from} -> {to}: {:?}",
                &sent[hold.start..hold.start + 40]
            );
            // Without, the valve stops short; with, at the target.
            let end = hold.end - 1;
            assert!(
                dir * (to - plain[end]) > 0.2,
                "{friction} {positioner} {from} -> {to}: {}",
                plain[end]
            );
            assert!(
                (comped[end] - to).abs() < 0.03,
                "{friction} {positioner} {from} -> {to}: {} against {} without",
                comped[end],
                plain[end]
            );
        }
    }
}

#[test]
fn a_noisy_controller_output_is_not_kicked() {
    // 0.45 % of white noise on every sample (the level loop's controller): its changes are
    // not reversals worth kicking.
    let valve = band_valve(1.5);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let op: Vec<f64> = (0..30_000)
        .map(|_| {
            let n: f64 = rand_distr::StandardNormal.sample(&mut rng);
            50.0 + 0.45 * n
        })
        .collect();
    let mut comp = compensator(&valve);
    let (sent, _) = run(&valve, Some(&mut comp), &op);
    let kicked = sent.iter().zip(&op).filter(|(s, o)| s != o).count();
    assert!(kicked * 200 < op.len(), "{kicked} of {} samples", op.len());
}

#[test]
fn pin_cart_two_crossing_times_become_a_band_growing_with_opening() {
    let pc2 = bundled(ModelKind::Pincart2);
    let id = compensator(&pc2).identified();
    let p = pc2.pincart2.unwrap();
    // The crossing a 1 % reversal needs at gain P_k, near what eq. (7) takes, over 0-100 %.
    for v in [10.0, 50.0, 90.0] {
        let t = id.band_pct * (1.0 + id.open_slowdown * v / 100.0) / p.p_gain_per_s;
        let want = p.crossing_time_s(v);
        assert!(
            (t / want - 1.0).abs() < 0.1,
            "{v} %: {t} s against {want} s"
        );
    }
    // An FOPDT has nothing to kick.
    let fopdt = compensator(&bundled(ModelKind::Fopdt));
    assert_eq!(fopdt.identified().band_pct, 0.0);
    assert!(
        fopdt.describe().starts_with("nothing"),
        "{}",
        fopdt.describe()
    );
}

#[test]
fn the_physical_simulator_is_refused() {
    let e = Compensator::new(
        &CompensationConfig::default(),
        &bundled(ModelKind::Physical),
        DT,
        (0.0, 100.0),
    )
    .unwrap_err();
    assert!(e.to_string().contains("diagnose --out"), "{e}");
}

#[test]
fn the_guard_switches_compensation_off_when_the_valve_does_worse_than_its_model() {
    let valve = band_valve(1.5);
    let cfg = CompensationConfig {
        model_file: Some("m.toml".into()),
        guard_window_s: 5.0,
        ..CompensationConfig::default()
    };
    let mut comp = Compensator::new(&cfg, &valve, DT, (0.0, 100.0)).unwrap();
    // A valve stuck at 40 % while the controller reverses between 50 and 49.7 % every 2.5 s:
    // every hold (each one kicked) ends far from where the model rests.
    let op: Vec<f64> = (0..3000)
        .map(|k| if (k / 250) % 2 == 0 { 50.0 } else { 49.7 })
        .collect();
    let mut verdicts = Vec::new();
    let mut sent = Vec::new();
    for (k, &u) in op.iter().enumerate() {
        sent.push(comp.setpoint(u, k as f64 * DT));
        verdicts.extend(comp.observe(Some(40.0)));
    }
    // One window is no evidence; the second is, its misses and the first's beyond chance
    // (on the closing moves the stuck valve is also past its target).
    assert!(!verdicts[0].worse, "{:?}", verdicts[0]);
    let w = verdicts[1];
    let misses = w.evidence_of(guard::Figure::Miss);
    assert!(w.worse && misses.exceeding == misses.holds, "{w:?}");
    assert!(!comp.active());
    // Switched off: the controller's O_P passes unchanged.
    assert!(sent[1000..].iter().zip(&op[1000..]).all(|(s, o)| s == o));
}

#[test]
fn settings_out_of_range_name_their_key() {
    let bad = CompensationConfig {
        kick_share: 1.5,
        ..CompensationConfig::default()
    };
    assert_eq!(bad.violation().unwrap().0, "kick_share");
    assert_eq!(
        CompensationConfig::default().violation().unwrap().0,
        "model_file"
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Whatever the controller does, the set-point stays within the range and what
    /// compensation adds changes by at most the rate limit a sample (unless the range cuts it
    /// short: the range comes first).
    #[test]
    fn set_points_keep_to_the_range_and_the_rate(
        moves in prop::collection::vec((-8.0f64..8.0, 1usize..80), 1..40),
        band in 0.2f64..4.0,
        gain in 0.8f64..1.2,
        offset in -3.0f64..3.0,
    ) {
        let mut valve = band_valve(band);
        valve.effects.calibration_gain = gain;
        valve.effects.calibration_offset_pct = offset;
        valve.effects.deadband_pct = 0.4;
        let (lo, hi) = (5.0, 95.0);
        let cfg = CompensationConfig {
            model_file: Some("m.toml".into()),
            max_rate_pct_per_s: 300.0,
            ..CompensationConfig::default()
        };
        let mut comp = Compensator::new(&cfg, &valve, DT, (lo, hi)).unwrap();
        let mut op = 50.0;
        let mut k = 0;
        let mut last_excursion = 0.0;
        for (step, hold) in moves {
            op = (op + step).clamp(lo, hi);
            for _ in 0..hold {
                let s = comp.setpoint(op, k as f64 * DT);
                comp.observe(None);
                prop_assert!((lo..=hi).contains(&s), "{s}");
                let excursion = s - op;
                prop_assert!(
                    (excursion - last_excursion).abs() <= 3.0 + 1e-9 || s == lo || s == hi,
                    "{last_excursion} -> {excursion}"
                );
                last_excursion = excursion;
                k += 1;
            }
        }
    }
}
