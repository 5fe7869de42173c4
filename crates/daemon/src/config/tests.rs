//! Tests of loading and checking whole config files.

use super::*;
use std::net::IpAddr;
use vb_core::model::ModelKind;

/// The emulated valve's settings of `c`'s first valve.
fn emulated(c: &Config) -> &EmulatedConfig {
    match &c.valves[0].backend {
        ValveSpec::Emulated(e) => e,
        other => panic!("{other:?}"),
    }
}

/// The register map of `c`'s first valve, a Modbus one.
fn registers(c: &Config) -> vb_modbus::map::RegisterMap {
    match &c.valves[0].backend {
        ValveSpec::ModbusTcp(_, d) | ValveSpec::ModbusRtu(_, d) => d.registers,
        other => panic!("{other:?}"),
    }
}

fn err(text: &str) -> String {
    Config::from_toml(text, Path::new("c.toml"))
        .unwrap_err()
        .to_string()
}

#[test]
fn shipped_file_is_the_embedded_default_and_states_the_defaults() {
    let on_disk = std::fs::read_to_string(concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/emulated.toml"
    ))
    .unwrap();
    assert_eq!(on_disk, DEFAULT_TOML);
    // Every value the file shows is the value an empty config gets.
    let shipped = Config::embedded_default().unwrap();
    let mut empty = Config::from_toml("", Path::new("empty.toml")).unwrap();
    // No `model` means pin-cart II; the file says so explicitly.
    if let ValveSpec::Emulated(e) = &mut empty.valves[0].backend {
        e.model = Some(ModelKind::Pincart2);
    }
    assert_eq!(format!("{shipped:?}"), format!("{empty:?}"));
    assert_eq!(shipped.loop_.rate_hz, 100.0);
    assert!(matches!(shipped.source.spec, SourceSpec::RandomSteps(_)));
    assert_eq!(
        emulated(&shipped).model_spec().unwrap().model,
        ModelKind::Pincart2
    );
    assert_eq!(shipped.log.dir, PathBuf::from("./logs"));
}

