//! Physics tests of the models: behaviour from the paper, invariants (proptest) and golden runs.

use super::*;
use proptest::prelude::*;

const DT: f64 = 0.01;

fn pincart1(backlash: f64, gain: f64, td: f64) -> ModelSpec {
    ModelSpec {
        pincart1: Some(PinCart1Params {
            backlash_pct: backlash,
            p_gain_per_s: gain,
        }),
        ..ModelSpec::bare(ModelKind::Pincart1, td)
    }
}

fn stiction(s: f64, j: f64, td: f64) -> ModelSpec {
    ModelSpec {
        stiction: Some(StictionParams {
            stickband_pct: s,
            jumpband_pct: j,
        }),
        ..ModelSpec::bare(ModelKind::Stiction, td)
    }
}

fn fopdt(tau: f64, td: f64) -> ModelSpec {
    ModelSpec {
        fopdt: Some(FopdtParams {
            time_constant_s: tau,
        }),
        ..ModelSpec::bare(ModelKind::Fopdt, td)
    }
}

fn run(valve: &mut Valve, op: f64, n: usize) -> Vec<f64> {
    (0..n).map(|_| valve.step(op)).collect()
}

#[test]
fn bundled_model_files_load_and_match_their_kind() {
    for kind in ModelKind::EVERY {
        let spec = bundled(kind);
        assert_eq!(spec.model, kind);
        let on_disk = ModelSpec::load(
            &Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
                .join(format!("config/models/{}.toml", kind.tag())),
        )
        .unwrap();
        assert_eq!(on_disk, spec);
        Valve::new(&spec, DT).unwrap();
    }
}

#[test]
fn toml_round_trip_keeps_every_parameter() {
    for kind in ModelKind::EVERY {
        let spec = bundled(kind);
        let back = ModelSpec::from_toml(&spec.to_toml(), Path::new("x.toml")).unwrap();
        assert_eq!(back, spec);
    }
}

#[test]
fn bad_model_files_name_the_key_and_line() {
    let cases = [
        ("model = \"pincart3\"\n", "x.toml:1: model:"),
        ("model = \"fopdt\"\ndead_time_s = 0.1\n", "x.toml:1: model:"),
        (
            "model = \"fopdt\"\n[fopdt]\ntime_constant_s = -1.0\n",
            "x.toml:3: fopdt.time_constant_s:",
        ),
        (
            "model = \"fopdt\"\n[fopdt]\ntime_constant_s = 1.0\ngain = 2\n",
            "x.toml:4: fopdt.gain:",
        ),
        (
            "model = \"delayed\"\ndead_time_s = \"long\"\n",
            "x.toml:2: dead_time_s:",
        ),
        (
            "model = \"delayed\"\n[fopdt]\ntime_constant_s = 1.0\n",
            "x.toml:2: fopdt:",
        ),
    ];
    for (text, want) in cases {
        let err = ModelSpec::from_toml(text, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with(want), "{text:?} gave {err:?}");
        assert!(!err.contains('\n'), "{err:?}");
    }
}

#[test]
fn pincart2_polynomial_must_stay_positive() {
    let mut spec = bundled(ModelKind::Pincart2);
    if let Some(p) = spec.pincart2.as_mut() {
        p.c_p = -0.1;
    }
    let err = spec.validate().unwrap_err().to_string();
    assert!(err.contains("pincart2.c_p"), "{err}");
}

#[test]
fn modelless_is_identity_and_delayed_is_a_shift() {
    let op: Vec<f64> = (0..50)
        .map(|k| (k as f64 * 0.3).sin() * 10.0 + 50.0)
        .collect();
    let mut m = Valve::new(&bundled(ModelKind::Modelless), DT).unwrap();
    assert_eq!(m.simulate(&op, op[0]), op);
    let mut d = Valve::new(&ModelSpec::bare(ModelKind::Delayed, 0.05), DT).unwrap();
    let out = d.simulate(&op, op[0]);
    assert_eq!(&out[5..], &op[..45]);
    assert!(out[..5].iter().all(|&v| v == op[0]));
}

