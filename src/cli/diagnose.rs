//! `valve-bridge diagnose`: locate model mismatch, name the missing physics, prove the fix.

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::diagnose::{self, Diagnosis};
use valve_bridge::model::ModelSpec;
use valve_bridge::recording;
use valve_bridge::report;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge diagnose`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The recording to diagnose (t_s,op_pct,vp_pct; see --columns): one file, or several
    /// (rotated logs) or a directory of them, joined in time order.
    #[arg(required = true)]
    recording: Vec<PathBuf>,
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
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let rec = recording::read_all(&args.recording, &args.read.options()?)?;
    let base = args.model.as_deref().map(ModelSpec::load).transpose()?;
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
    let d = diagnose::diagnose(&rec.view(), base.as_ref(), &report).with_context(|| match &args
        .model
    {
        Some(m) => format!("diagnosing {} from --model {}", rec.source, m.display()),
        None => format!("diagnosing {}", rec.source),
    })?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    tracing::info!(
        seconds = %valve_bridge::human::num(started.elapsed().as_secs_f64()),
        "diagnosis done"
    );
    if let Some(dir) = &args.out {
        write_out(dir, &rec, &d)?;
    }
    if args.json {
        outln!(
            "{}",
            serde_json::to_string_pretty(&report::diagnose::json(&d))?
        )?;
    } else {
        out!("{}", report::diagnose::text(&d))?;
    }
    Ok(())
}

fn write_out(
    dir: &std::path::Path,
    rec: &recording::Recording,
    d: &Diagnosis,
) -> anyhow::Result<()> {
    let paths = report::write_files(dir, &report::diagnose::files(&rec.source, &rec.view(), d))?;
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    errln!("wrote {}", names.join(", "));
    Ok(())
}
