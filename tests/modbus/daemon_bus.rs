//! Two valves on one Modbus RTU bus, through the real binaries over a pseudo-terminal:
//! sim-device serves unit ids on one pty, `config/two-valves-rtu.toml` drives them through one
//! open port in the order of the file.
//! - both units there: every cycle of both valves reads its V_P, each from its own unit (each
//!   valve's source and model), and the bus budget is checked and logged once for the pair;
//! - the second unit absent: its rows are `timeout` within its share of the period, the first
//!   valve's cycles all read their V_P, and the run exits 1 naming the absent valve;
//! - a rate the bus cannot carry is refused at load, naming the port, the total wire time,
//!   the period and what to change.

use std::path::Path;

use crate::common::sim::{config, real_time_turn, run_cmd, SimDevice, RTU_CONFIG};
use crate::common::{log_rows, logs, LogRow};

const SHIPPED: &str = "config/two-valves-rtu.toml";
const PORT: &str = "/tmp/vb-sim-bus";

/// Every row of the log of valve `name` in `dir`.
fn rows(dir: &Path, name: &str) -> Vec<LogRow> {
    let files = logs(dir, &format!("vb-{name}-"));
    assert_eq!(files.len(), 1, "{files:?}");
    log_rows(&files[0])
}

#[test]
fn two_units_on_one_pty_are_driven_through_one_port() {
    let _turn = real_time_turn();
    // Unit 2 is a modelless valve: its V_P is its O_P, which tells the two units apart.
    let sim = SimDevice::start_bare(
        &["--pty", "--unit", "1", "--unit", "2=modelless"],
        RTU_CONFIG,
    );
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), SHIPPED, &[(PORT, &sim.endpoint)], "");
    let out = run_cmd(&cfg, dir.path(), 3.0)
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}{stderr}");
    assert_eq!(
        stderr.matches("bus budget: 2 valves on ").count(),
        1,
        "the bus budget is logged once:\n{stderr}"
    );
    assert!(
        stderr.contains(
            "level 7.0 ms (FC 23) + cyclone 7.0 ms (FC 23) = 14.0 ms on the wire per cycle"
        ),
        "{stderr}"
    );
    let level = rows(dir.path(), "level");
    let cyclone = rows(dir.path(), "cyclone");
    // 150 cycles at 50 Hz and the stop action, each.
    assert_eq!((level.len(), cyclone.len()), (151, 151));
    for (name, r) in [("level", &level), ("cyclone", &cyclone)] {
        let ok = r.iter().filter(|x| x.status == "ok").count();
        assert!(ok >= 140, "{name}: {ok} of {} ok\n{stdout}", r.len());
    }
    // Unit 2 is modelless and answers O_P (per mille) as of its last model step, on its own
    // 100 Hz clock: the row's O_P, or the previous row's where the write came after that step
    // (a stalled machine). Unit 1's pin-cart II lags its random steps by its dead time and
    // strokes at its speed limit, so it does not.
    let echoes = |r: &[LogRow]| {
        r.windows(2).filter(|w| w[1].status == "ok").all(|w| {
            w[1].vp
                .is_some_and(|vp| (vp - w[1].op).abs() < 0.051 || (vp - w[0].op).abs() < 0.051)
        })
    };
    assert!(echoes(&cyclone));
    assert!(!echoes(&level));
    sim.stop();
}

#[test]
fn an_absent_unit_costs_its_own_rows_and_its_own_share_of_the_period() {
    let _turn = real_time_turn();
    let sim = SimDevice::start_bare(&["--pty", "--unit", "1"], RTU_CONFIG);
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), SHIPPED, &[(PORT, &sim.endpoint)], "");
    let out = run_cmd(&cfg, dir.path(), 3.0).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains("valve cyclone: no cycle read a V_P"),
        "{stderr}"
    );
    let level = rows(dir.path(), "level");
    let cyclone = rows(dir.path(), "cyclone");
    // Every cycle that ran read the level valve (the first may find the new port slow); a
    // loaded machine may skip a slot for both.
    let ran = level.iter().filter(|x| x.status != "skipped").count();
    assert!(ran >= 140, "{ran} cycles ran\n{stdout}");
    // (A loaded machine can stall the loop past a deadline now and then: a few level rows
    // may time out with it, never the level valve's cycles as a rule.)
    let level_lost = (level[1..].iter())
        .filter(|x| x.status != "skipped" && x.vp.is_none())
        .count();
    assert!(
        level_lost <= 3,
        "{level_lost} level rows without V_P: {level:?}"
    );
    // The absent unit times out at its deadline, 8 ms of the 20 ms period (tokio's timer
    // fires up to a millisecond after it; a loaded machine may add more now and then).
    let timeouts: Vec<f64> = (cyclone.iter())
        .filter(|x| x.status == "timeout")
        .filter_map(|x| x.latency_us)
        .collect();
    assert!(timeouts.len() >= 140, "{cyclone:?}");
    // Never before its deadline, and typically just after it (a loaded machine stretches some
    // cycles, so single ones are not held to it).
    assert!(timeouts.iter().all(|&us| us >= 8000.0), "{timeouts:?}");
    let mut sorted = timeouts.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[sorted.len() / 2];
    assert!(median < 10_500.0, "median {median} µs: {timeouts:?}");
    assert!(cyclone.iter().all(|x| x.vp.is_none()));
    assert!(
        stdout.contains("valve level:\n  samples: ")
            && stdout.contains(" error, 0 disconnected)\n"),
        "{stdout}"
    );
    sim.stop();
}

#[test]
fn a_rate_the_bus_cannot_carry_is_refused_at_load() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(
        dir.path(),
        SHIPPED,
        &[("rate_hz = 50.0", "rate_hz = 100.0")],
        "",
    );
    let out = run_cmd(&cfg, dir.path(), 1.0).output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains(
            "valve.modbus-rtu.port: bus budget: 2 valves on /tmp/vb-sim-bus take level 7.0 ms \
             (FC 23) + cyclone 7.0 ms (FC 23) = 14.0 ms on the wire per cycle at 115200 baud, \
             11 bits/char = 140 % of the 10.0 ms loop period; the bus carries at most 71.6 Hz: \
             refusing 100.0 Hz (raise [valve.modbus-rtu] baud of every valve on /tmp/vb-sim-bus, \
             lower [loop] rate_hz to 71 or less, or put fewer valves on this bus)"
        ),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
}