#[test]
fn fopdt_step_response_is_exponential() {
    let mut v = Valve::new(&fopdt(0.5, 0.2), DT).unwrap();
    v.reset(0.0, 0.0);
    let out = run(&mut v, 10.0, 200);
    // Nothing before the dead time, then 10 * (1 - exp(-t/tau)) sampled exactly.
    assert!(out[..20].iter().all(|&x| x == 0.0));
    for (k, &y) in out.iter().enumerate().skip(20) {
        let t = (k - 19) as f64 * DT;
        assert!(
            (y - 10.0 * (1.0 - (-t / 0.5f64).exp())).abs() < 1e-9,
            "k={k}"
        );
    }
}

#[test]
fn pincart1_reversal_waits_while_the_pin_crosses_the_cart() {
    // B_L = 1 %, P_k = 2.5 /s: with an error of 3 % the pin moves 0.075 % a sample, so after a
    // reversal it needs 14 samples (1 / 0.075 = 13.3) to reach the other side of the cart.
    let mut v = Valve::new(&pincart1(1.0, 2.5, 0.0), DT).unwrap();
    v.reset(50.0, 50.0);
    run(&mut v, 60.0, 3000);
    let settled = v.step(60.0);
    assert!((settled - 60.0).abs() < 1e-9);
    let out = run(&mut v, 57.0, 20);
    assert!(out[..13].iter().all(|&x| x == settled), "{out:?}");
    assert!(out[13] < settled - 0.04, "{out:?}");
}

#[test]
fn pincart1_same_direction_moves_at_once() {
    let mut v = Valve::new(&pincart1(1.0, 2.5, 0.0), DT).unwrap();
    v.reset(50.0, 50.0);
    run(&mut v, 60.0, 3000);
    let before = v.step(60.0);
    assert!(v.step(63.0) > before);
}

/// Time (s) until V_P has moved a tenth of the way to a new O_P of `to`, starting at rest at
/// `from` where the valve arrived moving in direction `came` (+1 opening, -1 closing).
fn step_delay(spec: &ModelSpec, from: f64, came: f64, to: f64) -> f64 {
    let mut v = Valve::new(spec, DT).unwrap();
    v.reset(from - 10.0 * came, from - 10.0 * came);
    run(&mut v, from, 3000);
    let start = v.step(from);
    let target = start + 0.1 * (to - start);
    for k in 1..1000 {
        let y = v.step(to);
        if (y - start).abs() >= (target - start).abs() {
            return k as f64 * DT;
        }
    }
    f64::INFINITY
}

#[test]
fn pincart2_defaults_reproduce_the_paper_delays() {
    let spec = bundled(ModelKind::Pincart2);
    let same = step_delay(&spec, 50.0, 1.0, 70.0);
    assert!((0.38..=0.55).contains(&same), "same-direction delay {same}");
    let reversal = step_delay(&spec, 50.0, 1.0, 30.0);
    assert!(
        (0.85..=1.15).contains(&reversal),
        "reversal delay {reversal}"
    );
    let near_closed = step_delay(&spec, 20.0, 1.0, 5.0);
    let near_open = step_delay(&spec, 90.0, 1.0, 70.0);
    assert!(
        near_closed + 0.2 < near_open,
        "{near_closed} vs {near_open}"
    );
    // Closing steps after a close keep the short delay too.
    let same_down = step_delay(&spec, 60.0, -1.0, 40.0);
    assert!((same - same_down).abs() < 0.05, "{same} vs {same_down}");
}

#[test]
fn pincart2_slew_rate_caps_large_steps() {
    let spec = bundled(ModelKind::Pincart2);
    let dymax = spec.pincart2.map(|p| p.dy_max_pct_per_s).unwrap_or(0.0);
    let mut v = Valve::new(&spec, DT).unwrap();
    v.reset(10.0, 10.0);
    let out = run(&mut v, 90.0, 500);
    let fastest = out.windows(2).map(|w| w[1] - w[0]).fold(0.0, f64::max);
    assert!((fastest - dymax * DT).abs() < 1e-9, "{fastest}");
}

