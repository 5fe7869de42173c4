//! Times the whole Table 1 (all six models fitted) on 41,300 samples, the paper's validation
//! size: 413 s of the paper's random-step experiment at 100 Hz through a pin-cart II valve
//! with opening-dependent reversal delay, plus 0.3 % noise.
//!
//! Run: `cargo bench --bench fit_table1`. It prints the median of five runs and each model's
//! SSE and simulation count, and writes `target/fit_bench/paper_41300.csv` and
//! `target/fit_bench/rust.json` (bounds, starts, budgets and results) for
//! `benches/fit_scipy.py`, which does the same fits with `scipy.optimize` on a Python
//! implementation of the models for comparison.

use std::path::Path;

use serde_json::json;
use valve_bridge::fit::{self, params::Layout, params::Limits, seeds, Options};
use valve_bridge::model::{bundled, ModelKind};
use valve_bridge::recording;
use valve_bridge::synth::{self, Excitation};

fn main() -> anyhow::Result<()> {
    let mut truth = bundled(ModelKind::Pincart2);
    if let Some(p) = truth.pincart2.as_mut() {
        p.p_gain_per_s = 20.0;
        p.dy_max_pct_per_s = 400.0;
    }
    let rec = synth::generate(&truth, Excitation::RandomSteps, 413.0, 0.01, 0.3, 3)?;
    assert_eq!(rec.len(), 41_300);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fit_bench");
    std::fs::create_dir_all(&dir)?;
    let csv = dir.join("paper_41300.csv");
    recording::write(&csv, &rec)?;
    let opts = Options::default();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..5 {
        let t0 = std::time::Instant::now();
        let id = fit::identify(&rec.view(), &opts, &|_, _| {})?;
        times.push(t0.elapsed().as_secs_f64());
        last = Some(id);
    }
    times.sort_by(f64::total_cmp);
    let Some(id) = last else {
        anyhow::bail!("no run");
    };
    println!(
        "Table 1 on {} samples: median {:.3} s, best {:.3} s, worst {:.3} s (5 runs, {} threads)",
        rec.len(),
        times[2],
        times[0],
        times[4],
        rayon::current_num_threads()
    );
    let limits = Limits::for_recording(
        rec.sample_period,
        id.physical
            .dead_time_s
            .max(id.physical.same_delay_s.unwrap_or(0.0)),
    );
    let mut models = Vec::new();
    for r in &id.rows {
        let layout = Layout::new(r.kind, limits);
        println!(
            "  {:<18} SSE {:>12.3}  held-out SSE {:>12.3}  {:>5} simulations",
            r.kind.display_name(),
            r.scores.sse,
            r.heldout.sse,
            r.evals
        );
        let defs: Vec<_> = layout
            .defs
            .iter()
            .map(|d| json!({"name": d.name, "lo": d.lo, "hi": d.hi, "log": d.scale == fit::params::Scale::Log}))
            .collect();
        models.push(json!({
            "model": r.kind.tag(),
            "defs": defs,
            "starts": seeds::starts(&layout, &id.physical),
            "x": layout.vector(&r.spec),
            "sse": r.scores.sse,
            "simulations": r.evals,
        }));
    }
    let out = json!({
        "csv": csv,
        "n_samples": rec.len(),
        "sample_period_s": rec.sample_period,
        "median_s": times[2],
        "models": models,
    });
    let path = dir.join("rust.json");
    std::fs::write(&path, serde_json::to_string_pretty(&out)?)?;
    println!("wrote {} and {}", csv.display(), path.display());
    Ok(())
}
