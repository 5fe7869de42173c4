//! `valve-bridge run` refusing to start, through the real binary: no device on the TCP port, no
//! serial port, a bad register map, a serial line too slow for the loop rate. Each exits 1
//! with one line on stderr that says what, where (address, device, file, line, key) and how to
//! fix it, without a panic or a debug dump, and creates no log.

use std::path::Path;

use crate::common;
use crate::common::sim::{config, run_cmd, CONSTANT, RTU_CONFIG, TCP_CONFIG};

/// Runs the daemon on `cfg` with `options`, which must fail to start; returns its error message, after checking
/// it is the one line on stderr (`RUST_LOG=warn`), without a panic or a debug dump, and that no
/// log was created.
fn startup_error(cfg: &Path, options: &[&str]) -> String {
    let logs = cfg.with_file_name("logs");
    let out = run_cmd(cfg, &logs, 1.0)
        .args(options)
        .env("RUST_LOG", "warn")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "not one line:\n{stderr}");
    for dump in [
        "panicked",
        "backtrace",
        "RUST_BACKTRACE",
        "Os {",
        "Custom {",
    ] {
        assert!(!stderr.contains(dump), "{stderr}");
    }
    assert!(!logs.exists(), "a log was created before the valve opened");
    stderr
        .strip_prefix("valve-bridge: error: ")
        .unwrap_or_else(|| panic!("{stderr}"))
        .trim_end()
        .to_string()
}

#[test]
fn no_device_on_the_tcp_port_with_require_device_is_one_line_naming_the_address() {
    let dir = tempfile::tempdir().unwrap();
    let (addr, cfg, _port) = common::sim::nobody_listening(dir.path(), CONSTANT);
    let e = startup_error(&cfg, &["--require-device"]);
    assert!(
        e.starts_with(&format!(
            "cannot connect to Modbus TCP {addr}: Connection refused"
        )) && e.ends_with("(check [valve.modbus-tcp] address and that the device is on)"),
        "{e}"
    );
}

#[test]
fn a_missing_serial_port_with_require_device_is_one_line_naming_the_device() {
    let dir = tempfile::tempdir().unwrap();
    let port = dir.path().join("ttyUSB-missing");
    let port = port.to_str().unwrap();
    let cfg = config(dir.path(), RTU_CONFIG.0, &[(RTU_CONFIG.1, port)], CONSTANT);
    let e = startup_error(&cfg, &["--require-device"]);
    assert_eq!(
        e,
        format!(
            "cannot open serial port {port}: No such file or directory (check [valve.modbus-rtu] port)"
        )
    );
}

#[test]
fn a_bad_register_map_is_one_line_naming_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            (
                "address = 1, format = \"i16\"",
                "address = 0, format = \"i16\"",
            ),
            "valve.registers.position.address: 0 overlaps setpoint (holding registers 0-0): \
             give each value its own registers",
        ),
        (
            ("format = \"i16\"", "format = \"i24\""),
            "valve.registers.position.format: unknown variant `i24`, \
             expected one of `u16`, `i16`, `u32`, `f32`",
        ),
        (
            (
                "format = \"i16\", scale = 0.1",
                "format = \"i16\", scale = 0.0",
            ),
            "valve.registers.position.scale: 0 is not allowed: percent per raw unit, \
             finite and not 0 (0.1 for per-mille)",
        ),
    ];
    for (edit, want) in cases {
        let cfg = config(dir.path(), TCP_CONFIG.0, &[edit], CONSTANT);
        let line = std::fs::read_to_string(&cfg)
            .unwrap()
            .lines()
            .position(|l| l.starts_with("position ="))
            .unwrap()
            + 1;
        assert_eq!(
            startup_error(&cfg, &[]),
            format!("{}:{line}: {want}", cfg.display())
        );
    }
}

#[test]
fn a_serial_line_too_slow_for_the_rate_is_refused_with_the_budget() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(
        dir.path(),
        RTU_CONFIG.0,
        &[("baud = 115200", "baud = 19200")],
        CONSTANT,
    );
    // FC 23 reading back the set-point with the position and the status: 15 + 11
    // characters of 11 bits at 19200 baud (14.9 ms), two 3.5-character silences (4.01 ms) and
    // 1 ms turnaround, against a 10 ms period. The map already uses FC 23, so that is not
    // offered as a fix.
    assert_eq!(
        startup_error(&cfg, &[]),
        "bus budget: one cycle takes 19.9 ms on the wire at 19200 baud, 11 bits/char \
         (FC 23 15+11 chars; 2 silences of 2.01 ms; 1 turnaround of 1.0 ms) = 199 % of the \
         10.0 ms loop period; the link carries at most 50.2 Hz: refusing 100.0 Hz \
         (raise [valve.modbus-rtu] baud, or lower [loop] rate_hz to 50 or less)"
    );
}