#[test]
fn pincart2_min_speed_closes_small_errors_without_overshoot() {
    let spec = bundled(ModelKind::Pincart2);
    let mut v = Valve::new(&spec, DT).unwrap();
    v.reset(40.0, 40.0);
    let out = run(&mut v, 40.05, 300);
    assert_eq!(*out.last().unwrap_or(&0.0), 40.05);
    assert!(out.iter().all(|&y| y <= 40.05));
}

#[test]
fn stiction_sticks_then_jumps() {
    // S = 2, J = 1: after a reversal the input must move 2 % before the valve jumps by 1 %.
    let mut v = Valve::new(&stiction(2.0, 1.0, 0.0), DT).unwrap();
    v.reset(50.0, 50.0);
    let ramp_up: Vec<f64> = (1..=100).map(|k| 50.0 + 0.1 * k as f64).collect();
    let up = v.simulate(&ramp_up, 50.0);
    let top = *up.last().unwrap_or(&0.0);
    assert!(
        (top - (60.0 - 0.5)).abs() < 1e-9,
        "moving offset (S-J)/2: {top}"
    );
    let mut y = top;
    let mut moved_at = None;
    for k in 1..=40 {
        let u = 60.0 - 0.1 * k as f64;
        let out = v.step(u);
        if out != y && moved_at.is_none() {
            moved_at = Some(k);
            assert!((y - out - 1.0).abs() < 0.11, "jump {}", y - out);
        }
        y = out;
    }
    assert_eq!(moved_at, Some(21), "first move once 60 - u > S");
}

proptest! {
    #[test]
    fn position_stays_in_travel(kind_idx in 0usize..6, ops in prop::collection::vec(-50.0f64..150.0, 1..400),
                                lo in 0.0f64..20.0, hi in 80.0f64..100.0) {
        let mut spec = bundled(ModelKind::ALL[kind_idx]);
        spec.travel = Travel { min_pct: lo, max_pct: hi };
        let mut v = Valve::new(&spec, DT).unwrap();
        v.reset(ops[0], 50.0);
        for &u in &ops {
            let y = v.step(u);
            prop_assert!(y >= lo && y <= hi, "{y} outside [{lo}, {hi}]");
        }
    }

    #[test]
    fn pin_never_leaves_the_cart(ops in prop::collection::vec(-20.0f64..120.0, 1..400),
                                 which in 0usize..2, gain in 0.5f64..40.0, backlash in 0.0f64..5.0) {
        let mut core = if which == 0 {
            PinCart::one(&PinCart1Params { backlash_pct: backlash, p_gain_per_s: gain }, DT)
        } else {
            let mut p = bundled(ModelKind::Pincart2).pincart2.unwrap();
            p.p_gain_per_s = gain;
            p.backlash_pct = backlash;
            PinCart::two(&p, &Effects::default(), DT)
        };
        core.reset(50.0);
        for &u in &ops {
            let v = core.step(u).clamp(0.0, 100.0);
            core.set_position(v);
            prop_assert!(core.pin_offset().abs() <= backlash / 2.0 + 1e-9);
        }
    }

    #[test]
    fn stiction_never_moves_inside_the_stickband(peak in 30.0f64..70.0, s in 0.2f64..5.0,
                                                 jfrac in 0.0f64..1.0,
                                                 walk in prop::collection::vec(0.0f64..1.0, 1..300)) {
        let mut core = Stiction::new(&StictionParams { stickband_pct: s, jumpband_pct: s * jfrac });
        core.reset(peak - 20.0, peak - 20.0);
        for k in 1..=200 {
            core.step(peak - 20.0 + 0.1 * k as f64);
        }
        let held = core.step(peak);
        // Any wandering of the input inside [peak - S, peak] after stopping keeps it stuck.
        for &w in &walk {
            let y = core.step(peak - s * w);
            prop_assert_eq!(y, held);
            prop_assert!(core.is_stuck());
        }
    }

    #[test]
    fn dead_time_shifts_output_exactly(kind_idx in 2usize..6, n in 0usize..60,
                                       ops in prop::collection::vec(0.0f64..100.0, 1..300)) {
        let kind = ModelKind::ALL[kind_idx];
        let mut base = bundled(kind);
        base.dead_time_s = 0.0;
        let mut delayed = base.clone();
        delayed.dead_time_s = n as f64 * DT;
        let y0 = Valve::new(&base, DT).unwrap().simulate(&ops, ops[0]);
        let yd = Valve::new(&delayed, DT).unwrap().simulate(&ops, ops[0]);
        // The delayed valve sees ops[0] for n extra samples first, so it is at rest meanwhile.
        for k in 0..ops.len().saturating_sub(n) {
            prop_assert_eq!(yd[k + n], y0[k]);
        }
    }
}

