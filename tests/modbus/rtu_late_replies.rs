//! Whatever an RTU line carries, a cycle that reads a V_P reads the answer to its own request:
//! the valve client against a fake positioner on a pseudo-terminal that answers in order, as an
//! RTU slave does, but some requests late, with a stray byte before a late reply, with a broken
//! CRC, 20 cycles late, or slow for its first second. Two kinds of device tell a reply taken for
//! the wrong request:
//! - on a ramp, the position is the set-point written in the same request, so a stale reply
//!   reads back another set-point than the cycle's;
//! - on a held set-point, the position counts the requests the device received, so a reply
//!   to an earlier request reads a lower count than the device had when the cycle ended.
//!
//! Both plans are tried on the ramp: FC 23 alone, and FC 16 then FC 3. And the daemon itself,
//! `valve-bridge run` on the same kind of line: every `ok` row of its log reads back its own
//! set-point.

use crate::common;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::{SerialPort, SerialStream};
use valve_bridge::modbus::client::{Fault, Link, LinkStats, ModbusValve};
use valve_bridge::modbus::link::RtuLink;
use valve_bridge::modbus::map::{RegisterMap, StatusRegister, Table};

const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// `body` with its CRC.
fn seal(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&CRC.checksum(body).to_le_bytes());
    f
}

/// How the fake positioner answers (registers: 0 set-point, 1 position, 2 status).
#[derive(Debug, Clone, Copy, Default)]
struct Device {
    /// Every `late_every`-th request is answered `late` late (0: none).
    late_every: u64,
    late: Duration,
    /// The first `slow_start` requests are all answered `late` late.
    slow_start: u64,
    /// A stray 0x00 (an RS-485 driver glitch) goes on the line before each late reply.
    stray_byte: bool,
    /// Each late reply's CRC is broken.
    broken_crc: bool,
    /// The position counts the requests received (mod 1000) instead of following the
    /// set-point.
    counter: bool,
}

impl Device {
    /// Serves `port` until it closes; `received` counts the requests taken in.
    async fn serve(self, mut port: SerialStream, received: Arc<AtomicU64>) {
        let mut regs = [0u16; 3];
        let mut buf = Vec::new();
        let mut chunk = [0u8; 256];
        loop {
            let Ok(got) = port.read(&mut chunk).await else {
                return;
            };
            if got == 0 {
                return;
            }
            buf.extend_from_slice(&chunk[..got]);
            while let Some(len) = request_len(&buf) {
                let req: Vec<u8> = buf.drain(..len).collect();
                let n = received.fetch_add(1, Ordering::SeqCst) + 1;
                let mut reply = self.answer(&req, &mut regs, n);
                let late = n <= self.slow_start
                    || (self.late_every > 0 && n.is_multiple_of(self.late_every));
                if late {
                    tokio::time::sleep(self.late).await;
                    if self.broken_crc {
                        let last = reply.len() - 1;
                        reply[last] ^= 0x5A;
                    }
                    if self.stray_byte {
                        reply.insert(0, 0x00);
                    }
                }
                if port.write_all(&reply).await.is_err() {
                    return;
                }
            }
        }
    }

    /// The reply to `req`, the device's `n`-th request.
    fn answer(&self, req: &[u8], regs: &mut [u16; 3], n: u64) -> Vec<u8> {
        let word = |i: usize| u16::from_be_bytes([req[i], req[i + 1]]);
        let update = |regs: &mut [u16; 3]| {
            regs[1] = if self.counter {
                (n % 1000) as u16
            } else {
                regs[0]
            };
        };
        let read = |regs: &[u16; 3], start: u16, count: u16, fc: u8| {
            let mut body = vec![req[0], fc, (2 * count) as u8];
            for a in start..start + count {
                body.extend_from_slice(&regs[usize::from(a)].to_be_bytes());
            }
            seal(&body)
        };
        match req[1] {
            3 => {
                update(regs);
                read(regs, word(2), word(4), 3)
            }
            16 => {
                regs[0] = word(7);
                update(regs);
                seal(&req[..6])
            }
            _ => {
                regs[usize::from(word(6))] = word(11);
                update(regs);
                read(regs, word(2), word(4), 23)
            }
        }
    }
}

