//! Tests of the effects inside pin-cart II's core: the friction band, the wind-up at a stop,
//! the positioner deadband and stick-slip by breakaway.

use super::super::*;

const DT: f64 = 0.01;

fn run(valve: &mut Valve, op: f64, n: usize) -> Vec<f64> {
    (0..n).map(|_| valve.step(op)).collect()
}

#[test]
fn a_positioner_deadband_stops_the_valve_at_its_edge_without_a_slow_approach() {
    // A 2 % band in the positioner, gain 4 /s: after a step the valve answers in full until it
    // is within 1 % of O_P, then stops at once; the same band on the input stops it 1 % short
    // too, but closes in on that target ever more slowly.
    let mut spec = bundled(ModelKind::Pincart2);
    if let Some(p) = spec.pincart2.as_mut() {
        (p.p_gain_per_s, p.dy_max_pct_per_s, p.dy_min_pct_per_s) = (4.0, 1000.0, 0.0);
        (p.a_p, p.b_p, p.c_p, p.backlash_pct) = (0.0, 0.0, 0.0, 0.0);
    }
    spec.dead_time_s = 0.0;
    let settle = |positioner: bool| {
        let mut s = spec.clone();
        if positioner {
            s.effects.positioner_deadband_pct = 2.0;
        } else {
            s.effects.deadband_pct = 2.0;
        }
        let mut v = Valve::new(&s, DT).unwrap();
        v.reset(40.0, 40.0);
        run(&mut v, 50.0, 500)
    };
    let (inside, input) = (settle(true), settle(false));
    // Both end 1 % short of 50 % (the positioner's band within the last sample's move).
    assert!((49.0..49.05).contains(&inside[499]), "{}", inside[499]);
    assert!((input[499] - 49.0).abs() < 0.01, "{}", input[499]);
    // The positioner's band stops the valve at once: it is there within 0.6 s (9 % at 4 e %/s
    // takes ln 9 / 4 = 0.55 s), and the last 0.1 % before it still moves at about 4 %/s.
    let arrived = inside.iter().position(|y| *y >= 49.0 - 1e-9).unwrap();
    assert!(
        (50..=60).contains(&arrived),
        "arrived after {arrived} samples"
    );
    let speed = (inside[arrived - 1] - inside[arrived - 3]) / (2.0 * DT);
    assert!(speed > 3.5, "{speed} %/s just before the edge");
    // On the input, the last 0.1 % before the target takes over half a second.
    let near = input.iter().position(|y| *y >= 48.9).unwrap();
    let there = input.iter().position(|y| *y >= 49.0 - 1e-3).unwrap();
    assert!(
        there - near > 50,
        "{} samples for the last 0.1 %",
        there - near
    );
    // Inside the band nothing moves: a command 0.8 % away leaves the valve where it is.
    let mut s = spec.clone();
    s.effects.positioner_deadband_pct = 2.0;
    let mut v = Valve::new(&s, DT).unwrap();
    v.reset(40.0, 40.0);
    assert!(run(&mut v, 40.8, 300)
        .iter()
        .all(|y| (*y - 40.0).abs() < 1e-12));
}

#[test]
fn a_friction_band_is_crossed_at_the_positioners_speed() {
    // A 2 % band, positioner gain 4 /s, no speed limit to speak of: a reversal by E % costs
    // the time the pin needs to cross the band at 4 E %/s, so small reversals lose more time
    // than large ones (eq. 7's crossing time would be the same for both).
    let mut spec = bundled(ModelKind::Pincart2);
    if let Some(p) = spec.pincart2.as_mut() {
        (p.p_gain_per_s, p.dy_max_pct_per_s, p.dy_min_pct_per_s) = (4.0, 1000.0, 0.0);
        (p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.0);
    }
    spec.dead_time_s = 0.0;
    spec.effects.friction_band_pct = 2.0;
    let first_move = |size: f64| {
        let mut v = Valve::new(&spec, DT).unwrap();
        v.reset(40.0, 40.0);
        let settled = *run(&mut v, 50.0, 2000).last().unwrap();
        let out = run(&mut v, 50.0 - size, 2000);
        out.iter().position(|y| *y < settled - 1e-6).unwrap_or(2000) as f64 * DT
    };
    let (small, large) = (first_move(2.0), first_move(20.0));
    // Crossing 2 % at about 4 * 2 = 8 %/s takes ~0.25 s; at 80 %/s ~0.025 s.
    assert!(
        (0.2..0.35).contains(&small),
        "{small} s after a 2 % reversal"
    );
    assert!(large < 0.06, "{large} s after a 20 % reversal");
    // Same-direction steps start at once.
    let mut v = Valve::new(&spec, DT).unwrap();
    v.reset(40.0, 40.0);
    let settled = *run(&mut v, 50.0, 2000).last().unwrap();
    assert!(v.step(52.0) > settled);
}

