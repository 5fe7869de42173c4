//! What the loop calls every cycle for the `modbus-server` source and the Prometheus metrics
//! allocates nothing: reading the controller's set-point, publishing V_P and status, and
//! updating the metric handles. Nor does walking a response test's plan (its O_P, and judging
//! from each row whether V_P has settled), nor stepping a model (the physical valve, with its internal
//! steps and seeded sensor noise), nor a drifting one, nor compensating a set-point and judging
//! its guard windows. A Modbus cycle, over TCP and over RTU against sim-device, allocates no
//! more than tokio-modbus's own call does (its request future and the reply's words, which
//! its API allocates). A counting global allocator (this test binary only) counts the
//! allocations made on the calling thread around those calls.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;
use std::time::Duration;

use tokio_modbus::client::Reader;
use tokio_modbus::{Request, Slave};
use tokio_serial::SerialPortBuilderExt;
use valve_bridge::compensate::{CompensationConfig, Compensator};
use valve_bridge::daemon::config::{Config, ValveSpec};
use valve_bridge::daemon::runtime::source::Source;
use valve_bridge::daemon::serve::exporter::LoopMetrics;
use valve_bridge::modbus::client::{LinkStats, ModbusValve};
use valve_bridge::modbus::link::{Link, RtuLink, TcpLink};
use valve_bridge::model::{bundled, Drift, DriftSpec, ModelKind, Valve};
use valve_bridge::recording::log_format::{Sample, Status};

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to the system allocator unchanged; counting touches only a
// const-initialised thread-local cell, which does not allocate.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        System.alloc(layout)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// Runs `f` and returns how many allocations it made on this thread.
fn allocations(f: impl FnOnce()) -> u64 {
    let before = ALLOCATIONS.with(Cell::get);
    f();
    ALLOCATIONS.with(Cell::get) - before
}

#[test]
fn per_cycle_calls_do_not_allocate() {
    let cfg = Config::from_toml(
        "[source]\nkind = \"modbus-server\"\n[source.modbus-server]\nwatchdog_s = 60.0\n[metrics]\n",
        Path::new("t.toml"),
    )
    .unwrap();
    let mut source = Source::new(&cfg.source, &cfg.safety, cfg.loop_.period_s());
    let bank = source.served_bank().unwrap().clone();
    let metrics = LoopMetrics::new(&["level", "cyclone"], false).unwrap();
    let valve = metrics.valve(1).unwrap();
    let mut counted = 0;
    for k in 0..500u64 {
        if k % 50 == 0 {
            // The controller's write (the server's side, outside the count).
            bank.handle(&Request::WriteSingleRegister(0, (k / 5) as u16))
                .unwrap();
        }
        let t_s = k as f64 * 0.01;
        counted += allocations(|| {
            let op = source.op_at(t_s);
            let status = match k % 7 {
                0 => Status::Timeout,
                1 => Status::Skipped,
                _ => Status::Ok,
            };
            let row = Sample {
                t_s,
                op_pct: op,
                vp_pct: (status == Status::Ok).then_some(42.0),
                status,
                lateness_us: None,
                latency_us: None,
                op_sent_pct: op,
                op_controller_pct: op,
                utc: std::time::SystemTime::UNIX_EPOCH,
            };
            source.feedback(&row);
            let lateness = (status != Status::Skipped).then(|| Duration::from_micros(k));
            if let Some(l) = lateness {
                metrics.timing(l);
            }
            valve.record(&row);
            let link = LinkStats {
                reconnects: k / 100,
                attempts: k / 100 + 1,
                late_replies: k / 10,
                noise_bytes: k,
                unexpected_replies: k / 50,
                late_reply_ms: Some(100),
            };
            valve.totals(link, source.watchdog_trips());
        });
        let op = source.op_at(t_s).unwrap();
        assert!((op - (k / 50) as f64).abs() < 1e-9, "{op} at cycle {k}");
    }
    assert_eq!(counted, 0, "allocations in 500 cycles");
    // The counter does count.
    assert_eq!(allocations(|| drop(std::hint::black_box(vec![0u8; 64]))), 1);
}

