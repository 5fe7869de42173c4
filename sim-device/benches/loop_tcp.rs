//! The daemon's valve loop against sim-device over Modbus TCP loopback: its timing at 100 Hz,
//! the transaction round trip, and the highest loop rate it sustains.
//!
//! `cargo bench -p sim-device --bench loop_tcp [-- SECONDS]` (default 20 s at 100 Hz; the rate
//! sweep adds about 3 s per rate).
//!
//! It starts sim-device (`--tcp 127.0.0.1:0` with the map of `config/sim-device-tcp.toml`) and
//! runs the real loop through the library, as `valve-bridge run` does (`vb_daemon::start`, real
//! clock, normal priority, CSV log in a temporary directory), with that config: `[valve] kind =
//! "modbus-tcp"`, FC 23 (one transaction per cycle), random steps as the source.
//!
//! 1. SECONDS at 100 Hz with the shipped 8 ms deadline: the timing error |actual - scheduled|
//!    p50/p99/max (the summary's figures; the target is p99 <= 250 µs), missed cycles,
//!    faults, and the transaction round trip p50/p99/max (the log's `latency_us` over the `ok`
//!    rows: write O_P and read V_P, from the loop's side).
//! 2. 3 s at each of 200, 500, 1000, 2000, 4000 and 8000 Hz with the default deadline (80 % of
//!    the period), until a rate misses a cycle or has a fault: the highest rate before that.
//!    `[loop] rate_hz` accepts at most 1000 Hz; the rates above are set on the loaded `Config`
//!    to show the headroom.
//!
//! `VB_BENCH_PRIORITY=N` runs the loop thread under SCHED_FIFO priority N (`[loop]
//! realtime_priority`; needs root or CAP_SYS_NICE), as `benches/loop_timing.rs` does. The figures
//! depend on the machine and its load: run it on an otherwise idle machine.

#[path = "../tests/common/mod.rs"]
mod common;

use std::error::Error;
use std::path::{Path, PathBuf};

use common::{percentile, Sim};
use vb_core::recording::log_format::Status;
use vb_daemon::config::ValveSpec;
use vb_daemon::{Config, RunOptions, ValveSummary};

/// The shipped daemon config for sim-device over TCP.
const SHIPPED: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/sim-device-tcp.toml");

/// Rates of the sweep, Hz.
const SWEEP_HZ: [f64; 6] = [200.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0];

/// Seconds per rate of the sweep.
const SWEEP_SECS: f64 = 3.0;

/// One run: its summary and the round trips of its `ok` rows, µs, ascending.
struct Run {
    summary: ValveSummary,
    round_trips_us: Vec<f64>,
}

impl Run {
    fn count(&self, status: Status) -> u64 {
        self.summary.stats.count(status)
    }

    /// Failed transactions of any kind.
    fn faults(&self) -> u64 {
        self.count(Status::Timeout) + self.count(Status::Error) + self.count(Status::Disconnected)
    }

    fn round_trip_us(&self, q: f64) -> f64 {
        percentile(&self.round_trips_us, q)
    }
}