#[test]
fn commented_examples_in_the_shipped_file_are_valid() {
    // Uncomment the example tables of the other sources and use each in turn.
    let start = DEFAULT_TOML.find("# [source.steps]").unwrap();
    let end = DEFAULT_TOML.find("[safety]").unwrap();
    let examples: String = DEFAULT_TOML[start..end]
        .lines()
        .map(|l| l.strip_prefix("# ").unwrap_or(l.trim_start_matches('#')))
        .collect::<Vec<_>>()
        .join("\n");
    let text = format!(
        "{}{examples}\n{}",
        &DEFAULT_TOML[..start],
        &DEFAULT_TOML[end..]
    );
    for kind in ["random-steps", "steps", "ramp", "sine", "prbs", "constant"] {
        let t = text.replace("kind = \"random-steps\"", &format!("kind = \"{kind}\""));
        let c = Config::from_toml(&t, Path::new("examples.toml")).unwrap();
        assert_eq!(c.source.spec.tag(), kind);
    }
    let t = text.replace("kind = \"random-steps\"", "kind = \"replay\"");
    let e = Config::from_toml(&t, Path::new("examples.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("source.replay.file: cannot replay `recording.csv`"),
        "{e}"
    );
}

#[test]
fn errors_name_file_line_key_and_what_is_allowed() {
    let e = err("[loop]\nrate_hz = 5000.0\n");
    assert!(
        e.starts_with("c.toml:2: loop.rate_hz: 5000 is out of range"),
        "{e}"
    );
    assert!(e.contains("1 to 1000"), "{e}");
    let e = err("[loop]\nrate_hz = 100.0\nrat = 1\n");
    assert!(
        e.starts_with("c.toml:3: loop.rat: unknown field `rat`"),
        "{e}"
    );
    let e = err("[source.sine]\nperiod_s = \"long\"\n");
    assert!(
        e.starts_with("c.toml:2: source.sine.period_s: invalid type"),
        "{e}"
    );
    let e = err("[valve.emulated]\nmodel_file = \"no/such/model.toml\"\n");
    assert!(
        e.starts_with(
            "c.toml:2: valve.emulated.model_file: cannot use model file `no/such/model.toml`"
        ),
        "{e}"
    );
    let e = err("[source]\nkind = \"steps\"\n");
    assert!(
        e.starts_with("c.toml:2: source.kind: kind = \"steps\" needs a [source.steps] table"),
        "{e}"
    );
    // A kind whose table has no defaults needs it.
    for (text, want) in [
        ("[source]\nkind = \"replay\"\n", "c.toml:2: source.kind: kind = \"replay\" needs a [source.replay] table, e.g. file = \"recording.csv\""),
        ("[source]\nkind = \"constant\"\n", "c.toml:2: source.kind: kind = \"constant\" needs a [source.constant] table, e.g. op_pct = 50.0"),
        ("[valve]\nkind = \"modbus-tcp\"\n", "c.toml:2: valve.modbus-tcp: kind = \"modbus-tcp\" needs this table, e.g. address = \"127.0.0.1:5502\""),
        ("[[valve]]\nname = \"a\"\n[[valve]]\nname = \"b\"\nkind = \"modbus-rtu\"\n", "c.toml:5: valve.modbus-rtu: kind = \"modbus-rtu\" needs this table, e.g. port = \"/dev/ttyUSB0\""),
    ] {
        assert_eq!(err(text), want);
    }
    // The line of `kind` is where serde read it, in any form of table.
    let e = err("# inline\nsource = { kind = \"steps\" }\nvalve = { kind = \"modbus-tcp\" }\n");
    assert!(
        e.starts_with("c.toml:2: source.kind: kind = \"steps\""),
        "{e}"
    );
    let e = err("# inline\nvalve = { kind = \"modbus-tcp\" }\n");
    assert!(
        e.starts_with("c.toml:2: valve.modbus-tcp: kind = \"modbus-tcp\""),
        "{e}"
    );
    let e = err("[safety]\non_stop = \"go-to\"\n");
    assert!(
        e.starts_with("c.toml:2: safety.on_stop: on_stop = \"go-to\" needs go_to_pct"),
        "{e}"
    );
    let e = err("[log]\ndir = \"x\"\non_error = \"ignore\"\n");
    assert!(
        e.starts_with(
            "c.toml:3: log.on_error: unknown variant `ignore`, expected `keep-running` or `stop`"
        ),
        "{e}"
    );
    let c = Config::from_toml("[log]\non_error = \"stop\"\n", Path::new("c.toml")).unwrap();
    assert_eq!(c.log.on_error, OnError::Stop);
    let e = err("[source]\nkind = \"noise\"\n");
    assert!(
        e.contains("source.kind: unknown variant `noise`, expected one of"),
        "{e}"
    );
    let e = err("[source]\nop_min_pct = 60.0\nop_max_pct = 50.0\n");
    assert!(
        e.starts_with("c.toml:3: source.op_max_pct: must be above op_min_pct"),
        "{e}"
    );
    let e = err("[source]\nkind = \"prbs\"\n[source.prbs]\nband_hz = 80.0\n");
    assert!(
        e.starts_with("c.toml:4: source.prbs.band_hz: 80 is out of range"),
        "{e}"
    );
    assert!(!e.contains('\n'), "{e}");
}

#[test]
fn modbus_server_and_metrics_errors_name_their_key() {
    let hil = "[source]\nkind = \"modbus-server\"\n";
    let cases = [
        (
            format!("{hil}[source.modbus-server]\nlisten = \"localhost:5020\"\n"),
            "c.toml:4: source.modbus-server.listen: `localhost:5020` is not an IP address and port",
        ),
        (
            format!("{hil}[source.modbus-server]\nwatchdog_s = 0.0\n"),
            "c.toml:4: source.modbus-server.watchdog_s: 0 is not allowed",
        ),
        (
            format!("{hil}[source.modbus-server]\ninitial_pct = 120.0\n"),
            "c.toml:4: source.modbus-server.initial_pct: 120 is out of range",
        ),
        (
            format!("{hil}op_min_pct = 50.0\nop_max_pct = 50.0\n"),
            "c.toml:4: source.op_max_pct: must be above op_min_pct",
        ),
        (
            format!("{hil}[source.modbus-server.registers]\nstatus = {{ address = 2, setpoint_error_bit = 2 }}\n"),
            "c.toml:4: source.modbus-server.registers.status.setpoint_error_bit: 2 is taken",
        ),
        (
            format!("{hil}[source.modbus-server.registers]\nposition = {{ address = 0, format = \"i16\" }}\n"),
            "c.toml:4: source.modbus-server.registers.position.address: 0 overlaps setpoint",
        ),
        (
            format!("{hil}[source.modbus-server]\ncontrollers = [\"plc-1\"]\n"),
            "c.toml:4: source.modbus-server.controllers: `plc-1` is not an IP address: write e.g. \"10.0.0.5\"",
        ),
        (
            format!("{hil}[source.modbus-server]\ncontrollers = [\"127.0.0.2:502\"]\n"),
            "c.toml:4: source.modbus-server.controllers: `127.0.0.2:502` is not an IP address: write the address without its port, \"127.0.0.2\"",
        ),
        (
            format!("{hil}[source.modbus-server]\ncontrollers = [\"127.0.0.2\", \"127.0.0.2\"]\n"),
            "c.toml:4: source.modbus-server.controllers: 127.0.0.2 is listed twice",
        ),
        (
            format!("{hil}[source.modbus-server]\ncontrollers = [\"10.0.0.5\"]\n"),
            "c.toml:4: source.modbus-server.controllers: 10.0.0.5 cannot connect: listen = \"127.0.0.1:5020\" serves this machine only",
        ),
        (
            format!("{hil}[source.modbus-server]\nmax_connections = 2\ncontrollers = [\"127.0.0.2\", \"::1\"]\n"),
            "c.toml:5: source.modbus-server.controllers: 2 controllers keep 2 of the max_connections = 2 slots",
        ),
        (
            format!("[loop]\nclock = \"virtual\"\n{hil}"),
            "c.toml:2: loop.clock: \"virtual\" cannot serve a process controller",
        ),
        (
            "[metrics]\nlisten = \"9100\"\n".to_string(),
            "c.toml:2: metrics.listen: `9100` is not an IP address and port",
        ),
        (
            format!("{hil}[metrics]\nlisten = \"127.0.0.1:5020\"\n"),
            "c.toml:4: metrics.listen: 127.0.0.1:5020 is also [source.modbus-server] listen",
        ),
    ];
    for (text, want) in cases {
        let e = err(&text);
        assert!(e.starts_with(want), "{text}: {e}");
        assert!(!e.contains('\n'), "{e}");
    }
    // Defaults: loopback 5020, 1 s watchdog, per-mille map with a status register; no metrics.
    let c = Config::from_toml(hil, Path::new("c.toml")).unwrap();
    let m = c.source.server().unwrap();
    assert_eq!(m.listen.0.to_string(), "127.0.0.1:5020");
    assert_eq!(m.watchdog_s, 1.0);
    assert_eq!(m.registers.status.map(|s| s.address), Some(2));
    assert!(c.metrics.is_none());
    assert!(m.limits().controllers.is_empty());
    // Controllers, an IPv4 address mapped into IPv6 as the one it maps.
    let text = format!("{hil}[source.modbus-server]\nlisten = \"[::]:5020\"\ncontrollers = [\"10.0.0.5\", \"::ffff:10.0.0.6\"]\n");
    let c = Config::from_toml(&text, Path::new("c.toml")).unwrap();
    let limits = c.source.server().unwrap().limits();
    assert_eq!(
        *limits.controllers,
        [IpAddr::from([10, 0, 0, 5]), IpAddr::from([10, 0, 0, 6])]
    );
    assert!(limits.is_controller("::ffff:10.0.0.5".parse().unwrap()));
    assert!(!limits.is_controller("10.0.0.7".parse().unwrap()));
    let c = Config::from_toml("[metrics]\n", Path::new("c.toml")).unwrap();
    assert_eq!(c.metrics.unwrap().listen.0.to_string(), "127.0.0.1:9100");
}

#[test]
fn shipped_hil_config_serves_loopback_with_metrics() {
    let path = Path::new(concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/hil.toml"
    ));
    let c = Config::load(Some(path)).unwrap();
    assert!(c.valves[0].backend.is_simulated());
    let m = c.source.server().unwrap();
    assert!(m.listen.0.ip().is_loopback());
    // The map written out in the file is the default one.
    assert_eq!(m.registers, ModbusServerConfig::default().registers);
    assert_eq!(c.safety.on_stop, OnStop::GoTo);
    assert_eq!(
        c.metrics.map(|x| x.listen.0.to_string()).as_deref(),
        Some("127.0.0.1:9100")
    );
    assert!(m.controllers.is_empty());
    // Its commented `controllers` line, uncommented, is valid.
    let text = std::fs::read_to_string(path).unwrap();
    let text = text.replace("# controllers = ", "controllers = ");
    let c = Config::from_toml(&text, path).unwrap();
    let m = c.source.server().unwrap();
    assert_eq!(
        m.controllers,
        [ControllerAddr(IpAddr::from([127, 0, 0, 1]))]
    );
}