#[test]
fn walking_a_response_tests_plan_does_not_allocate() {
    let config = Config::embedded_default().unwrap();
    let test =
        valve_bridge::daemon::response::Test::new(config, Path::new("t.toml"), None, "quick")
            .unwrap();
    let cfg = &test.config;
    let mut source = Source::new(&cfg.source, &cfg.safety, cfg.loop_.period_s());
    let (mut vp, mut k, mut counted) = (50.0, 0u64, 0);
    loop {
        let t_s = k as f64 * 0.01;
        let mut op = None;
        counted += allocations(|| {
            op = source.op_at(t_s);
            if let Some(op) = op {
                let row = Sample {
                    t_s,
                    op_pct: Some(op),
                    vp_pct: (k % 9 != 0).then_some(vp),
                    status: if k % 9 != 0 {
                        Status::Ok
                    } else {
                        Status::Timeout
                    },
                    lateness_us: None,
                    latency_us: None,
                    op_sent_pct: Some(op),
                    op_controller_pct: Some(op),
                    utc: std::time::SystemTime::UNIX_EPOCH,
                };
                source.feedback(&row);
                std::hint::black_box(source.progress());
            }
        });
        let Some(op) = op else { break };
        vp += 0.1 * (op - vp);
        k += 1;
    }
    assert_eq!(source.progress(), Some((29, 29)));
    assert_eq!(
        counted, 0,
        "allocations in the {k} cycles of the quick plan"
    );
}

#[test]
fn stepping_a_physical_valve_does_not_allocate() {
    let mut valve = Valve::new(&bundled(ModelKind::Physical), 0.01).unwrap();
    valve.reset(30.0, 30.0);
    let mut last = 0.0;
    let counted = allocations(|| {
        for k in 0..2000 {
            let op = if (k / 300) % 2 == 0 { 30.0 } else { 70.0 };
            last = valve.step(op);
        }
        valve.reset(50.0, 50.0);
    });
    assert_eq!(counted, 0, "allocations in 2000 steps");
    assert!(last.is_finite());
}

#[test]
fn stepping_a_drifting_valve_does_not_allocate() {
    let mut valve = Valve::new(&bundled(ModelKind::Pincart2), 0.01).unwrap();
    let spec = DriftSpec {
        dead_time_drift_s_per_h: 3600.0,
        dead_time_drift_max_s: 1.0,
        friction_band_drift_pct_per_h: 100.0,
        ..DriftSpec::default()
    };
    let mut drift = Drift::new(&spec, &valve).unwrap().unwrap();
    valve.reset(30.0, 30.0);
    drift.reset(30.0);
    let mut last = 0.0;
    let counted = allocations(|| {
        for k in 0..2000u64 {
            let op = if (k / 300) % 2 == 0 { 30.0 } else { 70.0 };
            last = drift.step(&mut valve, op, k);
        }
    });
    assert_eq!(counted, 0, "allocations in 2000 steps");
    assert!(last > 29.0, "{last}");
}

#[test]
fn compensating_a_set_point_does_not_allocate() {
    // A pin-cart II valve with a crossing time, a deadband and a calibration error: every part
    // acts, and the guard judges its windows (two a second here).
    let mut model = bundled(ModelKind::Pincart2);
    model.effects.deadband_pct = 0.4;
    model.effects.calibration_gain = 0.95;
    let cfg = CompensationConfig {
        model_file: Some("model.toml".into()),
        guard_window_s: 0.5,
        ..CompensationConfig::default()
    };
    let mut comp = Compensator::new(&cfg, &model, 0.01, (0.0, 100.0)).unwrap();
    let mut valve = Valve::new(&model, 0.01).unwrap();
    valve.reset(30.0, 30.0);
    let (mut windows, mut kicked) = (0, 0);
    let counted = allocations(|| {
        for k in 0..3000 {
            // Steps of 1 % that reverse every 3 s, and a missed slot now and then.
            if k % 97 == 0 {
                continue;
            }
            let op = 30.0 + f64::from((k / 300) % 2);
            let sent = comp.setpoint(op, f64::from(k) * 0.01);
            kicked += usize::from((sent - op).abs() > 0.5);
            windows += usize::from(comp.observe(Some(valve.step(sent))).is_some());
        }
    });
    assert_eq!(counted, 0, "allocations in 3000 cycles");
    assert!(
        windows >= 50 && kicked > 0,
        "{windows} windows, {kicked} kicks"
    );
}

