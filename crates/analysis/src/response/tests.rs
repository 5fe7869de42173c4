//! The figures on synthetic valves whose answers are known in closed form, driven through the
//! response test's own schedule: a dead time and a first-order lag (dead time, T63 and T86
//! exactly), an underdamped second-order stem (its overshoot), a lost motion (what it does not
//! resolve, and its dead band on the signature), with noise, a per-mille register and lost rows.

use std::path::Path;
use std::time::SystemTime;

use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use super::spec::Spec;
use super::*;
use vb_core::recording::log_format::{Sample, Status};
use vb_core::response_plan::Schedule;

const DT: f64 = 0.01;

/// A plan at 50 % of the `sizes` with the pattern up, up, back, back, and `signature`; each
/// step held 4 to 20 s.
fn plan(sizes: &str, signature: &str) -> Plan {
    plan_held(sizes, signature, 20.0)
}

/// [`plan`] with holds of 4 to `max_s` s.
fn plan_held(sizes: &str, signature: &str, max_s: f64) -> Plan {
    let text = format!(
        "openings_pct = [50.0]\nsizes_pct = {sizes}\npattern = [1, 1, -1, -1]\n\
         [hold]\nmin_s = 4.0\nmax_s = {max_s}\nstill_s = 0.5\nstill_pct = 0.02\n{signature}"
    );
    Plan::from_toml(&text, Path::new("p.toml"), (0.0, 100.0)).unwrap()
}

/// How a synthetic log is read: the noise on V_P, the lattice it is read on, the register
/// step the set-point is written on, and the rows whose reply is lost.
#[derive(Clone, Copy)]
struct Reading<'a> {
    noise: f64,
    lattice: f64,
    setpoint: f64,
    lost: &'a dyn Fn(usize) -> bool,
}

const EXACT: Reading = Reading {
    noise: 0.0,
    lattice: 0.0,
    setpoint: 0.0,
    lost: &|_| false,
};

/// The log of `plan` run on `valve` (the position after one period with the set-point it is
/// handed), read as `reading` says.
fn log(plan: &Plan, mut valve: impl FnMut(f64) -> f64, reading: Reading) -> Recording {
    let mut s = Schedule::new(plan, DT);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let normal = Normal::new(0.0, reading.noise.max(1e-12)).unwrap();
    let round = |v: f64, q: f64| if q > 0.0 { (v / q).round() * q } else { v };
    let (mut t, mut op, mut vp) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0.. {
        let Some(o) = s.op_at(k as f64 * DT) else {
            break;
        };
        let o = vb_core::recording::log_format::round_pct(o);
        let x = valve(round(o, reading.setpoint));
        let noise = if reading.noise > 0.0 {
            normal.sample(&mut rng)
        } else {
            0.0
        };
        let read = (!(reading.lost)(k)).then(|| round(x + noise, reading.lattice));
        s.feedback(&Sample {
            t_s: k as f64 * DT,
            op_pct: Some(o),
            vp_pct: read,
            status: if read.is_some() {
                Status::Ok
            } else {
                Status::Timeout
            },
            lateness_us: None,
            latency_us: None,
            op_sent_pct: None,
            utc: SystemTime::UNIX_EPOCH,
            op_controller_pct: None,
        });
        t.push(k as f64 * DT);
        op.push(o);
        vp.push(read.unwrap_or(f64::NAN));
    }
    Recording::from_vectors(t, op, vp).unwrap()
}

/// A valve with a dead time of `td` s and a first-order lag of `tau` s, at rest at 50 %.
fn lagged(td: f64, tau: f64) -> impl FnMut(f64) -> f64 {
    let delay = (td / DT).round() as usize;
    let mut line = std::collections::VecDeque::from(vec![50.0; delay]);
    let mut x = 50.0;
    let a = 1.0 - (-DT / tau).exp();
    move |u| {
        line.push_back(u);
        let u = line.pop_front().unwrap_or(u);
        x += a * (u - x);
        x
    }
}

/// The dead time, T63 and T86 of the first-order valve `lagged(td, tau)`, s: the first sample
/// at which its discrete answer covers each share of the step (dead time: `dead_share`).
fn lagged_figures(td: f64, tau: f64, dead_share: f64) -> [f64; 3] {
    let at = |share: f64| {
        // After j + 1 samples of input the answer has covered 1 - e^-(j+1)dt/tau.
        let j = (-(1.0 - share).ln() * tau / DT - 1.0 - 1e-9)
            .ceil()
            .max(0.0);
        td + j * DT
    };
    [at(dead_share), at(T63_SHARE), at(T86_SHARE)]
}

