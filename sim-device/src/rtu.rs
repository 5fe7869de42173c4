//! The Modbus RTU server of sim-device: framing, fault injection and line-speed emulation.
//!
//! Written by hand, small on purpose: tokio-modbus's RTU server owns its frame encoder
//! privately, so through it a reply cannot carry a deliberately wrong CRC, and it cannot hold a
//! reply back for the time its characters would take on a real line. Requests are decoded by
//! tokio-modbus (`Request::try_from` on the PDU) and answered by the shared
//! [`RegisterBank`], whose responses the library encodes (`response_pdu`); only the frame
//! (address, PDU, CRC) is built here.
//!
//! A request frame ends when its function code says it is complete, or, for function codes
//! whose length is not known here, at an idle gap. Frames with a bad CRC or for an address no
//! unit has are ignored (a device on a bus stays silent); broadcasts (address 0) are executed
//! by every unit, unanswered. Each unit answers from its own bank.

use std::sync::Arc;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_modbus::bytes::{Bytes, BytesMut};
use tokio_modbus::{ExceptionCode, Request};
use tokio_serial::SerialStream;
use vb_modbus::server::response_pdu;
use vb_modbus::tcp_server::{garble_pdu, Garble};

use crate::faults::{Action, Decision, Faults};
use crate::units::Banks;

const MODBUS_CRC: crc::Crc<u16> = crc::Crc::<u16>::new(&crc::CRC_16_MODBUS);

/// Line-speed emulation: how long characters take on the emulated wire.
#[derive(Debug, Clone, Copy)]
pub(crate) struct LineSpeed {
    /// Baud rate.
    pub baud: u32,
    /// Bits per character (10 for 8N1, 11 for 8E1 or 8N2).
    pub bits_per_char: u32,
    /// Device response time.
    pub turnaround: Duration,
}

impl LineSpeed {
    /// Time for `chars` characters.
    pub(crate) fn chars(&self, chars: usize) -> Duration {
        Duration::from_secs_f64(chars as f64 * f64::from(self.bits_per_char) / f64::from(self.baud))
    }
}

/// Everything the RTU server needs besides the port.
#[derive(Debug, Clone)]
pub(crate) struct RtuDevice {
    /// The registers of each unit, by slave address.
    pub banks: Banks,
    /// Fault injection.
    pub faults: Arc<Faults>,
    /// Optional line-speed emulation.
    pub line: Option<LineSpeed>,
}

/// Gap after which buffered bytes count as a complete (or broken) frame.
const IDLE_GAP: Duration = Duration::from_millis(5);

/// The length of the RTU request frame at the start of `buf`, if its function code tells it
/// and enough bytes are there to know; `Err(())` if the function code does not tell it.
fn request_len(buf: &[u8]) -> Result<Option<usize>, ()> {
    let Some(&fc) = buf.get(1) else {
        return Ok(None);
    };
    let counted = |at: usize, fixed: usize| buf.get(at).map(|&n| fixed + usize::from(n));
    match fc {
        1..=6 => Ok(Some(8)),
        15 | 16 => Ok(counted(6, 9)),
        22 => Ok(Some(10)),
        23 => Ok(counted(10, 13)),
        _ => Err(()),
    }
}

/// Appends the CRC (low byte first) to `adu`, inverted when `corrupt`.
pub(crate) fn seal(mut adu: Vec<u8>, corrupt: bool) -> Vec<u8> {
    let crc = MODBUS_CRC.checksum(&adu) ^ if corrupt { 0xFFFF } else { 0 };
    adu.extend_from_slice(&crc.to_le_bytes());
    adu
}

