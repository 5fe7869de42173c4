//! The shipped Modbus configs: their register maps are valid and their serial links carry the
//! loop rate they ask for (bus budget), so `valve-bridge run` can start with each of them.

use std::path::Path;

use serde::Deserialize;
use valve_bridge::modbus::budget::{Budget, Verdict};
use valve_bridge::modbus::link::{RtuLink, TcpLink};
use valve_bridge::modbus::map::RegisterMap;
use valve_bridge::modbus::plan::Plan;
use valve_bridge::toml_file;

#[derive(Deserialize)]
struct File {
    #[serde(default, rename = "loop")]
    loop_: Loop,
    valve: Valve,
}

#[derive(Deserialize, Default)]
struct Loop {
    rate_hz: Option<f64>,
}

#[derive(Deserialize)]
struct Valve {
    kind: String,
    registers: RegisterMap,
    #[serde(rename = "modbus-tcp")]
    tcp: Option<TcpLink>,
    #[serde(rename = "modbus-rtu")]
    rtu: Option<RtuLink>,
}

fn load(name: &str) -> (File, String) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name);
    let (file, text): (File, String) = toml_file::load(&path).unwrap_or_else(|e| panic!("{e}"));
    file.valve
        .registers
        .check_in(
            toml_file::Layout::parse(&text).lines(),
            &path,
            "valve.registers",
        )
        .unwrap_or_else(|e| panic!("{e}"));
    (file, text)
}

#[test]
fn sim_device_tcp_config_is_valid() {
    let (f, _) = load("sim-device-tcp.toml");
    assert_eq!(f.valve.kind, "modbus-tcp");
    let tcp = f.valve.tcp.expect("[valve.modbus-tcp]");
    assert_eq!(tcp.violation(), None);
    assert!(f.valve.registers.fc23 && f.valve.registers.status.is_some());
}

#[test]
fn rtu_configs_fit_their_loop_rate() {
    for (name, want_fc23, rate) in [
        ("sim-device-rtu.toml", true, 100.0),
        ("burkert-rtu.toml", false, 50.0),
    ] {
        let (f, _) = load(name);
        assert_eq!(f.valve.kind, "modbus-rtu", "{name}");
        let rtu = f.valve.rtu.expect("[valve.modbus-rtu]");
        assert_eq!(rtu.violation(), None, "{name}");
        assert_eq!(f.valve.registers.fc23, want_fc23, "{name}");
        let hz = f.loop_.rate_hz.unwrap_or(100.0);
        assert_eq!(hz, rate, "{name}");
        let plan = Plan::rtu(&f.valve.registers);
        let b = Budget::rtu(&rtu, &plan, 1.0 / hz);
        assert_eq!(b.verdict(), Verdict::Fits, "{name}: {}", b.describe());
        // The cycle deadline lies between the wire time and the loop period.
        let t = rtu.timeout_ms.expect("timeout_ms") / 1000.0;
        assert!(
            t > b.cycle_s && t < 1.0 / hz,
            "{name}: timeout {t} s vs {}",
            b.describe()
        );
        // The same line at twice the rate is refused.
        assert_eq!(
            Budget::rtu(&rtu, &plan, 0.5 / hz).verdict(),
            Verdict::TooSlow,
            "{name}"
        );
    }
}

#[test]
fn sim_device_configs_use_the_map_sim_device_serves_by_default() {
    // `sim-device --tcp ...` without --config and these configs must agree, as README runs them.
    for name in ["sim-device-tcp.toml", "sim-device-rtu.toml"] {
        let (f, _) = load(name);
        assert_eq!(
            f.valve.registers.setpoint,
            RegisterMap::device_default().setpoint
        );
        assert_eq!(
            f.valve.registers.position,
            RegisterMap::device_default().position
        );
        assert_eq!(
            f.valve.registers.status,
            RegisterMap::device_default().status,
            "{name}"
        );
    }
}
