//! Start-up errors of the client that need no device: settings, budget, unreachable links.

use super::*;
use crate::link::{RtuLink, TcpLink};
use crate::map::RegisterMap;

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

/// A device whose position register reads `raw` (register 1; set-point in 0, status in 2).
async fn device_reading(raw: u16) -> std::net::SocketAddr {
    use crate::tcp_server::{self, Reply, Respond};
    use tokio_modbus::{Request, Response};
    struct NoValue(u16);
    impl Respond for NoValue {
        fn respond(&mut self, _unit: u8, request: &Request<'_>) -> Reply {
            let words = [500, self.0, 0];
            let response = match request {
                Request::ReadWriteMultipleRegisters(..) => {
                    Response::ReadWriteMultipleRegisters(words[1..].to_vec())
                }
                _ => Response::ReadHoldingRegisters(words[1..2].to_vec()),
            };
            Reply::Answer(Ok(response), Duration::ZERO)
        }
    }
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let limits = crate::net::Limits {
        max_connections: 2,
        idle_timeout: Duration::from_secs(5),
        controllers: Arc::default(),
    };
    tokio::spawn(tcp_server::serve(
        "test",
        listener,
        limits,
        Arc::default(),
        move |_, _| NoValue(raw),
    ));
    addr
}

#[tokio::test]
async fn a_no_value_code_is_an_error_with_its_raw_word_not_a_position() {
    let addr = device_reading(0x8000).await;
    let tcp = TcpLink {
        address: addr.to_string(),
        unit_id: 1,
        timeout_ms: Some(50.0),
    };
    let map = RegisterMap {
        fc23: true,
        ..RegisterMap::device_default()
    };
    let mut valve = ModbusValve::open(Link::Tcp(tcp), map, 0.01).await.unwrap();
    let fault = valve.transact(50.0).await.unwrap_err();
    assert!(
        matches!(fault, Fault::Error(ReplyError::Value(_))),
        "{fault:?}"
    );
    assert_eq!(
        fault.to_string(),
        "error: position reads [8000] = -3276.8 %, outside its valid range -10 to 110 % \
         (position_valid_pct): a transmitter's no-value code, or a wrong scale"
    );
}
