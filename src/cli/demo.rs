//! `valve-bridge demo concealed`: hide an effect in a plausible recording, show that the
//! baseline fit looks fine, then let `diagnose` find it.

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::diagnose::{self, composed};
use valve_bridge::metrics;
use valve_bridge::model::{bundled, ModelKind, ModelSpec};
use valve_bridge::recording;
use valve_bridge::report::diagnose as report;
use valve_bridge::synth::{self, Excitation};

/// Arguments of `valve-bridge demo`.
#[derive(clap::Args)]
pub struct Args {
    /// Which demo: only `concealed` so far.
    #[arg(value_parser = ["concealed"])]
    which: String,
    /// The effect to hide: backlash, deadband, calibration, quantization, stiction, dead_time.
    #[arg(long, default_value = "backlash")]
    effect: String,
    /// Seed of the recording's noise and disturbances.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Where to write the generated recording.
    #[arg(long, default_value = "demo-concealed.csv")]
    out: PathBuf,
}

/// A healthy valve (FOPDT-like, 0.1 s dead time, 60 %/s stroke) with one small effect added.
fn hidden(effect: &str) -> anyhow::Result<ModelSpec> {
    let mut spec = composed::compose(&bundled(ModelKind::Fopdt), 0.01);
    spec.dead_time_s = 0.1;
    let set = |spec: &mut ModelSpec, knob, v| composed::set(spec, knob, v);
    match effect {
        "backlash" => set(&mut spec, composed::Knob::Crossing, 0.4),
        "deadband" => set(&mut spec, composed::Knob::Deadband, 0.4),
        "calibration" => set(&mut spec, composed::Knob::CalOffset, 0.8),
        "quantization" => set(&mut spec, composed::Knob::Quantum, 0.2),
        "stiction" => set(&mut spec, composed::Knob::Stickband, 0.8),
        "dead_time" => spec.dead_time_s = 0.6,
        other => anyhow::bail!("unknown effect `{other}`: one of backlash, deadband, calibration, quantization, stiction, dead_time"),
    }
    composed::set(&mut spec, composed::Knob::Slew, 60.0);
    Ok(spec)
}

/// Generates the recording, shows the baseline, runs the diagnosis and prints what it found.
pub fn run(args: Args) -> anyhow::Result<()> {
    let spec = hidden(&args.effect)?;
    let dt = 0.01;
    // A quantizing sensor reports the lattice itself, so that case is recorded without extra noise.
    let noise = if args.effect == "quantization" {
        0.0
    } else {
        0.1
    };
    let rec = synth::generate(
        &spec,
        Excitation::ClosedLoop { level_pct: 50.0 },
        900.0,
        dt,
        noise,
        args.seed,
    )?;
    recording::write(&args.out, &rec).with_context(|| format!("writing {}", args.out.display()))?;
    println!(
        "1. Generated 15 min of closed-loop level control through a valve with a hidden `{}` ({noise} % sensor noise): {}",
        args.effect,
        args.out.display()
    );
    let d = diagnose::diagnose(&rec.view(), None, &|_, _| {})?;
    let base = metrics::scores(&rec.vp, &d.sim_before, &rec.op, dt);
    println!("2. A fitted FOPDT looks fine by eye (whole recording):");
    println!("   {}", metrics::table1_header());
    println!("   {}", metrics::table1_row("FOPDT", &base));
    println!("3. valve-bridge diagnose {}:", args.out.display());
    if d.findings.is_empty() {
        println!("   found nothing: {}", report::verdict(&d.outcome));
    }
    for f in &d.findings {
        println!(
            "   found {}: {}\n   held-out SSE {:.2} -> {:.2} %²",
            f.effect.name(),
            report::evidence(f),
            f.heldout_sse_before,
            f.heldout_sse_after
        );
    }
    let hit = d.findings.iter().any(|f| f.effect.name() == args.effect);
    println!(
        "4. {} {}",
        if hit { "Right:" } else { "Missed:" },
        report::verdict(&d.outcome)
    );
    Ok(())
}
