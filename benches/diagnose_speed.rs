//! How long `diagnose` takes on long recordings and on recordings with rows without V_P.
//!
//! Two recordings of the emulated pin-cart II valve (`config/models/pincart2.toml`, no noise)
//! on the paper's random steps, as `valve-bridge run --as-fast-as-possible` logs them: 20
//! minutes at 100 Hz (120,000 samples), and 10 minutes (60,000 samples) diagnosed intact, with
//! V_P missing on every tenth row (a device that drops replies), and as the daemon logs it
//! (per mille, 0.5 % of the rows without V_P in bursts of 1-3). Each is diagnosed
//! `VB_BENCH_RUNS` times (default 3); the median wall-clock time is printed, with the
//! findings, and the ratio of each gappy recording's time to the intact one's.
//!
//! `cargo bench --bench diagnose_speed`

use std::time::Instant;

use valve_bridge::diagnose::{self, Diagnosis};
use valve_bridge::model::{bundled, ModelKind, Valve};
use valve_bridge::recording::Recording;
use valve_bridge::signal::{RandomSteps, RandomStepsParams};
use valve_bridge::synth::logged;

/// The valve's recording of `n` samples at 100 Hz.
fn recording(n: usize) -> Result<Recording, Box<dyn std::error::Error>> {
    let dt = 0.01;
    let mut sig = RandomSteps::new(&RandomStepsParams::default());
    let op: Vec<f64> = (0..n).map(|k| sig.op_at(k as f64 * dt)).collect();
    let vp = Valve::new(&bundled(ModelKind::Pincart2), dt)?.simulate(&op, op[0]);
    let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
    Ok(Recording::from_vectors(t, op, vp)?)
}

/// Median wall-clock time of `runs` diagnoses of `rec`, s, and the last diagnosis.
fn timed(rec: &Recording, runs: usize) -> Result<(f64, Diagnosis), Box<dyn std::error::Error>> {
    let mut secs = Vec::with_capacity(runs);
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        last = Some(diagnose::diagnose(&rec.view(), None, &|_, _| {})?);
        secs.push(t.elapsed().as_secs_f64());
    }
    secs.sort_by(f64::total_cmp);
    let d = last.ok_or("no run")?;
    Ok((secs[secs.len() / 2], d))
}

fn names(d: &Diagnosis) -> String {
    let n: Vec<&str> = d.findings.iter().map(|f| f.effect.name()).collect();
    format!("[{}]", n.join(", "))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let runs: usize = match std::env::var("VB_BENCH_RUNS") {
        Ok(v) => v.parse().map_err(|e| format!("VB_BENCH_RUNS={v}: {e}"))?,
        Err(_) => 3,
    };
    let long = recording(120_000)?;
    let (secs, d) = timed(&long, runs)?;
    println!(
        "120,000 samples (20 min at 100 Hz): median {secs:.2} s of {runs} runs, found {}",
        names(&d)
    );
    let intact = recording(60_000)?;
    let mut tenth = intact.clone();
    tenth
        .vp
        .iter_mut()
        .skip(9)
        .step_by(10)
        .for_each(|v| *v = f64::NAN);
    let as_logged = logged::as_logged(&intact, 0.005, 1);
    let (base, d) = timed(&intact, runs)?;
    println!(
        "60,000 samples intact: median {base:.2} s, found {}",
        names(&d)
    );
    for (what, rec) in [
        ("every tenth row without V_P", &tenth),
        (
            "as the daemon logs it (per mille, 0.5 % of rows without V_P)",
            &as_logged,
        ),
    ] {
        let (secs, d) = timed(rec, runs)?;
        println!(
            "60,000 samples, {what}: median {secs:.2} s ({:.2} times intact), found {}",
            secs / base,
            names(&d)
        );
    }
    Ok(())
}
