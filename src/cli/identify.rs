//! `valve-bridge identify`: fit every model of the paper to a recording by simulation error and
//! print Table 1 (with held-out scores and AIC/BIC), Table 2 and the maintenance figures;
//! `--out` writes the fitted model files, the JSON and a self-contained HTML report.

use std::path::{Path, PathBuf};

use anyhow::Context;
use valve_bridge::fit::{self, windows::WindowList, Identification, Options};
use valve_bridge::model::ModelKind;
use valve_bridge::recording::{self, Recording};
use valve_bridge::report;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge identify`.
#[derive(clap::Args)]
pub(crate) struct Args {
    /// The recording to identify (t_s,op_pct,vp_pct; see --columns): one file, or several
    /// (rotated logs) or a directory of them, joined in time order.
    #[arg(required = true)]
    recording: Vec<PathBuf>,
    /// Models to fit, comma separated (modelless and delayed are always added as references).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "fopdt,stiction,pincart1,pincart2"
    )]
    models: Vec<ModelKind>,
    /// Fit and score only inside these windows, in seconds: `12.5-80,130-400`. Default: all
    /// samples except where the valve sits saturated at 0 or 100 % (and 2 s after).
    #[arg(long)]
    windows: Option<WindowList>,
    /// Write each fitted model as `<model>.toml`, `identify.json` and `report.html` here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print the results as JSON instead of tables.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    read: RecordingArgs,
}

/// Runs the identification and prints or writes the results.
pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let rec = recording::read_all(&args.recording, &args.read.options()?)?;
    let opts = Options {
        windows: args.windows.map(|w| w.0),
        ..Options::for_models(&args.models)
    };
    let bar = super::progress_bar(
        opts.models.len() as u64,
        "fitting {bar:30} {pos}/{len} models",
    );
    let tick = |done: usize, _total: usize| {
        if let Some(b) = &bar {
            b.set_position(done as u64);
        }
    };
    let id = fit::identify(&rec.view(), &opts, &tick)?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    tracing::info!(seconds = %format!("{:.2}", id.elapsed_s), "identification done");
    let doc = serde_json::to_string_pretty(&id)?;
    if let Some(dir) = &args.out {
        write_out(dir, &rec, &id, &doc)?;
    }
    if args.json {
        outln!("{doc}")?;
    } else {
        out!(
            "{}",
            report::identify::text(&rec.source, rec.duration(), &id)
        )?;
    }
    Ok(())
}

fn write_out(dir: &Path, rec: &Recording, id: &Identification, doc: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let write = |name: &str, text: String| -> anyhow::Result<PathBuf> {
        let p = dir.join(name);
        std::fs::write(&p, text).with_context(|| format!("cannot write {}", p.display()))?;
        Ok(p)
    };
    for r in &id.rows {
        let header = format!(
            "# Fitted by `valve-bridge identify` to {} ({} samples scored; SSE {:.4} %², held-out SSE {:.4} %²).\n",
            rec.source, r.scores.n, r.scores.sse, r.heldout.sse
        );
        write(
            &format!("{}.toml", r.kind.tag()),
            header + &r.spec.to_toml(),
        )?;
    }
    write("identify.json", doc.to_string())?;
    let html = write(
        "report.html",
        report::identify::html(&rec.source, &rec.view(), id),
    )?;
    errln!(
        "wrote {} model files, identify.json and {} to {}",
        id.rows.len(),
        html.display(),
        dir.display()
    );
    Ok(())
}
