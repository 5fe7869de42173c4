//! `valve-bridge probe` against sim-device over Modbus TCP and RTU on a pseudo-terminal: every
//! mapped register read once and shown raw and scaled, nothing written unless `--write-test`,
//! an unmapped address shown as exception 02 with what to check, one-line errors otherwise.

use std::process::Output;

use crate::common;

use crate::common::sim::{probe, SimDevice, RTU_CONFIG};

fn text(out: &Output) -> (String, String) {
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The row of `register` in the first (or, with `after`, the second) table.
fn row<'a>(table: &'a str, register: &str, after: bool) -> &'a str {
    let part = match table.split_once("after the write:") {
        Some((_, rest)) if after => rest,
        Some((before, _)) => before,
        None => table,
    };
    part.lines()
        .find(|l| l.trim_start().starts_with(register))
        .unwrap_or_else(|| panic!("no {register} row in\n{table}"))
}

fn reads_and_writes_only_when_asked(device: &SimDevice) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = device.config(dir.path(), &[], "");
    let out = probe(&cfg, &[]);
    let (table, err) = text(&out);
    assert!(out.status.success(), "{table}{err}");
    assert!(table.contains("nothing written"), "{table}");
    // sim-device starts closed with a 0 % set-point; the status word is clear.
    for (register, want) in [
        ("set-point", "holding        0  u16    0 (0x0000)"),
        ("position", "holding        1  i16    0 (0x0000)"),
        ("status", "holding        2  u16    0 (0x0000)"),
    ] {
        assert!(row(&table, register, false).contains(want), "{table}");
    }
    assert!(
        row(&table, "set-point", false).contains("0.00 %"),
        "{table}"
    );
    assert!(
        row(&table, "status", false).contains("no bit set"),
        "{table}"
    );
    // Nothing was written: a second probe still reads the 0 % set-point.
    let (again, _) = text(&probe(&cfg, &[]));
    assert!(
        row(&again, "set-point", false).contains("0 (0x0000)"),
        "{again}"
    );
    // --write-test writes once, shows what the device got, and reads again.
    let out = probe(&cfg, &["--write-test", "45.67"]);
    let (table, err) = text(&out);
    assert!(out.status.success(), "{table}{err}");
    assert!(
        table.contains("write test: set-point 45.67 % written; the device received 45.70 %"),
        "{table}"
    );
    assert!(
        row(&table, "set-point", true).contains("457 (0x01C9)"),
        "{table}"
    );
    assert!(
        row(&table, "set-point", true).contains("45.70 %"),
        "{table}"
    );
    common::assert_for_people(&table);
}

#[test]
fn probes_sim_device_over_tcp() {
    let device = SimDevice::start(&["--tcp", "127.0.0.1:0", "--model", "modelless"]);
    reads_and_writes_only_when_asked(&device);
}

#[test]
fn probes_sim_device_over_a_pty() {
    let device = SimDevice::start(&["--pty", "--model", "modelless"]);
    reads_and_writes_only_when_asked(&device);
}

#[test]
fn an_address_the_device_lacks_is_exception_02_with_what_to_check() {
    let device = SimDevice::start(&["--tcp", "127.0.0.1:0"]);
    let dir = tempfile::tempdir().unwrap();
    let cfg = device.config(
        dir.path(),
        &[(
            "status   = { table = \"holding\", address = 2",
            "status   = { table = \"holding\", address = 9",
        )],
        "",
    );
    let out = probe(&cfg, &[]);
    let (table, err) = text(&out);
    assert_eq!(out.status.code(), Some(1), "{table}{err}");
    let status = row(&table, "status", false);
    assert!(
        status.contains("holding        9")
            && status.contains("exception 02 (illegal data address: the device has no such register; check the addresses and tables in [valve.registers]"),
        "{table}"
    );
    assert!(row(&table, "position", false).contains("0.00 %"), "{table}");
    assert_eq!(
        err.trim_end(),
        "valve-bridge: error: 1 of the probe's requests failed (see the table)"
    );
}

#[test]
fn no_device_or_no_modbus_valve_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let (addr, cfg, _port) = common::sim::nobody_listening(dir.path(), "");
    let (out, err) = text(&probe(&cfg, &[]));
    assert!(out.is_empty(), "{out}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(
        err.starts_with(&format!(
            "valve-bridge: error: cannot connect to Modbus TCP {addr}: Connection refused"
        )),
        "{err}"
    );
    let cfg = dir.path().join("emulated.toml");
    std::fs::write(&cfg, "[valve]\nkind = \"emulated\"\n").unwrap();
    let (_, err) = text(&probe(&cfg, &[]));
    assert!(
        err.contains("has no device to probe") && err.lines().count() == 1,
        "{err}"
    );
    // The shipped RTU config on a serial port that is not there.
    let cfg = common::sim::config(
        dir.path(),
        RTU_CONFIG.0,
        &[(RTU_CONFIG.1, "/dev/ttyUSB-probe-missing")],
        "",
    );
    let (_, err) = text(&probe(&cfg, &[]));
    assert!(
        err.starts_with("valve-bridge: error: cannot open serial port /dev/ttyUSB-probe-missing: No such file or directory"),
        "{err}"
    );
}

#[test]
fn a_pty_link_is_removed_on_stop_and_a_dangling_one_is_named() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("vb-sim-link");
    let link_arg = link.to_str().unwrap();
    let device = SimDevice::start_bare(&["--pty", "--pty-link", link_arg], RTU_CONFIG);
    assert_eq!(
        std::fs::read_link(&link).unwrap().to_str(),
        Some(device.endpoint.as_str())
    );
    let cfg = common::sim::config(dir.path(), RTU_CONFIG.0, &[(RTU_CONFIG.1, link_arg)], "");
    assert!(probe(&cfg, &[]).status.success());
    let pty = device.endpoint.clone();
    device.signal(libc::SIGINT);
    device.stop();
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "the link is left"
    );
    // A link to a pseudo-terminal that is gone (left by something else) is named as such.
    std::os::unix::fs::symlink(&pty, &link).unwrap();
    let (out, err) = text(&probe(&cfg, &[]));
    assert!(
        err.trim_end().ends_with(&format!(
            "cannot open serial port {link_arg}: it is a link to {pty}, which does not exist \
             (the device behind it is gone) (check [valve.modbus-rtu] port)"
        )),
        "{out}{err}"
    );
}
