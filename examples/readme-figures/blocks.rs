//! The deterministic figures README and docs/ quote, generated from the tool's own `--json`
//! documents: the table of the shared recordings' diagnoses ([`diagnose_row`]), the fleet
//! ranking of the same recordings ([`fleet_table`], from `summary.json`), identify's Table 1 on
//! the paper-like recording ([`table1`]), the vocabulary's words ([`vocabulary_table`]), the
//! standard response test of the emulated valve ([`response_table`], from its `response.json`),
//! and the marked blocks of the pages that hold them (`<!-- generated: NAME -->` ...
//! `<!-- end generated -->`, each block in the page [`page`] names).
//!
//! `main.rs` prints them or writes them into their pages ([`REGENERATE`]); the tests that
//! already diagnose and identify those recordings include this file (`#[path]`) and compare the
//! pages' blocks with them ([`check_line`], [`check_block`]), so no recording is analysed twice
//! for it and the rows have one implementation.
//!
//! Not here: the analyses themselves.

use serde_json::Value;

use valve_bridge::compensate::CompensationConfig;
use valve_bridge::compensation_trial::bench::{bench_valve, lineup, models, table, BenchError};
use valve_bridge::metrics::{table1_cells, Scores};
use valve_bridge::model::ModelKind;
use valve_bridge::report::verdict::{num, size_text};

/// The command that regenerates the blocks.
pub(crate) const REGENERATE: &str = "cargo run --example readme-figures -- --write";

/// The page (relative to the checkout) that holds block `name`.
pub(crate) fn page(name: &str) -> &'static str {
    match name {
        DIAGNOSE_CASES | DIAGNOSE_REAL | VOCABULARY => "docs/diagnosis.md",
        FLEET_CASES => "docs/fleet.md",
        COMPENSATION_BENCH => "docs/compensation.md",
        _ => "README.md",
    }
}

/// The shared recordings (`tests/data/cases/`) in the order of the diagnoses' table.
pub(crate) const CASES: [&str; 9] = [
    "pub_clean_rs",
    "pub_backlash_rs",
    "pub_backlash_normal_op",
    "pub_asym_rs",
    "pub_slew_mixed",
    "pub_sdd_paper_rs",
    "pub_deadtime_mixed",
    "pub_sdd_rs",
    "pub_stiction_normal_op",
];

/// The block of the diagnoses of [`CASES`].
pub(crate) const DIAGNOSE_CASES: &str = "diagnose-cases";
/// The block of the diagnosis of the real recording [`REAL_CASE`].
pub(crate) const DIAGNOSE_REAL: &str = "diagnose-real";
/// The real recording of [`DIAGNOSE_REAL`]: its path under `tests/data/`, its name in the table
/// and its column mapping (`--columns`).
pub(crate) const REAL_CASE: (&str, &str, &str) = (
    "real/damadics-actuator3-1h/actuator3_2001-10-11_1h_1Hz.csv",
    "DAMADICS actuator 3",
    "t=t_s,op=LC74_20CV_pct,vp=LC74_20X_pct",
);
/// The block of identify's Table 1 on [`TABLE1_CASE`].
pub(crate) const IDENTIFY_TABLE1: &str = "identify-table1";
/// The recording of identify's Table 1 (README).
pub(crate) const TABLE1_CASE: &str = "pub_sdd_paper_rs";

/// The block of the fleet ranking of [`CASES`].
pub(crate) const FLEET_CASES: &str = "fleet-cases";
/// The block of the vocabulary's words.
pub(crate) const VOCABULARY: &str = "vocabulary";
/// The block of the blind bench's figures (`benches/blind/record.rs`).
pub(crate) const BLIND_BENCH: &str = "blind-bench";
/// The block of the compensation bench's valves in process: their models and the table.
pub(crate) const COMPENSATION_BENCH: &str = "compensation-bench";
/// The seeds of each scenario of [`COMPENSATION_BENCH`] (`cargo bench --bench compensation
/// -- --seeds 3` prints the same).
const COMPENSATION_SEEDS: u64 = 3;