#[test]
fn model_file_loads_any_model() {
    let path = concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/models/stiction.toml"
    );
    let c = Config::from_toml(
        &format!("[valve.emulated]\nmodel_file = \"{path}\"\n"),
        Path::new("c.toml"),
    )
    .unwrap();
    assert_eq!(
        emulated(&c).model_spec().unwrap().model,
        ModelKind::Stiction
    );
    let e = err(&format!(
        "[valve.emulated]\nmodel = \"fopdt\"\nmodel_file = \"{path}\"\n"
    ));
    assert!(e.contains("not both"), "{e}");
}

proptest::proptest! {
    /// Any text, valid TOML or not, gives a config or a one-line error; never a panic.
    #[test]
    fn any_text_loads_or_fails_on_one_line(text in "(\\PC|\n|\\[|\\]|=|\"){0,300}") {
        if let Err(e) = Config::from_toml(&text, Path::new("fuzz.toml")) {
            let e = e.to_string();
            proptest::prop_assert!(!e.contains('\n'), "{e}");
            proptest::prop_assert!(e.starts_with("fuzz.toml"), "{e}");
        }
    }

    /// Keys of the real config with arbitrary values: checked, never a panic.
    #[test]
    fn known_keys_with_any_value(table in "loop|valve|source|safety|log|metrics", key in "[a-z_]{1,12}", value in "-?[0-9.e+]{1,12}|\"[a-z-]{0,12}\"|true|nan|inf") {
        let text = format!("[{table}]\n{key} = {value}\n");
        if let Err(e) = Config::from_toml(&text, Path::new("fuzz.toml")) {
            proptest::prop_assert!(!e.to_string().contains('\n'), "{e}");
        }
    }
}

