//! `valve-bridge fleet` as a real binary: a directory of recordings (one valve each, one file
//! that is not a recording) and a wide export with a column-mapping file are diagnosed, ranked,
//! and written as a page, CSV and JSON summaries and one report per valve; the per-valve
//! diagnosis is the one `valve-bridge diagnose --json` gives. The shared recordings rank by
//! consequence for the process as the generated table of `docs/fleet.md` says, the valves whose findings
//! make a loop cycle (stick-slip, the large friction bands) first, each finding in the
//! vocabulary's words.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

// The generator of the figures README and docs/ quote: the example's own code, one implementation.
use crate::blocks;

fn case(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/cases")
        .join(name)
}

fn run(args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_valve-bridge"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn json(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn the_shared_recordings_rank_by_consequence_as_readme_says() {
    let out = tempfile::tempdir().unwrap();
    let cases = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cases");
    run(&[
        "fleet",
        cases.to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
    ]);
    let summary = json(&out.path().join("summary.json"));
    let page = blocks::page(blocks::FLEET_CASES);
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join(page)).unwrap();
    let table = blocks::fleet_table(&summary);
    if let Err(e) = blocks::check_block(&text, blocks::FLEET_CASES, &table) {
        panic!("{e}");
    }
    let valves = summary["valves"].as_array().unwrap();
    let top: Vec<&str> = valves[..3]
        .iter()
        .map(|v| v["valve"].as_str().unwrap())
        .collect();
    for hunting in [
        "pub_stiction_normal_op",
        "pub_backlash_rs",
        "pub_sdd_paper_rs",
    ] {
        assert!(
            top.contains(&hunting),
            "{hunting} not in the top three: {table}"
        );
    }
    // Each valve's priority is the sum of its findings', in the vocabulary's words and units.
    for v in valves {
        let advice = v["advice"].as_array().unwrap();
        let sum: f64 = advice.iter().map(|a| a["priority"].as_f64().unwrap()).sum();
        assert!((v["priority"].as_f64().unwrap() - sum).abs() < 1e-9, "{v}");
        assert_eq!(advice.len(), v["findings"].as_array().unwrap().len(), "{v}");
        for a in advice {
            let text = format!(
                "{} {} {} {}",
                a["name"], a["does"], a["control"], a["action"]
            );
            assert!(!text.contains('_') && !text.contains("%²"), "{text}");
            assert!(
                [" % (", " s (", " %/s (", " times ("]
                    .iter()
                    .any(|u| a["does"].as_str().unwrap().contains(u)),
                "{a}"
            );
        }
    }
    let verdicts: Vec<&str> = valves
        .iter()
        .map(|v| v["verdict"].as_str().unwrap())
        .collect();
    assert!(
        verdicts
            .iter()
            .all(|t| !t.contains("%²") && !t.contains("_")),
        "{verdicts:?}"
    );
}

