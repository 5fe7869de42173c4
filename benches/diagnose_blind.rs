//! A blind, randomised benchmark of `diagnose` on valves of two families it does not share.
//!
//! Draws valves from the physical model (`model = "physical"`, not the composed pin-cart valve
//! diagnosis fits) and from a digital positioner simulated apart from the project's models
//! (`valve_bridge::synth::digital`): healthy ones, ones with one effect of the vocabulary, and
//! ones with two, under five excitations (random steps, closed-loop level control, small
//! steps, ramps, a mix), three sensor-noise levels, with and without a fine sensor lattice.
//! Each valve is labelled from its physics by the thresholds in `benches/blind/cases.rs`, never
//! from what diagnosis finds, with the physical truth of each label's size; each 10-minute
//! recording at 100 Hz is diagnosed and scored (`benches/blind/score.rs`), every table for
//! each family apart (and for both together when both run).
//!
//! Run: `cargo bench --bench diagnose_blind -- [--seed N] [--cases N] [--family F]
//! [--only EFFECT|none] [--jsonl PATH] [--as-logged] [--materiality X] [--heldout-share Y]`
//! (also `VB_BLIND_SEED`, `VB_BLIND_CASES`; defaults seed 1, 220 physical valves plus the
//! broadened healthy class: 33 healthy valves in closed loop under a noisy controller, then
//! half as many digital ones, 110 and 16). `--family physical|digital|all` (default all) runs
//! one family or both; the physical family's valves are those of the same seed before the
//! digital one was added. `--as-logged` diagnoses each recording as
//! the daemon logs it (per mille, 0.5 % of the rows without V_P in bursts of 1-3);
//! `--materiality` and `--heldout-share` set the [`diagnose::Tuning`] thresholds; `--stride K`
//! runs every K-th valve of the plan (the same valves as the full run's, by index).
//! `--jsonl` writes one JSON line per case (physics, labels with their truth, findings with
//! their sizes, scores, the diagnosis's wall time and its CPU time in all threads) for
//! analysis; `--case N` runs only the case of that index; `--csv DIR`
//! also writes each case's recording (`case-N.csv`) and its truth (`case-N.truth.json`: the
//! labels, their truth and the valve's parameters; for the physical family also its model
//! file `case-N.toml`), so `valve-bridge diagnose DIR/case-N.csv` repeats it; `--write-only`
//! with `--csv` writes the cases without diagnosing them.

#[path = "blind/cases.rs"]
mod cases;
#[path = "blind/score.rs"]
mod score;

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use serde_json::json;
use valve_bridge::diagnose::{self, Effect};
use valve_bridge::report::diagnose as report;

struct Options {
    seed: u64,
    cases: usize,
    /// The family to run, or both.
    family: Option<cases::Family>,
    only: Option<Option<Effect>>,
    case: Option<usize>,
    jsonl: Option<PathBuf>,
    csv: Option<PathBuf>,
    write_only: bool,
    as_logged: bool,
    tuning: diagnose::Tuning,
    stride: usize,
}

fn env_number(name: &str) -> Result<Option<u64>, String> {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .map(Some)
            .map_err(|_| format!("{name}={v}: expected a whole number")),
        Err(_) => Ok(None),
    }
}