impl RtuDevice {
    /// The reply to one request frame and the injected delay before it, or None when the
    /// device stays silent.
    pub(crate) fn reply(&self, frame: &[u8]) -> Option<(Vec<u8>, Duration)> {
        if frame.len() < 4 {
            return None;
        }
        let (body, crc) = frame.split_at(frame.len() - 2);
        if MODBUS_CRC.checksum(body) != u16::from_le_bytes([crc[0], crc[1]]) {
            tracing::debug!("ignored a frame with a bad CRC: {frame:02X?}");
            return None;
        }
        let (slave, pdu) = (body[0], &body[1..]);
        let request = Request::try_from(Bytes::copy_from_slice(pdu));
        if slave == 0 {
            if let Ok(req) = &request {
                for bank in self.banks.all() {
                    // Unanswered: the reply, or an exception, has nowhere to go.
                    drop(bank.handle(req));
                }
            }
            return None;
        }
        let bank = self.banks.at(slave)?;
        let fc = pdu[0];
        let Decision { action, delay } = self.faults.next();
        let result = match request {
            _ if action == Action::Exception => Err(ExceptionCode::ServerDeviceFailure),
            Ok(req) => bank.handle(&req),
            Err(_) => Err(ExceptionCode::IllegalFunction),
        };
        if action == Action::Drop {
            return None;
        }
        let mut adu = vec![slave];
        let mut pdu = response_pdu(fc, &result);
        if action == Action::BadByteCount {
            garble_pdu(&mut pdu, Garble::ByteCount);
        }
        adu.extend_from_slice(&pdu);
        Some((seal(adu, action == Action::CorruptCrc), delay))
    }

    /// Serves requests on `port` until it closes.
    pub(crate) async fn serve(&self, mut port: SerialStream) -> std::io::Result<()> {
        let mut buf = BytesMut::with_capacity(512);
        loop {
            let n = if buf.is_empty() {
                port.read_buf(&mut buf).await?
            } else {
                match tokio::time::timeout(IDLE_GAP, port.read_buf(&mut buf)).await {
                    Ok(r) => r?,
                    Err(_) => {
                        // Silence: what is buffered is a whole frame (unknown function) or garbage.
                        let frame = buf.split();
                        self.answer(&mut port, &frame).await?;
                        continue;
                    }
                }
            };
            if n == 0 {
                return Ok(());
            }
            while let Ok(Some(len)) = request_len(&buf) {
                if buf.len() < len {
                    break;
                }
                let frame = buf.split_to(len);
                self.answer(&mut port, &frame).await?;
            }
        }
    }

