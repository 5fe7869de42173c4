//! The compensation bench: does compensation built from an identified model help the valve it
//! was identified from, and an independent physical valve, in closed and open loop?
//!
//! Each valve first records 15 minutes of its own log and a model is identified from it, as a
//! user would: the pin-cart II valve (`config/models/pincart2.toml`) by `identify` (pin-cart II
//! on the paper's random steps), the physical valves (`model = "physical"`: healthy, with a
//! Coulomb friction band of 1, 1.5 and 3 %, and with a 0.6 % positioner deadband) by
//! `diagnose` on the mixed excitation (random steps, ramps, small steps); the 1.5 % valve once
//! more by `identify` on its random steps. Then every scenario runs 10 minutes with and without the
//! compensator of that model (default `[valve.compensation]` settings), for several seeds:
//! the paper's level loop, the paper's random steps, and small steps. Figures per run:
//! `valve_bridge::compensation_trial::Figures`.
//!
//! Then foreign valves over Modbus ([`modbus`]): physical valves with physics the model
//! `diagnose` fits does not have, each a unit of sim-device, logging 200 s of their own small
//! steps through `valve-bridge run`, diagnosed by `valve-bridge diagnose` from that log, and run
//! without compensation, with it and the default guard, and with it while the guard does not
//! judge, in real time: small steps, and the sequence of closing and opening moves.
//!
//! Run: `cargo bench --bench compensation -- [--seeds N] [--kick-share S] [--plot PATH]
//! [--modbus-log-s S] [--modbus-run-s S] [--no-modbus | --modbus-only]` (default 3 seeds and
//! the default `kick_share`; shares above the config's limit of 1 are taken, to show why there
//! is one; over Modbus a 200 s log and 200 s runs of small steps). It writes the SVG of a
//! reversal of the 1.5 % valve with and without compensation to PATH (default
//! `target/compensation-bench/reversal.svg`), and the set-point sent to `PATH-kick.svg`; the
//! Modbus part's files go to `target/compensation-bench/modbus/`.

use std::path::{Path, PathBuf};
use std::time::Instant;

#[path = "compensation/modbus.rs"]
mod modbus;

use valve_bridge::compensate::{CompensationConfig, Compensator};
use valve_bridge::compensation_trial::bench::{
    bench_valve, lineup, models, table, BenchValve, DT, RUN_S,
};
use valve_bridge::compensation_trial::{self as trial, Scenario};
use valve_bridge::model::ModelSpec;
use valve_bridge::report::plot::{self, Series};

type Error = Box<dyn std::error::Error>;

/// Where the bench writes what it makes unless told otherwise.
fn work_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("target/compensation-bench")
}

/// What the command line asks for.
struct Args {
    seeds: u64,
    kick_share: f64,
    plot: PathBuf,
    /// The Modbus part's log and runs, s (None: not run).
    modbus: Option<(f64, f64)>,
    /// Run the valves in process (`--modbus-only`: not).
    in_process: bool,
}

fn options() -> Result<Args, Error> {
    let mut out = Args {
        seeds: 3,
        kick_share: CompensationConfig::default().kick_share,
        plot: work_dir().join("reversal.svg"),
        modbus: Some((200.0, 200.0)),
        in_process: true,
    };
    let secs = |a: Option<String>, name: &str| -> Result<f64, Error> {
        let s: f64 = a.ok_or(format!("{name} needs seconds"))?.parse()?;
        (s >= 30.0)
            .then_some(s)
            .ok_or_else(|| format!("{name}: at least 30 s").into())
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seeds" => {
                let n: u64 = args.next().ok_or("--seeds needs a number")?.parse()?;
                out.seeds = n.max(1);
            }
            "--kick-share" => {
                out.kick_share = args.next().ok_or("--kick-share needs a number")?.parse()?;
            }
            "--plot" => out.plot = PathBuf::from(args.next().ok_or("--plot needs a path")?),
            "--modbus-log-s" => {
                let s = secs(args.next(), "--modbus-log-s")?;
                out.modbus = out.modbus.map(|m| (s, m.1));
            }
            "--modbus-run-s" => {
                let s = secs(args.next(), "--modbus-run-s")?;
                out.modbus = out.modbus.map(|m| (m.0, s));
            }
            "--no-modbus" => out.modbus = None,
            "--modbus-only" => out.in_process = false,
            "--bench" => {}
            other => return Err(format!("unknown argument `{other}`").into()),
        }
    }
    Ok(out)
}