fn options() -> Result<Options, String> {
    let mut o = Options {
        seed: env_number("VB_BLIND_SEED")?.unwrap_or(1),
        cases: env_number("VB_BLIND_CASES")?.map_or(cases::PLAN_VALVES, |n| n as usize),
        family: None,
        only: None,
        case: None,
        jsonl: None,
        csv: None,
        write_only: false,
        as_logged: false,
        tuning: diagnose::Tuning::default(),
        stride: 1,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |what: &str| args.next().ok_or(format!("{a} needs {what}"));
        match a.as_str() {
            "--seed" => {
                o.seed = value("a number")?
                    .parse()
                    .map_err(|_| "--seed: expected a whole number".to_string())?
            }
            "--cases" => {
                o.cases = value("a number")?
                    .parse()
                    .map_err(|_| "--cases: expected a whole number".to_string())?
            }
            "--family" => {
                let v = value("physical, digital or all")?;
                o.family = match v.as_str() {
                    "all" => None,
                    name => Some(
                        (cases::Family::ALL.into_iter())
                            .find(|f| f.name() == name)
                            .ok_or(format!("--family {name}: physical, digital or all"))?,
                    ),
                };
            }
            "--only" => {
                let v = value("an effect name or `none`")?;
                o.only = Some(if v == "none" {
                    None
                } else {
                    Some(v.parse::<Effect>()?)
                });
            }
            "--case" => {
                o.case = Some(
                    value("a case index")?
                        .parse()
                        .map_err(|_| "--case: expected a whole number".to_string())?,
                )
            }
            "--jsonl" => o.jsonl = Some(PathBuf::from(value("a file path")?)),
            "--csv" => o.csv = Some(PathBuf::from(value("a directory")?)),
            "--write-only" => o.write_only = true,
            "--as-logged" => o.as_logged = true,
            "--stride" => {
                o.stride = value("a number")?
                    .parse::<usize>()
                    .map_err(|_| "--stride: expected a whole number".to_string())?
                    .max(1)
            }
            "--materiality" => {
                o.tuning.materiality = value("a number")?
                    .parse()
                    .map_err(|_| "--materiality: expected a number".to_string())?
            }
            "--heldout-share" => {
                o.tuning.min_heldout_share = value("a number")?
                    .parse()
                    .map_err(|_| "--heldout-share: expected a number".to_string())?
            }
            // `cargo bench` passes `--bench` to every bench binary.
            "--bench" => {}
            other => {
                return Err(format!(
                    "unknown argument `{other}`: use --seed N, --cases N, --family F, --only EFFECT|none, --case N, --jsonl PATH, --csv DIR, --write-only, --as-logged, --materiality X, --heldout-share Y, --stride K"
                ))
            }
        }
    }
    Ok(o)
}

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("diagnose_blind: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let o = options()?;
    let mut plans = cases::plans(o.seed, o.cases);
    if let Some(family) = o.family {
        plans.retain(|p| p.family == family);
    }
    if let Some(only) = o.only {
        plans.retain(|p| match only {
            None => p.effects.is_empty(),
            Some(e) => p.effects.contains(&e),
        });
    }
    if let Some(index) = o.case {
        plans.retain(|p| p.index == index);
    }
    plans.retain(|p| p.index % o.stride == 0);
    if o.write_only && o.csv.is_none() {
        return Err("--write-only needs --csv DIR".into());
    }
    if let Some(dir) = &o.csv {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("--csv {}: cannot create: {e}", dir.display()))?;
    }
    let mut jsonl = match &o.jsonl {
        Some(path) => Some(
            std::fs::File::create(path)
                .map_err(|e| format!("--jsonl {}: cannot create: {e}", path.display()))?,
        ),
        None => None,
    };
    println!(
        "diagnose_blind: seed {}, {} valves, {} s at 100 Hz each{}; materiality x{}, held-out share {}",
        o.seed,
        plans.len(),
        cases::DURATION_S,
        if o.as_logged {
            ", as the daemon logs them (per mille, 0.5 % of rows without V_P)"
        } else {
            ""
        },
        o.tuning.materiality,
        o.tuning.min_heldout_share
    );
    let mut outcomes = Vec::new();
    for (k, plan) in plans.iter().enumerate() {
        let case =
            cases::build_as(plan, o.as_logged).map_err(|e| format!("case {}: {e}", plan.index))?;
        let rec = &case.rec;
        if let Some(dir) = &o.csv {
            write_case(dir, &case)?;
            if o.write_only {
                continue;
            }
        }
        let (started, cpu_started) = (Instant::now(), process_cpu_seconds()?);
        let d = diagnose::diagnose_with(&rec.view(), None, &o.tuning, &|_, _| {})
            .map_err(|e| format!("case {}: diagnose: {e}", plan.index))?;
        let seconds = started.elapsed().as_secs_f64();
        let cpu_seconds = process_cpu_seconds()? - cpu_started;
        let out = score::Outcome {
            family: plan.family.name(),
            excitation: plan.excitation,
            labels: case.labels.clone(),
            sizes: case.sizes.clone(),
            truth: case.truth.clone(),
            findings: d.findings.iter().map(|f| f.effect).collect(),
            sized: d.findings.iter().map(|f| (f.effect, f.size)).collect(),
            baseline_heldout_sse: d.baseline.heldout_sse,
            final_heldout_sse: d.final_model.heldout_sse,
            seconds,
            cpu_seconds,
            items: items(&d),
        };
        eprintln!(
            "{:>4}/{} case {:>3} {:<8} {:<13} noise {:.2} lattice {:.3} labels [{}] found [{}] gain {:>5.1} % {:.1} s ({:.1} s of CPU)",
            k + 1,
            plans.len(),
            plan.index,
            plan.family.name(),
            plan.excitation,
            case.noise_pct,
            case.lattice_pct,
            names(&out.labels),
            names(&out.findings),
            100.0 * out.gain(),
            seconds,
            cpu_seconds
        );
        if let Some(f) = jsonl.as_mut() {
            writeln!(f, "{}", json_line(&case, &d, &out))
                .map_err(|e| format!("--jsonl: cannot write: {e}"))?;
        }
        outcomes.push(out);
    }
    if o.write_only {
        return Ok(());
    }
    let mut groups: Vec<(&str, Vec<score::Outcome>)> = cases::Family::ALL
        .into_iter()
        .map(|f| {
            let of: Vec<score::Outcome> = (outcomes.iter())
                .filter(|x| x.family == f.name())
                .cloned()
                .collect();
            (f.name(), of)
        })
        .filter(|(_, of)| !of.is_empty())
        .collect();
    if groups.len() > 1 {
        groups.push(("all families", outcomes));
    }
    for (name, group) in &groups {
        report(name, group, o.tuning.min_heldout_share);
    }
    Ok(())
}

