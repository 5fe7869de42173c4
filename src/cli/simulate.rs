//! `valve-bridge simulate`: run a model over the O_P of a recording and score it.

use std::path::PathBuf;

use anyhow::Context;
use valve_bridge::fit::cost;
use valve_bridge::model::{ModelSpec, Valve};
use valve_bridge::recording;
use valve_bridge::{human, metrics};

use super::input::RecordingArgs;

/// Arguments of `valve-bridge simulate`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Model parameter file (TOML, e.g. config/models/pincart2.toml).
    #[arg(long)]
    model: PathBuf,
    /// Recording whose O_P drives the model: one file, or several (rotated logs) or a
    /// directory of them, joined in time order.
    #[arg(long, required = true, num_args = 1..)]
    input: Vec<PathBuf>,
    /// Where to write the simulated run (t_s,op_pct,vp_pct[,vp_meas_pct]).
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    read: RecordingArgs,
}

/// Simulates, writes the CSV and prints the Table 1 row against the measurement.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let spec = ModelSpec::load(&args.model)?;
    let rec = recording::read_all(&args.input, &args.read.options()?)?;
    // Built here for its error (a sample period the model cannot run at); the simulation
    // builds its own.
    Valve::new(&spec, rec.sample_period)
        .with_context(|| format!("building {}", args.model.display()))?;
    let sim = cost::simulate(&spec, &rec.view());
    let has_vp = !rec.vp.is_empty();
    let mut names = vec!["t_s", "op_pct", "vp_pct"];
    let mut cols: Vec<&[f64]> = vec![&rec.t, &rec.op, &sim];
    if has_vp {
        names.push("vp_meas_pct");
        cols.push(&rec.vp);
    }
    recording::write_columns(&args.out, &names, &cols)?;
    tracing::info!(
        samples = rec.op.len(),
        out = %args.out.display(),
        "simulated {} at {} s",
        spec.model.display_name(),
        human::num(rec.sample_period)
    );
    let measured: Vec<bool> = (0..rec.len()).map(|k| rec.view().has_vp(k)).collect();
    let s = metrics::scores_masked(&rec.vp, &sim, &rec.op, rec.sample_period, &measured);
    if has_vp && s.n > 0 {
        outln!("{}", metrics::table1_header())?;
        outln!("{}", metrics::table1_row(spec.model.display_name(), &s))?;
        out!("{}", metrics::table1_notes([&s]))?;
    } else {
        outln!("no measured V_P in {}: nothing to score", rec.source)?;
    }
    Ok(())
}