/// A fixed input that exercises every model: steps both ways, a reversal, a ramp, saturation.
fn golden_input() -> Vec<f64> {
    (0..1200)
        .map(|k| match k {
            0..=149 => 40.0,
            150..=349 => 55.0,
            350..=449 => 48.0,
            450..=549 => 58.0,
            550..=799 => 58.0 - 0.08 * (k - 550) as f64,
            800..=999 => 99.5,
            _ => 20.0 + 3.0 * ((k - 1000) as f64 * 0.05).sin(),
        })
        .collect()
}

#[test]
fn golden_runs_match_stored_outputs() {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("tests/data/golden");
    let op = golden_input();
    for kind in ModelKind::ALL {
        let out = Valve::new(&bundled(kind), DT).unwrap().simulate(&op, 40.0);
        let path = dir.join(format!("{}.txt", kind.tag()));
        if std::env::var_os("UPDATE_GOLDEN").is_some() {
            std::fs::create_dir_all(&dir).unwrap();
            let text: Vec<String> = out.iter().map(|y| format!("{y:.12}")).collect();
            std::fs::write(&path, text.join("\n") + "\n").unwrap();
            continue;
        }
        let stored: Vec<f64> = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{}: {e} (run with UPDATE_GOLDEN=1 once)", path.display()))
            .lines()
            .map(|l| l.parse().unwrap())
            .collect();
        assert_eq!(stored.len(), out.len());
        for (k, (a, b)) in stored.iter().zip(&out).enumerate() {
            assert!(
                (a - b).abs() < 1e-9,
                "{kind} sample {k}: stored {a}, now {b}"
            );
        }
    }
}

fn with_effects(kind: ModelKind, effects: Effects) -> Valve {
    let spec = ModelSpec {
        effects,
        ..bundled(kind)
    };
    Valve::new(&spec, DT).unwrap()
}

#[test]
fn calibration_sets_the_steady_state() {
    let mut v = with_effects(
        ModelKind::Fopdt,
        Effects {
            calibration_gain: 0.9,
            calibration_offset_pct: 2.0,
            ..Effects::default()
        },
    );
    v.reset(50.0, 47.0);
    let end = *run(&mut v, 60.0, 2000).last().unwrap();
    assert!((end - 56.0).abs() < 1e-6, "{end}");
}

#[test]
fn deadband_stops_short_by_half_the_band() {
    let mut v = with_effects(
        ModelKind::Fopdt,
        Effects {
            deadband_pct: 1.0,
            ..Effects::default()
        },
    );
    v.reset(50.0, 50.0);
    let up = *run(&mut v, 60.0, 2000).last().unwrap();
    assert!((up - 59.5).abs() < 1e-6, "{up}");
    // A move smaller than the band does nothing; a reversal stops short from the other side.
    let small = *run(&mut v, 59.2, 500).last().unwrap();
    assert!((small - 59.5).abs() < 1e-6, "{small}");
    let down = *run(&mut v, 40.0, 2000).last().unwrap();
    assert!((down - 40.5).abs() < 1e-6, "{down}");
}