/// The size of the request at the start of `buf`, once it is all there.
fn request_len(buf: &[u8]) -> Option<usize> {
    let len = match buf.get(1)? {
        3 => 8,
        16 => 9 + usize::from(*buf.get(6)?),
        _ => 13 + usize::from(*buf.get(10)?),
    };
    (buf.len() >= len).then_some(len)
}

/// What a run of cycles gave.
#[derive(Debug)]
struct Outcome {
    cycles: u32,
    ok: u32,
    /// Cycles whose V_P was not their own request's answer.
    wrong: Vec<String>,
    link: LinkStats,
}

/// Runs `cycles` cycles every 10 ms against `device`: on a ramp of 0.1 % a cycle, or (with a
/// counting device) a set-point held at 50 %.
async fn run(map: RegisterMap, device: Device, cycles: u32) -> Outcome {
    let (server, client) = SerialStream::pair().expect("a pseudo-terminal");
    let path = client.name().expect("pty path");
    let received = Arc::new(AtomicU64::new(0));
    let counted = Arc::clone(&received);
    let dev = tokio::spawn(async move {
        let _client_end = client;
        device.serve(server, counted).await;
    });
    let link = Link::Rtu(RtuLink {
        baud: 115200,
        timeout_ms: Some(8.0),
        ..RtuLink::new(&path)
    });
    // The device answers in ~0 ms on a pty: the budget is not what is tested here.
    let mut valve = ModbusValve::new(link, map, 0.02).expect("valid link");
    valve.connect_now().await.expect("pty opens");
    let mut out = Outcome {
        cycles,
        ok: 0,
        wrong: Vec::new(),
        link: LinkStats::default(),
    };
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    for k in 0..cycles {
        tick.tick().await;
        let op = if device.counter {
            50.0
        } else {
            10.0 + 0.1 * f64::from(k)
        };
        match valve.transact(op).await {
            Ok(r) => {
                out.ok += 1;
                // The device's count when the cycle ended is its request's: the cycle's
                // request is the last one sent.
                let own = if device.counter {
                    (received.load(Ordering::SeqCst) % 1000) as f64 / 10.0
                } else {
                    r.sent_pct
                };
                if (r.vp_pct - own).abs() > 1e-9 {
                    out.wrong
                        .push(format!("cycle {k}: V_P {} %, its own {own} %", r.vp_pct));
                }
            }
            Err(Fault::Timeout(_) | Fault::Error(_)) => {}
            Err(other) => panic!("cycle {k}: {other}"),
        }
    }
    out.link = valve.link_stats();
    dev.abort();
    out
}

fn fc23() -> RegisterMap {
    RegisterMap {
        fc23: true,
        status: Some(StatusRegister {
            table: Table::Holding,
            address: 2,
            setpoint_error_bit: 0,
        }),
        ..RegisterMap::default()
    }
}

fn fc16_fc3() -> RegisterMap {
    RegisterMap {
        fc23: false,
        ..fc23()
    }
}

/// Every 4th request 25 ms late: the late reply lands two cycles on.
fn every_4th_late() -> Device {
    Device {
        late_every: 4,
        late: Duration::from_millis(25),
        ..Device::default()
    }
}

fn assert_own(out: &Outcome, min_ok: u32) {
    assert!(out.wrong.is_empty(), "{:#?}", out);
    assert!(
        out.ok >= min_ok,
        "{} ok cycles of {}: {out:#?}",
        out.ok,
        out.cycles
    );
}

#[tokio::test]
async fn late_replies_are_never_taken_for_later_cycles() {
    // A late request's cycle times out, the next is held for its reply, then the line is free
    // again: 3 cycles of 5 read their V_P with FC 23, fewer with two requests a cycle.
    for (map, min_ok) in [(fc23(), 80), (fc16_fc3(), 35)] {
        let out = run(map, every_4th_late(), 200).await;
        assert_own(&out, min_ok);
        assert!(out.link.late_replies >= 20, "{out:#?}");
    }
}

#[tokio::test]
async fn a_stray_byte_before_a_late_reply_is_noise_not_a_reason_to_trust_it() {
    let device = Device {
        stray_byte: true,
        ..every_4th_late()
    };
    for (map, min_ok) in [(fc23(), 80), (fc16_fc3(), 35)] {
        let out = run(map, device, 200).await;
        assert_own(&out, min_ok);
        assert!(out.link.noise_bytes >= 20, "{out:#?}");
    }
}

