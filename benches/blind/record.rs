//! A run of the blind bench as it was recorded (`--jsonl`: one line per valve), read back into
//! the [`Outcome`]s the tables are made of, and the figures README quotes from the records of
//! one seed diagnosed intact and as logged ([`readme_block`]): per family, the figures the
//! method is judged by, recall per excitation, and how often the 90 % intervals hold the
//! physical value.
//!
//! A run takes most of an hour on two cores, so README's figures come from its records:
//! `cargo run --example readme-figures -- --write` writes the block from [`README_RECORDS`],
//! and `tests/analysis/diagnose_blind_readme.rs` checks the block against them, that they hold
//! every valve of their plan, and that diagnosis today finds in some of those valves what the
//! records say. Times are left out: they are not the same twice.

use std::path::Path;

use serde_json::Value;
use valve_bridge::diagnose::{Effect, Size};

use crate::cases::{self, Truth};
use crate::score::{coverage, headline, Item, Outcome, Share};

/// The seed of the plan README's figures come from, and the stride of the valves diagnosed
/// (every third: 85 physical, 42 digital).
pub(crate) const README_SEED: u64 = 64;
pub(crate) const README_STRIDE: usize = 3;
/// The records of that run (relative to the checkout), intact and as logged:
/// `cargo bench --bench diagnose_blind -- --seed 64 --stride 3 [--as-logged] --jsonl PATH`.
pub(crate) const README_RECORDS: [(&str, &str); 2] = [
    ("intact", "benches/blind/results/seed-64.jsonl"),
    ("as logged", "benches/blind/results/seed-64-as-logged.jsonl"),
];

/// The [`Outcome`] of every line of the record at `path`, with the index of each valve.
pub(crate) fn read(path: &Path) -> Result<Vec<(usize, Outcome)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    (text.lines().enumerate())
        .map(|(k, line)| {
            let at = |e: String| format!("{} line {}: {e}", path.display(), k + 1);
            let v: Value = serde_json::from_str(line).map_err(|e| at(e.to_string()))?;
            let index = v["index"].as_u64().ok_or_else(|| at("no `index`".into()))?;
            Ok((index as usize, outcome(&v).map_err(at)?))
        })
        .collect()
}

/// A name the tables compare by, kept for the rest of the run: [`Outcome`] holds the names of
/// the bench's own code (`&'static str`), and a record has a few dozen distinct ones.
fn name(v: &Value) -> Result<&'static str, String> {
    let s = v.as_str().ok_or_else(|| format!("`{v}` is not a name"))?;
    Ok(Box::leak(s.to_string().into_boxed_str()))
}

fn effect(v: &Value) -> Result<Effect, String> {
    let s = v.as_str().unwrap_or_default();
    (Effect::ALL.into_iter())
        .find(|e| e.name() == s)
        .ok_or_else(|| format!("`{v}` is not an effect"))
}

/// A number of the record (`null` is what JSON makes of NaN).
fn number(v: &Value) -> Result<f64, String> {
    match v {
        Value::Null => Ok(f64::NAN),
        _ => v.as_f64().ok_or_else(|| format!("`{v}` is not a number")),
    }
}

fn size(v: &Value) -> Result<Size, String> {
    Ok(Size {
        name: name(&v["name"])?,
        unit: name(&v["unit"])?,
        value: number(&v["value"])?,
        low: number(&v["low"])?,
        // Without an upper end, `high` is infinite, `null` in JSON (a NaN size has no `low`).
        high: match (&v["low"], &v["high"]) {
            (Value::Number(_), Value::Null) => f64::INFINITY,
            (_, high) => number(high)?,
        },
        worth: number(&v["worth"])?,
        worth_low: number(&v["worth_low"])?,
    })
}

fn list(v: &Value) -> &[Value] {
    v.as_array().map_or(&[], Vec::as_slice)
}