/// The compensation bench's models and table, as `cargo bench --bench compensation` prints
/// them (default settings).
pub(crate) fn compensation_block() -> Result<String, BenchError> {
    let kick_share = CompensationConfig::default().kick_share;
    let valves = (lineup().into_iter())
        .map(|entry| bench_valve(entry, kick_share))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(format!(
        "{}\n\n{}",
        models(&valves),
        table(&valves, COMPENSATION_SEEDS)?
    ))
}

/// The fleet ranking of a `summary.json` document `summary` as a Markdown table: rank, valve,
/// severity, priority, what is wrong (each finding's plain name and what it does) and what to
/// do first (the first clause of the highest-priority finding's action).
pub(crate) fn fleet_table(summary: &Value) -> String {
    let mut o = String::from(
        "| rank | valve | severity | priority | what is wrong | to do first |\n|---|---|---|---|---|---|\n",
    );
    let valves = summary["valves"].as_array().cloned().unwrap_or_default();
    for (i, v) in valves.iter().enumerate() {
        let advice = v["advice"].as_array().cloned().unwrap_or_default();
        let text = |a: &Value, key: &str| a[key].as_str().unwrap_or("").to_string();
        let wrong: Vec<String> = (advice.iter())
            .map(|a| format!("{} {}", text(a, "name"), text(a, "does")))
            .collect();
        let first = advice.first().map_or(String::new(), |a| text(a, "action"));
        o += &format!(
            "| {} | {} | {} | {:.1} | {} | {} |\n",
            i + 1,
            v["valve"].as_str().unwrap_or("?"),
            v["severity"].as_str().unwrap_or("none"),
            v["priority"].as_f64().unwrap_or(f64::NAN),
            if wrong.is_empty() {
                "nothing worth maintenance".to_string()
            } else {
                wrong.join("; ")
            },
            first.split(';').next().unwrap_or("")
        );
    }
    o.trim_end().to_string()
}

/// The vocabulary as a Markdown table: each effect's name in the JSON, its plain name, what it
/// does to control, the weight of that consequence in a finding's priority, and what to do.
pub(crate) fn vocabulary_table() -> String {
    use valve_bridge::model::composed::Effect;
    use valve_bridge::vocabulary::words;
    let mut o = String::from(
        "| effect (JSON) | plain name | what it does to control | weight | what to do |\n|---|---|---|---|---|\n",
    );
    for e in Effect::ALL {
        let w = words(e);
        o += &format!(
            "| `{}` | {} | {} | {} | {} |\n",
            e.name(),
            w.plain,
            w.control,
            w.consequence.weight(),
            w.action
        );
    }
    o.trim_end().to_string()
}

/// The block of the standard response test of `config/emulated.toml`, as fast as possible.
pub(crate) const RESPONSE_EMULATED: &str = "response-emulated";

/// The head of the diagnoses' table.
pub(crate) const DIAGNOSE_HEADER: &str =
    "| case | truth | found | measure before → after |\n|---|---|---|---|";

/// The row of `case` in the diagnoses' table, from its `truth.json` and its `diagnose --json`
/// document `d`.
pub(crate) fn diagnose_row(case: &str, truth: &Value, d: &Value) -> String {
    let truth: Vec<&str> = (truth["effects"].as_array().into_iter().flatten())
        .filter_map(Value::as_str)
        .collect();
    let truth = if truth.is_empty() {
        "—".to_string()
    } else {
        truth.join(", ")
    };
    row(case, &truth, d)
}

/// The block of the diagnosis of [`REAL_CASE`], from its `diagnose --json` document `d`: the
/// diagnoses' table with its one row, whose truth no one knows.
pub(crate) fn real_block(d: &Value) -> String {
    format!(
        "{DIAGNOSE_HEADER}\n{}",
        row(REAL_CASE.1, "not known (a real plant)", d)
    )
}