#[test]
fn several_valves_are_named_tables_with_their_own_sources() {
    let text = std::fs::read_to_string(concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/two-valves.toml"
    ))
    .unwrap();
    let c = Config::from_toml(&text, Path::new("two-valves.toml")).unwrap();
    let names: Vec<&str> = c.valves.iter().map(|v| v.label()).collect();
    assert_eq!(names, ["level", "cyclone"]);
    let seed = |v: &ValveConfig| match &c.source_of(v).spec {
        SourceSpec::RandomSteps(p) => p.seed,
        other => panic!("{other:?}"),
    };
    assert_eq!(seed(&c.valves[0]), 1);
    assert_eq!(seed(&c.valves[1]), 2);
    assert_eq!(c.source_of(&c.valves[1]).op_min_pct, 30.0);
    // A single [valve] is one unnamed valve driven by [source].
    let one = Config::from_toml("[valve]\nkind = \"emulated\"\n", Path::new("c.toml")).unwrap();
    assert_eq!(one.valves.len(), 1);
    assert_eq!(one.valves[0].label(), "valve");
    assert!(std::ptr::eq(one.source_of(&one.valves[0]), &one.source));
}

#[test]
fn errors_in_a_later_valve_name_its_line() {
    let two = "[[valve]]\nname = \"a\"\n\n[[valve]]\nname = \"b\"\n[valve.emulated]\nnoise_std_pct = -1.0\n";
    let e = err(two);
    assert!(
        e.starts_with("c.toml:7: valve.emulated.noise_std_pct: -1 is out of range"),
        "{e}"
    );
    let e = err("[[valve]]\nname = \"a\"\n[[valve]]\nname = \"b\"\n[valve.source]\nkind = \"ramp\"\n[valve.source.ramp]\nduration_s = 0.0\n");
    assert!(
        e.starts_with("c.toml:8: valve.source.ramp.duration_s"),
        "{e}"
    );
    let e = err("[[valve]]\nname = \"a\"\n[[valve]]\nkind = \"emulated\"\n");
    assert!(
        e.starts_with("c.toml:3: valve: valve 2 of 2 has no name"),
        "{e}"
    );
    let e = err("[[valve]]\nname = \"a\"\n[[valve]]\nname = \"a\"\n");
    assert!(
        e.starts_with("c.toml:4: valve.name: `a` names two valves"),
        "{e}"
    );
    let e = err("[[valve]]\nname = \"a b\"\n");
    assert!(e.contains("letters, digits"), "{e}");
}

