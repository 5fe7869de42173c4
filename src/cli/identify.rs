//! `valve-bridge identify`: fit every model of the paper to a recording by simulation error and
//! print Table 1 (with held-out scores and AIC/BIC), Table 2 and the maintenance figures;
//! `--out` writes the fitted model files, the JSON and a self-contained HTML report.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::{json, Value};
use valve_bridge::fit::{self, windows::WindowList, Identification, Options};
use valve_bridge::metrics;
use valve_bridge::model::ModelKind;
use valve_bridge::recording::{self, Recording};
use valve_bridge::report;

use super::input::RecordingArgs;

/// Arguments of `valve-bridge identify`.
#[derive(clap::Args)]
pub struct Args {
    /// The recording to identify (t_s,op_pct,vp_pct; see --columns).
    recording: PathBuf,
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
pub fn run(args: Args) -> anyhow::Result<()> {
    let rec = recording::read(&args.recording, &args.read.options()?)?;
    let mut models = vec![ModelKind::Modelless, ModelKind::Delayed];
    for m in &args.models {
        if !models.contains(m) {
            models.push(*m);
        }
    }
    let opts = Options {
        models,
        windows: args.windows.map(|w| w.0),
        ..Options::default()
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
    let started = std::time::Instant::now();
    let id = fit::identify(&rec.t, &rec.op, &rec.vp, rec.sample_period, &opts, &tick)?;
    let elapsed = started.elapsed().as_secs_f64();
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    tracing::info!(seconds = elapsed, "identification done");
    let doc = to_json(&id, elapsed);
    if let Some(dir) = &args.out {
        write_out(dir, &rec, &id, &doc)?;
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&doc)?);
    } else {
        print_text(&rec, &id, elapsed);
    }
    Ok(())
}

