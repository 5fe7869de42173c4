//! The guard on made-up valves: what exceeds, what is chance, and what the evidence needs.

use super::*;

/// A sample of a controller at `op` whose valve reads `vp` where the model says `model`.
fn sample(op: f64, model: f64, vp: Option<f64>) -> Sample {
    Sample {
        op,
        target: op,
        gate: 0.1,
        compensated: true,
        model_with: model,
        model_without: model,
        measured: vp,
    }
}

/// `n` samples at O_P `op`, the model at `model` and the valve at `vp`; the last verdict.
fn hold(g: &mut Guard, n: usize, op: f64, model: f64, vp: Option<f64>) -> Option<Window> {
    (0..n).filter_map(|_| g.add(sample(op, model, vp))).last()
}

/// `n` samples at O_P `op` in which the model and the valve close a tenth of the way to
/// `model_to` and `valve_to` each sample, from `at` (both positions, updated); the last verdict.
fn approach(
    g: &mut Guard,
    (n, op): (usize, f64),
    (model_to, valve_to): (f64, f64),
    at: &mut (f64, f64),
) -> Option<Window> {
    (0..n)
        .filter_map(|_| {
            at.0 += 0.1 * (model_to - at.0);
            at.1 += 0.1 * (valve_to - at.1);
            g.add(sample(op, at.0, Some(at.1)))
        })
        .last()
}

/// A small linear congruential generator: uniform noise of standard deviation `sd`.
fn noise(sd: f64) -> impl FnMut() -> f64 {
    let mut x: u64 = 1;
    move || {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        sd * 3f64.sqrt() * (2.0 * (x >> 11) as f64 / (1u64 << 53) as f64 - 1.0)
    }
}

#[test]
fn the_resolution_is_the_step_every_step_is_a_multiple_of() {
    let r = |steps: &[f64]| steps.iter().fold(f64::INFINITY, |a, &b| common_step(a, b));
    // Per-mille readings: differences of a stroke and of noise, with the rounding of decimals.
    let per_mille = [50.6 - 50.0, 0.3, 49.9 - 49.8, 0.2];
    assert!((r(&per_mille) - 0.1).abs() < 1e-9, "{}", r(&per_mille));
    assert!((r(&[0.6, 0.4]) - 0.2).abs() < 1e-9);
    // A continuous sensor's steps share no step worth the name.
    assert!(r(&[0.0137, 0.0251, 0.1003]) < MIN_RESOLUTION_PCT);
}

#[test]
fn chance_is_the_binomial_tail() {
    let p: f64 = CHANCE_PER_HOLD;
    let two_of_four = 1.0 - (1.0 - p).powi(4) - 4.0 * p * (1.0 - p).powi(3);
    assert!((chance_of(2, 4) - two_of_four).abs() < 1e-12);
    assert_eq!(chance_of(0, 10), 1.0);
    assert!((chance_of(1, 1) - p).abs() < 1e-12);
    assert!(chance_of(3, 3) < 1e-5);
}

#[test]
fn a_valve_resting_away_from_where_its_model_rests_misses_in_every_hold() {
    // Windows of 2 s at 100 Hz, a move every second between 48 and 50 %: the model rests at
    // each target, the valve 0.5 % short of it.
    let mut g = Guard::new(2.0, 0.01, 0.1);
    let mut verdicts = Vec::new();
    let mut at = (50.0, 49.5);
    for k in 0..6 {
        let (op, short) = if k % 2 == 0 {
            (50.0, 49.5)
        } else {
            (48.0, 48.5)
        };
        verdicts.extend(approach(&mut g, (100, op), (op, short), &mut at));
    }
    // One window is no evidence; the second, with its misses, is: it ends at its first hold
    // that puts the evidence beyond chance.
    assert!(verdicts.len() >= 2, "{verdicts:?}");
    assert!(!verdicts[0].worse, "{:?}", verdicts[0]);
    let w = verdicts[1];
    assert!(w.rows < 200, "{w:?}");
    assert_eq!(w.exceeded, Some(Figure::Miss), "{w:?}");
    let e = w.evidence_of(Figure::Miss);
    assert_eq!((e.exceeding, e.windows), (e.holds, 2), "{e:?}");
    // The model is read with the noise measured on the valve (here, its moves): by a hair.
    assert!((e.by_pct - 0.5).abs() < 0.01, "{e:?}");
    // Where both rest at the target, nothing exceeds.
    let mut g = Guard::new(2.0, 0.01, 0.1);
    let mut at = (50.0, 50.0);
    for k in 0..6 {
        let op = if k % 2 == 0 { 50.0 } else { 48.0 };
        if let Some(w) = approach(&mut g, (100, op), (op, op), &mut at) {
            assert!(
                !w.worse && w.evidence.iter().all(|e| e.exceeding == 0),
                "{w:?}"
            );
        }
    }
}

