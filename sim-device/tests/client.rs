//! The valve-bridge Modbus client against the real sim-device: cycles over TCP and RTU (pty),
//! injected faults reported as the right kinds, reconnection, the set-point error flag and the
//! line-speed emulation against the bus budget.

mod common;

use std::time::{Duration, Instant};

use common::{free_port, Sim};
use vb_modbus::client::{Fault, Link, ModbusValve, Reading, ReplyError, Timeout};
use vb_modbus::link::{RtuLink, TcpLink};
use vb_modbus::map::{RegisterMap, StatusRegister, Table};

fn tcp(addr: &str, timeout_ms: f64) -> Link {
    Link::Tcp(TcpLink {
        address: addr.to_string(),
        unit_id: 1,
        timeout_ms: Some(timeout_ms),
    })
}

fn rtu(port: &str, baud: u32, timeout_ms: f64) -> Link {
    Link::Rtu(RtuLink {
        baud,
        timeout_ms: Some(timeout_ms),
        ..RtuLink::new(port)
    })
}

fn fc23() -> RegisterMap {
    RegisterMap {
        fc23: true,
        ..RegisterMap::default()
    }
}

/// Cycles at `op` every 10 ms until V_P reaches it (modelless valve: one model step).
async fn settle(v: &mut ModbusValve, op: f64) -> Reading {
    let mut last = None;
    for _ in 0..100 {
        match v.transact(op).await {
            Ok(r) if (r.vp_pct - op).abs() < 1e-9 => return r,
            other => last = Some(other),
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    panic!("V_P never reached {op} %: last {last:?}");
}

/// The kind of each of `n` cycles, `pause` apart.
async fn kinds(v: &mut ModbusValve, n: usize, pause: Duration) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    for k in 0..n {
        let r = v.transact(30.0 + k as f64).await;
        out.push(match r {
            Ok(_) => ("ok", String::new()),
            Err(Fault::Timeout(t)) => ("timeout", t.to_string()),
            Err(Fault::Error(e)) => ("error", e.to_string()),
            Err(Fault::Disconnected(d)) => ("disconnected", d.to_string()),
        });
        tokio::time::sleep(pause).await;
    }
    out
}

fn names(k: &[(&'static str, String)]) -> Vec<&'static str> {
    k.iter().map(|(n, _)| *n).collect()
}

#[tokio::test]
async fn tcp_cycles_with_and_without_fc23() {
    let sim = Sim::start(&["--tcp", "127.0.0.1:0", "--model", "modelless"]);
    let addr = sim.tcp.clone().expect("tcp endpoint");
    for map in [fc23(), RegisterMap::default()] {
        let mut v = ModbusValve::open(tcp(&addr, 50.0), map, 0.01)
            .await
            .expect("connects");
        settle(&mut v, 37.5).await;
        settle(&mut v, 80.0).await;
        assert_eq!(v.reconnects(), 0);
    }
}

#[tokio::test]
async fn rtu_over_pty_cycles() {
    let sim = Sim::start(&["--pty", "--model", "modelless"]);
    let pty = sim.pty.clone().expect("pty endpoint");
    let mut v = ModbusValve::open(rtu(&pty, 115200, 50.0), fc23(), 0.01)
        .await
        .expect("opens the pty");
    assert!(v
        .budget()
        .is_some_and(|b| (b.cycle_s - 0.0068).abs() < 1e-4));
    settle(&mut v, 12.3).await;
    settle(&mut v, 99.9).await;
}

#[tokio::test]
async fn a_dropped_reply_costs_its_own_cycle_only() {
    let sim = Sim::start(&["--pty", "--model", "modelless", "--drop-every", "3"]);
    let mut v = ModbusValve::open(
        rtu(sim.pty.as_deref().unwrap_or(""), 115200, 30.0),
        fc23(),
        0.01,
    )
    .await
    .expect("opens");
    // Back to back: the cycle after a lost reply is answered, on the same port.
    let k = kinds(&mut v, 6, Duration::ZERO).await;
    assert_eq!(
        names(&k),
        ["ok", "ok", "timeout", "ok", "ok", "timeout"],
        "{k:?}"
    );
    assert!(k[2].1.contains("no reply to FC 23 within 30 ms"), "{k:?}");
    assert_eq!(
        (v.reconnects(), v.attempts()),
        (0, 1),
        "the port stays open"
    );
}

#[tokio::test]
async fn corrupted_crc_is_an_error_not_a_timeout() {
    let sim = Sim::start(&["--pty", "--model", "modelless", "--corrupt-crc-every", "2"]);
    let mut v = ModbusValve::open(
        rtu(sim.pty.as_deref().unwrap_or(""), 115200, 30.0),
        fc23(),
        0.01,
    )
    .await
    .expect("opens");
    let k = kinds(&mut v, 4, Duration::ZERO).await;
    assert_eq!(names(&k), ["ok", "error", "ok", "error"], "{k:?}");
    assert!(k[1].1.starts_with("CRC error in reply to FC 23"), "{k:?}");
    assert_eq!(
        (v.reconnects(), v.attempts()),
        (0, 1),
        "the port stays open"
    );
}

#[tokio::test]
async fn exceptions_are_errors_and_keep_the_link() {
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--model",
        "modelless",
        "--exception-every",
        "2",
    ]);
    let mut v = ModbusValve::open(tcp(sim.tcp.as_deref().unwrap_or(""), 50.0), fc23(), 0.01)
        .await
        .expect("connects");
    let k = kinds(&mut v, 4, Duration::from_millis(5)).await;
    assert_eq!(names(&k), ["ok", "error", "ok", "error"], "{k:?}");
    assert!(
        k[1].1
            .contains("with exception 04 (server device failure: the device failed"),
        "{k:?}"
    );
    assert!(v.is_connected());
    assert_eq!(v.reconnects(), 0);
}

#[tokio::test]
async fn late_replies_are_timeouts_and_keep_the_connection() {
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--model",
        "modelless",
        "--delay-ms",
        "40",
    ]);
    let mut v = ModbusValve::open(tcp(sim.tcp.as_deref().unwrap_or(""), 20.0), fc23(), 0.01)
        .await
        .expect("connects");
    let t0 = Instant::now();
    let r = v.transact(50.0).await;
    assert_eq!(
        r,
        Err(Fault::Timeout(Timeout {
            fc: 23,
            ms: 20,
            partial: None,
            late_replies: 0,
            held: None,
        }))
    );
    assert_eq!(
        r.unwrap_err().to_string(),
        "timeout: no reply to FC 23 within 20 ms"
    );
    // The deadline holds: a call that waited for the reply (40 ms) would have read it, not
    // timed out; and it gives up no earlier than its deadline.
    assert!(
        t0.elapsed() >= Duration::from_millis(20),
        "gave up before the deadline: {:?}",
        t0.elapsed()
    );
    assert!(v.is_connected(), "a late reply does not break the link");
    assert_eq!(v.attempts(), 1);
}