#[test]
fn quantization_reports_a_lattice_but_moves_smoothly() {
    let mut v = with_effects(
        ModelKind::Fopdt,
        Effects {
            quantization_pct: 0.5,
            ..Effects::default()
        },
    );
    v.reset(40.0, 40.0);
    let out = run(&mut v, 43.3, 300);
    assert!(out
        .iter()
        .all(|y| ((y / 0.5).round() * 0.5 - y).abs() < 1e-12));
    assert_eq!(*out.last().unwrap(), 43.5);
}

#[test]
fn asymmetry_slows_closing_only() {
    let effects = Effects {
        closing_slew_pct_per_s: 5.0,
        ..Effects::default()
    };
    let speed = |from: f64, to: f64| {
        let mut v = with_effects(ModelKind::Pincart2, effects);
        v.reset(from, from);
        let out = run(&mut v, to, 600);
        out.windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max)
            / DT
    };
    assert!((speed(20.0, 80.0) - 20.0).abs() < 1e-6);
    assert!((speed(80.0, 20.0) - 5.0).abs() < 1e-6);
}

#[test]
fn stiction_effect_makes_a_smooth_core_stick() {
    let mut v = with_effects(
        ModelKind::Fopdt,
        Effects {
            stickband_pct: 2.0,
            jumpband_pct: 1.0,
            ..Effects::default()
        },
    );
    v.reset(50.0, 50.0);
    // A staircase of 0.2 % steps: once moving, the valve only follows after J = 1 % more, so
    // the settled position changes every fifth stair or so, never in 0.2 % moves.
    let mut settled = Vec::new();
    for stair in 1..=40 {
        let out = run(&mut v, 50.0 + 0.2 * stair as f64, 300);
        settled.push(*out.last().unwrap());
    }
    let moves: Vec<f64> = settled
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| d.abs() > 0.05)
        .collect();
    assert!(!moves.is_empty() && moves.len() <= 10, "{moves:?}");
    assert!(moves.iter().all(|&d| d > 0.9), "{moves:?}");
}

#[test]
fn effects_round_trip_and_stay_off_by_default() {
    let spec = ModelSpec {
        effects: Effects {
            deadband_pct: 0.4,
            quantization_pct: 0.1,
            ..Effects::default()
        },
        ..bundled(ModelKind::Pincart2)
    };
    let text = spec.to_toml();
    assert!(text.contains("[effects]") && text.contains("deadband_pct"));
    assert!(!text.contains("calibration_gain"));
    assert_eq!(
        ModelSpec::from_toml(&text, Path::new("x.toml")).unwrap(),
        spec
    );
    assert!(!bundled(ModelKind::Pincart2).to_toml().contains("effects"));
}

/// The bundled pin-cart II without dead time, three times slower fully open than closed.
fn slowed_when_open() -> ModelSpec {
    ModelSpec {
        effects: Effects {
            open_slowdown: 2.0,
            ..Effects::default()
        },
        dead_time_s: 0.0,
        ..bundled(ModelKind::Pincart2)
    }
}

#[test]
fn open_slowdown_makes_the_valve_slower_when_open() {
    let spec = slowed_when_open();
    let t90 = |from: f64, to: f64| {
        let mut v = Valve::new(&spec, DT).unwrap();
        v.reset(from, from);
        let out = run(&mut v, to, 1000);
        out.iter()
            .position(|y| (y - from).abs() >= 0.9 * (to - from).abs())
            .unwrap_or(1000)
    };
    let (closed, open) = (t90(10.0, 15.0), t90(85.0, 90.0));
    assert!(
        open as f64 > 2.0 * closed as f64,
        "{closed} vs {open} samples"
    );
    // The stroke speed falls alike: the fastest move of a large step is slower when open.
    let fastest = |from: f64, to: f64| {
        let mut v = Valve::new(&spec, DT).unwrap();
        v.reset(from, from);
        let out = run(&mut v, to, 1000);
        out.windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max)
            / DT
    };
    let slew = spec.pincart2.unwrap().dy_max_pct_per_s;
    let (near_closed, near_open) = (fastest(5.0, 35.0), fastest(65.0, 95.0));
    assert!((near_closed - slew / 1.1).abs() < 0.5, "{near_closed} %/s");
    assert!(near_open < slew / 2.0, "{near_open} %/s");
}

