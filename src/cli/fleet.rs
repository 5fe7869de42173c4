//! `valve-bridge fleet`: diagnose every recording of a directory in parallel and rank the valves
//! for maintenance; `--out` gets the fleet page, `summary.csv`, `summary.json` and each valve's
//! own report.

use std::path::PathBuf;

use valve_bridge::fleet::{self, ValveMap};
use valve_bridge::vocabulary::Severity;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge fleet`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Directory of recordings (*.csv): one valve per file, or wide exports with --valves.
    dir: PathBuf,
    /// Write index.html, summary.csv, summary.json and valves/<valve>/ (report.html, model.toml,
    /// diagnosis.json) here.
    #[arg(long)]
    out: PathBuf,
    /// Column-mapping file (TOML) for wide exports: `time = "t_s"` and, under [valves], one
    /// `TAG = { op = "OP_COLUMN", vp = "VP_COLUMN" }` per valve.
    #[arg(long, conflicts_with = "columns")]
    valves: Option<PathBuf>,
    #[command(flatten)]
    read: RecordingArgs,
}

/// Diagnoses the fleet, writes its summaries and prints the ranking.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let map = args.valves.as_deref().map(ValveMap::load).transpose()?;
    let jobs = fleet::jobs(&args.dir, map.as_ref())?;
    let read = args.read.options()?;
    let bar = super::progress_bar(jobs.len() as u64, "diagnosing {bar:30} {pos}/{len} valves");
    let tick = |done: usize, _total: usize| {
        if let Some(b) = &bar {
            b.set_position(done as u64);
        }
    };
    let started = std::time::Instant::now();
    let f = fleet::run(&jobs, &read, Some(&args.out), &tick);
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let seconds = started.elapsed().as_secs_f64();
    let written = fleet::write(&args.out, &f)?;
    outln!(
        "fleet: {} valves diagnosed, {} failed, in {seconds:.1} s ({:.1} recordings per minute)",
        f.diagnosed,
        f.failed,
        jobs.len() as f64 * 60.0 / seconds.max(1e-9)
    )?;
    outln!(
        "{:>4}  {:<28} {:>8} {:>8}  {:>6} {:>8} {:>8} {:>8} {:>8}  findings",
        "rank",
        "valve",
        "severity",
        "priority",
        "T_d s",
        "rev. s",
        "band %",
        "open %/s",
        "close %/s"
    )?;
    let num = |v: Option<f64>, d: usize| v.map_or("-".to_string(), |v| format!("{v:.d$}"));
    for (i, v) in f.valves.iter().enumerate() {
        if let Some(e) = &v.error {
            outln!("{:>4}  {:<28} error: {e}", i + 1, v.valve)?;
            continue;
        }
        outln!(
            "{:>4}  {:<28} {:>8} {:>8.1}  {:>6} {:>8} {:>8} {:>8} {:>8}  {}",
            i + 1,
            v.valve,
            v.severity.map_or("none", Severity::name),
            v.priority,
            num(v.dead_time_s, 2),
            num(v.reversal_delay_s, 2),
            num(v.friction_band_pct, 2),
            num(v.stroke_speed_open_pct_per_s, 1),
            num(v.stroke_speed_close_pct_per_s, 1),
            if v.advice.is_empty() {
                "none".to_string()
            } else {
                let names: Vec<&str> = v.advice.iter().map(|a| a.name.as_str()).collect();
                names.join(", ")
            }
        )?;
    }
    let names: Vec<String> = written.iter().map(|p| p.display().to_string()).collect();
    errln!(
        "wrote {} and {} valve reports",
        names.join(", "),
        f.diagnosed
    );
    Ok(())
}