#[test]
fn a_dead_time_and_a_lag_give_their_dead_time_t63_and_t86() {
    let (td, tau) = (0.3, 0.5);
    let p = plan("[1.0, 5.0]", "");
    let r = analyse(&log(&p, lagged(td, tau), EXACT), &p, 0.0).unwrap();
    assert_eq!((r.steps.len(), r.planned_steps, r.complete), (8, 8, true));
    let [dead, t63, t86] = lagged_figures(td, tau, DEAD_TIME_SHARE);
    for s in &r.steps {
        let near = |got: Option<f64>, want: f64| got.is_some_and(|g| (g - want).abs() < 0.011);
        assert!(near(s.dead_time_s, dead), "{s:?}: dead time {dead}");
        assert!(
            near(s.t63_s, t63) && near(s.t86_s, t86),
            "{s:?}: {t63} {t86}"
        );
        assert_eq!(s.overshoot_pct, Some(0.0), "{s:?}");
        assert!(
            s.resolved && s.measured && s.final_error_pct.unwrap().abs() < 0.01,
            "{s:?}"
        );
        assert!((s.sent_size_pct.abs() - s.size_pct).abs() < 1e-9);
    }
    let reversals: Vec<bool> = r.steps.iter().map(|s| s.reversal).collect();
    assert_eq!(
        reversals,
        [false, false, true, false, true, false, true, false]
    );
    let dirs: Vec<&str> = r.steps.iter().map(|s| s.direction.name()).collect();
    assert_eq!(
        dirs,
        ["open", "open", "close", "close", "open", "open", "close", "close"]
    );
    assert_eq!(r.signature.resolution_pct, Some(1.0));
    let one = &r.summary[0];
    assert_eq!(
        (one.size_pct, one.open.steps, one.close.resolved),
        (1.0, 2, 2)
    );
    assert!((one.open.t86_s.unwrap() - t86).abs() < 0.011);
}

#[test]
fn noise_and_a_per_mille_register_are_not_motion() {
    let (td, tau) = (0.3, 0.5);
    let p = plan("[0.25, 2.0]", "");
    let reading = Reading {
        noise: 0.03,
        lattice: 0.1,
        setpoint: 0.1,
        ..EXACT
    };
    let r = analyse(&log(&p, lagged(td, tau), reading), &p, 0.1).unwrap();
    assert!(
        (r.resolution.lattice_pct - 0.1).abs() < 1e-9,
        "{:?}",
        r.resolution
    );
    assert!(r.resolution.noise_pct < 0.05, "{:?}", r.resolution);
    let floor = r.resolution.threshold_pct;
    assert!((0.099..0.2).contains(&floor), "{floor}");
    for s in &r.steps {
        assert!(s.resolved, "{s:?}");
        // Noise on a still valve never shows as an overshoot (a step within two thresholds
        // has none to show).
        assert_eq!(s.overshoot_pct.unwrap_or(0.0), 0.0, "{s:?}");
        // The per-mille register sends 0.25 % steps as 0.2 or 0.3 %.
        let sent = s.sent_size_pct.abs();
        if s.size_pct == 0.25 {
            assert!(
                (sent - 0.2).abs() < 1e-9 || (sent - 0.3).abs() < 1e-9,
                "{sent}"
            );
            continue;
        }
        // A 2 % step: the figures of the exact valve, off by what half a lattice step and
        // three noise sigmas can move a crossing at the lag's slope there.
        let [dead, t63, t86] = lagged_figures(td, tau, DEAD_TIME_SHARE);
        for (got, want, share) in [
            (s.dead_time_s, dead, DEAD_TIME_SHARE),
            (s.t63_s, t63, T63_SHARE),
            (s.t86_s, t86, T86_SHARE),
        ] {
            let slope = 2.0 / tau * (1.0 - share);
            let tol = (0.05 + 3.0 * 0.03) / slope + DT;
            let got = got.unwrap();
            assert!(
                (got - want).abs() <= tol,
                "{s:?}: {got} against {want} ± {tol}"
            );
        }
    }
}

/// A stem answering its set-point as a second-order system of damping `zeta` and natural
/// frequency `wn` (rad/s), at rest at 50 %.
fn underdamped(zeta: f64, wn: f64) -> impl FnMut(f64) -> f64 {
    let (mut x, mut v) = (50.0, 0.0);
    move |u| {
        for _ in 0..10 {
            let h = DT / 10.0;
            v += h * (wn * wn * (u - x) - 2.0 * zeta * wn * v);
            x += h * v;
        }
        x
    }
}

#[test]
fn an_underdamped_stem_overshoots_as_its_damping_says() {
    let p = plan("[2.0]", "");
    let zeta: f64 = 0.5;
    let want = 100.0 * (-std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt()).exp();
    let r = analyse(&log(&p, underdamped(zeta, 8.0), EXACT), &p, 0.0).unwrap();
    for s in &r.steps {
        let got = s.overshoot_pct.unwrap();
        assert!((got - want).abs() < 0.5, "{got} against {want:.2}");
    }
}