/// A number for JSON: NaN and infinities become null.
fn num(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// The `--json` document (also written as `identify.json`).
fn to_json(id: &Identification, elapsed: f64) -> Value {
    let rows: Vec<Value> = id
        .rows
        .iter()
        .map(|r| {
            let params: serde_json::Map<String, Value> = r
                .params()
                .into_iter()
                .map(|(k, v, _)| (k.to_string(), num(v)))
                .collect();
            json!({
                "model": r.kind.tag(),
                "mae": num(r.scores.mae),
                "mae_filtered": if r.scores.filtered { num(r.scores.mae_filtered) } else { Value::Null },
                "r2": num(r.scores.r2),
                "sse": num(r.scores.sse),
                "rel_sse": num(r.scores.rel_sse),
                "heldout_sse": num(r.heldout.sse),
                "heldout_rel_sse": num(r.heldout.rel_sse),
                "aic": num(r.aic),
                "bic": num(r.bic),
                "n_params": r.n_params,
                "params": params,
                "figures": r.figures,
                "simulations": r.evals,
            })
        })
        .collect();
    json!({
        "n_samples": id.n_samples,
        "sample_period_s": id.sample_period_s,
        "windows": id.windows,
        "windows_auto": id.windows_auto,
        "n_scored": id.n_scored,
        "n_heldout": id.n_heldout,
        "split": id.split.describe(),
        "rows": rows,
        "steps": {
            "same_direction": id.steps.same,
            "reversal": id.steps.reversal,
            "reversal_poly": id.steps.reversal_poly,
            "pincart2_from_steps": id.steps.pincart2,
        },
        "elapsed_s": elapsed,
    })
}

fn write_out(dir: &Path, rec: &Recording, id: &Identification, doc: &Value) -> anyhow::Result<()> {
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
    write("identify.json", serde_json::to_string_pretty(doc)?)?;
    let html = write(
        "report.html",
        report::identify::identification_html(&rec.source, &rec.t, &rec.op, &rec.vp, id),
    )?;
    eprintln!(
        "wrote {} model files, identify.json and {} to {}",
        id.rows.len(),
        html.display(),
        dir.display()
    );
    Ok(())
}

fn opt(x: Option<f64>, digits: usize) -> String {
    x.filter(|v| v.is_finite())
        .map_or("-".into(), |v| format!("{v:.digits$}"))
}

fn print_text(rec: &Recording, id: &Identification, elapsed: f64) {
    println!(
        "{}: {} samples at {} s ({:.1} s)",
        rec.source,
        id.n_samples,
        id.sample_period_s,
        rec.duration()
    );
    let list: Vec<String> = id
        .windows
        .iter()
        .map(|w| format!("{:.2}-{:.2}", w.start_s, w.end_s))
        .collect();
    if id.windows_auto {
        println!(
            "windows (saturation at 0/100 % left out automatically; choose with --windows): {}",
            list.join(",")
        );
    } else {
        println!("windows (given): {}", list.join(","));
    }
    println!(
        "{} samples scored; held out: {} ({})",
        id.n_scored,
        id.n_heldout,
        id.split.describe()
    );
    print_steps_summary(&id.steps);
    println!("\nTable 1: free-run simulation error over the windows");
    println!("{}", metrics::table1_header());
    for r in &id.rows {
        println!("{}", metrics::table1_row(r.kind.display_name(), &r.scores));
    }
    println!(
        "\nHeld-out (fitted on the fit blocks only) and information criteria over the windows"
    );
    println!(
        "{:<20} {:>14} {:>10} {:>8} {:>14} {:>14}",
        "model", "held-out SSE", "Rel. SSE", "params", "AIC", "BIC"
    );
    for r in &id.rows {
        println!(
            "{:<20} {:>14.3} {:>9.2}% {:>8} {:>14.1} {:>14.1}",
            r.kind.display_name(),
            r.heldout.sse,
            100.0 * r.heldout.rel_sse,
            r.n_params,
            r.aic,
            r.bic
        );
    }
    println!("\nTable 2: fitted parameters");
    println!("{:<20} {:<6} parameters", "model", "count");
    for r in &id.rows {
        let p: Vec<String> = r
            .params()
            .iter()
            .map(|(k, v, u)| format!("{k} = {} {u}", fmt_param(*v)))
            .collect();
        println!(
            "{:<20} {:<6} {}",
            r.kind.display_name(),
            r.n_params,
            if p.is_empty() {
                "-".into()
            } else {
                p.join(", ")
            }
        );
    }
    println!("\nMaintenance figures of the fitted models (simulated tests around 50 %)");
    println!(
        "{:<20} {:>7} {:>14} {:>14} {:>9} {:>9} {:>10} {:>10} {:>10}",
        "model",
        "T_d s",
        "1% T63/T86 s",
        "10% T63/T86 s",
        "band %",
        "B_L/S %",
        "slip %",
        "open %/s",
        "close %/s"
    );
    for r in &id.rows {
        let f = &r.figures;
        println!(
            "{:<20} {:>7.3} {:>14} {:>14} {:>9.3} {:>9.3} {:>10.3} {:>10.1} {:>10.1}",
            r.kind.display_name(),
            f.dead_time_s,
            format!("{}/{}", opt(f.t63_small_s, 2), opt(f.t86_small_s, 2)),
            format!("{}/{}", opt(f.t63_large_s, 2), opt(f.t86_large_s, 2)),
            f.dead_band_pct,
            f.backlash_pct,
            f.stick_slip_pct,
            f.max_speed_open_pct_per_s,
            f.max_speed_close_pct_per_s
        );
    }
    let sims: usize = id.rows.iter().map(|r| r.evals).sum();
    println!("\nidentified in {elapsed:.2} s ({sims} full-length simulations equivalent)");
}

/// Prints the step-delay populations and the polynomial (shared with `steps`).
pub fn print_steps_summary(s: &fit::steps::StepAnalysis) {
    println!(
        "steps: {} found; delay to {:.0} % of the step: same direction {} ; reversal {}",
        s.steps.len(),
        100.0 * s.options_fraction,
        s.same,
        s.reversal
    );
    match (&s.reversal_poly, &s.pincart2) {
        (Some(p), Some(c)) => println!(
            "reversal delay = {} V² + {} V + {} s; pin-cart II crossing time: a_p = {}, b_p = {}, c_p = {} ({:.3}/{:.3}/{:.3} s at 0/50/100 %)",
            fmt_param(p.a),
            fmt_param(p.b),
            fmt_param(p.c),
            fmt_param(c.a_p),
            fmt_param(c.b_p),
            fmt_param(c.c_p),
            c.at_0_50_100_s[0],
            c.at_0_50_100_s[1],
            c.at_0_50_100_s[2]
        ),
        (Some(p), None) => println!(
            "reversal delay = {} V² + {} V + {} s (no same-direction steps: no pin-cart II seed)",
            fmt_param(p.a),
            fmt_param(p.b),
            fmt_param(p.c)
        ),
        _ => println!("reversal polynomial: not enough reversals (needs 5 spread over 10 % of travel)"),
    }
}

/// Four significant digits, scientific for very small or large magnitudes.
pub fn fmt_param(v: f64) -> String {
    if v != 0.0 && (v.abs() < 1e-3 || v.abs() >= 1e5) {
        format!("{v:.4e}")
    } else {
        format!("{v:.4}")
    }
}
