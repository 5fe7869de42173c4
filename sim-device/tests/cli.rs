//! sim-device's start-up errors: one line, naming the key, option or device.

mod common;

use common::run_to_end;

fn fails_with(args: &[&str], want: &[&str]) {
    let (ok, err) = run_to_end(args);
    assert!(!ok, "{args:?} should fail");
    let err = err.trim_end();
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    for w in want {
        assert!(err.contains(w), "{args:?}: `{w}` not in: {err}");
    }
}

#[test]
fn bad_register_maps_name_file_line_and_key() {
    let dir = std::env::temp_dir().join(format!("sim-device-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bad_format = dir.join("format.toml");
    std::fs::write(&bad_format, "[valve]\nkind = \"modbus-tcp\"\n\n[valve.registers]\nposition = { address = 1, format = \"u64\" }\n")
        .expect("write");
    let path = bad_format.display().to_string();
    fails_with(
        &["--tcp", "127.0.0.1:0", "--config", &path],
        &[&format!("{path}:5: valve.registers.position"), "u64", "u16"],
    );
    let overlap = dir.join("overlap.toml");
    std::fs::write(&overlap, "[valve.registers]\nstatus = { address = 0 }\n").expect("write");
    let path = overlap.display().to_string();
    fails_with(
        &["--tcp", "127.0.0.1:0", "--config", &path],
        &[&format!(
            "{path}:2: valve.registers.status.address: 0 overlaps setpoint"
        )],
    );
    drop(std::fs::remove_dir_all(&dir));
}

#[test]
fn unreachable_devices_and_bad_options_are_named() {
    fails_with(
        &["--serial", "/dev/ttyUSB-sim-missing"],
        &["cannot open serial port /dev/ttyUSB-sim-missing (--serial)"],
    );
    fails_with(
        &["--tcp", "127.0.0.1:0", "--corrupt-crc-every", "2"],
        &["--corrupt-crc-every needs --pty or --serial"],
    );
    fails_with(
        &["--pty", "--disconnect-after", "2"],
        &["--disconnect-after needs --tcp"],
    );
    fails_with(
        &["--tcp", "127.0.0.1:0", "--model", "no/such/model.toml"],
        &["no/such/model.toml", "cannot read"],
    );
    fails_with(&[], &["nothing to serve"]);
    // Each cause once: the OS error is not repeated after the message that quotes it.
    let (_, err) = run_to_end(&["--tcp", "127.0.0.1:0", "--config", "/no/such/file.toml"]);
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
}
