//! Reproduces the paper's Table 1 ordering on its own experiment (Section 3.1): 20 minutes of
//! random steps (levels 20-97 %, holds 0-20 s) through a valve with 1 % backlash whose reversal
//! delay grows with opening (pin-cart II, crossing time 0.3 s closed to 0.8 s open), plus
//! measurement noise. Identification must rank pin-cart II first, with FOPDT and stiction close
//! to delayed modelless, as in the paper.

use valve_bridge::fit::{self, Options};
use valve_bridge::model::{bundled, ModelKind};
use valve_bridge::synth::{self, Excitation};

#[test]
fn table1_ordering_of_the_paper() {
    // The bundled pin-cart II (T_d 0.38 s, crossing 0.3 s closed to 0.8 s open, B_L 1 %) with a
    // fast positioner, as on the paper's valve, where the delays dominate the step responses.
    let mut truth = bundled(ModelKind::Pincart2);
    if let Some(p) = truth.pincart2.as_mut() {
        p.p_gain_per_s = 20.0;
        p.dy_max_pct_per_s = 400.0;
    }
    let rec = synth::generate(&truth, Excitation::RandomSteps, 1200.0, 0.01, 0.3, 11).unwrap();
    let started = std::time::Instant::now();
    let id = fit::identify(&rec.view(), &Options::default(), &|_, _| {}).unwrap();
    let elapsed = started.elapsed().as_secs_f64();
    let row = |k: ModelKind| id.rows.iter().find(|r| r.kind == k).unwrap();
    for r in &id.rows {
        eprintln!(
            "{:<18} SSE {:>10.2} rel {:>6.2}% held-out {:>9.2} params {:?}",
            r.kind.display_name(),
            r.scores.sse,
            100.0 * r.scores.rel_sse,
            r.heldout.sse,
            r.params()
        );
    }
    eprintln!("identified 120,000 samples in {elapsed:.2} s");
    let truth_sse =
        fit::cost::Problem::new(&rec.op, &rec.vp, &id.scored_mask, rec.sample_period).sse(&truth);
    eprintln!("truth SSE {truth_sse:.2}");
    let sse = |k| row(k).scores.sse;
    let held = |k| row(k).heldout.sse;
    let delayed = sse(ModelKind::Delayed);
    // Pin-cart II best, on all scored samples and on held-out blocks.
    for k in ModelKind::ALL {
        if k != ModelKind::Pincart2 {
            assert!(sse(ModelKind::Pincart2) < sse(k), "pin-cart II vs {k}");
            assert!(
                held(ModelKind::Pincart2) < held(k),
                "held-out: pin-cart II vs {k}"
            );
        }
    }
    assert!(sse(ModelKind::Pincart2) < 0.6 * delayed);
    // Every model beats modelless; FOPDT and stiction are close to delayed modelless.
    for k in [
        ModelKind::Delayed,
        ModelKind::Fopdt,
        ModelKind::Stiction,
        ModelKind::Pincart1,
    ] {
        assert!(sse(k) < sse(ModelKind::Modelless), "{k} vs modelless");
    }
    // "Close": within a factor 1.6 below delayed modelless (the paper's normal-operation
    // windows gave 0.975 and 1.0; random steps give FOPDT a little more to smooth), while
    // pin-cart II is far below.
    for k in [ModelKind::Fopdt, ModelKind::Stiction] {
        let ratio = sse(k) / delayed;
        assert!((0.6..=1.001).contains(&ratio), "{k}: {ratio} of delayed");
    }
    // The search reaches the truth's error (the noise) within 10 %.
    assert!(
        sse(ModelKind::Pincart2) < 1.1 * truth_sse,
        "{} vs truth {truth_sse}",
        sse(ModelKind::Pincart2)
    );
    // The fitted pin-cart II finds the true dead time and a reversal delay that grows with
    // opening, and the step analysis saw the same.
    let p2 = row(ModelKind::Pincart2).spec.pincart2.unwrap();
    assert!(
        (row(ModelKind::Pincart2).spec.dead_time_s - truth.dead_time_s).abs() < 0.1,
        "{:?}",
        row(ModelKind::Pincart2).spec
    );
    assert!(p2.crossing_time_s(90.0) > p2.crossing_time_s(20.0));
    assert!(id.steps.reversal.mean_s > id.steps.same.mean_s + 0.2);
    assert!(id.steps.pincart2.is_some());
}