#[tokio::test]
async fn a_late_reply_costs_its_own_cycle_only() {
    // Every 4th reply comes 15 ms late against an 8 ms deadline, in the middle of the next
    // cycle: it must not be taken for that cycle's answer, nor any later one's.
    for map in [fc23(), RegisterMap::default()] {
        let sim = Sim::start(&[
            "--tcp",
            "127.0.0.1:0",
            "--model",
            "modelless",
            "--delay-ms",
            "15",
            "--delay-every",
            "4",
        ]);
        let requests = if map.fc23 { 1 } else { 2 };
        let mut v = ModbusValve::open(tcp(sim.tcp.as_deref().unwrap_or(""), 8.0), map, 0.01)
            .await
            .expect("connects");
        let mut got = Vec::new();
        for k in 0..12 {
            let op = 30.0 + k as f64;
            got.push(match v.transact(op).await {
                // A late reply taken for this cycle's would be refused by tokio-modbus as a
                // header mismatch (an error, below), and shift every later reply by one.
                Ok(_) => "ok",
                Err(Fault::Timeout(_)) => "timeout",
                Err(f) => panic!("cycle {k}: {f}"),
            });
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        let late = got.iter().filter(|g| **g == "timeout").count();
        // Every 4th request is late; a busy machine may make a cycle or two late as well.
        let want = 12 * requests / 4;
        assert!((want..=want + 2).contains(&late), "{got:?}");
        assert_eq!(v.attempts(), 1, "one connection throughout: {got:?}");
    }
}

#[tokio::test]
async fn tcp_disconnects_are_reported_and_recovered() {
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--model",
        "modelless",
        "--disconnect-after",
        "3",
    ]);
    let mut v = ModbusValve::open(tcp(sim.tcp.as_deref().unwrap_or(""), 50.0), fc23(), 0.01)
        .await
        .expect("connects");
    // Back to back: the link had answered, so it is reopened in the very next cycle.
    let k = kinds(&mut v, 6, Duration::ZERO).await;
    assert_eq!(
        names(&k),
        ["ok", "ok", "disconnected", "ok", "ok", "disconnected"],
        "{k:?}"
    );
    assert_eq!(v.reconnects(), 1);
    // Said as what happened, not as the thread's last errno (`Operation now in progress`).
    assert!(
        k[2].1.ends_with("FC 23: the device closed the connection"),
        "{k:?}"
    );
    assert!(!k.iter().any(|(_, m)| m.contains("os error")), "{k:?}");
}

