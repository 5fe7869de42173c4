//! `valve-bridge diagnose`: locate model mismatch, name the missing physics, prove the fix.

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::diagnose::{self, Diagnosis};
use valve_bridge::metrics;
use valve_bridge::model::{ModelKind, ModelSpec};
use valve_bridge::recording;
use valve_bridge::report;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge diagnose`.
#[derive(clap::Args)]
pub struct Args {
    /// The recording to diagnose (t_s,op_pct,vp_pct; see --columns).
    recording: PathBuf,
    /// Starting model (any model file); without it an FOPDT with unity gain is fitted.
    #[arg(long)]
    model: Option<PathBuf>,
    /// Write report.html, model.toml (the final model) and diagnosis.json here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the diagnosis as JSON instead of text.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: RecordingArgs,
}

/// Runs the diagnosis and prints it.
pub fn run(args: Args) -> anyhow::Result<()> {
    let rec = recording::read(&args.recording, &args.read.options()?)?;
    let base = args.model.as_deref().map(ModelSpec::load).transpose()?;
    if let (Some(b), Some(path)) = (&base, &args.model) {
        anyhow::ensure!(b.model != ModelKind::Physical, "--model {}: model = \"physical\" is a simulator, not a starting model diagnosis can extend: give one of the paper's models (e.g. config/models/pincart2.toml) or none", path.display());
    }
    let bar = super::progress_bar(
        1,
        "diagnosing {bar:30} {pos}/{len} refit rounds of candidates",
    );
    let report = |done: usize, total: usize| {
        if let Some(b) = &bar {
            b.set_length(total as u64);
            b.set_position(done as u64);
        }
    };
    let started = std::time::Instant::now();
    let d = diagnose::diagnose(
        &rec.t,
        &rec.op,
        &rec.vp,
        rec.sample_period,
        base.as_ref(),
        &report,
    )?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    tracing::info!(seconds = started.elapsed().as_secs_f64(), "diagnosis done");
    if let Some(dir) = &args.out {
        write_out(dir, &rec, &d)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&d)?);
    } else {
        print_text(&d);
    }
    Ok(())
}

fn write_out(
    dir: &std::path::Path,
    rec: &recording::Recording,
    d: &Diagnosis,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let model = dir.join("model.toml");
    std::fs::write(&model, d.final_model.spec.to_toml())
        .with_context(|| format!("cannot write {}", model.display()))?;
    let json = dir.join("diagnosis.json");
    std::fs::write(&json, serde_json::to_string_pretty(d)?)
        .with_context(|| format!("cannot write {}", json.display()))?;
    let html = dir.join("report.html");
    let page = report::diagnosis_html(&rec.source, &rec.t, &rec.op, &rec.vp, d);
    std::fs::write(&html, page).with_context(|| format!("cannot write {}", html.display()))?;
    eprintln!(
        "wrote {}, {} and {}",
        html.display(),
        model.display(),
        json.display()
    );
    Ok(())
}

fn print_text(d: &Diagnosis) {
    println!(
        "baseline: {} (held-out SSE {:.2} %², whole SSE {:.2} %²)",
        d.baseline.model, d.baseline.heldout_sse, d.baseline.sse
    );
    println!(
        "noise floor of V_P: {:.3} % (standard deviation)",
        d.noise_floor_pct
    );
    let mut worst = d.mismatch_windows.clone();
    worst.sort_by(|a, b| b.excess_sse.total_cmp(&a.excess_sse));
    println!(
        "\n{} windows where the baseline misses by more than the noise (largest first):",
        worst.len()
    );
    for w in worst.iter().take(10) {
        println!(
            "  {:>8.2}-{:<8.2} s  excess {:>8.2} %²  {}",
            w.start_s, w.end_s, w.excess_sse, w.context
        );
    }
    if d.findings.is_empty() {
        println!("\nfindings: none");
    }
    for f in &d.findings {
        println!("\nfinding: {}", f.effect.name());
        println!("  evidence: {}", f.evidence);
        println!(
            "  parameters: {}",
            serde_json::Value::Object(f.params.clone())
        );
        println!(
            "  held-out SSE {:.2} -> {:.2} %² ({:+.1} %), delta BIC {:.0}",
            f.heldout_sse_before,
            f.heldout_sse_after,
            100.0 * (f.heldout_sse_after / f.heldout_sse_before - 1.0),
            f.delta_bic
        );
    }
    if let Some(h) = &d.heldout {
        println!("\nTable 1 on the held-out blocks:");
        println!("{}", metrics::table1_header());
        println!("{}", metrics::table1_row("before (baseline)", &h.before));
        println!("{}", metrics::table1_row("after (final)", &h.after));
    }
    println!(
        "\nmismatch windows: {} before, {} after; excess {:.1} -> {:.1} %²",
        d.mismatch_windows.len(),
        d.windows_after.len(),
        d.mismatch_windows.iter().map(|w| w.excess_sse).sum::<f64>(),
        d.windows_after.iter().map(|w| w.excess_sse).sum::<f64>()
    );
    for n in &d.notes {
        println!("note: {n}");
    }
    println!("\nverdict: {}", d.verdict);
}