/// One line of a record as the bench's [`Outcome`].
fn outcome(v: &Value) -> Result<Outcome, String> {
    let labels = (v["labels"].as_str().unwrap_or_default().split(','))
        .filter(|s| !s.is_empty())
        .map(|s| effect(&Value::from(s)))
        .collect::<Result<_, _>>()?;
    let sizes = (list(&v["sizes"]).iter())
        .map(|s| Ok((effect(&s["effect"])?, number(&s["size"])?)))
        .collect::<Result<_, String>>()?;
    let truth = (list(&v["truth"]).iter())
        .map(|t| {
            Ok(Truth {
                effect: effect(&t["effect"])?,
                name: name(&t["name"])?,
                value: number(&t["value"])?,
            })
        })
        .collect::<Result<_, String>>()?;
    let sized: Vec<(Effect, Size)> = (list(&v["findings"]).iter())
        .map(|f| Ok((effect(&f["effect"])?, size(&f["size"])?)))
        .collect::<Result<_, String>>()?;
    // A finding's share of the held-out error, as the bench weighs it (`items`).
    let shares = list(&v["findings"]).iter().map(|f| -> Result<f64, String> {
        let m = &f["measure"];
        match m["kind"].as_str() {
            Some("heldout_sse") => {
                Ok(1.0 - number(&m["after"])? / number(&m["before"])?.max(1e-12))
            }
            _ => Ok(1.0),
        }
    });
    let findings = sized.iter().zip(shares).map(|((e, s), share)| {
        Ok(Item {
            effect: *e,
            worth_low: s.worth_low,
            heldout_share: share?,
        })
    });
    let traces = list(&v["traces"]).iter().map(|t| {
        Ok(Item {
            effect: effect(&t["effect"])?,
            worth_low: number(&t["size"]["worth_low"])?,
            heldout_share: number(&t["heldout_share"])?,
        })
    });
    Ok(Outcome {
        family: name(&v["family"])?,
        excitation: name(&v["excitation"])?,
        labels,
        sizes,
        truth,
        findings: sized.iter().map(|(e, _)| *e).collect(),
        items: findings.chain(traces).collect::<Result<_, String>>()?,
        sized,
        baseline_heldout_sse: number(&v["baseline_heldout_sse"])?,
        final_heldout_sse: number(&v["final_heldout_sse"])?,
        seconds: number(&v["seconds"])?,
        cpu_seconds: number(&v["cpu_seconds"])?,
    })
}

fn share(s: Share) -> String {
    if s.den == 0 {
        return "-".into();
    }
    format!("{:.1} % ({} of {})", 100.0 * s.rate(), s.num, s.den)
}

fn of(s: Share) -> String {
    format!("{} of {}", s.num, s.den)
}

/// README's block: the figures of `runs` (each recording kind with its outcomes) per family and
/// for both, recall per excitation, and the coverage of the intervals per size.
pub(crate) fn readme_block(runs: &[(&str, Vec<Outcome>)]) -> String {
    let mut groups: Vec<(&str, &str, Vec<&Outcome>)> = Vec::new();
    for (kind, all) in runs {
        for family in cases::Family::ALL {
            let of: Vec<&Outcome> = all.iter().filter(|o| o.family == family.name()).collect();
            groups.push((family.name(), kind, of));
        }
        groups.push(("both", kind, all.iter().collect()));
    }
    let mut rows = vec![
        "| family | recording | valves | first finding right | precision | recall | healthy with a finding | deadband named stiction |".to_string(),
        "|---|---|---|---|---|---|---|---|".to_string(),
    ];
    for (family, kind, group) in &groups {
        let h = headline(group);
        rows.push(format!(
            "| {family} | {kind} | {} | {} | {} | {} | {} | {} |",
            group.len(),
            share(h.first),
            share(h.precision),
            share(h.recall),
            of(h.healthy_flagged),
            of(h.deadband_as_stiction),
        ));
    }
    rows.push(String::new());
    rows.push(format!(
        "| recall per excitation | recording | {} |",
        cases::EXCITATIONS.join(" | ")
    ));
    rows.push(format!(
        "|---|---|{}",
        "---|".repeat(cases::EXCITATIONS.len())
    ));
    for (family, kind, group) in &groups {
        let cells: Vec<String> = (cases::EXCITATIONS.iter())
            .map(|x| {
                let of: Vec<&Outcome> = group
                    .iter()
                    .copied()
                    .filter(|o| o.excitation == *x)
                    .collect();
                share(headline(&of).recall)
            })
            .collect();
        rows.push(format!("| {family} | {kind} | {} |", cells.join(" | ")));
    }
    rows.push(String::new());
    let kinds: Vec<&str> = runs.iter().map(|(k, _)| *k).collect();
    rows.push(format!(
        "| 90 % interval holds the drawn value (both families) | {} |",
        kinds.join(" | ")
    ));
    rows.push(format!("|---|{}", "---|".repeat(kinds.len())));
    for e in Effect::ALL {
        let cells: Vec<_> = runs.iter().map(|(_, all)| coverage(all, e)).collect();
        let Some(name) = cells.iter().flatten().map(|c| c.name).next() else {
            continue;
        };
        let cells: Vec<String> = (cells.iter())
            .map(|c| {
                c.as_ref().map_or("-".into(), |c| {
                    share(Share {
                        num: c.holds,
                        den: c.sized,
                    })
                })
            })
            .collect();
        rows.push(format!("| `{name}` | {} |", cells.join(" | ")));
    }
    rows.join("\n")
}