mod common;

/// A Modbus cycle of the shipped sim-device configs (one FC 23 transaction: write the
/// set-point, read set-point, position and status) against sim-device over `args`: the
/// allocations of each of 40 cycles through [`ModbusValve::cycle`], and of 40 bare tokio-modbus
/// calls of the same transaction on the same device.
fn modbus_cycle_allocations(args: &[&str]) -> (Vec<u64>, Vec<u64>) {
    let dev = common::sim::SimDevice::start(args);
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join(dev.shipped.0);
    let cfg = Config::load(Some(&shipped)).unwrap();
    // A deadline no stall of a loaded machine reaches: a timeout would allocate its message.
    let (link, device) = match &cfg.valves[0].backend {
        ValveSpec::ModbusTcp(tcp, device) => (
            Link::Tcp(TcpLink {
                address: dev.endpoint.clone(),
                timeout_ms: Some(900.0),
                ..tcp.clone()
            }),
            device,
        ),
        ValveSpec::ModbusRtu(rtu, device) => (
            Link::Rtu(RtuLink {
                port: dev.endpoint.clone(),
                timeout_ms: Some(900.0),
                ..rtu.clone()
            }),
            device,
        ),
        ValveSpec::Emulated(_) => panic!("{} names no Modbus link", dev.shipped.0),
    };
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let mut valve = ModbusValve::new(link.clone(), device.registers, 1.0).unwrap();
    rt.block_on(valve.connect_now()).unwrap();
    let mut cycle = |k: u64| {
        let c = rt.block_on(valve.cycle(40.0 + (k % 3) as f64));
        assert!(c.vp_pct.is_ok(), "cycle {k}: {c:?}");
    };
    // The first cycles size what is kept from cycle to cycle.
    (0..5).for_each(&mut cycle);
    let ours = (5..45).map(|k| allocations(|| cycle(k))).collect();
    drop(valve);
    let mut ctx = match &link {
        Link::Tcp(l) => {
            let addr = l.address.parse().unwrap();
            rt.block_on(tokio_modbus::client::tcp::connect_slave(addr, Slave(1)))
                .unwrap()
        }
        Link::Rtu(l) => {
            let port = rt
                .block_on(async { tokio_serial::new(&l.port, l.baud).open_native_async() })
                .unwrap();
            tokio_modbus::client::rtu::attach_slave(port, Slave(l.slave_id))
        }
    };
    let mut bare = |k: u16| {
        let words = [400 + k % 3];
        let r = rt.block_on(ctx.read_write_multiple_registers(0, 3, 0, &words));
        assert!(matches!(r, Ok(Ok(_))), "bare call {k}: {r:?}");
    };
    (0..5).for_each(&mut bare);
    let floor = (5..45).map(|k| allocations(|| bare(k))).collect();
    (ours, floor)
}

/// A Modbus cycle allocates nothing of its own: no more than tokio-modbus itself allocates for
/// the transaction (its request future and the reply's words), over TCP and over RTU on a
/// pseudo-terminal.
#[test]
fn a_modbus_cycle_allocates_only_what_tokio_modbus_does() {
    for args in [&["--tcp", "127.0.0.1:0"][..], &["--pty"][..]] {
        let (ours, floor) = modbus_cycle_allocations(args);
        let most = floor.iter().copied().max().unwrap();
        assert!(
            most > 0 && ours.iter().all(|&n| n <= most),
            "{args:?}: allocations per cycle {ours:?}, tokio-modbus alone {floor:?}"
        );
    }
}
