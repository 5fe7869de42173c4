//! Start-up errors of the client that need no device: settings, budget, unreachable links.

use super::*;
use crate::modbus::link::{RtuLink, TcpLink};
use crate::modbus::map::RegisterMap;

#[tokio::test]
async fn unreachable_devices_give_one_line_errors() {
    let rtu = RtuLink {
        baud: 115200,
        ..RtuLink::new("/dev/ttyUSB-missing-7")
    };
    let map = RegisterMap {
        fc23: true,
        ..RegisterMap::default()
    };
    let err = ModbusValve::open(Link::Rtu(rtu), map, 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("cannot open serial port /dev/ttyUSB-missing-7: "),
        "{err}"
    );
    assert!(
        err.ends_with("(check [valve.modbus-rtu] port)") && !err.contains('\n'),
        "{err}"
    );

    // A port nobody listens on (bound then released).
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let tcp = TcpLink {
        address: format!("127.0.0.1:{port}"),
        unit_id: 1,
        timeout_ms: None,
    };
    let err = ModbusValve::open(Link::Tcp(tcp), RegisterMap::default(), 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with(&format!("cannot connect to Modbus TCP 127.0.0.1:{port}: ")),
        "{err}"
    );

    let tcp = TcpLink {
        address: "no-port-here".into(),
        unit_id: 1,
        timeout_ms: None,
    };
    let err = ModbusValve::open(Link::Tcp(tcp), RegisterMap::default(), 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("valve.modbus-tcp.address: \"no-port-here\""),
        "{err}"
    );
}

#[tokio::test]
async fn settings_and_budget_are_checked_before_connecting() {
    let rtu = RtuLink::new("/dev/ttyUSB-missing-7"); // 19200 baud
    let err = ModbusValve::open(Link::Rtu(rtu.clone()), RegisterMap::default(), 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("bus budget: one cycle takes 30.6 ms"),
        "{err}"
    );
    let bad = RtuLink {
        stop_bits: 3,
        ..rtu
    };
    let err = ModbusValve::open(Link::Rtu(bad), RegisterMap::default(), 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.starts_with("valve.modbus-rtu.stop_bits: 3 is not allowed"),
        "{err}"
    );
}
