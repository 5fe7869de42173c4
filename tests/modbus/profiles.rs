//! Each shipped register profile walked through with no hardware: sim-device serves the profile
//! on a pseudo-terminal (`--profile NAME`), `valve-bridge probe` reads it with the shipped
//! `config/sim-device-NAME.toml` (registers by their manual names and numbers, the profile's
//! further registers, a write test) and `valve-bridge run` drives it for two seconds.

use std::process::Command;

use valve_bridge::modbus::profile::{self, Profile};

use crate::common;

use crate::common::sim::{probe, read_log, real_time_turn, run_cmd, stdout, SimDevice, CONSTANT};

/// Each shipped profile, its walk-through config and the pty link that config names.
const WALKS: [(&str, &str, &str); 4] = [
    (
        "belimo-uk24mod",
        "config/sim-device-belimo-uk24mod.toml",
        "/tmp/vb-belimo-uk24mod",
    ),
    (
        "belimo-vav-compact-mod",
        "config/sim-device-belimo-vav-compact-mod.toml",
        "/tmp/vb-belimo-vav-compact-mod",
    ),
    (
        "burkert-mfc-float",
        "config/sim-device-burkert-mfc-float.toml",
        "/tmp/vb-burkert-mfc-float",
    ),
    (
        "burkert-style-example",
        "config/sim-device-burkert-style-example.toml",
        "/tmp/vb-burkert-style-example",
    ),
];

#[derive(Debug, serde::Deserialize)]
struct LogRow {
    op_sent_pct: Option<f64>,
    vp_pct: Option<f64>,
    status: String,
}

/// The tokens after `name` in the row of the table (before any write) that holds it.
fn after<'a>(table: &'a str, name: &str) -> Vec<&'a str> {
    let before = table.split("after the write:").next().unwrap_or(table);
    let line = (before.lines())
        .find(|l| l.contains(&format!(" {name} ")))
        .unwrap_or_else(|| panic!("no row {name} in\n{table}"));
    let rest = &line[line.find(name).unwrap() + name.len()..];
    rest.split_whitespace().collect()
}

/// probe and run against sim-device serving `name`.
fn walk(name: &str, config: &'static str, link: &'static str) {
    let p: Profile = profile::find(name).unwrap().unwrap();
    let device = SimDevice::start_bare(
        &["--pty", "--profile", name, "--model", "modelless"],
        (config, link),
    );
    let dir = tempfile::tempdir().unwrap();
    let cfg = device.config(dir.path(), &[], "");
    let table = stdout(&probe(&cfg, &["--write-test", "42.5"]));
    assert!(
        table.contains(&format!("profile {name}: {}", p.about.device)),
        "{table}"
    );
    // The mapped registers by their manual names, numbers next to the wire addresses.
    let map = p.map;
    for (called, reg) in [
        (p.names.setpoint.as_deref(), map.setpoint),
        (p.names.position.as_deref(), map.position),
    ] {
        let cells = after(&table, called.unwrap());
        let want = [
            p.number(reg.address).to_string(),
            reg.table.to_string(),
            reg.address.to_string(),
            reg.format.to_string(),
        ];
        assert_eq!(&cells[..4], want, "{table}");
    }
    // Every further register is read (sim-device serves it as 0), its value named if the
    // manual names 0.
    for o in &p.others {
        let cells = after(&table, &o.name);
        assert_eq!(cells[0], p.number(o.address).to_string(), "{table}");
        assert_eq!(
            (cells[2], cells[4]),
            (o.address.to_string().as_str(), "0"),
            "{table}"
        );
        if let Some(m) = o.meaning(0) {
            assert!(cells[6..].join(" ").starts_with(m), "{table}");
        }
    }
    assert!(
        table.contains("write test: set-point 42.50 % written; the device received 42.50 %"),
        "{table}"
    );
    let after_write = table.split("after the write:").nth(1).unwrap();
    assert!(
        (after_write.lines())
            .any(|l| l.trim_start().starts_with("set-point") && l.contains("42.50 %")),
        "{table}"
    );
    // Two seconds of the loop at a constant 40 %: every cycle answered (but a rare timeout where
    // a stalled machine kept a reply past its deadline, or a slot it made the loop miss), V_P
    // at 40 %.
    let logs = dir.path().join("logs");
    let cfg = device.config(dir.path(), &[], CONSTANT);
    let _turn = real_time_turn();
    let out = run_cmd(&cfg, &logs, 2.0).output().unwrap();
    let summary = stdout(&out);
    assert!(summary.contains(" 0 error, 0 disconnected"), "{summary}");
    let rows: Vec<LogRow> = read_log(&logs);
    assert!(rows.len() >= 19, "{}", rows.len());
    let (last, cycles) = rows.split_last().unwrap();
    let answered = cycles.iter().filter(|r| r.status == "ok").count();
    assert!(
        answered * 25 >= cycles.len() * 24
            && (cycles.iter()).all(|r| matches!(r.status.as_str(), "ok" | "timeout" | "skipped")),
        "{summary}"
    );
    assert_eq!(last.status, "safe-hold", "the stop action's row");
    assert_eq!(last.op_sent_pct, Some(40.0));
    assert!((last.vp_pct.unwrap() - 40.0).abs() < 1e-6, "{last:?}");
}

#[test]
fn every_shipped_profile_has_a_walk_through() {
    let mut walked: Vec<&str> = WALKS.iter().map(|w| w.0).collect();
    walked.sort();
    assert_eq!(walked, profile::names());
}

#[test]
fn belimo_uk24mod() {
    walk(WALKS[0].0, WALKS[0].1, WALKS[0].2);
}

#[test]
fn belimo_vav_compact_mod() {
    walk(WALKS[1].0, WALKS[1].1, WALKS[1].2);
}

#[test]
fn burkert_mfc_float() {
    walk(WALKS[2].0, WALKS[2].1, WALKS[2].2);
}

#[test]
fn burkert_style_example() {
    walk(WALKS[3].0, WALKS[3].1, WALKS[3].2);
}

#[test]
fn the_gateway_takes_fc6_only_as_its_manual_says() {
    // sim-device answers the UK24MOD profile's functions only: a map written with FC 16 (the
    // profile's fc6 overridden) is refused with exception 01.
    let (name, config, link) = WALKS[0];
    let device = SimDevice::start_bare(&["--pty", "--profile", name], (config, link));
    let dir = tempfile::tempdir().unwrap();
    let cfg = device.config(dir.path(), &[], "[valve.registers]\nfc6 = false\n");
    let out = probe(&cfg, &["--write-test", "10"]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{table}");
    assert!(
        table.contains("write test: set-point 10.00 %: ") && table.contains("exception 01"),
        "{table}"
    );
    // sim-device refuses an unknown profile with the shipped names.
    let out = Command::new(common::sim::sim_device_bin())
        .args(["--pty", "--profile", "belimo"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains(&profile::unknown("belimo")),
        "{err}"
    );
}