    async fn answer(&self, port: &mut SerialStream, frame: &[u8]) -> std::io::Result<()> {
        let Some((reply, mut wait)) = self.reply(frame) else {
            return Ok(());
        };
        if let Some(line) = self.line {
            wait += line.chars(frame.len() + reply.len()) + line.turnaround;
        }
        if !wait.is_zero() {
            tokio::time::sleep(wait).await;
        }
        port.write_all(&reply).await?;
        port.flush().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::faults::FaultConfig;
    use crate::units::{parse_unit, Defaults, Served, Unit};
    use vb_core::model::DriftSpec;
    use vb_modbus::map::RegisterMap;

    /// A device with units at `ids`, every position at 50 %.
    fn device_at(ids: &[u8], faults: FaultConfig) -> RtuDevice {
        let defaults = Defaults {
            model: "pincart2".into(),
            noise_pct: 0.0,
            drift: DriftSpec::default(),
            seed: 1,
        };
        let units: Vec<Unit> = (ids.iter())
            .map(|id| {
                let arg = parse_unit(&id.to_string()).unwrap();
                Unit::new(&arg, &defaults, &Served::map(RegisterMap::default())).unwrap()
            })
            .collect();
        let banks = Banks::of(&units);
        for b in banks.all() {
            b.set_position_pct(50.0);
        }
        RtuDevice {
            banks,
            faults: Arc::new(Faults::new(faults)),
            line: None,
        }
    }

    fn device(faults: FaultConfig) -> RtuDevice {
        device_at(&[7], faults)
    }

    #[test]
    fn frame_lengths() {
        assert_eq!(request_len(&[1]), Ok(None));
        assert_eq!(request_len(&[1, 3]), Ok(Some(8)));
        assert_eq!(request_len(&[1, 16, 0, 0, 0, 1]), Ok(None));
        assert_eq!(request_len(&[1, 16, 0, 0, 0, 1, 2]), Ok(Some(11)));
        assert_eq!(
            request_len(&[1, 23, 0, 1, 0, 1, 0, 0, 0, 1, 2]),
            Ok(Some(15))
        );
        assert_eq!(request_len(&[1, 17]), Err(()));
    }

    #[test]
    fn reads_position_with_valid_crc() {
        let d = device(FaultConfig::default());
        // Read holding register 1 of slave 7: the reference frame from the Modbus spec's CRC.
        let req = seal(vec![7, 3, 0, 1, 0, 1], false);
        let reply = d.reply(&req).unwrap().0;
        assert_eq!(&reply[..5], &[7, 3, 2, 0x01, 0xF4]); // 500 per mille
        assert_eq!(reply, seal(vec![7, 3, 2, 0x01, 0xF4], false));
        // Known CRC: 01 03 00 00 00 01 -> 84 0A.
        assert_eq!(seal(vec![1, 3, 0, 0, 0, 1], false)[6..], [0x84, 0x0A]);
    }

    #[test]
    fn silence_for_bad_crc_other_slaves_and_broadcasts() {
        let d = device(FaultConfig::default());
        let mut bad = seal(vec![7, 3, 0, 1, 0, 1], false);
        bad[7] ^= 1;
        assert_eq!(d.reply(&bad), None);
        assert_eq!(d.reply(&seal(vec![8, 3, 0, 1, 0, 1], false)), None);
        // Broadcast write is executed, unanswered.
        assert_eq!(d.reply(&seal(vec![0, 6, 0, 0, 0x01, 0x2C], false)), None);
        assert_eq!(d.banks.at(7).unwrap().setpoint_pct(), 30.0);
    }

    #[test]
    fn each_unit_answers_from_its_own_bank_and_others_stay_silent() {
        let d = device_at(&[1, 2], FaultConfig::default());
        d.banks.at(2).unwrap().set_position_pct(12.3);
        let reply = d.reply(&seal(vec![2, 3, 0, 1, 0, 1], false)).unwrap().0;
        assert_eq!(reply, seal(vec![2, 3, 2, 0, 123], false));
        let reply = d
            .reply(&seal(vec![1, 6, 0, 0, 0x01, 0xF4], false))
            .unwrap()
            .0;
        assert_eq!(reply, seal(vec![1, 6, 0, 0, 0x01, 0xF4], false));
        assert_eq!(d.banks.at(1).unwrap().setpoint_pct(), 50.0);
        assert_eq!(
            d.banks.at(2).unwrap().setpoint_pct(),
            0.0,
            "unit 2 untouched"
        );
        assert_eq!(
            d.reply(&seal(vec![3, 3, 0, 1, 0, 1], false)),
            None,
            "no unit 3"
        );
        // A broadcast reaches both.
        assert_eq!(d.reply(&seal(vec![0, 6, 0, 0, 0x00, 0x64], false)), None);
        assert!(d.banks.all().all(|b| b.setpoint_pct() == 10.0));
    }

    #[test]
    fn writes_exceptions_and_injected_faults() {
        let d = device(FaultConfig {
            corrupt_crc_every: Some(2),
            exception_every: Some(3),
            ..FaultConfig::default()
        });
        // 1: FC16 write 700 per mille.
        let reply = d
            .reply(&seal(vec![7, 16, 0, 0, 0, 1, 2, 0x02, 0xBC], false))
            .unwrap()
            .0;
        assert_eq!(reply, seal(vec![7, 16, 0, 0, 0, 1], false));
        assert_eq!(d.banks.at(7).unwrap().setpoint_pct(), 70.0);
        // 2: corrupted CRC.
        let reply = d.reply(&seal(vec![7, 3, 0, 1, 0, 1], false)).unwrap().0;
        assert_eq!(reply, seal(vec![7, 3, 2, 0x01, 0xF4], true));
        // 3: injected exception 04.
        let reply = d.reply(&seal(vec![7, 3, 0, 1, 0, 1], false)).unwrap().0;
        assert_eq!(reply, seal(vec![7, 0x83, 4], false));
        // 5: unmapped address gives exception 02 (4 is a corrupted CRC).
        d.reply(&seal(vec![7, 3, 0, 1, 0, 1], false));
        let reply = d.reply(&seal(vec![7, 3, 0, 9, 0, 1], false)).unwrap().0;
        assert_eq!(reply, seal(vec![7, 0x83, 2], false));
        // 6: injected exception again, whatever the function; 7: unknown function, exception 01.
        let reply = d.reply(&seal(vec![7, 0x41, 1, 2], false)).unwrap().0;
        assert_eq!(reply, seal(vec![7, 0xC1, 4], false));
        let reply = d.reply(&seal(vec![7, 0x41, 1, 2], false)).unwrap().0;
        assert_eq!(reply, seal(vec![7, 0xC1, 1], false));
    }

    #[test]
    fn line_speed_figures() {
        let l = LineSpeed {
            baud: 19200,
            bits_per_char: 11,
            turnaround: Duration::ZERO,
        };
        assert!((l.chars(22).as_secs_f64() - 22.0 * 11.0 / 19200.0).abs() < 1e-9);
    }
}