/// A valve with lost motion `band` (a backlash: the stem follows the set-point only once it is
/// more than half the band away) and a lag of 0.1 s, at rest where an opening to 50 % leaves it.
fn lost_motion(band: f64) -> impl FnMut(f64) -> f64 {
    let mut target = 50.0 - band / 2.0;
    let mut x = target;
    let a = 1.0 - (-DT / 0.1f64).exp();
    move |u| {
        target = target.clamp(u - band / 2.0, u + band / 2.0);
        x += a * (target - x);
        x
    }
}

#[test]
fn lost_motion_leaves_small_reversals_unresolved_and_is_the_signatures_dead_band() {
    let sig = "[signature]\nopening_pct = 50.0\nspan_pct = 1.5\nrate_pct_per_s = 0.1\n";
    let p = plan("[0.25, 0.5, 1.0, 2.0, 5.0]", sig);
    let r = analyse(&log(&p, lost_motion(0.6), EXACT), &p, 0.0).unwrap();
    assert!(r.complete, "{} steps, {:?}", r.steps.len(), r.signature);
    // Where lost motion leaves the stem after each set-point: it follows only what passes
    // the band (a reversal of 1 % moves 0.4 %, short of half the step).
    let mut target = 49.7;
    for s in &r.steps {
        let u = s.start_pct + s.sent_size_pct;
        let next = f64::clamp(target, u - 0.3, u + 0.3);
        let moved = (next - target) * s.direction.sign();
        target = next;
        assert_eq!(
            s.resolved,
            moved >= 0.5 * s.size_pct - 1e-9,
            "{s:?}: {moved}"
        );
        assert_eq!(s.dead_time_s.is_none(), moved < 1e-9, "{s:?}: {moved}");
    }
    assert_eq!(r.signature.resolution_pct, Some(2.0));
    let g = &r.signature;
    assert_eq!(g.reversals.len(), 2);
    let band = g.dead_band_pct.unwrap();
    assert!((band - 0.6).abs() < 0.06, "{band} {:?}", g.reversals);
    let hd = g.hysteresis_plus_dead_band_pct.unwrap();
    assert!((hd - 0.6).abs() < 0.05, "{hd}");
    assert!(g.hysteresis_pct.unwrap() < 0.05, "{g:?}");
    // The same valve without lost motion: no dead band beyond what its lag makes of the ramp.
    let r = analyse(&log(&p, lost_motion(0.0), EXACT), &p, 0.0).unwrap();
    assert!(
        r.signature.dead_band_pct.unwrap() < 0.05,
        "{:?}",
        r.signature
    );
    assert_eq!(r.signature.resolution_pct, Some(0.25));
}

#[test]
fn lost_replies_are_counted_and_never_taken_for_motion() {
    // Holds of 4 s exactly, so both logs step on the same rows.
    let p = plan_held("[1.0, 5.0]", "", 4.0);
    let whole = analyse(&log(&p, lagged(0.3, 0.5), EXACT), &p, 0.0).unwrap();
    // One reply in 20 lost, three in a row every 300 rows, and five in a row around where the
    // first 5 % step's dead time ends (more than a crossing may follow).
    let first = whole.steps[4].clone();
    let crossed = first.rows.0 + (first.dead_time_s.unwrap() / DT).round() as usize;
    let lost =
        move |k: usize| k % 20 == 7 || k % 300 < 3 || (crossed - 2..crossed + 3).contains(&k);
    let reading = Reading {
        lost: &lost,
        ..EXACT
    };
    let holed = analyse(&log(&p, lagged(0.3, 0.5), reading), &p, 0.0).unwrap();
    let missing: usize = holed.rows_without_vp.values().sum();
    assert_eq!(
        holed.rows_without_vp.keys().collect::<Vec<_>>(),
        ["missing"]
    );
    assert!(missing > holed.rows / 20, "{missing}");
    for (a, b) in whole.steps.iter().zip(&holed.steps) {
        assert!(b.measured && b.missing_rows > 0, "{b:?}");
        // A lost row can delay a crossing by the rows lost in a row, never advance it.
        let pairs = [
            (a.dead_time_s, b.dead_time_s),
            (a.t63_s, b.t63_s),
            (a.t86_s, b.t86_s),
        ];
        for (i, (x, y)) in pairs.into_iter().enumerate() {
            if i == 0 && b.rows.0 == first.rows.0 {
                assert_eq!(y, None, "the gap hides the dead time: {b:?}");
                assert!(b.answered && b.hidden_by_gap, "{b:?}");
                continue;
            }
            let d = y.unwrap() - x.unwrap();
            assert!((-1e-9..=0.03 + 1e-9).contains(&d), "{a:?} {b:?}");
        }
        assert_eq!(a.resolved, b.resolved);
    }
}