#[tokio::test]
async fn device_killed_and_restarted_mid_run() {
    let port = free_port();
    let addr = format!("127.0.0.1:{port}");
    let args = ["--tcp", addr.as_str(), "--model", "modelless"];
    let mut sim = Sim::start(&args);
    let mut v = ModbusValve::open(tcp(&addr, 20.0), fc23(), 0.01)
        .await
        .expect("connects");
    settle(&mut v, 40.0).await;
    sim.kill();
    let k = kinds(&mut v, 5, Duration::from_millis(10)).await;
    assert!(k.iter().all(|(n, _)| *n == "disconnected"), "{k:?}");
    let _sim = Sim::start(&args);
    let t0 = Instant::now();
    loop {
        if v.transact(40.0).await.is_ok() {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(3),
            "no reconnect within 3 s"
        );
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    assert!(v.reconnects() >= 1);
    // The new device starts closed; the set-point is written again and followed.
    settle(&mut v, 40.0).await;
}

#[tokio::test]
async fn out_of_range_set_point_keeps_last_value_and_is_reported() {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/../config/sim-device-tcp.toml");
    let sim = Sim::start(&[
        "--tcp",
        "127.0.0.1:0",
        "--model",
        "modelless",
        "--config",
        config,
    ]);
    let map = RegisterMap {
        fc23: true,
        status: Some(StatusRegister {
            table: Table::Holding,
            address: 2,
            setpoint_error_bit: 0,
        }),
        ..RegisterMap::default()
    };
    let mut v = ModbusValve::open(tcp(sim.tcp.as_deref().unwrap_or(""), 50.0), map, 0.01)
        .await
        .expect("connects");
    let r = settle(&mut v, 60.0).await;
    assert_eq!(r.status, Some(0));
    // 120 % is raw 1200: a valid u16 on the wire, refused by the device (keeps 60 %).
    let err = v.transact(120.0).await.unwrap_err();
    assert!(
        matches!(
            err,
            Fault::Error(ReplyError::Refused {
                word: 1,
                bit: 0,
                ..
            })
        ),
        "{err}"
    );
    assert!(err.to_string().contains("status 0x0001"), "{err}");
    tokio::time::sleep(Duration::from_millis(30)).await;
    let r = v
        .transact(55.0)
        .await
        .expect("a valid set-point clears the flag");
    assert_eq!(r.status, Some(0));
    assert_eq!(
        r.vp_pct, 60.0,
        "the position followed the kept set-point, not 120 %"
    );
}

#[tokio::test]
async fn line_speed_emulation_matches_the_bus_budget() {
    let sim = Sim::start(&[
        "--pty",
        "--model",
        "modelless",
        "--baud-emulation",
        "19200",
        "--turnaround-ms",
        "1",
    ]);
    let pty = sim.pty.clone().expect("pty endpoint");
    // 19200 baud cannot carry 100 Hz, even with FC 23.
    let err = ModbusValve::open(rtu(&pty, 19200, 100.0), fc23(), 0.01)
        .await
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("18.8 ms") && err.contains("refusing 100.0 Hz"),
        "{err}"
    );
    // 50 Hz fits (thin margin). The emulated line needs 24 chars * 11 bits / 19200 + 1 ms = 14.8 ms
    // per cycle (the reply reads the set-point back); the budget adds the two 3.5-character
    // silences a pty does not have (18.8 ms).
    let mut v = ModbusValve::open(rtu(&pty, 19200, 100.0), fc23(), 0.02)
        .await
        .expect("opens");
    let budget = v.budget().map(|b| b.cycle_s).unwrap_or(0.0);
    let mut fastest = f64::INFINITY;
    for k in 0..5 {
        let t0 = Instant::now();
        v.transact(50.0 + k as f64).await.expect("cycle");
        let el = t0.elapsed().as_secs_f64();
        // No cycle beats the line: the emulation never answers faster than 19200 baud allows.
        assert!(el >= 0.0147, "cycle {k}: {el} s, faster than the line");
        fastest = fastest.min(el);
    }
    // And it adds nothing of its own: the fastest of five cycles is within the budget (a loaded
    // machine can stretch any one cycle, so single cycles are not held to it).
    assert!(
        fastest < budget + 0.005,
        "fastest cycle {fastest} s vs budget {budget} s"
    );
}
