//! Generates the deterministic figures README and docs/ quote: diagnoses the nine shared
//! recordings (their table, and their fleet ranking as `valve-bridge fleet` makes it) and the
//! real DAMADICS one, identifies the paper-like one, runs the standard response test on the
//! emulated valve, writes the vocabulary's table and the blind bench's figures from its
//! records, runs the compensation bench's valves in process, then prints the generated blocks, or with `--write` puts each into its page
//! (`blocks::page`). Tests compare the pages with the same rows, made by this example's own
//! `blocks.rs` (`tests/analysis/diagnose_cases.rs`, `tests/analysis/fleet_cli.rs`,
//! `tests/analysis/identify_cli.rs`, `tests/analysis/response_test.rs`,
//! `tests/analysis/diagnose_blind_readme.rs`, `tests/analysis/compensation_trial.rs`; the
//! vocabulary in `tests.rs`), so a stale figure
//! fails CI.
//!
//! Run: `cargo run --example readme-figures -- [--write]` (a few minutes: the library is built
//! optimised in debug builds too, and the tests that check the pages are debug builds).
//!
//! Not here: how the rows are worded (`blocks.rs`).

// The checks of `blocks.rs` are the tests' (they include the file), not the generator's.
#[allow(dead_code)]
mod blocks;
// The blind bench's records and how its figures are made, shared with `benches/` (only the
// records' figures are used here; which plan they hold is the tests').
#[path = "../../benches/blind/cases.rs"]
mod cases;
#[allow(dead_code)]
#[path = "../../benches/blind/record.rs"]
mod record;
#[allow(dead_code)]
#[path = "../../benches/blind/score.rs"]
mod score;
#[cfg(test)]
mod tests;

use std::path::Path;

use anyhow::Context;
use valve_bridge::daemon::response::Test;
use valve_bridge::daemon::{Config, RunOptions};
use valve_bridge::fit::{self, Options};
use valve_bridge::fleet::{Fleet, Job, ValveSummary};
use valve_bridge::model::ModelKind;
use valve_bridge::recording::{self, ReadOptions};
use valve_bridge::report::diagnose;

fn main() -> anyhow::Result<()> {
    let write = std::env::args().skip(1).any(|a| a == "--write");
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let cases = root.join("tests/data/cases");
    let bar = indicatif::ProgressBar::new(blocks::CASES.len() as u64 + 1);
    let mut rows = vec![blocks::DIAGNOSE_HEADER.to_string()];
    let mut valves: Vec<ValveSummary> = Vec::new();
    for case in blocks::CASES {
        bar.set_message(case);
        let rec = recording::read(&cases.join(format!("{case}.csv")), &ReadOptions::default())?;
        let d = valve_bridge::diagnose::diagnose(&rec.view(), None, &|_, _| {})
            .with_context(|| format!("diagnosing {case}"))?;
        let truth_path = cases.join(format!("{case}.truth.json"));
        let truth: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(&truth_path)
                .with_context(|| format!("reading {}", truth_path.display()))?,
        )?;
        rows.push(blocks::diagnose_row(case, &truth, &diagnose::json(&d)));
        let job = Job {
            valve: case.to_string(),
            path: cases.join(format!("{case}.csv")),
            tag: None,
            columns: None,
        };
        valves.push(ValveSummary::of(&job, &rec, &d));
        bar.inc(1);
    }
    let ranking = blocks::fleet_table(&serde_json::to_value(Fleet::ranked(valves))?);
    let (path, _, columns) = blocks::REAL_CASE;
    let options = ReadOptions {
        columns: columns.parse()?,
        ..ReadOptions::default()
    };
    let rec = recording::read(&root.join("tests/data").join(path), &options)?;
    let d = valve_bridge::diagnose::diagnose(&rec.view(), None, &|_, _| {})
        .with_context(|| format!("diagnosing {path}"))?;
    let real = blocks::real_block(&diagnose::json(&d));
    let rec = recording::read(
        &cases.join(format!("{}.csv", blocks::TABLE1_CASE)),
        &ReadOptions::default(),
    )?;
    let models = [
        ModelKind::Fopdt,
        ModelKind::Stiction,
        ModelKind::Pincart1,
        ModelKind::Pincart2,
    ];
    let id = fit::identify(&rec.view(), &Options::for_models(&models), &|_, _| {})?;
    let table1 = blocks::table1(&serde_json::to_value(&id)?);
    let response = response_test(root)?;
    let compensation = blocks::compensation_block()?;
    bar.finish_and_clear();
    let blocks = [
        (blocks::DIAGNOSE_CASES, rows.join("\n")),
        (blocks::DIAGNOSE_REAL, real),
        (blocks::FLEET_CASES, ranking),
        (blocks::IDENTIFY_TABLE1, table1),
        (blocks::VOCABULARY, blocks::vocabulary_table()),
        (blocks::RESPONSE_EMULATED, response),
        (blocks::BLIND_BENCH, blind_bench(root)?),
        (blocks::COMPENSATION_BENCH, compensation),
    ];
    if write {
        for (name, content) in &blocks {
            let path = root.join(blocks::page(name));
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("reading {}", path.display()))?;
            let text = blocks::with_block(&text, name, content)
                .with_context(|| format!("{} has no block `{name}`", path.display()))?;
            std::fs::write(&path, text)?;
            eprintln!("wrote block `{name}` into {}", path.display());
        }
    } else {
        for (name, content) in &blocks {
            println!("<!-- generated: {name} -->\n{content}\n<!-- end generated -->\n");
        }
    }
    Ok(())
}

/// README's figures of the blind bench, from its records ([`record::README_RECORDS`]).
fn blind_bench(root: &Path) -> anyhow::Result<String> {
    let runs = (record::README_RECORDS.iter())
        .map(|(kind, path)| {
            let outcomes = record::read(&root.join(path)).map_err(anyhow::Error::msg)?;
            Ok((*kind, outcomes.into_iter().map(|(_, o)| o).collect()))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    Ok(record::readme_block(&runs))
}

/// README's response test: the standard plan on `config/emulated.toml`, as fast as possible.
fn response_test(root: &Path) -> anyhow::Result<String> {
    let path = root.join("config/emulated.toml");
    let test = Test::new(Config::load(Some(&path))?, &path, None, "standard")?;
    let (plan, setpoint_step) = (test.plan.clone(), test.setpoint_step_pct);
    let dir = tempfile::tempdir()?;
    let summary = test.run(
        false,
        RunOptions {
            log_dir: Some(dir.path().to_path_buf()),
            virtual_clock: true,
            ..RunOptions::default()
        },
    )?;
    let files: Vec<_> = (summary.valves.iter())
        .flat_map(|v| v.log.files.clone())
        .collect();
    let rec = recording::read_all(&files, &ReadOptions::default())?;
    let found = valve_bridge::response::analyse(&rec, &plan, setpoint_step)?;
    Ok(blocks::response_table(&serde_json::to_value(&found)?))
}