#[test]
fn a_process_controller_drives_several_valves_from_blocks_that_hold_its_map() {
    let two =
        "[source]\nkind = \"modbus-server\"\n[[valve]]\nname = \"a\"\n[[valve]]\nname = \"b\"\n";
    let c = Config::from_toml(two, Path::new("c.toml")).unwrap();
    assert_eq!(c.controller_server().unwrap().block_size, 10);
    let e = err(&format!("{two}[source.modbus-server]\nblock_size = 2\n"));
    assert!(
        e.starts_with(
            "c.toml:8: source.modbus-server.block_size: 2 registers per valve cannot hold the map"
        ),
        "{e}"
    );
    assert!(e.contains("set block_size = 3 or more"), "{e}");
    let e = err("[[valve]]\nname = \"a\"\n[valve.source]\nkind = \"modbus-server\"\n");
    assert!(
        e.starts_with("c.toml:4: valve.source.kind: valve `a`: the process controller's server is the [source] table"),
        "{e}"
    );
    // The second valve's own source, at its line (not the first valve's `kind`).
    let e = err("[[valve]]\nname = \"a\"\n[valve.source]\nkind = \"ramp\"\n[[valve]]\nname = \"b\"\n[valve.source]\nkind = \"modbus-server\"\n");
    assert!(
        e.starts_with("c.toml:8: valve.source.kind: valve `b`: the process controller's server"),
        "{e}"
    );
    let e = err("[source]\nkind = \"modbus-server\"\n[source.modbus-server.registers]\nstatus = { table = \"holding\", address = 2, setpoint_error_bit = 3 }\n");
    assert!(e.contains("a health alarm in bit 3"), "{e}");
}

#[test]
fn drift_settings_are_checked() {
    let e = err("[valve.emulated]\ndead_time_drift_s_per_h = -0.1\n");
    assert!(
        e.starts_with("c.toml:2: valve.emulated.dead_time_drift_s_per_h"),
        "{e}"
    );
    let e = err("[valve.emulated]\nmodel = \"fopdt\"\nfriction_band_drift_pct_per_h = 1.0\n");
    assert!(
        e.starts_with("c.toml:3: valve.emulated.friction_band_drift_pct_per_h: 1 is not allowed: only a pin-cart model"),
        "{e}"
    );
    let e = err("[valve.emulated]\nfriction_band_drift_max_pct = 500.0\n");
    assert!(
        e.starts_with("c.toml:2: valve.emulated.friction_band_drift_max_pct: 500 is not allowed"),
        "{e}"
    );
}

