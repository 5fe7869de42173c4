//! `valve-bridge demo concealed`: hide an effect in a plausible recording, show that the
//! baseline fit looks fine, then let `diagnose` find it.
//!
//! The valve is the physical one (`model = "physical"`: positioner, chamber, stem friction,
//! stops, sensor), not the composed valve diagnosis fits, with the named effect built from the
//! physics that causes it at a moderate size ([`synth::physical`]).

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::diagnose::{self, Effect};
use valve_bridge::metrics;
use valve_bridge::model::ModelSpec;
use valve_bridge::recording;
use valve_bridge::report::diagnose as report;
use valve_bridge::synth::{self, physical, Excitation};

/// Arguments of `valve-bridge demo`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Which demo: only `concealed` so far.
    #[arg(value_parser = ["concealed"])]
    which: String,
    /// The effect to hide, any of the vocabulary: dead_time, backlash, state_dependent_delay,
    /// slew_rate, asymmetry, min_speed, stiction, deadband, saturation, quantization, calibration.
    #[arg(long, default_value = "backlash")]
    effect: Effect,
    /// Seed of the recording's noise and disturbances.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Where to write the generated recording.
    #[arg(long, default_value = "demo-concealed.csv")]
    out: PathBuf,
}

/// A healthy physical valve with `effect` at a moderate size, its sensor noise `noise` (%).
fn hidden(effect: Effect, noise: f64, seed: u64) -> ModelSpec {
    let mut spec = physical::with_effect(effect, physical::moderate_size(effect));
    if let Some(p) = spec.physical.as_mut() {
        p.sensor_noise_pct = noise;
        p.noise_seed = seed;
    }
    spec
}

/// Generates the recording, shows the baseline, runs the diagnosis and prints what it found.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let effect = args.effect;
    let dt = 0.01;
    // A quantizing sensor reports the lattice itself, so that case is recorded without extra noise.
    let noise = if effect == Effect::Quantization {
        0.0
    } else {
        0.1
    };
    let spec = hidden(effect, noise, args.seed);
    let rec = synth::generate(
        &spec,
        Excitation::ClosedLoop { level_pct: 50.0 },
        900.0,
        dt,
        0.0,
        args.seed,
    )?;
    recording::write(&args.out, &rec).with_context(|| format!("writing {}", args.out.display()))?;
    outln!(
        "1. Generated 15 min of closed-loop level control through a physical valve (positioner, chamber, stem friction, sensor) with a hidden `{}` ({}; {noise} % sensor noise): {}",
        effect.name(),
        physical::describe(effect, physical::moderate_size(effect)),
        args.out.display()
    )?;
    let d = diagnose::diagnose(&rec.view(), None, &|_, _| {})?;
    let base = metrics::scores(&rec.vp, &d.sim_before, &rec.op, dt);
    outln!("2. A fitted FOPDT looks fine by eye (whole recording):")?;
    outln!("   {}", metrics::table1_header())?;
    outln!("   {}", metrics::table1_row("FOPDT", &base))?;
    out!("{}", metrics::table1_notes([&base]))?;
    outln!("3. valve-bridge diagnose {}:", args.out.display())?;
    if d.findings.is_empty() {
        outln!("   found nothing: {}", report::verdict(&d))?;
    }
    for f in &d.findings {
        outln!(
            "   found {}: {}\n   held-out SSE {:.2} -> {:.2} %²",
            valve_bridge::vocabulary::words(f.effect).plain,
            report::evidence(f),
            f.heldout_sse_before,
            f.heldout_sse_after
        )?;
    }
    let hit = d.findings.iter().any(|f| f.effect == effect);
    outln!(
        "4. {} {}",
        if hit { "Right:" } else { "Missed:" },
        report::verdict(&d)
    )?;
    Ok(())
}