/// Every table over the valves of `group` (one family, or all).
fn report(name: &str, group: &[score::Outcome], share: f64) {
    println!("\n======== {name}: {} valves ========", group.len());
    score::print_confusion(group);
    score::print_precision_recall(group);
    score::print_smallest_found(group, &cases::EXCITATIONS);
    let mut excitations = cases::EXCITATIONS.to_vec();
    excitations.push(cases::NOISY_LOOP);
    score::print_curve(group, &excitations, share);
    score::print_coverage(group);
    score::print_overall(group);
}

/// The findings and traces of `d`, weighed (see [`score::Item`]).
fn items(d: &diagnose::Diagnosis) -> Vec<score::Item> {
    let findings = d.findings.iter().map(|f| score::Item {
        effect: f.effect,
        worth_low: f.size.worth_low,
        heldout_share: match f.measure {
            diagnose::Measure::HeldoutSse { before, after } => 1.0 - after / before.max(1e-12),
            diagnose::Measure::SlipDistance { .. } => 1.0,
        },
    });
    let traces = d.traces.iter().map(|t| score::Item {
        effect: t.effect,
        worth_low: t.size.worth_low,
        heldout_share: t.heldout_share,
    });
    findings.chain(traces).collect()
}

/// CPU time the process has used so far, in all its threads, s: what a diagnosis costs the
/// machine whatever the threads it runs on (the wall time depends on what else runs).
#[allow(unsafe_code)]
fn process_cpu_seconds() -> Result<f64, String> {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a timespec the call writes into; the clock is one every Linux has.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut t) };
    if rc != 0 {
        let e = std::io::Error::last_os_error();
        return Err(format!("cannot read the process's CPU clock: {e}"));
    }
    Ok(t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9)
}