#[test]
fn a_wound_up_drive_holds_the_valve_on_its_stop_after_o_p_comes_back() {
    // Stop at 80 %, O_P asks for 95 % for 10 s, then 70 %. Without wind-up the valve leaves the
    // stop at once; with 15 % of wind-up the drive must first come back from 95 %.
    let mut spec = bundled(ModelKind::Pincart2);
    if let Some(p) = spec.pincart2.as_mut() {
        (p.p_gain_per_s, p.dy_max_pct_per_s) = (5.0, 50.0);
        (p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.0);
    }
    spec.dead_time_s = 0.0;
    spec.travel.max_pct = 80.0;
    let leave = |windup: f64| {
        let mut s = spec.clone();
        s.effects.stop_windup_pct = windup;
        let mut v = Valve::new(&s, DT).unwrap();
        v.reset(70.0, 70.0);
        let held = run(&mut v, 95.0, 1000);
        assert!((held[999] - 80.0).abs() < 1e-9);
        let out = run(&mut v, 70.0, 1000);
        out.iter().position(|y| *y < 80.0 - 1e-6).unwrap_or(1000) as f64 * DT
    };
    let (free, wound) = (leave(0.0), leave(15.0));
    assert!(free <= 0.02, "{free} s without wind-up");
    // 15 % back at up to 50 %/s (the error is 10-25 %, so 5 * e caps at 50): about 0.3-0.4 s.
    assert!(
        (0.25..0.5).contains(&wound),
        "{wound} s with 15 % of wind-up"
    );
}

#[test]
fn breakaway_makes_the_valve_hunt_around_a_steady_op() {
    let spec = ModelSpec {
        effects: Effects {
            breakaway_pct: 0.5,
            ..Effects::default()
        },
        ..bundled(ModelKind::Pincart2)
    };
    let mut v = Valve::new(&spec, DT).unwrap();
    v.reset(50.0, 50.0);
    let out = run(&mut v, 52.0, 6000);
    let tail = &out[2000..];
    // Stick, slip past the target, stick again: the position keeps crossing 52 % in jumps.
    let crossings = tail
        .windows(2)
        .filter(|w| (w[0] - 52.0) * (w[1] - 52.0) < 0.0)
        .count();
    let jumps = tail
        .windows(2)
        .filter(|w| (w[1] - w[0]).abs() >= 0.4)
        .count();
    assert!(
        crossings >= 4 && jumps >= 4,
        "{crossings} crossings, {jumps} jumps"
    );
    // Without breakaway it settles.
    let mut calm = Valve::new(&bundled(ModelKind::Pincart2), DT).unwrap();
    calm.reset(50.0, 50.0);
    assert!((run(&mut calm, 52.0, 6000)[5999] - 52.0).abs() < 1e-9);
}

#[test]
fn breakaway_without_a_cart_follows_a_reversed_command() {
    // Pin-cart II without a cart (the FOPDT diagnosis starts from) and with stick-slip: a
    // command that reverses while the pressure is loaded against the stuck stem must unload it
    // and move the valve the other way, not leave it stuck.
    let mut spec = ModelSpec {
        effects: Effects {
            breakaway_pct: 0.5,
            ..Effects::default()
        },
        ..bundled(ModelKind::Pincart2)
    };
    if let Some(p) = spec.pincart2.as_mut() {
        (p.backlash_pct, p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.0, 0.0);
    }
    spec.dead_time_s = 0.0;
    let mut v = Valve::new(&spec, DT).unwrap();
    v.reset(50.0, 50.0);
    // A small push up: the stem crawls, sticks, and the pressure loads against it.
    let up = run(&mut v, 50.05, 100);
    assert!(up[99] < 50.05, "{:?}", &up[90..]);
    let down = run(&mut v, 45.0, 3000);
    let last = down[2999];
    assert!((last - 45.0).abs() < 1.0, "stuck at {last}");
}

#[test]
fn crossing_polynomial_passes_through_its_three_points() {
    let (a, b, c) = crossing_poly(0.3, 0.5, 0.8);
    let p = |v: f64| (a * v + b) * v + c;
    assert!((p(0.0) - 0.3).abs() < 1e-12);
    assert!((p(50.0) - 0.5).abs() < 1e-12);
    assert!((p(100.0) - 0.8).abs() < 1e-12);
    // The bundled file's polynomial: 2e-5, 3e-3, 0.3.
    assert!((a - 2e-5).abs() < 1e-12 && (b - 3e-3).abs() < 1e-12);
    // A dip below zero is lifted.
    let (a, b, c) = crossing_poly(1.0, 0.0, 1.0);
    let min = (0..=100)
        .map(|v| (a * v as f64 + b) * v as f64 + c)
        .fold(f64::INFINITY, f64::min);
    assert!(min >= -1e-12);
}