#[tokio::test]
async fn a_late_reply_with_a_broken_crc_is_never_taken_for_a_later_cycle() {
    let device = Device {
        broken_crc: true,
        ..every_4th_late()
    };
    // The broken reply shows the device answered: the held cycle goes on at once.
    let out = run(fc23(), device, 200).await;
    assert_own(&out, 80);
    assert!(out.link.noise_bytes >= 20 * 11, "{out:#?}");
}

#[tokio::test]
async fn a_held_set_point_never_takes_an_earlier_requests_reply() {
    let device = Device {
        counter: true,
        ..every_4th_late()
    };
    let out = run(fc23(), device, 300).await;
    assert_own(&out, 120);
    let device = Device {
        stray_byte: true,
        ..device
    };
    assert_own(&run(fc23(), device, 300).await, 120);
}

#[tokio::test]
async fn replies_twenty_cycles_late_are_caught_and_the_wait_grows_to_cover_them() {
    // Every 50th reply 205 ms late, on the ramp and on a held set-point.
    let late = Device {
        late_every: 50,
        late: Duration::from_millis(205),
        ..Device::default()
    };
    for device in [
        late,
        Device {
            counter: true,
            ..late
        },
    ] {
        // Each costs the cycles the device is silent for, and a few more the first time.
        let out = run(fc23(), device, 400).await;
        assert_own(&out, 230);
        // The first one shows the device answers that late: the line then waits for it.
        let raised = out.link.late_reply_ms.expect("an RTU link");
        assert!(raised >= 205, "{out:#?}");
    }
}

#[tokio::test]
async fn a_device_that_starts_slowly_is_waited_for() {
    // The first 20 requests are each answered 150 ms late, then every one on time: the first
    // 3 s give few readings, none of them another request's.
    let device = Device {
        slow_start: 20,
        late: Duration::from_millis(150),
        counter: true,
        ..Device::default()
    };
    let out = run(fc23(), device, 400).await;
    assert_own(&out, 80);
}

/// The daemon on a line with stray bytes and late replies: its `ok` rows read back their own
/// set-points (`op_sent_pct`), and the summary counts the late replies and the noise.
#[test]
fn the_daemon_logs_no_stale_v_p_from_a_noisy_line() {
    let _turn = common::sim::real_time_turn();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let _in_rt = rt.enter();
    let (server, client) = SerialStream::pair().expect("a pseudo-terminal");
    let path = client.name().expect("pty path");
    let device = Device {
        stray_byte: true,
        ..every_4th_late()
    };
    let dev = rt.spawn(async move {
        let _client_end = client;
        device.serve(server, Arc::default()).await;
    });
    let dir = tempfile::tempdir().unwrap();
    let ramp = "[source]\nkind = \"ramp\"\n[source.ramp]\nfrom_pct = 10.0\nto_pct = 90.0\n\
                duration_s = 8.0\n";
    let (shipped, endpoint) = common::sim::RTU_CONFIG;
    let cfg = common::sim::config(dir.path(), shipped, &[(endpoint, &path)], ramp);
    let out = common::sim::run_cmd(&cfg, dir.path(), 4.0)
        .output()
        .unwrap();
    dev.abort();
    let summary = String::from_utf8_lossy(&out.stdout);
    let files = common::logs(dir.path(), "vb-");
    assert_eq!(files.len(), 1, "{files:?}\n{summary}");
    let mut r = csv::Reader::from_path(&files[0]).unwrap();
    let (mut ok, mut wrong) = (0, Vec::new());
    for rec in r.records() {
        let rec = rec.unwrap();
        if &rec[3] != "ok" {
            continue;
        }
        ok += 1;
        let (vp, sent): (f64, f64) = (rec[2].parse().unwrap(), rec[6].parse().unwrap());
        if (vp - sent).abs() > 1e-6 {
            wrong.push(format!("t {} s: V_P {vp} %, set-point {sent} %", &rec[0]));
        }
    }
    assert!(wrong.is_empty(), "{wrong:#?}\n{summary}");
    // 3 rows of 5 on an idle machine.
    assert!(ok >= 100, "{ok} ok rows of 400\n{summary}");
    assert!(common::sim::summary_count(&summary, "late replies discarded: ") >= 20);
    assert!(common::sim::summary_count(&summary, "line noise: ") >= 20);
}