/// The compensator of the model file `path`, default settings.
fn compensator(path: &Path) -> Result<Compensator, Error> {
    let cfg = CompensationConfig {
        model_file: Some(path.to_path_buf()),
        ..CompensationConfig::default()
    };
    Ok(Compensator::new(
        &cfg,
        &ModelSpec::load(path)?,
        DT,
        (0.0, 100.0),
    )?)
}

/// The SVG of the first reversal of the small steps after a minute, with and without.
fn reversal_plot(b: &BenchValve, path: &PathBuf) -> Result<(), Error> {
    let plain = trial::run(&b.valve, None, Scenario::SmallSteps, RUN_S, DT, 1)?;
    let comped = trial::run(
        &b.valve,
        Some(b.compensator.clone()),
        Scenario::SmallSteps,
        RUN_S,
        DT,
        1,
    )?;
    let nominal = valve_bridge::model::Valve::new(&trial::nominal(&b.valve), DT)?
        .simulate(&comped.op, comped.op[0]);
    // The first reversal after a minute whose step is at most 0.6 %: small reversals are
    // where the band costs most time.
    let op = &comped.op;
    let mut last_dir = 0.0;
    let mut at = None;
    for k in 6000..op.len() - 400 {
        let d = op[k] - op[k - 1];
        if d != 0.0 {
            if last_dir != 0.0 && d.signum() != last_dir && d.abs() <= 0.6 {
                at = Some(k);
                break;
            }
            last_dir = d.signum();
        }
    }
    let k = at.ok_or("no reversal in the small steps")?;
    let t: Vec<f64> = (0..op.len()).map(|i| i as f64 * DT).collect();
    let window = k - 30..k + 120;
    let series = |name, y, color| Series { name, y, color };
    let positions = plot::lines(
        &format!(
            "{}: a reversal of the controller's O_P, with and without compensation",
            b.name
        ),
        "%",
        "t, s",
        &t,
        &[
            series("O_P (controller)", op, plot::MEASURED),
            series("V_P without compensation", &plain.vp, plot::BEFORE),
            series("V_P with compensation", &comped.vp, plot::AFTER),
            series("V_P of the healthy twin", &nominal, plot::EXTRA),
        ],
        window.clone(),
    );
    let kick = plot::lines(
        "the set-point sent: the controller's O_P and the kick",
        "%",
        "t, s",
        &t,
        &[
            series("O_P (controller)", op, plot::MEASURED),
            series("set-point sent (compensated)", &comped.sent, plot::AFTER),
        ],
        window,
    );
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, positions)?;
    let kick_path = path.with_file_name(format!(
        "{}-kick.svg",
        path.file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("reversal")
    ));
    std::fs::write(&kick_path, kick)?;
    eprintln!("wrote {}", kick_path.display());
    eprintln!("wrote {}", path.display());
    Ok(())
}

fn main() -> Result<(), Error> {
    let Args {
        seeds,
        kick_share,
        plot: plot_path,
        modbus: modbus_secs,
        in_process,
    } = options()?;
    if in_process {
        in_process_part(seeds, kick_share, &plot_path)?;
    }
    if let Some(secs) = modbus_secs {
        let outcome = modbus::run(&work_dir().join("modbus"), secs, &|what| {
            eprintln!("{what}")
        })?;
        modbus_tables(&outcome, secs);
    }
    Ok(())
}

/// The valves in process: their models, the table and the plot.
fn in_process_part(seeds: u64, kick_share: f64, plot_path: &PathBuf) -> Result<(), Error> {
    let mut valves = Vec::new();
    for entry in lineup() {
        let started = Instant::now();
        let b = bench_valve(entry, kick_share)?;
        eprintln!(
            "{}: model in {:.1} s; compensates {}",
            b.name,
            started.elapsed().as_secs_f64(),
            b.compensator.describe()
        );
        valves.push(b);
    }
    println!("{}", models(&valves));
    println!();
    println!("{}", table(&valves, seeds)?);
    let b = valves
        .iter()
        .find(|b| b.name.contains("1.5 %"))
        .ok_or("no 1.5 % valve")?;
    reversal_plot(b, plot_path)?;
    Ok(())
}

/// `a → b (±c %)`.
fn pct_change(a: f64, b: f64) -> String {
    let c = if a > 0.0 { 100.0 * (b / a - 1.0) } else { 0.0 };
    format!("{b:.3} ({c:+.0} %)")
}