#[test]
fn a_log_cut_short_is_incomplete_and_a_log_of_something_else_is_refused() {
    let p = plan("[1.0, 5.0]", "");
    let full = log(&p, lagged(0.3, 0.5), EXACT);
    let n = full.len() / 2;
    let cut = Recording::from_vectors(
        full.t[..n].to_vec(),
        full.op[..n].to_vec(),
        full.vp[..n].to_vec(),
    )
    .unwrap();
    let r = analyse(&cut, &p, 0.0).unwrap();
    assert!(!r.complete && r.steps.len() < 8 && !r.steps.is_empty());
    let flat =
        Recording::from_vectors(full.t.clone(), vec![50.0; full.len()], full.vp.clone()).unwrap();
    assert!(matches!(
        analyse(&flat, &p, 0.0),
        Err(ResponseError::NoSteps(_))
    ));
    let blind =
        Recording::from_vectors(full.t.clone(), full.op.clone(), vec![f64::NAN; full.len()])
            .unwrap();
    assert!(matches!(
        analyse(&blind, &p, 0.0),
        Err(ResponseError::NoPosition(_))
    ));
}

fn spec(text: &str) -> Result<Spec, String> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("spec.toml");
    std::fs::write(&path, text).unwrap();
    Spec::load(&path).map_err(|e| {
        e.to_string()
            .replace(&path.display().to_string(), "spec.toml")
    })
}

#[test]
fn a_spec_passes_on_what_the_test_showed_and_fails_on_anything_else() {
    let sig = "[signature]\nopening_pct = 50.0\nspan_pct = 1.5\nrate_pct_per_s = 0.1\n";
    let p = plan("[0.25, 1.0, 2.0]", sig);
    let r = analyse(&log(&p, lost_motion(0.6), EXACT), &p, 0.0).unwrap();
    let worst_2 = (r.steps.iter())
        .filter(|s| s.size_pct == 2.0)
        .filter_map(|s| s.t86_s)
        .fold(0.0, f64::max);
    let s = spec(&format!(
        "[[limit]]\nmin_size_pct = 2.0\nt86_s = {}\novershoot_pct = 1.0\n\
         [[limit]]\nmin_size_pct = 1.0\nmax_size_pct = 1.0\ndead_time_s = 10.0\n\
         [[limit]]\nmin_size_pct = 0.25\nmax_size_pct = 0.25\ndead_time_s = 10.0\n\
         [[limit]]\nmin_size_pct = 20.0\nt63_s = 10.0\n\
         [signature]\ndead_band_pct = 0.5\nresolution_pct = 2.0\n",
        worst_2 + 0.001
    ))
    .unwrap();
    let lines = s.check(&r);
    let verdicts: Vec<(&str, bool)> = lines.iter().map(|l| (l.figure, l.pass)).collect();
    assert_eq!(
        verdicts,
        [
            ("t86_s", true),
            ("overshoot_pct", true),
            // The 1 % reversals moved 0.4 %: answered, within 10 s.
            ("dead_time_s", true),
            // The 0.25 % reversals never moved.
            ("dead_time_s", false),
            // No step of 20 %.
            ("t63_s", false),
            ("dead_band_pct", false),
            ("resolution_pct", true),
        ]
    );
    assert_eq!(lines[0].worst, Some(worst_2));
    assert_eq!((lines[3].worst, lines[4].steps), (None, 0));
}

#[test]
fn a_spec_file_is_checked_at_its_keys() {
    let e = spec("[[limit]]\nmin_size_pct = 1.0\n").unwrap_err();
    assert!(
        e.starts_with("spec.toml:1: limit: a [[limit]] needs at least one of"),
        "{e}"
    );
    let e = spec("[[limit]]\nmin_size_pct = 1.0\nt86_s = 2.0\n[[limit]]\nmin_size_pct = 5.0\nmax_size_pct = 2.0\nt86_s = 1.0\n").unwrap_err();
    assert!(
        e.starts_with("spec.toml:6: limit.max_size_pct: below min_size_pct = 5"),
        "{e}"
    );
    let e = spec("[signature]\ndead_band_pct = -1.0\n").unwrap_err();
    assert!(
        e.starts_with("spec.toml:2: signature.dead_band_pct:"),
        "{e}"
    );
    let e = spec("[[limit]]\nmin_size_pct = 1.0\nt90_s = 2.0\n").unwrap_err();
    assert!(e.contains("unknown field `t90_s`"), "{e}");
    let shipped =
        Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../..")).join("config/response-spec.toml");
    assert!(Spec::load(&shipped).is_ok());
}
