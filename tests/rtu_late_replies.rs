//! Late RTU replies are never taken for the current one: the valve client against a device on a
//! pseudo-terminal that answers every request, in order, but every 4th one 25 ms late (three
//! cycles of an 8 ms deadline at 100 Hz), so the late reply lands while the client waits for a
//! later request's answer. The device's position is the set-point written in the same request,
//! and the set-point ramps, so a reply taken for the wrong cycle shows as a V_P that is not the
//! cycle's set-point. Both plans are tried: FC 23 alone, and FC 16 then FC 3.

use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_serial::{SerialPort, SerialStream};
use valve_bridge::modbus::client::{Fault, Link, ModbusValve};
use valve_bridge::modbus::link::RtuLink;
use valve_bridge::modbus::map::{RegisterMap, StatusRegister, Table};

const CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// `body` with its CRC.
fn seal(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&CRC.checksum(body).to_le_bytes());
    f
}

/// A positioner whose position is the set-point it was last sent (registers: 0 set-point,
/// 1 position, 2 status), answering requests in order, every `late_every`-th `late` late.
async fn device(mut port: SerialStream, late_every: u64, late: Duration) {
    let mut regs = [0u16; 3];
    let mut buf = Vec::new();
    let mut n = 0u64;
    let mut chunk = [0u8; 256];
    loop {
        let Ok(got) = port.read(&mut chunk).await else {
            return;
        };
        if got == 0 {
            return;
        }
        buf.extend_from_slice(&chunk[..got]);
        loop {
            let len = match buf.get(1) {
                Some(3) => 8,
                Some(16) if buf.len() > 6 => 9 + usize::from(buf[6]),
                Some(23) if buf.len() > 10 => 13 + usize::from(buf[10]),
                _ => break,
            };
            if buf.len() < len {
                break;
            }
            let req: Vec<u8> = buf.drain(..len).collect();
            let word = |i: usize| u16::from_be_bytes([req[i], req[i + 1]]);
            let read = |regs: &[u16; 3], start: u16, count: u16, fc: u8| {
                let mut body = vec![req[0], fc, (2 * count) as u8];
                for a in start..start + count {
                    body.extend_from_slice(&regs[usize::from(a)].to_be_bytes());
                }
                seal(&body)
            };
            let reply = match req[1] {
                3 => read(&regs, word(2), word(4), 3),
                16 => {
                    regs[0] = word(7);
                    regs[1] = regs[0];
                    seal(&req[..6])
                }
                _ => {
                    regs[usize::from(word(6))] = word(11);
                    regs[1] = regs[0];
                    read(&regs, word(2), word(4), 23)
                }
            };
            n += 1;
            if n.is_multiple_of(late_every) {
                tokio::time::sleep(late).await;
            }
            if port.write_all(&reply).await.is_err() {
                return;
            }
        }
    }
}

/// Runs a ramp of `cycles` set-points (0.1 % a cycle) every 10 ms against the late device and
/// returns (ok cycles, late replies discarded); panics on a V_P that is not its cycle's set-point.
async fn ramp(map: RegisterMap, cycles: u32) -> (u32, u64) {
    let (server, client) = SerialStream::pair().expect("a pseudo-terminal");
    let path = client.name().expect("pty path");
    let dev = tokio::spawn(async move {
        let _client_end = client;
        device(server, 4, Duration::from_millis(25)).await;
    });
    let link = Link::Rtu(RtuLink {
        baud: 115200,
        timeout_ms: Some(8.0),
        ..RtuLink::new(&path)
    });
    // The device answers in ~0 ms on a pty: the budget is not what is tested here.
    let mut valve = ModbusValve::new(link, map, 0.02).expect("valid link");
    valve.connect_now().await.expect("pty opens");
    let mut ok = 0;
    let mut tick = tokio::time::interval(Duration::from_millis(10));
    for k in 0..cycles {
        tick.tick().await;
        let op = 10.0 + 0.1 * f64::from(k);
        match valve.transact(op).await {
            Ok(r) => {
                assert!(
                    (r.vp_pct - r.sent_pct).abs() < 1e-9,
                    "cycle {k}: V_P {} % is another cycle's (set-point {} %)",
                    r.vp_pct,
                    r.sent_pct
                );
                ok += 1;
            }
            Err(Fault::Timeout(_)) => {}
            Err(other) => panic!("cycle {k}: {other}"),
        }
    }
    dev.abort();
    (ok, valve.link_stats().late_replies)
}

fn status_at_2() -> Option<StatusRegister> {
    Some(StatusRegister {
        table: Table::Holding,
        address: 2,
        setpoint_error_bit: 0,
    })
}

#[tokio::test]
async fn fc23_late_replies_are_discarded_not_logged_as_later_cycles() {
    let map = RegisterMap {
        fc23: true,
        status: status_at_2(),
        ..RegisterMap::default()
    };
    let (ok, late) = ramp(map, 200).await;
    // Every 4th request is answered 25 ms late: it and the next time out, the two after are ok.
    assert!(ok >= 80, "{ok} ok cycles of 200");
    assert!(late >= 40, "{late} late replies discarded");
}

#[tokio::test]
async fn fc16_then_fc3_late_replies_are_discarded_not_logged_as_later_cycles() {
    let map = RegisterMap {
        status: status_at_2(),
        ..RegisterMap::default()
    };
    let (ok, late) = ramp(map, 200).await;
    assert!(ok >= 40, "{ok} ok cycles of 200");
    // A late FC 3 reply that arrives while the next FC 16 waits has the wrong function code; a
    // late FC 16 echo is the same as the current one and harmless (the read that follows
    // reads the set-point back).
    assert!(late > 0, "{late} late replies discarded");
}