/// The case's recording, truth and (physical family) model file, for the command line.
fn write_case(dir: &std::path::Path, case: &cases::Case) -> Result<(), String> {
    let stem = dir.join(format!("case-{}", case.plan.index));
    let csv = stem.with_extension("csv");
    valve_bridge::recording::write(&csv, &case.rec)
        .map_err(|e| format!("--csv: {}: {e}", csv.display()))?;
    let write = |ext: &str, text: String| {
        let path = stem.with_extension(ext);
        std::fs::write(&path, text).map_err(|e| format!("--csv: {}: {e}", path.display()))
    };
    if let cases::Physics::Physical(spec) = &case.physics {
        write("toml", spec.to_toml())?;
    }
    let mut truth = case_json(case);
    truth.insert("case".into(), json!(format!("case-{}", case.plan.index)));
    truth.insert(
        "effects".into(),
        json!(case.labels.iter().map(|e| e.name()).collect::<Vec<_>>()),
    );
    write("truth.json", serde_json::Value::Object(truth).to_string())
}

fn names(v: &[Effect]) -> String {
    v.iter().map(|e| e.name()).collect::<Vec<_>>().join(",")
}

/// What a case is: its plan, sensor, draws, labels with their truth, and its valve's
/// parameters (the physical model's, or the digital valve's).
fn case_json(case: &cases::Case) -> serde_json::Map<String, serde_json::Value> {
    let plan = &case.plan;
    let sizes: Vec<serde_json::Value> = case
        .sizes
        .iter()
        .map(|(e, s)| json!({"effect": e.name(), "size": s}))
        .collect();
    let truth: Vec<serde_json::Value> = case
        .truth
        .iter()
        .map(|t| json!({"effect": t.effect.name(), "name": t.name, "value": t.value}))
        .collect();
    let mut out: serde_json::Map<String, serde_json::Value> = [
        ("index", json!(plan.index)),
        ("seed", json!(plan.seed)),
        ("family", json!(plan.family.name())),
        ("excitation", json!(plan.excitation)),
        ("noise_pct", json!(case.noise_pct)),
        ("lattice_pct", json!(case.lattice_pct)),
        ("draws", json!(case.draws)),
        ("planned", json!(names(&plan.effects))),
        ("labels", json!(names(&case.labels))),
        ("sizes", json!(sizes)),
        ("truth", json!(truth)),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    match &case.physics {
        cases::Physics::Physical(spec) => {
            out.insert("dead_time_s".into(), json!(spec.dead_time_s));
            out.insert(
                "travel".into(),
                json!([spec.travel.min_pct, spec.travel.max_pct]),
            );
            out.insert("physical".into(), json!(spec.physical));
        }
        cases::Physics::Digital(params) => {
            out.insert("digital".into(), json!(params));
        }
    }
    out
}

/// One case as a JSON line: its physics, labels with their truth, findings with their sizes,
/// and scores.
fn json_line(case: &cases::Case, d: &diagnose::Diagnosis, out: &score::Outcome) -> String {
    let findings: Vec<serde_json::Value> = d
        .findings
        .iter()
        .map(|f| {
            json!({
                "effect": f.effect.name(),
                "params": f.params,
                "heldout_sse_before": f.heldout_sse_before,
                "heldout_sse_after": f.heldout_sse_after,
                "support": f.support,
                "alternatives": f.alternatives,
                "size": f.size,
                "measure": f.measure,
            })
        })
        .collect();
    let mut line = case_json(case);
    line.extend(
        [
            ("findings", json!(findings)),
            ("baseline_heldout_sse", json!(out.baseline_heldout_sse)),
            ("final_heldout_sse", json!(out.final_heldout_sse)),
            ("gain", json!(out.gain())),
            ("seconds", json!(out.seconds)),
            ("cpu_seconds", json!(out.cpu_seconds)),
            ("verdict", json!(report::verdict(d))),
            ("traces", json!(d.traces)),
            ("notes", json!(d.notes)),
        ]
        .map(|(k, v)| (k.to_string(), v)),
    );
    serde_json::Value::Object(line).to_string()
}
