//! `valve-bridge steps`: the step-delay analysis of the paper's Section 4.1 (Figs. 5-7) on a
//! recording: delays of same-direction steps and reversals, the reversal polynomial against the
//! initial opening, and pin-cart II's a_p, b_p, c_p derived from it.

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::metrics::steps::{self, StepOptions};
use valve_bridge::recording;
use valve_bridge::report::identify;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge steps`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The recording (t_s,op_pct,vp_pct; see --columns): one file, or several (rotated logs)
    /// or a directory of them, joined in time order.
    #[arg(required = true)]
    recording: Vec<PathBuf>,
    /// Share of the step V_P must have covered for the delay to end (0-1).
    #[arg(long, default_value_t = 0.1)]
    fraction: f64,
    /// Smallest O_P jump that counts as a step, %.
    #[arg(long, default_value_t = 0.5)]
    min_size: f64,
    /// Shortest hold of O_P after a jump, s.
    #[arg(long, default_value_t = 1.0)]
    min_hold: f64,
    /// Also list every step.
    #[arg(long)]
    list: bool,
    /// Print the analysis as JSON.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: RecordingArgs,
}

/// Runs the analysis and prints it.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let opts = StepOptions::new(args.min_size, args.fraction, args.min_hold)?;
    let rec = recording::read_all(&args.recording, &args.read.options()?)?;
    let a = steps::analyse_recording(&rec.view(), &opts).with_context(|| rec.source.clone())?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&a)?)?;
        return Ok(());
    }
    outln!(
        "{}: {} samples at {} s; V_P noise {:.3} % (sd)",
        rec.source,
        rec.len(),
        valve_bridge::human::num(rec.sample_period),
        a.noise_pct
    )?;
    out!("{}", identify::steps_summary(&a))?;
    if args.list {
        out!("\n{}", identify::steps_list(&a, rec.t[0]))?;
    }
    Ok(())
}
