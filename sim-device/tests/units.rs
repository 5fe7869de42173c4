//! Several units on one sim-device, and their drift, through the real binary over Modbus TCP
//! (the RTU side is tested from the daemon, `tests/modbus/daemon_bus.rs`):
//! - each unit id answers from its own registers and model; an id no unit has gets exception
//!   0B (gateway target device failed to respond); one unit alone answers any id;
//! - a unit's dead-time drift delays its valve more as it runs;
//! - bad unit settings fail at start, saying why.

mod common;

use std::time::{Duration, Instant};

use common::{run_to_end, Sim};
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::slave::SlaveContext;
use tokio_modbus::{ExceptionCode, Slave};

async fn connect(sim: &Sim) -> Context {
    let addr = sim.tcp.as_deref().expect("tcp announced").parse().unwrap();
    tokio_modbus::client::tcp::connect(addr).await.unwrap()
}

#[tokio::test]
async fn each_unit_id_has_its_own_valve_and_others_get_0b() {
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--unit",
        "1",
        "--unit",
        "2=modelless",
    ]);
    let mut ctx = connect(&sim).await;
    ctx.set_slave(Slave(2));
    ctx.write_single_register(0, 420).await.unwrap().unwrap();
    ctx.set_slave(Slave(1));
    ctx.write_single_register(0, 300).await.unwrap().unwrap();
    tokio::time::sleep(Duration::from_millis(100)).await;
    ctx.set_slave(Slave(2));
    // Modelless: V_P is the set-point at once.
    assert_eq!(
        ctx.read_holding_registers(0, 2).await.unwrap(),
        Ok(vec![420, 420])
    );
    ctx.set_slave(Slave(1));
    let words = ctx.read_holding_registers(0, 2).await.unwrap().unwrap();
    assert_eq!(words[0], 300);
    assert!(
        words[1] < 300,
        "pin-cart II has not arrived after 0.1 s: {words:?}"
    );
    ctx.set_slave(Slave(3));
    assert_eq!(
        ctx.read_holding_registers(0, 2).await.unwrap(),
        Err(ExceptionCode::GatewayTargetDevice)
    );
    // One unit alone answers whatever id a client sends.
    let one = Sim::start(&["--tcp", "127.0.0.1:0", "--unit", "5"]);
    let mut ctx = connect(&one).await;
    ctx.set_slave(Slave(9));
    assert!(ctx.read_holding_registers(0, 2).await.unwrap().is_ok());
}

/// Seconds from writing `to` (per mille) until unit 1's V_P shows it.
async fn delay_of_step(ctx: &mut Context, to: u16) -> f64 {
    ctx.write_single_register(0, to).await.unwrap().unwrap();
    let start = Instant::now();
    loop {
        let words = ctx.read_holding_registers(1, 1).await.unwrap().unwrap();
        if words[0] == to {
            return start.elapsed().as_secs_f64();
        }
        assert!(
            start.elapsed() < Duration::from_secs(3),
            "V_P never reached {to}"
        );
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

#[tokio::test]
async fn a_unit_with_dead_time_drift_answers_later_as_it_runs() {
    // 360 s/h: the dead time grows by 0.1 s per second of running, up to 0.5 s.
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--unit",
        "1=modelless,dead_time_drift_s_per_h=360,dead_time_drift_max_s=0.5",
    ]);
    let started = Instant::now();
    let mut ctx = connect(&sim).await;
    let early = delay_of_step(&mut ctx, 100).await;
    let early_at = started.elapsed().as_secs_f64();
    tokio::time::sleep(Duration::from_millis(3000)).await;
    let late = delay_of_step(&mut ctx, 200).await;
    let late_at = started.elapsed().as_secs_f64();
    assert!(early < 0.1 * early_at + 0.1, "{early} s after {early_at} s");
    // Written at about `late_at - late`, seen `late` later, when the dead time is a tenth of
    // the time run: late ≈ 0.1 * late_at.
    assert!(
        late > 0.25 && (late - 0.1 * late_at).abs() < 0.1,
        "{late} s after {late_at} s"
    );
}

#[test]
fn bad_units_fail_saying_why() {
    for (args, want) in [
        (
            vec![
                "--tcp",
                "127.0.0.1:0",
                "--unit",
                "1=fopdt,friction_band_drift_pct_per_h=1",
            ],
            "only a pin-cart model (pincart1, pincart2) has a friction band to widen",
        ),
        (
            vec![
                "--tcp",
                "127.0.0.1:0",
                "--unit",
                "1",
                "--unit",
                "1=modelless",
            ],
            "--unit 1: two units at one address",
        ),
        (
            vec!["--tcp", "127.0.0.1:0", "--unit", "300"],
            "a unit id is 1-247",
        ),
    ] {
        let (ok, err) = run_to_end(&args);
        assert!(!ok, "{args:?}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}