#[test]
fn valves_on_one_serial_port_share_its_line_and_its_period() {
    let valve = |name: &str, slave: u8, extra: &str| {
        format!(
            "[[valve]]\nname = \"{name}\"\nkind = \"modbus-rtu\"\n[valve.modbus-rtu]\nport = \"/dev/ttyS7\"\nbaud = 115200\nslave_id = {slave}\n{extra}[valve.registers]\nfc23 = true\n"
        )
    };
    let bus = |a: &str, b: &str| format!("[loop]\nrate_hz = 50.0\n{a}{b}");
    let ok = bus(&valve("a", 1, ""), &valve("b", 2, ""));
    let c = Config::from_toml(&ok, Path::new("c.toml")).unwrap();
    assert_eq!(
        bus::buses(&c.valves),
        vec![("/dev/ttyS7".to_string(), vec![0, 1])]
    );
    let e = err(&bus(&valve("a", 1, ""), &valve("b", 1, "")));
    assert!(
        e.starts_with(
            "c.toml:18: valve.modbus-rtu.slave_id: 1 is also valve `a`'s slave id on /dev/ttyS7"
        ),
        "{e}"
    );
    let e = err(&bus(
        &valve("a", 1, ""),
        &valve("b", 2, "parity = \"none\"\n"),
    ));
    assert!(
        e.contains(
            "valve.modbus-rtu.port: /dev/ttyS7 is also valve `a`'s port, with other line settings"
        ),
        "{e}"
    );
    let e = err(&bus(
        &valve("a", 1, "timeout_ms = 12.0\n"),
        &valve("b", 2, "timeout_ms = 9.0\n"),
    ));
    assert!(
        e.contains("valve.modbus-rtu.timeout_ms: the timeout_ms of the valves on /dev/ttyS7 add up to 21.0 ms, more than the 20.0 ms loop period"),
        "{e}"
    );
    let e = err(&ok.replace("rate_hz = 50.0", "rate_hz = 100.0"));
    assert!(
        e.contains("valve.modbus-rtu.port: bus budget: 2 valves on /dev/ttyS7"),
        "{e}"
    );
}

#[test]
fn compensation_is_per_valve_and_checked_at_its_lines() {
    let pc2 = concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/models/pincart2.toml"
    );
    let phys = concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/../.."),
        "/config/models/physical.toml"
    );
    let c = Config::from_toml(
        &format!("[[valve]]\nname = \"a\"\n[valve.compensation]\nmodel_file = \"{pc2}\"\ndeadband = false\n[[valve]]\nname = \"b\"\n"),
        Path::new("c.toml"),
    )
    .unwrap();
    let comp = c.valves[0].compensation.as_ref().unwrap();
    assert!(comp.backlash && !comp.deadband && comp.calibration);
    assert!(c.valves[1].compensation.is_none());
    let e = err("[valve.compensation]\nbacklash = true\n");
    assert!(
        e.starts_with("c.toml:1: valve.compensation.model_file: is missing"),
        "{e}"
    );
    let e = err(&format!(
        "[valve.compensation]\nmodel_file = \"{pc2}\"\nkick_share = 2.0\n"
    ));
    assert!(
        e.starts_with("c.toml:3: valve.compensation.kick_share: 2 is out of range"),
        "{e}"
    );
    let e = err(&format!("[valve.compensation]\nmodel_file = \"{phys}\"\n"));
    assert!(
        e.starts_with("c.toml:2: valve.compensation.model_file: cannot use model file")
            && e.contains("is a simulator, not an identified model"),
        "{e}"
    );
    let e = err("[[valve]]\nname = \"a\"\n[[valve]]\nname = \"b\"\n[valve.compensation]\nmodel_file = \"no/such.toml\"\n");
    assert!(
        e.starts_with(
            "c.toml:6: valve.compensation.model_file: cannot use model file `no/such.toml`"
        ),
        "{e}"
    );
    let e = err(&format!(
        "[valve.compensation]\nmodel_file = \"{pc2}\"\nkick = 1\n"
    ));
    assert!(e.contains("kick"), "{e}");
}