#[test]
fn open_slowdown_also_slows_the_crossing_of_the_cart() {
    // The chamber that fills more slowly when open also takes longer to cross the friction
    // band: the reversal delay grows by the same factor 1 + r V / 100.
    let mut spec = slowed_when_open();
    if let Some(p) = spec.pincart2.as_mut() {
        (p.a_p, p.b_p, p.c_p) = (0.0, 0.0, 0.3);
    }
    let reversal_delay = |at: f64| {
        let mut v = Valve::new(&spec, DT).unwrap();
        v.reset(at - 5.0, at - 5.0);
        let settled = *run(&mut v, at, 1000).last().unwrap();
        let out = run(&mut v, at - 5.0, 1000);
        out.iter().position(|y| *y < settled - 1e-6).unwrap_or(1000) as f64 * DT
    };
    let (closed, open) = (reversal_delay(10.0), reversal_delay(90.0));
    assert!((closed - 0.3 * 1.2).abs() < 0.03, "{closed} s near closed");
    assert!((open - 0.3 * 2.8).abs() < 0.05, "{open} s near open");
}

#[test]
fn slow_sampling_keeps_every_model_stable() {
    // At 1 Hz, P_k dt exceeds 1 for the bundled pin-cart gains: no model may overshoot a step.
    for kind in ModelKind::ALL {
        let mut v = Valve::new(&bundled(kind), 1.0).unwrap();
        v.reset(40.0, 40.0);
        let out: Vec<f64> = (0..60).map(|_| v.step(60.0)).collect();
        assert!(
            out.iter().all(|&y| (40.0..=60.0 + 1e-9).contains(&y)),
            "{kind}: {out:?}"
        );
    }
}

#[test]
fn running_a_slice_steps_exactly_like_step_by_step() {
    // Every kind, and pin-cart II with every core effect (opening-dependent slowdown, friction
    // band, breakaway, wind-up, positioner deadband) and the input and sensor effects, driven
    // into both travel stops: `run` gives the same bits, and leaves the same state behind.
    let mut specs: Vec<ModelSpec> = ModelKind::EVERY.into_iter().map(bundled).collect();
    let mut full = bundled(ModelKind::Pincart2);
    full.travel = Travel {
        min_pct: 5.0,
        max_pct: 95.0,
    };
    full.effects = Effects {
        open_slowdown: 2.5,
        closing_slew_pct_per_s: 30.0,
        friction_band_pct: 0.8,
        breakaway_pct: 0.3,
        stop_windup_pct: 1.0,
        quantization_pct: 0.05,
        calibration_gain: 1.02,
        deadband_pct: 0.2,
        stickband_pct: 0.4,
        jumpband_pct: 0.2,
        ..Effects::default()
    };
    specs.push(full.clone());
    full.effects.positioner_deadband_pct = 0.3;
    full.effects.friction_band_pct = 0.0;
    specs.push(full);
    let op: Vec<f64> = golden_input()
        .iter()
        .enumerate()
        .map(|(k, &u)| {
            if (k / 700) % 3 == 0 {
                u
            } else {
                2.0 * u - 50.0
            }
        })
        .collect();
    for spec in &specs {
        let mut stepped = Valve::new(spec, DT).unwrap();
        let mut ran = stepped.clone();
        stepped.reset(op[0], 50.0);
        ran.reset(op[0], 50.0);
        let a: Vec<u64> = op.iter().map(|&u| stepped.step(u).to_bits()).collect();
        let mut b = Vec::with_capacity(op.len());
        ran.run(&op, |v| b.push(v.to_bits()));
        assert_eq!(a, b, "{}", spec.model);
        let after = |v: &mut Valve| (0..300).map(|_| v.step(70.0).to_bits()).collect::<Vec<_>>();
        assert_eq!(after(&mut stepped), after(&mut ran), "{}", spec.model);
    }
}