/// What the guard did in a run.
fn guard_cell(f: &modbus::Figures) -> String {
    match &f.switched_off {
        None => "on".into(),
        Some((t, why)) if why.is_empty() => format!("off at {t:.1} s"),
        Some((t, why)) => format!("off at {t:.1} s ({why})"),
    }
}

/// The Modbus part's tables: per valve and model, without, with the guard and with the guard
/// not judging.
fn modbus_tables(o: &modbus::Outcome, (log_s, run_s): (f64, f64)) {
    println!();
    println!("Over Modbus (sim-device in real time, foreign valves), models diagnosed from each valve's own {log_s:.0} s small-step log:");
    for (name, d) in o.names.iter().zip(&o.described) {
        println!("- {name}: {d}");
    }
    let rows = table_rows(o);
    small_steps_table(o, &rows, run_s);
    sequence_table(o, &rows);
}

/// The tables' rows: `valve | model` and the cases without, with the guard and with the guard
/// not judging. The cases come in threes but for the healthy valve given another's model,
/// whose "without" is the healthy valve's own.
fn table_rows(o: &modbus::Outcome) -> Vec<(String, [usize; 3])> {
    use modbus::Variant;
    let find = |valve: usize, model: usize, v: Variant| {
        (o.cases.iter()).position(|c| c.valve == valve && c.model == model && c.variant == v)
    };
    let mut pairs: Vec<(usize, usize)> = o.cases.iter().map(|c| (c.valve, c.model)).collect();
    pairs.dedup();
    pairs
        .into_iter()
        .filter_map(|(valve, model)| {
            let idx = [
                find(valve, valve, Variant::Without)?,
                find(valve, model, Variant::Guarded)?,
                find(valve, model, Variant::Unguarded)?,
            ];
            let whose = if valve == model {
                "its own".to_string()
            } else {
                format!("the {} valve's", o.names[model])
            };
            Some((format!("{} | {whose}", o.names[valve]), idx))
        })
        .collect()
}

/// The small steps' table.
fn small_steps_table(o: &modbus::Outcome, rows: &[(String, [usize; 3])], run_s: f64) {
    println!();
    println!("Small steps, {run_s:.0} s (seed 1): tracking error of the stem against its healthy twin, % RMS; travel and reversals of the stem through 0.1 %");
    println!();
    println!("| valve | model | without | with the guard | guard not judging | travel, % | reversals | rows that read a V_P | the guard |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for (label, [a, g, u]) in rows {
        let (a, g, u) = (&o.small[*a], &o.small[*g], &o.small[*u]);
        println!(
            "| {label} | {:.3} | {} | {} | {:.1} / {:.1} / {:.1} | {} / {} / {} | {} / {} / {} of {} | {} |",
            a.tracking_pct,
            pct_change(a.tracking_pct, g.tracking_pct),
            pct_change(a.tracking_pct, u.tracking_pct),
            a.travel.travel_pct,
            g.travel.travel_pct,
            u.travel.travel_pct,
            a.travel.reversals,
            g.travel.reversals,
            u.travel.reversals,
            a.read.0,
            g.read.0,
            u.read.0,
            a.read.1,
            guard_cell(g),
        );
    }
}

/// The sequence's table.
fn sequence_table(o: &modbus::Outcome, rows: &[(String, [usize; 3])]) {
    println!();
    println!(
        "The sequence {:?} % twice, each level held {:.0} s: holds whose stem ends within {} % of the target, and the ends (stem - target, %)",
        trial::SEQUENCE, trial::SEQUENCE_HOLD_S, trial::SEQUENCE_TOLERANCE_PCT
    );
    println!();
    println!("| valve | model | without | with the guard | guard not judging | ends with the guard | the guard |");
    println!("|---|---|---|---|---|---|---|");
    let within = |f: &modbus::Figures| {
        let n = (f.ends.iter())
            .filter(|e| e.abs() <= trial::SEQUENCE_TOLERANCE_PCT)
            .count();
        format!("{n} of {}", f.ends.len())
    };
    for (label, [a, g, u]) in rows {
        let (a, g, u) = (&o.sequence[*a], &o.sequence[*g], &o.sequence[*u]);
        let ends: Vec<String> = g.ends.iter().map(|e| format!("{e:+.2}")).collect();
        println!(
            "| {label} | {} | {} | {} | {} | {} |",
            within(a),
            within(g),
            within(u),
            ends.join(" "),
            guard_cell(g),
        );
    }
}