/// A row of the diagnoses' table: `case`, what is known of its truth, what `d` found.
fn row(case: &str, truth: &str, d: &Value) -> String {
    let findings = d["findings"].as_array().cloned().unwrap_or_default();
    let f64_of = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let found: Vec<String> = (findings.iter())
        .map(|f| {
            let s = &f["size"];
            let by_slips = f["measure"]["kind"] == "slip_distance";
            format!(
                "{}{}: {}",
                f["effect"].as_str().unwrap_or("?"),
                if by_slips { " (by its slips)" } else { "" },
                size_text(
                    s["name"].as_str().unwrap_or(""),
                    f64_of(&s["value"]),
                    f64_of(&s["low"]),
                    // `null`: the size has no upper end.
                    s["high"].as_f64().unwrap_or(f64::INFINITY)
                )
            )
        })
        .collect();
    let slips = (findings.iter()).find(|f| f["measure"]["kind"] == "slip_distance");
    let measure = match slips {
        Some(f) => format!(
            "slip-histogram distance ({}) {} → {}",
            if f["measure"]["heldout"] == true {
                "held-out pieces"
            } else {
                "whole recording"
            },
            num(f64_of(&f["measure"]["before"])),
            num(f64_of(&f["measure"]["after"]))
        ),
        None => format!(
            "held-out SSE {} → {}",
            num(f64_of(&d["baseline"]["heldout_sse"])),
            num(f64_of(&d["final"]["heldout_sse"]))
        ),
    };
    format!(
        "| {case} | {truth} | {} | {measure} |",
        if found.is_empty() {
            "— (nothing worth maintenance)".to_string()
        } else {
            found.join("; ")
        }
    )
}

/// identify's Table 1 of the `identify --json` document `doc` as a Markdown table (with the
/// held-out Rel. SSE), then pin-cart II's speed limit and the reversal delay its step
/// analysis fits, at 20 % and 95 % opening.
pub(crate) fn table1(doc: &Value) -> String {
    let mut o = String::from(
        "| model | MAE | MAE filtered | R² | SSE (%²) | Rel. SSE | held-out Rel. SSE | samples |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for r in doc["rows"].as_array().into_iter().flatten() {
        let kind: Option<ModelKind> = r["model"].as_str().and_then(|m| m.parse().ok());
        let scores = serde_json::from_value::<Scores>(r.clone()).ok();
        let held = serde_json::from_value::<Scores>(r["heldout"].clone()).ok();
        let (Some(kind), Some(scores), Some(held)) = (kind, scores, held) else {
            continue;
        };
        let [mae, filtered, r2, sse, rel, n] = table1_cells(&scores);
        o += &format!(
            "| {} | {mae} | {filtered} | {r2} | {sse} | {rel} | {} | {n} |\n",
            kind.display_name(),
            table1_cells(&held)[4]
        );
    }
    let rows = doc["rows"].as_array().cloned().unwrap_or_default();
    let pincart2 = rows.iter().find(|r| r["model"] == "pincart2");
    if let Some(slew) = pincart2.and_then(|r| r["params"]["dy_max_pct_per_s"].as_f64()) {
        o += &format!("\nPin-cart II's speed limit: {} %/s.", num(slew));
    }
    let poly = &doc["steps"]["reversal_poly"];
    if let (Some(a), Some(b), Some(c)) =
        (poly["a"].as_f64(), poly["b"].as_f64(), poly["c"].as_f64())
    {
        let at = |v: f64| (a * v + b) * v + c;
        o += &format!(
            " Reversal delay (the polynomial `steps` fits): {} s at 20 % opening, {} s at 95 %.",
            num(at(20.0)),
            num(at(95.0))
        );
    }
    o.trim_end().to_string()
}

/// The opening marker of block `name`.
fn opening(name: &str) -> String {
    format!("<!-- generated: {name} -->")
}

