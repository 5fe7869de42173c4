//! `valve-bridge steps`: the step-delay analysis of the paper's Section 4.1 (Figs. 5-7) on a
//! recording: delays of same-direction steps and reversals, the reversal polynomial against the
//! initial opening, and pin-cart II's a_p, b_p, c_p derived from it.

use std::path::PathBuf;

use valve_bridge::fit::steps::{self, StepOptions};
use valve_bridge::recording;

use super::identify::{fmt_param, print_steps_summary};
use super::input::RecordingArgs;

/// Arguments of `valve-bridge steps`.
#[derive(clap::Args)]
pub struct Args {
    /// The recording (t_s,op_pct,vp_pct; see --columns).
    recording: PathBuf,
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
pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.fraction > 0.0 && args.fraction < 1.0) {
        anyhow::bail!(
            "--fraction {}: must be between 0 and 1 (e.g. 0.1 for a tenth of the step)",
            args.fraction
        );
    }
    if !(args.min_size > 0.0 && args.min_hold > 0.0) {
        anyhow::bail!("--min-size and --min-hold must be positive");
    }
    let rec = recording::read(&args.recording, &args.read.options()?)?;
    if rec.vp.is_empty() {
        anyhow::bail!(
            "{} has no measured V_P column: step delays need it (map it with --columns vp=NAME)",
            rec.source
        );
    }
    let opts = StepOptions {
        min_size_pct: args.min_size,
        fraction: args.fraction,
        min_hold_s: args.min_hold,
    };
    let a = steps::analyse(&rec.op, &rec.vp, rec.sample_period, &opts);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&a)?);
        return Ok(());
    }
    println!(
        "{}: {} samples at {} s; V_P noise {:.3} % (sd)",
        rec.source,
        rec.len(),
        rec.sample_period,
        a.noise_pct
    );
    print_steps_summary(&a);
    if args.list {
        println!(
            "\n{:>10} {:>9} {:>9} {:>10} {:>9}",
            "t (s)", "from %", "step %", "direction", "delay s"
        );
        for s in &a.steps {
            println!(
                "{:>10.2} {:>9.2} {:>+9.2} {:>10} {:>9}",
                rec.t[0] + s.t_s,
                s.from_pct,
                s.size_pct,
                match s.reversal {
                    Some(true) => "reversal",
                    Some(false) => "same",
                    None => "first",
                },
                s.delay_s.map_or("-".into(), fmt_param)
            );
        }
    }
    Ok(())
}
