//! Cost of one live-health window: the figures of 10 minutes at 100 Hz (60,000 samples of the
//! paper's random steps through pin-cart II), as the health thread computes them every minute,
//! and the same with a model baseline (the model simulated over the window and analysed too).
//!
//! `cargo bench --bench health_window`; `VB_BENCH_RUNS` sets the runs (default 20).

use std::time::Instant;

use valve_bridge::daemon::monitor::health::Figures;
use valve_bridge::model::{bundled, ModelKind, Valve};
use valve_bridge::signal::{RandomSteps, RandomStepsParams};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: usize = match std::env::var("VB_BENCH_RUNS") {
        Ok(v) => v.parse().map_err(|e| format!("VB_BENCH_RUNS={v}: {e}"))?,
        Err(_) => 20,
    };
    let dt = 0.01;
    let mut sig = RandomSteps::new(&RandomStepsParams::default());
    let op: Vec<f64> = (0..60_000).map(|k| sig.op_at(k as f64 * dt)).collect();
    let mut valve = Valve::new(&bundled(ModelKind::Pincart2), dt)?;
    let vp = valve.simulate(&op, op[0]);
    let mut plain = Vec::with_capacity(runs);
    let mut with_model = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        std::hint::black_box(Figures::of(&op, &vp, dt, 5));
        plain.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let sim = valve.simulate(&op, vp[0]);
        std::hint::black_box(Figures::of(&op, &sim, dt, 5));
        std::hint::black_box(Figures::of(&op, &vp, dt, 5));
        with_model.push(t.elapsed().as_secs_f64() * 1e3);
    }
    for (what, mut ms) in [
        ("first-window baseline", plain),
        ("model baseline", with_model),
    ] {
        ms.sort_by(f64::total_cmp);
        println!(
            "health window (60,000 samples), {what}: median {:.2} ms, max {:.2} ms over {runs} runs",
            ms[ms.len() / 2],
            ms[ms.len() - 1]
        );
    }
    Ok(())
}