#[test]
fn a_profile_supplies_the_map_and_the_config_overrides_it_key_by_key() {
    let link = "kind = \"modbus-rtu\"\n[valve.modbus-rtu]\nport = \"/dev/ttyS7\"\nbaud = 38400\nslave_id = 1\n";
    let c = Config::from_toml(
        &format!("[loop]\nrate_hz = 10.0\n[valve]\nprofile = \"belimo-uk24mod\"\n{link}"),
        Path::new("c.toml"),
    )
    .unwrap();
    let map = registers(&c);
    assert_eq!((map.setpoint.address, map.position.address), (0, 3));
    assert!(map.fc6 && (map.setpoint.scale - 0.01).abs() < 1e-12);
    // MP2 of the gateway: the registers given replace the profile's whole; the rest stays.
    let c = Config::from_toml(
        &format!("[loop]\nrate_hz = 10.0\n[valve]\nprofile = \"belimo-uk24mod\"\n{link}[valve.registers]\nsetpoint = {{ address = 20, format = \"u16\", scale = 0.01 }}\nposition = {{ address = 23, format = \"u16\", scale = 0.01 }}\n"),
        Path::new("c.toml"),
    )
    .unwrap();
    let map = registers(&c);
    assert_eq!((map.setpoint.address, map.position.address), (20, 23));
    assert!(map.fc6 && map.position_valid_pct == [0.0, 100.0]);
    // Without a profile, the default map as before.
    let c = Config::from_toml(&format!("[valve]\n{link}"), Path::new("c.toml")).unwrap();
    assert_eq!(registers(&c), vb_modbus::map::RegisterMap::default());
}

#[test]
fn profile_errors_name_file_line_key_and_the_shipped_profiles() {
    let e = err("[loop]\nrate_hz = 10.0\n[valve]\nkind = \"modbus-tcp\"\nprofile = \"belimo-uk24\"\n[valve.modbus-tcp]\naddress = \"127.0.0.1:5502\"\n");
    assert_eq!(
        e,
        "c.toml:5: valve.profile: no profile `belimo-uk24`: the shipped profiles (config/profiles/) are belimo-uk24mod, belimo-vav-compact-mod, burkert-mfc-float, burkert-style-example"
    );
    // In the second of two [[valve]] tables, at its line in the file.
    let two = "[[valve]]\nname = \"a\"\n[[valve]]\nname = \"b\"\nprofile = \"nope\"\n";
    assert!(
        err(two).starts_with("c.toml:5: valve.profile: no profile `nope`"),
        "{}",
        err(two)
    );
    // A key of the config that does not fit the profile's map: the config's line.
    let e = err(
        "[valve]\nprofile = \"burkert-mfc-float\"\n[valve.registers]\nfc23 = false\nfc6 = true\n",
    );
    assert!(
        e.starts_with("c.toml:5: valve.registers.fc6: true needs a one-register set-point")
            && e.ends_with("(over profile `burkert-mfc-float`)"),
        "{e}"
    );
    // A bad value in [valve.registers] is still named at its line.
    let e =
        err("[valve]\nprofile = \"belimo-uk24mod\"\n[valve.registers]\nword_order = \"middle\"\n");
    assert!(
        e.starts_with("c.toml:4: valve.registers.word_order: unknown variant `middle`"),
        "{e}"
    );
}

#[test]
fn diagnosis_is_checked_against_its_table_and_needs_health() {
    let c = Config::from_toml("[health]\n[diagnosis]\n", Path::new("c.toml")).unwrap();
    assert_eq!(c.diagnosis, Some(DiagnosisConfig::default()));
    assert_eq!(
        (
            c.diagnosis.unwrap().every_s,
            DiagnosisConfig::default().window_s
        ),
        (1800.0, 1200.0)
    );
    let e = err("[diagnosis]\nevery_s = 600.0\n");
    assert!(
        e.starts_with(
            "c.toml:1: diagnosis: the live diagnosis is fed with the rows of the health check"
        ),
        "{e}"
    );
    let e = err("[health]\n\n[diagnosis]\nwindow_s = 10.0\n");
    assert!(
        e.starts_with(
            "c.toml:4: diagnosis.window_s: 10 is out of range: a window in s, at least 30 s"
        ),
        "{e}"
    );
    let e = err("[health]\n[diagnosis]\nevery_s = 1.0\n");
    assert!(
        e.starts_with("c.toml:3: diagnosis.every_s: 1 is out of range"),
        "{e}"
    );
    let e = err("[health]\n[diagnosis]\nevery = 1.0\n");
    assert!(e.contains("c.toml:3") && e.contains("every"), "{e}");
}