#[test]
fn a_valve_carried_past_its_targets_overshoots_and_one_hold_is_chance() {
    // Moves of 1 % every 2 s (windows of 4 s): the model lands on each target, the valve
    // goes 0.6 % past and comes back.
    let run = |overshooting: &dyn Fn(usize) -> bool| {
        let mut g = Guard::new(4.0, 0.01, 0.1);
        let mut verdicts = Vec::new();
        for k in 0..6 {
            let op = 49.0 + (k % 2) as f64;
            let past = if overshooting(k) { 0.6 } else { 0.0 };
            let dir = if k % 2 == 1 { 1.0 } else { -1.0 };
            verdicts.extend(hold(&mut g, 30, op, op, Some(op + dir * past)));
            verdicts.extend(hold(&mut g, 170, op, op, Some(op)));
        }
        // The first verdict that finds it worse, else the last.
        let worse = verdicts.iter().find(|w| w.worse);
        *worse.or(verdicts.last()).unwrap()
    };
    let w = run(&|_| true);
    assert_eq!(w.exceeded, Some(Figure::Overshoot), "{w:?}");
    assert!(
        (w.evidence_of(Figure::Overshoot).by_pct - 0.6).abs() < 0.01,
        "{w:?}"
    );
    // One overshooting hold in six is what chance may do.
    let w = run(&|k| k == 2);
    assert_eq!(w.evidence_of(Figure::Overshoot).exceeding, 1, "{w:?}");
    assert!(!w.worse, "{w:?}");
}

#[test]
fn holds_compensation_left_alone_and_rows_without_v_p_are_not_judged() {
    let mut g = Guard::new(1.0, 0.01, 0.1);
    let off = |op: f64, vp: f64| Sample {
        compensated: false,
        ..sample(op, op, Some(vp))
    };
    for k in 0..400 {
        // A valve far from its model, but compensation added nothing.
        let op = if (k / 50) % 2 == 0 { 40.0 } else { 45.0 };
        if let Some(w) = g.add(off(op, 30.0)) {
            assert_eq!((w.holds, w.worse), (0, false), "{w:?}");
        }
    }
    // No V_P in a whole window: nothing to judge.
    let mut g = Guard::new(0.02, 0.01, 0.1);
    g.add(sample(50.0, 50.0, None));
    assert_eq!(g.add(sample(50.0, 50.0, None)), None);
}

#[test]
fn the_model_is_read_with_the_noise_and_the_steps_of_the_valve_s_register() {
    // A valve that is its model, read with 0.05 % of noise in steps of 0.1 %, on moves of
    // 0.3-0.9 % every 3 s: the noise and the steps give the valve overshoot and misses the
    // exact model has not; read as the valve is, the model has them too, and no window finds
    // compensation worse.
    let mut g = Guard::new(20.0, 0.01, 0.1);
    let mut n = noise(0.05);
    let mut windows = 0;
    for k in 0..40 {
        let op = 50.0 + [0.0, 0.3, -0.4, 0.5, 0.9, 0.2][k % 6];
        for _ in 0..300 {
            let vp = ((op + n()) * 10.0).round() / 10.0;
            if let Some(w) = g.add(sample(op, op, Some(vp))) {
                windows += 1;
                assert!(!w.worse, "{w:?}");
                assert!((w.resolution_pct - 0.1).abs() < 1e-9, "{w:?}");
                assert!(w.noise_pct > 0.04 && w.noise_pct < 0.08, "{w:?}");
            }
        }
    }
    assert_eq!(windows, 6);
}

#[test]
fn the_deadband_rises_above_the_sensor_s_noise() {
    // 0.2 % of noise on a resting valve: counted through the minimum deadband it would be
    // reversals; the guard measures the noise and counts through five times it.
    let mut g = Guard::new(10.0, 0.01, 0.1);
    let mut n = noise(0.2);
    let mut last = None;
    for k in 0..3000 {
        let op = if k < 10 { 49.0 } else { 50.0 };
        last = g.add(sample(op, op, Some(op + n()))).or(last);
    }
    let w = last.unwrap();
    assert!(w.deadband_pct > 0.5 && w.deadband_pct < 1.5, "{w:?}");
    assert!(!w.worse, "{w:?}");
}
