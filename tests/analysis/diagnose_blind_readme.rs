//! README's figures of the blind bench (`benches/blind/record.rs`): the block is the one its
//! records make, the records hold every valve of their plan as the plan draws it, and
//! diagnosis today finds in valves of those records, rebuilt from the plan, what the records
//! say. A change to diagnosis that alters what it finds makes the records stale: rerun the
//! bench into them (the commands are in `record.rs`) and regenerate README.

use std::path::Path;

use crate::blocks;
use crate::cases::{self, build_as, plans, Plan};
use crate::record::{self, README_RECORDS, README_SEED, README_STRIDE};
use crate::score::Outcome;
use valve_bridge::diagnose;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Each record, with its kind (`intact`, `as logged`).
fn records() -> Vec<(&'static str, Vec<(usize, Outcome)>)> {
    (README_RECORDS.iter())
        .map(|(kind, path)| (*kind, record::read(&root().join(path)).unwrap()))
        .collect()
}

/// The valves of README's run: every [`README_STRIDE`]-th of the seed's plan.
fn plan() -> Vec<Plan> {
    let mut all = plans(README_SEED, cases::PLAN_VALVES);
    all.retain(|p| p.index % README_STRIDE == 0);
    all
}

#[test]
fn readme_quotes_the_figures_of_the_records() {
    let runs: Vec<(&str, Vec<Outcome>)> = (records().into_iter())
        .map(|(kind, r)| (kind, r.into_iter().map(|(_, o)| o).collect()))
        .collect();
    let want = record::readme_block(&runs);
    let page = std::fs::read_to_string(root().join(blocks::page(blocks::BLIND_BENCH))).unwrap();
    if let Err(e) = blocks::check_block(&page, blocks::BLIND_BENCH, &want) {
        panic!("{e}");
    }
}

#[test]
fn the_records_hold_every_valve_of_their_plan() {
    let plan = plan();
    for (kind, record) in records() {
        assert_eq!(record.len(), plan.len(), "{kind}");
        for ((index, o), p) in record.iter().zip(&plan) {
            assert_eq!(*index, p.index, "{kind}");
            assert_eq!(o.family, p.family.name(), "{kind}, valve {index}");
            assert_eq!(o.excitation, p.excitation, "{kind}, valve {index}");
            let mut planned: Vec<_> = o.sizes.iter().map(|(e, _)| *e).collect();
            planned.sort_by_key(|e| *e as usize);
            let mut want = p.effects.clone();
            want.sort_by_key(|e| *e as usize);
            assert_eq!(planned, want, "{kind}, valve {index}");
            // docs/diagnosis-bench.md quotes the CPU time of these diagnoses.
            assert!(o.cpu_seconds > 0.0, "{kind}, valve {index}: no CPU time");
        }
    }
}

/// The first valve of each family with an effect, in each record: diagnosed today, it gets the
/// findings its record holds, of the same sizes.
#[test]
fn diagnosis_today_finds_what_the_records_say() {
    let plan = plan();
    for ((kind, record), as_logged) in records().into_iter().zip([false, true]) {
        for family in cases::Family::ALL {
            let (index, o) = (record.iter())
                .find(|(_, o)| o.family == family.name() && !o.labels.is_empty())
                .unwrap();
            let p = plan.iter().find(|p| p.index == *index).unwrap();
            let case = build_as(p, as_logged).unwrap();
            let d = diagnose::diagnose(&case.rec.view(), None, &|_, _| {}).unwrap();
            let today: Vec<_> = d
                .findings
                .iter()
                .map(|f| (f.effect, f.size.value))
                .collect();
            let recorded: Vec<_> = o.sized.iter().map(|(e, s)| (*e, s.value)).collect();
            assert_eq!(
                today.len(),
                recorded.len(),
                "{kind}, valve {index}: {today:?} against {recorded:?}"
            );
            for ((e, v), (re, rv)) in today.iter().zip(&recorded) {
                assert!(
                    e == re && (v - rv).abs() <= 1e-9 * rv.abs(),
                    "{kind}, valve {index}: diagnosis today finds {today:?}, the record {recorded:?}; rerun the bench into {}",
                    README_RECORDS.iter().map(|(_, p)| *p).collect::<Vec<_>>().join(" and ")
                );
            }
        }
    }
}