/// The closing marker of every block.
const CLOSING: &str = "<!-- end generated -->";

/// The text between the markers of block `name` in `text`, trimmed.
pub(crate) fn block<'a>(text: &'a str, name: &str) -> Option<&'a str> {
    let start = text.find(&opening(name))? + opening(name).len();
    let end = start + text[start..].find(CLOSING)?;
    Some(text[start..end].trim())
}

/// `text` with block `name` holding `content`; `None` without the block's markers.
pub(crate) fn with_block(text: &str, name: &str, content: &str) -> Option<String> {
    let start = text.find(&opening(name))? + opening(name).len();
    let end = start + text[start..].find(CLOSING)?;
    Some(format!(
        "{}\n{}\n{}",
        &text[..start],
        content.trim(),
        &text[end..]
    ))
}

/// Checks that block `name` of `text` (the text of its [`page`]) holds the line starting with
/// `prefix` as `want`; the error names the page, the difference and the command that
/// regenerates the block.
pub(crate) fn check_line(text: &str, name: &str, prefix: &str, want: &str) -> Result<(), String> {
    let page = page(name);
    let Some(b) = block(text, name) else {
        return Err(format!(
            "{page} has no block `{}` ... `{CLOSING}`",
            opening(name)
        ));
    };
    match b.lines().find(|l| l.starts_with(prefix)) {
        Some(l) if l == want => Ok(()),
        Some(l) => Err(format!(
            "{page}'s block `{name}` is stale:\n  page:      {l}\n  generated: {want}\nregenerate it with `{REGENERATE}`"
        )),
        None => Err(format!(
            "{page}'s block `{name}` has no line starting `{prefix}`; it should read\n  {want}\nregenerate it with `{REGENERATE}`"
        )),
    }
}

/// The worst figures per step size and the signature of a response test, from its
/// `response.json` document `r`.
pub(crate) fn response_table(r: &Value) -> String {
    let secs = |v: &Value| v.as_f64().map_or("-".into(), |v| format!("{v:.2} s"));
    let pct = |v: &Value| v.as_f64().map_or("-".into(), |v| format!("{v:.2} %"));
    let side = |w: &Value| {
        format!(
            "{}, {}, {}/{}",
            secs(&w["dead_time_s"]),
            secs(&w["t86_s"]),
            w["resolved"],
            w["steps"]
        )
    };
    let mut rows = vec![
        "| step | opening: worst dead time, T86, resolved | closing: the same |".to_string(),
        "|---|---|---|".to_string(),
    ];
    for s in r["summary"].as_array().into_iter().flatten() {
        rows.push(format!(
            "| {} % | {} | {} |",
            s["size_pct"].as_f64().unwrap_or(f64::NAN),
            side(&s["open"]),
            side(&s["close"])
        ));
    }
    let g = &r["signature"];
    rows.push(String::new());
    rows.push(format!(
        "Signature: dead band {}, hysteresis {}, resolution {}.",
        pct(&g["dead_band_pct"]),
        pct(&g["hysteresis_pct"]),
        pct(&g["resolution_pct"])
    ));
    rows.join("\n")
}

/// Checks that block `name` of `text` (the text of its [`page`]) is `want`, naming the first
/// line that differs.
pub(crate) fn check_block(text: &str, name: &str, want: &str) -> Result<(), String> {
    let have = block(text, name).unwrap_or("");
    if have == want.trim() {
        return Ok(());
    }
    let (mut h, mut w) = (have.lines(), want.trim().lines());
    loop {
        match (h.next(), w.next()) {
            (a, b) if a != b => {
                return Err(format!(
                    "{}'s block `{name}` is stale:\n  page:      {}\n  generated: {}\nregenerate it with `{REGENERATE}`",
                    page(name),
                    a.unwrap_or("(nothing)"),
                    b.unwrap_or("(nothing)")
                ))
            }
            (None, None) => return Ok(()),
            _ => {}
        }
    }
}