#[test]
fn a_directory_of_recordings_is_ranked_with_a_report_per_valve() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    for f in ["pub_clean_rs.csv", "pub_asym_rs.csv"] {
        std::fs::copy(case(f), dir.path().join(f)).unwrap();
    }
    std::fs::write(dir.path().join("notes.csv"), "when,who\n1,me\n").unwrap();
    let o = run(&[
        "fleet",
        dir.path().to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.starts_with("fleet: 2 valves diagnosed, 1 failed"),
        "{stdout}"
    );

    let s = json(&out.path().join("summary.json"));
    let valves = s["valves"].as_array().unwrap();
    let names: Vec<&str> = valves
        .iter()
        .map(|v| v["valve"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["pub_asym_rs", "pub_clean_rs", "notes"], "{s}");
    let asym = &valves[0];
    assert_eq!(asym["findings"], serde_json::json!(["asymmetry"]));
    let (open, close) = (
        asym["stroke_speed_open_pct_per_s"].as_f64().unwrap(),
        asym["stroke_speed_close_pct_per_s"].as_f64().unwrap(),
    );
    assert!(open > 1.5 * close && close < 40.0, "{open} {close}");
    assert!(asym["attention"].as_f64().unwrap() > 1.0);
    assert_eq!(valves[1]["findings"], serde_json::json!([]));
    assert_eq!(valves[1]["attention"].as_f64(), Some(0.0));
    for v in &valves[..2] {
        for k in ["dead_time_s", "reversal_delay_s", "friction_band_pct"] {
            assert!(v[k].as_f64().is_some_and(|x| x >= 0.0), "{k}: {v}");
        }
    }
    let err = valves[2]["error"].as_str().unwrap();
    assert!(err.contains("notes.csv:1: no column"), "{err}");

    // The per-valve files are `diagnose --out`'s, linked from the page and the CSV.
    let report = asym["report"].as_str().unwrap();
    assert_eq!(report, "valves/pub_asym_rs/report.html");
    assert!(out.path().join(report).is_file());
    let page = std::fs::read_to_string(out.path().join("index.html")).unwrap();
    assert!(page.contains(&format!("<a href=\"{report}\">pub_asym_rs</a>")));
    assert!(page.contains("Not diagnosed"));
    let csv = std::fs::read_to_string(out.path().join("summary.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert!(rows[0].starts_with("rank,valve,attention,findings,dead_time_s"));
    assert!(rows[1].starts_with("1,pub_asym_rs,"), "{}", rows[1]);
    assert!(rows[1].contains(",valves/pub_asym_rs/report.html,"));
    assert_eq!(rows.len(), 4);

    let fleet_diag = json(&out.path().join("valves/pub_asym_rs/diagnosis.json"));
    let alone = run(&[
        "diagnose",
        dir.path().join("pub_asym_rs.csv").to_str().unwrap(),
        "--json",
    ]);
    let alone: Value = serde_json::from_slice(&alone.stdout).unwrap();
    assert_eq!(
        fleet_diag, alone,
        "fleet and diagnose give the same diagnosis"
    );
}

/// Two valves side by side, 40 s each, in one historian export: the healthy valve's columns
/// `A_OP`, `A_PV` and the slow-closing one's `B_OP`, `B_PV`, each prefix as given.
fn wide_export(path: &Path, a_prefix: &str, b_prefix: &str) {
    let read = |f: &str| std::fs::read_to_string(case(f)).unwrap();
    let (a, b) = (read("pub_clean_rs.csv"), read("pub_asym_rs.csv"));
    let mut wide = format!("time,{a_prefix}_OP,{a_prefix}_PV,{b_prefix}_OP,{b_prefix}_PV\n");
    for (la, lb) in a.lines().zip(b.lines()).skip(1).take(4000) {
        let (ca, cb): (Vec<&str>, Vec<&str>) = (la.split(',').collect(), lb.split(',').collect());
        wide.push_str(&format!(
            "{},{},{},{},{}\n",
            ca[0], ca[1], ca[2], cb[1], cb[2]
        ));
    }
    std::fs::write(path, wide).unwrap();
}

#[test]
fn a_wide_export_is_split_by_the_mapping_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    wide_export(&dir.path().join("export.csv"), "FV1", "FV2");
    let map = out.path().join("valves.toml");
    std::fs::write(
        &map,
        "time = \"time\"\n[valves]\nFV1 = { op = \"FV1_OP\", vp = \"FV1_PV\" }\nFV2 = { op = \"FV2_OP\", vp = \"FV2_PV\" }\nFV3 = { op = \"FV3_OP\", vp = \"FV3_PV\" }\n",
    )
    .unwrap();
    let fleet_out = out.path().join("fleet");
    run(&[
        "fleet",
        dir.path().to_str().unwrap(),
        "--out",
        fleet_out.to_str().unwrap(),
        "--valves",
        map.to_str().unwrap(),
    ]);
    let s = json(&fleet_out.join("summary.json"));
    let valves = s["valves"].as_array().unwrap();
    let find = |n: &str| valves.iter().find(|v| v["valve"] == n).unwrap();
    assert_eq!(find("FV1")["samples"].as_u64(), Some(4000));
    assert!(find("FV2")["source"]
        .as_str()
        .unwrap()
        .ends_with("export.csv [FV2]"));
    assert!(fleet_out.join("valves/FV2/report.html").is_file());
    let e = find("FV3")["error"].as_str().unwrap();
    assert!(e.contains("no column `FV3_OP`, `FV3_PV`"), "{e}");
    assert_eq!(
        (s["diagnosed"].as_u64(), s["failed"].as_u64()),
        (Some(2), Some(1))
    );
}

#[test]
fn tags_that_collide_or_name_paths_each_get_a_folder_and_a_link_of_their_own() {
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    wide_export(&dir.path().join("export.csv"), "A", "B");
    // The slow-closing valve (B) under tags that were once one folder with the healthy one's
    // (A), or the output directory itself, or its parent.
    let tags = [
        ("FV 101", "A"),
        ("FV/101", "B"),
        ("fv 101", "A"),
        ("..", "B"),
        (".", "A"),
        ("", "B"),
        ("/etc", "A"),
    ];
    let mut map = String::from("time = \"time\"\n[valves]\n");
    for (tag, c) in tags {
        map += &format!("{tag:?} = {{ op = \"{c}_OP\", vp = \"{c}_PV\" }}\n");
    }
    let map_file = out.path().join("valves.toml");
    std::fs::write(&map_file, map).unwrap();
    let fleet = out.path().join("fleet");
    run(&[
        "fleet",
        dir.path().to_str().unwrap(),
        "--out",
        fleet.to_str().unwrap(),
        "--valves",
        map_file.to_str().unwrap(),
    ]);

    let s = json(&fleet.join("summary.json"));
    let valves = s["valves"].as_array().unwrap();
    assert_eq!(s["diagnosed"].as_u64(), Some(7), "{s}");
    let page = std::fs::read_to_string(fleet.join("index.html")).unwrap();
    let mut folders = std::collections::BTreeSet::new();
    let mut diagnoses = std::collections::BTreeMap::new();
    for (tag, c) in tags {
        let v = valves
            .iter()
            .find(|v| {
                v["source"]
                    .as_str()
                    .unwrap()
                    .ends_with(&format!("export.csv [{tag}]"))
            })
            .unwrap();
        let (name, report) = (v["valve"].as_str().unwrap(), v["report"].as_str().unwrap());
        // One folder of `valves/`, named like no other but for case.
        let folder = report
            .strip_prefix("valves/")
            .and_then(|r| r.strip_suffix("/report.html"))
            .unwrap();
        assert_eq!(folder, name);
        assert!(
            !folder.contains('/') && !folder.trim_matches('.').is_empty(),
            "{folder}"
        );
        assert!(folders.insert(folder.to_lowercase()), "{folder} twice");
        // The page links the valve to the report of its own tag, which shows its own data.
        assert!(
            page.contains(&format!("<a href=\"{report}\">{name}</a>")),
            "{name}"
        );
        let html = std::fs::read_to_string(fleet.join(report)).unwrap();
        let source = v["source"].as_str().unwrap();
        assert!(
            html.contains(&format!("<h1>Diagnosis: {source}</h1>")),
            "{tag}"
        );
        let d = json(&fleet.join(format!("valves/{folder}/diagnosis.json")));
        let first = diagnoses.entry(c).or_insert_with(|| d.clone());
        assert_eq!(
            *first, d,
            "{tag}: the diagnosis of the columns {c}_OP, {c}_PV"
        );
    }
    assert_ne!(diagnoses["A"], diagnoses["B"]);
    // Nothing was written beside the fleet's own files, or above them.
    let mut top: Vec<String> = std::fs::read_dir(&fleet)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    top.sort();
    assert_eq!(top, ["index.html", "summary.csv", "summary.json", "valves"]);
    assert_eq!(std::fs::read_dir(fleet.join("valves")).unwrap().count(), 7);
    let mut beside: Vec<String> = std::fs::read_dir(out.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    beside.sort();
    assert_eq!(beside, ["fleet", "valves.toml"]);
}

#[test]
fn one_valve_shows_the_same_figures_in_every_output() {
    // A worn valve: its friction band, dead time and stroke speeds are one number each in the
    // fleet row, `diagnose --json` (what the Python package returns) and the valve's report.
    let dir = tempfile::tempdir().unwrap();
    let out = tempfile::tempdir().unwrap();
    std::fs::copy(
        case("pub_backlash_rs.csv"),
        dir.path().join("pub_backlash_rs.csv"),
    )
    .unwrap();
    run(&[
        "fleet",
        dir.path().to_str().unwrap(),
        "--out",
        out.path().to_str().unwrap(),
    ]);
    let row = &json(&out.path().join("summary.json"))["valves"][0];
    let alone = run(&[
        "diagnose",
        dir.path().join("pub_backlash_rs.csv").to_str().unwrap(),
        "--json",
    ]);
    let d: Value = serde_json::from_slice(&alone.stdout).unwrap();
    let figures = &d["figures"];
    for (in_row, in_json) in [
        ("friction_band_pct", "friction_band_pct"),
        ("dead_time_s", "dead_time_s"),
        ("stroke_speed_open_pct_per_s", "opening_speed_pct_per_s"),
        ("stroke_speed_close_pct_per_s", "closing_speed_pct_per_s"),
    ] {
        assert_eq!(row[in_row], figures[in_json], "{in_row}: {row} {figures}");
    }
    // The finding's size is the figure, with its interval, in the row and the report alike.
    let band = figures["friction_band_pct"].as_f64().unwrap();
    let size = &d["findings"][0]["size"];
    assert_eq!(size["name"], "friction_band_pct");
    assert_eq!(size["value"].as_f64(), Some(band));
    assert!(size["low"].as_f64().unwrap() <= band && band <= size["high"].as_f64().unwrap());
    assert!((4.5..7.0).contains(&band), "{band}");
    let text = row["sizes"][0].as_str().unwrap();
    assert!(
        text.starts_with(&format!("friction band {band:.2} % (")),
        "{text}"
    );
    let page =
        std::fs::read_to_string(out.path().join("valves/pub_backlash_rs/report.html")).unwrap();
    assert!(page.contains(text), "{text}");
    assert!(
        page.contains(&format!("friction band {band:.2} %,")),
        "the figures line"
    );
    // The verdict says it in the vocabulary's words, with the same figures.
    let verdict = d["verdict"].as_str().unwrap();
    let loses = format!(
        "lost motion (backlash) loses {} of travel on every reversal",
        text.trim_start_matches("friction band ")
    );
    assert!(verdict.contains(&loses), "{verdict}");
    assert!(row["verdict"].as_str() == Some(verdict), "{row}");
}
