//! The generator's own tests: rows made from `--json` documents, blocks found, replaced and
//! checked, and the pages holding every block (the figures themselves are checked by the tests
//! that run the analyses: `tests/analysis/diagnose_cases.rs`, `tests/analysis/identify_cli.rs`,
//! `tests/analysis/response_test.rs`, `tests/analysis/fleet_cli.rs`).

use serde_json::json;

use crate::blocks::*;

#[test]
fn rows_are_made_from_the_json_documents() {
    let d = json!({
        "baseline": {"heldout_sse": 16032.4},
        "final": {"heldout_sse": 1542.2},
        "findings": [{"effect": "backlash", "measure": {"kind": "heldout_sse"},
            "size": {"name": "friction_band_pct", "value": 5.83, "low": 5.63, "high": 5.83}}]
    });
    let truth = json!({"effects": ["backlash"]});
    assert_eq!(
        diagnose_row("pub_backlash_rs", &truth, &d),
        "| pub_backlash_rs | backlash | backlash: friction band 5.83 % (5.63-5.83) | held-out SSE 16032 → 1542 |"
    );
    let none = json!({"baseline": {"heldout_sse": 683.0}, "final": {"heldout_sse": 683.0}, "findings": []});
    assert_eq!(
        diagnose_row("c", &json!({"effects": []}), &none),
        "| c | — | — (nothing worth maintenance) | held-out SSE 683 → 683 |"
    );
}

#[test]
fn blocks_are_found_replaced_and_checked() {
    let readme = "a\n<!-- generated: t -->\n| x | 1 |\n| y | 2 |\n<!-- end generated -->\nb\n";
    assert_eq!(block(readme, "t"), Some("| x | 1 |\n| y | 2 |"));
    let new = with_block(readme, "t", "| x | 1 |\n| y | 3 |").unwrap();
    assert_eq!(
        new,
        "a\n<!-- generated: t -->\n| x | 1 |\n| y | 3 |\n<!-- end generated -->\nb\n"
    );
    assert!(check_line(readme, "t", "| x |", "| x | 1 |").is_ok());
    let e = check_line(readme, "t", "| y |", "| y | 3 |").unwrap_err();
    assert!(e.contains("| y | 2 |") && e.contains("| y | 3 |") && e.contains(REGENERATE));
    assert!(check_block(readme, "t", "| x | 1 |\n| y | 2 |").is_ok());
    assert!(check_block(&new, "t", "| x | 1 |\n| y | 2 |").is_err());
    assert!(check_line(readme, "missing", "| x |", "").is_err());
}

/// The text of the page that holds block `name`.
fn page_of(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(page(name));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The pages hold the blocks, the diagnoses' with its head and a row for every case (each
/// row's figures are checked where its case is diagnosed: `tests/analysis/diagnose_cases.rs`).
#[test]
fn the_pages_have_the_generated_blocks() {
    let text = page_of(DIAGNOSE_CASES);
    let cases = block(&text, DIAGNOSE_CASES).expect("no diagnose-cases block");
    assert!(cases.starts_with(DIAGNOSE_HEADER), "{cases}");
    let rows: Vec<&str> = cases.lines().skip(2).collect();
    assert_eq!(rows.len(), CASES.len(), "{cases}");
    for (row, case) in rows.iter().zip(CASES) {
        assert!(row.starts_with(&format!("| {case} |")), "{row}");
    }
    let text = page_of(IDENTIFY_TABLE1);
    assert!(block(&text, IDENTIFY_TABLE1).is_some_and(|b| b.contains("| Pin-cart II |")));
    let text = page_of(FLEET_CASES);
    let fleet = block(&text, FLEET_CASES).expect("no fleet-cases block");
    assert_eq!(fleet.lines().count(), 2 + CASES.len(), "{fleet}");
}

/// The quoted vocabulary is the table's (each ranking's figures are checked where the fleet
/// runs: `tests/analysis/fleet_cli.rs`).
#[test]
fn the_vocabulary_quoted_is_the_tables() {
    if let Err(e) = check_block(&page_of(VOCABULARY), VOCABULARY, &vocabulary_table()) {
        panic!("{e}");
    }
}

#[test]
fn a_fleet_summary_is_a_ranking_table() {
    let summary = json!({"valves": [
        {"valve": "a", "severity": "high", "priority": 58.25, "advice": [
            {"name": "lost motion (backlash)", "does": "loses 5.83 % (5.69-5.86) of travel on every reversal",
             "action": "check the packing; tighten"}]},
        {"valve": "b", "severity": null, "priority": 0.0, "advice": []}
    ]});
    assert_eq!(
        fleet_table(&summary),
        "| rank | valve | severity | priority | what is wrong | to do first |\n|---|---|---|---|---|---|\n\
         | 1 | a | high | 58.2 | lost motion (backlash) loses 5.83 % (5.69-5.86) of travel on every reversal | check the packing |\n\
         | 2 | b | none | 0.0 | nothing worth maintenance |  |"
    );
}
