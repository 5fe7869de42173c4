//! Maximum sustainable transaction rate of the valve-bridge Modbus client against sim-device
//! over TCP loopback, next to a pymodbus client polling the same sim-device.
//!
//! `cargo bench -p sim-device --bench client_rate [-- SECONDS]` (default 3 s per case). Each case
//! runs back-to-back cycles (no loop pacing) and prints cycles/s, Modbus transactions/s and the
//! cycle latency percentiles. The pymodbus figure comes from `benches/pymodbus_rate.py` and is
//! skipped, with a message, when python3 or pymodbus is missing.

#[path = "../tests/common/mod.rs"]
mod common;

use std::process::Command;
use std::time::Instant;

use common::{percentile, Sim};
use vb_modbus::client::{Link, ModbusValve};
use vb_modbus::link::TcpLink;
use vb_modbus::map::RegisterMap;

fn main() {
    let secs: f64 = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(3.0);
    let device = Sim::start(&["--tcp", "127.0.0.1:0", "--model", "modelless"]);
    let addr = device.tcp.clone().expect("a `tcp: ADDR` line");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    println!("sim-device at {addr}, {secs} s per case");
    for fc23 in [true, false] {
        let map = RegisterMap {
            fc23,
            ..RegisterMap::default()
        };
        let per_cycle = if fc23 { 1 } else { 2 };
        let link = Link::Tcp(TcpLink {
            address: addr.clone(),
            unit_id: 1,
            timeout_ms: Some(100.0),
        });
        let mut valve = rt
            .block_on(ModbusValve::open(link, map, 0.01))
            .expect("client connects");
        let mut lat = Vec::with_capacity(200_000);
        let mut faults = 0u64;
        let start = Instant::now();
        let mut k = 0u64;
        while start.elapsed().as_secs_f64() < secs {
            let op = 20.0 + (k % 60) as f64;
            let t0 = Instant::now();
            if rt.block_on(valve.transact(op)).is_err() {
                faults += 1;
            }
            lat.push(t0.elapsed().as_secs_f64() * 1e6);
            k += 1;
        }
        let el = start.elapsed().as_secs_f64();
        lat.sort_by(f64::total_cmp);
        println!(
            "valve-bridge client, {}: {:.0} cycles/s = {:.0} transactions/s; cycle p50 {:.0} us, p99 {:.0} us, max {:.0} us; {} faults",
            if fc23 { "FC 23 (1 transaction/cycle)" } else { "FC 16 + FC 3 (2 transactions/cycle)" },
            k as f64 / el,
            (k * per_cycle) as f64 / el,
            percentile(&lat, 0.5),
            percentile(&lat, 0.99),
            percentile(&lat, 1.0),
            faults
        );
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/benches/pymodbus_rate.py");
    match Command::new("python3")
        .args([script, &addr, &secs.to_string()])
        .output()
    {
        Ok(out) if out.status.success() => print!("{}", String::from_utf8_lossy(&out.stdout)),
        Ok(out) => println!(
            "pymodbus comparison skipped: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ),
        Err(e) => println!("pymodbus comparison skipped: cannot run python3: {e}"),
    }
}