fn main() -> Result<(), Box<dyn Error>> {
    let secs: f64 = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(20.0);
    let priority: u8 = match std::env::var("VB_BENCH_PRIORITY") {
        Ok(v) => v
            .parse()
            .map_err(|e| format!("VB_BENCH_PRIORITY={v}: {e}"))?,
        Err(_) => 0,
    };
    let device = Sim::start(&["--tcp", "127.0.0.1:0", "--config", SHIPPED]);
    let addr = device
        .tcp
        .clone()
        .ok_or("sim-device announced no TCP address")?;
    println!(
        "loop_tcp: daemon loop against sim-device at {addr} (Modbus TCP loopback, FC 23), SCHED_FIFO priority {priority}"
    );
    let config = |rate_hz, shipped_deadline| -> Result<Config, Box<dyn Error>> {
        let mut c = config(&addr, rate_hz, shipped_deadline)?;
        c.loop_.realtime_priority = priority;
        Ok(c)
    };

    let r = run(config(100.0, true)?, secs)?;
    let s = &r.summary.stats;
    println!(
        "100 Hz for {secs} s: {} samples ({} ok, {} timeout, {} error, {} disconnected), {} missed cycles, {} reconnects",
        r.summary.samples(),
        r.count(Status::Ok),
        r.count(Status::Timeout),
        r.count(Status::Error),
        r.count(Status::Disconnected),
        r.summary.missed(),
        r.summary.link.unwrap_or_default().reconnects
    );
    println!(
        "  timing error |actual - scheduled|: p50 {:.2} us, p99 {:.2} us, max {:.2} us (target p99 <= 250 us: {})",
        s.lateness_us(0.5),
        s.lateness_us(0.99),
        s.max_lateness_us(),
        if s.lateness_us(0.99) <= 250.0 { "met" } else { "missed" }
    );
    println!(
        "  transaction round trip (write O_P + read V_P, ok rows): p50 {:.0} us, p99 {:.0} us, max {:.0} us",
        r.round_trip_us(0.5),
        r.round_trip_us(0.99),
        r.round_trip_us(1.0)
    );

    println!("rate sweep, {SWEEP_SECS} s each, deadline 80 % of the period:");
    let mut sustained = None;
    for rate in SWEEP_HZ {
        let r = run(config(rate, false)?, SWEEP_SECS)?;
        let ok = r.summary.missed() == 0 && r.faults() == 0;
        println!(
            "  {rate:>5} Hz: {} samples, {} missed cycles, {} faults ({} timeout); timing error p99 {:.1} us, max {:.1} us; round trip p50 {:.0} us, p99 {:.0} us: {}",
            r.summary.samples(),
            r.summary.missed(),
            r.faults(),
            r.count(Status::Timeout),
            r.summary.stats.lateness_us(0.99),
            r.summary.stats.max_lateness_us(),
            r.round_trip_us(0.5),
            r.round_trip_us(0.99),
            if ok { "sustained" } else { "not sustained" }
        );
        if !ok {
            break;
        }
        sustained = Some(rate);
    }
    match sustained {
        Some(rate) => {
            println!("highest sustained loop rate: {rate} Hz (0 missed cycles, 0 faults)")
        }
        None => println!("highest sustained loop rate: below {} Hz", SWEEP_HZ[0]),
    }
    Ok(())
}

/// The shipped TCP config pointed at `addr`, at `rate_hz`, with the shipped deadline or the
/// default one (80 % of the period).
fn config(addr: &str, rate_hz: f64, shipped_deadline: bool) -> Result<Config, Box<dyn Error>> {
    let mut config = Config::load(Some(Path::new(SHIPPED)))?;
    config.loop_.rate_hz = rate_hz;
    let tcp = match config.valves.first_mut().map(|v| &mut v.backend) {
        Some(ValveSpec::ModbusTcp(tcp, _)) => tcp,
        _ => return Err("the shipped config has no [valve.modbus-tcp]".into()),
    };
    tcp.address = addr.to_string();
    if !shipped_deadline {
        tcp.timeout_ms = None;
    }
    Ok(config)
}

/// Runs the loop for `secs` on the real clock, logging to a temporary directory.
fn run(config: Config, secs: f64) -> Result<Run, Box<dyn Error>> {
    let dir = tempfile::tempdir()?;
    let summary = vb_daemon::start(
        config,
        RunOptions {
            duration_s: Some(secs),
            log_dir: Some(dir.path().to_path_buf()),
            virtual_clock: false,
            progress: false,
            require_device: true,
            // The config has no [health] or [diagnosis]: nothing runs beside the loop.
            analysis: vb_daemon::Analysis::default(),
        },
    )?
    .finish()?
    .valves
    .into_iter()
    .next()
    .ok_or("the run has no valve")?;
    let round_trips_us = ok_latencies_us(&summary.log.files)?;
    Ok(Run {
        summary,
        round_trips_us,
    })
}

/// The `latency_us` of the `ok` rows of the log files, ascending.
fn ok_latencies_us(files: &[PathBuf]) -> Result<Vec<f64>, Box<dyn Error>> {
    let mut out = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(file)?;
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap_or_default().split(',').collect();
        let column = |name: &str| {
            header
                .iter()
                .position(|h| *h == name)
                .ok_or_else(|| format!("{}: no `{name}` column", file.display()))
        };
        let (status, latency) = (column("status")?, column("latency_us")?);
        for line in lines {
            let cells: Vec<&str> = line.split(',').collect();
            if cells.get(status) == Some(&Status::Ok.as_str()) {
                if let Some(us) = cells.get(latency).and_then(|c| c.parse().ok()) {
                    out.push(us);
                }
            }
        }
    }
    out.sort_by(f64::total_cmp);
    Ok(out)
}
