//! Independent Modbus implementations against sim-device: mbpoll (libmodbus) and pymodbus,
//! over TCP and RTU on a pseudo-terminal. Without those tools a test cannot run: see
//! `tests/common/tools.rs` (a visible SKIPPED line, or a failure under `VB_REQUIRE_TOOLS=1`).

mod common;

use std::process::Command;
use std::time::Duration;

use common::tools::{have_mbpoll, have_pymodbus};
use common::Sim;

fn mbpoll(endpoint: &[&str], extra: &[&str]) -> String {
    let out = Command::new("mbpoll")
        .args(endpoint)
        .args(["-a", "1", "-t", "4", "-1", "-q"])
        .args(extra)
        .output()
        .expect("mbpoll runs");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "mbpoll {endpoint:?} {extra:?} failed: {text}"
    );
    text
}

/// Writes 420 per mille with mbpoll, then reads set-point and position back.
fn mbpoll_round_trip(endpoint: &[&str], target: &str) {
    mbpoll(endpoint, &["-r", "1", target, "420"]);
    std::thread::sleep(Duration::from_millis(100));
    let read = mbpoll(endpoint, &["-r", "1", "-c", "2", target]);
    assert!(
        read.contains("[1]: \t420") && read.contains("[2]: \t420"),
        "{read}"
    );
}

#[test]
fn mbpoll_reads_and_writes_over_tcp() {
    if !have_mbpoll() {
        return;
    }
    let sim = Sim::start(&["--tcp", "127.0.0.1:0", "--model", "modelless"]);
    let addr = sim.tcp.clone().expect("tcp endpoint");
    let (host, port) = addr.rsplit_once(':').expect("host:port");
    mbpoll_round_trip(&["-m", "tcp", "-p", port], host);
}

#[test]
fn mbpoll_reads_and_writes_over_rtu_pty() {
    if !have_mbpoll() {
        return;
    }
    let sim = Sim::start(&["--pty", "--model", "modelless"]);
    let pty = sim.pty.clone().expect("pty endpoint");
    mbpoll_round_trip(&["-m", "rtu", "-b", "19200", "-P", "even"], &pty);
}

const PY: &str = r#"
import sys, time, inspect
from pymodbus.client import ModbusTcpClient, ModbusSerialClient
kind, where = sys.argv[1], sys.argv[2]
if kind == "tcp":
    host, port = where.rsplit(":", 1)
    c = ModbusTcpClient(host, port=int(port), timeout=1)
else:
    # Parity N: this kernel's pseudo-terminals refuse PARENB in tcsetattr (a pty has no parity
    # anyway), and pyserial, unlike libmodbus and serialport, does not ignore that error.
    c = ModbusSerialClient(where, baudrate=19200, parity="N", timeout=1)
assert c.connect(), "connect"
kw = "device_id" if "device_id" in inspect.signature(c.read_holding_registers).parameters else "slave"
u = {kw: 1}
assert not c.write_registers(0, [650], **u).isError()
time.sleep(0.1)
r = c.read_holding_registers(0, count=2, **u)
assert not r.isError(), r
print("read", r.registers)
r = c.readwrite_registers(read_address=1, read_count=1, write_address=0, values=[300], **u)
assert not r.isError(), r
print("fc23", r.registers)
r = c.read_holding_registers(9, count=1, **u)
print("unmapped", r.isError(), r.exception_code)
r = c.write_register(1, 5, **u)
print("read-only", r.isError(), r.exception_code)
c.close()
"#;

fn pymodbus(kind: &str, where_: &str) -> String {
    let out = Command::new("python3")
        .args(["-c", PY, kind, where_])
        .output()
        .expect("python3 runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "pymodbus {kind} failed: {text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    text
}

fn check_pymodbus(text: &str) {
    // 650 per mille was written and the modelless valve followed.
    assert!(
        text.contains("read [650, 650, 0]") || text.contains("read [650, 650]"),
        "{text}"
    );
    // FC 23 writes 300, then reads the position, still at 650 (the model steps every 10 ms).
    assert!(
        text.contains("fc23 [650]") || text.contains("fc23 [300]"),
        "{text}"
    );
    assert!(
        text.contains("unmapped True 2"),
        "exception 02 for an unmapped address: {text}"
    );
    assert!(
        text.contains("read-only True 2"),
        "exception 02 for the read-only position: {text}"
    );
}

#[test]
fn pymodbus_reads_and_writes_over_tcp() {
    if !have_pymodbus() {
        return;
    }
    let sim = Sim::start(&["--tcp", "127.0.0.1:0", "--model", "modelless"]);
    check_pymodbus(&pymodbus("tcp", sim.tcp.as_deref().unwrap_or("")));
}

#[test]
fn pymodbus_reads_and_writes_over_rtu_pty() {
    if !have_pymodbus() {
        return;
    }
    let sim = Sim::start(&["--pty", "--model", "modelless"]);
    check_pymodbus(&pymodbus("rtu", sim.pty.as_deref().unwrap_or("")));
}
