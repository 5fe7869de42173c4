//! `valve-bridge response-test`: a response test of a configured valve. The daemon runs it
//! (`valve_bridge::daemon::response`: the plan as the loop's source, its checks, the log and the
//! stop action), the analysis reads the log (`valve_bridge::response`), and the report writes
//! `response.json`, `report.html` and `summary.txt` into `--out` (the log in `--out/log/`).
//! Wiring only; the exit code is 1 when the test did not run to its end or a spec line failed.

use std::path::{Path, PathBuf};

use anyhow::bail;
use valve_bridge::daemon::response::Test;
use valve_bridge::daemon::runtime::stats::StopReason;
use valve_bridge::daemon::{Analysis, Config, RunOptions};
use valve_bridge::recording::{self, ReadOptions};
use valve_bridge::report::{self, response as words};
use valve_bridge::response::{self, spec::Spec};

/// Arguments of `valve-bridge response-test`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// Daemon config (TOML): the valve to test and the range the test keeps to (its [source]
    /// op_min_pct..op_max_pct; the source itself is the plan).
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The valve to test, by `name`, in a config with several `[[valve]]` tables.
    #[arg(long, value_name = "NAME")]
    valve: Option<String>,
    /// Directory for the log (`log/`, which must not hold an earlier run's files),
    /// response.json, report.html and summary.txt.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// The plan: `standard` (25, 50 and 75 %), `quick` (50 % only) or a plan file (see
    /// config/response-plans/).
    #[arg(long, value_name = "standard|quick|FILE", default_value = "standard")]
    plan: String,
    /// Upper limits to check the figures against (see config/response-spec.toml); exit 1 when
    /// one fails.
    #[arg(long, value_name = "FILE")]
    spec: Option<PathBuf>,
    /// Move a real (Modbus) valve without asking first.
    #[arg(long)]
    yes: bool,
    /// Run on the virtual clock, as fast as possible (emulated valves only).
    #[arg(long)]
    as_fast_as_possible: bool,
}

/// Runs the test, writes and prints what it found; fails when it stopped early or the spec
/// failed.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let config = Config::load(Some(&args.config))?;
    let spec = args.spec.as_deref().map(Spec::load).transpose()?;
    let test = Test::new(config, &args.config, args.valve.as_deref(), &args.plan)?;
    let log_dir = args.out.join("log");
    refuse_earlier_run(&log_dir)?;
    let (plan, setpoint_step, valve) = (
        test.plan.clone(),
        test.setpoint_step_pct,
        test.valve.clone(),
    );
    let summary = test.run(
        args.yes,
        RunOptions {
            duration_s: None,
            log_dir: Some(log_dir),
            virtual_clock: args.as_fast_as_possible,
            progress: true,
            require_device: true,
            analysis: Analysis::default(),
        },
    )?;
    outln!("{summary}")?;
    summary.check()?;
    let files: Vec<PathBuf> = (summary.valves.iter())
        .flat_map(|v| v.log.files.clone())
        .collect();
    let rec = recording::read_all(&files, &ReadOptions::default())?;
    let found = response::analyse(&rec, &plan, setpoint_step)?;
    let lines = spec.as_ref().map(|s| s.check(&found)).unwrap_or_default();
    let text = words::text(&found, &lines);
    let title = format!("Response test of valve {valve} ({})", args.config.display());
    let json = words::json(&valve, &args.plan, &plan, &found, &lines);
    let written = report::write_files(
        &args.out,
        &[
            ("response.json", serde_json::to_string_pretty(&json)?),
            ("report.html", words::html(&title, &rec, &found, &lines)),
            ("summary.txt", text.clone()),
        ],
    )?;
    out!("\n{text}")?;
    for p in written {
        outln!("wrote {}", p.display())?;
    }
    if summary.reason != StopReason::SourceEnded {
        bail!(
            "the test stopped before the end of its plan ({}): the figures cover the {} of {} steps it made",
            summary.reason,
            found.steps.len(),
            found.planned_steps
        );
    }
    let failed = lines.iter().filter(|l| !l.pass).count();
    if failed > 0 {
        bail!(
            "{failed} of the {} lines of the spec failed (see above)",
            lines.len()
        );
    }
    Ok(())
}

/// Refuses a log directory that holds files already: their rows would be read as this test's.
fn refuse_earlier_run(dir: &Path) -> anyhow::Result<()> {
    let held = match std::fs::read_dir(dir) {
        Ok(mut entries) => entries.next().is_some(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => false,
        Err(e) => bail!("{}: cannot read: {e}", dir.display()),
    };
    if held {
        bail!(
            "{}: holds an earlier run's files, which would be read as this test's: give --out a new directory",
            dir.display()
        );
    }
    Ok(())
}
