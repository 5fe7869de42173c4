//! The device side of a register map: a bank of registers that a Modbus server serves.
//!
//! [`RegisterBank`] holds the set-point, the position and the status word of one register map
//! and answers Modbus requests on them the way a Bürkert-style positioner does: reads of mapped
//! registers (FC 3, FC 4), writes of the whole set-point (FC 6, FC 16) and both at once (FC 23,
//! write first). A set-point outside the accepted range is either kept-last-value-and-flagged
//! (the positioner's behaviour: the status register's error bit is raised until a valid
//! set-point arrives) or refused with exception 03 (what a process-controller-facing server
//! wants). Unmapped or read-only addresses give exception 02, bad quantities exception 03, other
//! function codes exception 01. [`response_pdu`] encodes its answers for a server's frames.
//!
//! The bank does no I/O, owns no clock and runs no valve model: `sim-device` advances its valve
//! and calls [`RegisterBank::set_position_pct`], the daemon's `modbus-server` source reads the
//! accepted set-points with [`RegisterBank::accepted`] and publishes V_P and its status bits with
//! [`RegisterBank::report`]; framing and fault injection live with the server. Every method holds
//! the bank's lock only for a few plain loads and stores, never across I/O.

use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use tokio_modbus::{ExceptionCode, Request, Response};

use super::map::{RegisterMap, Table, Words};

/// Largest register count of a read (FC 3/4/23), from the Modbus application protocol.
pub const MAX_READ: u16 = 125;
/// Largest register count of FC 16.
pub const MAX_WRITE: u16 = 123;
/// Largest write count of FC 23.
pub const MAX_RW_WRITE: u16 = 121;

/// What the bank does with a set-point outside the accepted range.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutOfRange {
    /// Keep the last set-point, raise the status error bit, answer normally (Bürkert); with no
    /// status register in the map, refuse as [`OutOfRange::Exception`].
    KeepAndFlag,
    /// Refuse the write with exception 03 (illegal data value).
    Exception,
}

#[derive(Debug)]
struct State {
    setpoint_pct: f64,
    position_pct: f64,
    status: u16,
    last_write: Option<Instant>,
    accepted: u64,
    rejected: u64,
}

/// The registers of one positioner (see the module documentation).
#[derive(Debug)]
pub struct RegisterBank {
    map: RegisterMap,
    min_pct: f64,
    max_pct: f64,
    policy: OutOfRange,
    /// Further registers served (as 0, read-only), a device profile's.
    others: Vec<(Table, u16)>,
    /// The function codes answered (others: exception 01); empty: every one the bank knows.
    functions: Vec<u8>,
    state: Mutex<State>,
}

impl RegisterBank {
    /// A bank for a (validated) `map` accepting set-points in `min_pct..=max_pct`.
    pub fn new(map: RegisterMap, min_pct: f64, max_pct: f64, policy: OutOfRange) -> Self {
        RegisterBank {
            map,
            min_pct,
            max_pct,
            policy,
            others: Vec::new(),
            functions: Vec::new(),
            state: Mutex::new(State {
                setpoint_pct: min_pct.max(0.0).min(max_pct),
                position_pct: 0.0,
                status: 0,
                last_write: None,
                accepted: 0,
                rejected: 0,
            }),
        }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // A panic while holding the lock cannot leave State half-written (plain stores), so a
        // poisoned lock is still usable.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The map served.
    pub fn map(&self) -> &RegisterMap {
        &self.map
    }

    /// The last accepted set-point, %.
    pub fn setpoint_pct(&self) -> f64 {
        self.state().setpoint_pct
    }

    /// The same bank with its set-point at `pct` before any write (what a read shows until then).
    pub fn with_setpoint(mut self, pct: f64) -> Self {
        match self.state.get_mut() {
            Ok(st) => st.setpoint_pct = pct,
            Err(poisoned) => poisoned.into_inner().setpoint_pct = pct,
        }
        self
    }

    /// The same bank also serving `others` (each one register, read as 0, not writable) and
    /// answering only `functions` (empty: all it knows), as a device profile describes.
    pub fn serving(mut self, others: &[(Table, u16)], functions: &[u8]) -> Self {
        self.others = others.to_vec();
        self.functions = functions.to_vec();
        self
    }

    /// The last accepted set-point, %, and how many set-point writes were accepted so far (read
    /// together, so a new count always comes with its value).
    pub fn accepted(&self) -> (f64, u64) {
        let st = self.state();
        (st.setpoint_pct, st.accepted)
    }

    /// Sets the position the bank reports, %.
    pub fn set_position_pct(&self, pct: f64) {
        self.state().position_pct = pct;
    }

    /// Publishes a cycle's outcome: the position (None keeps the last one) and the status bits
    /// under `mask` (the other bits, such as the set-point error bit, are left alone).
    pub fn report(&self, position_pct: Option<f64>, mask: u16, bits: u16) {
        let mut st = self.state();
        if let Some(p) = position_pct {
            st.position_pct = p;
        }
        st.status = (st.status & !mask) | (bits & mask);
    }

    /// The status word.
    pub fn status(&self) -> u16 {
        self.state().status
    }

    /// When the last set-point write arrived (accepted or not); None before the first.
    pub fn last_write(&self) -> Option<Instant> {
        self.state().last_write
    }

    /// Number of set-points refused as out of range.
    pub fn rejected(&self) -> u64 {
        self.state().rejected
    }

    /// Answers one request.
    pub fn handle(&self, req: &Request<'_>) -> Result<Response, ExceptionCode> {
        let fc = req.function_code().value();
        if !self.functions.is_empty() && !self.functions.contains(&fc) {
            return Err(ExceptionCode::IllegalFunction);
        }
        match req {
            Request::ReadHoldingRegisters(a, n) => self
                .read(Table::Holding, *a, *n, MAX_READ)
                .map(Response::ReadHoldingRegisters),
            Request::ReadInputRegisters(a, n) => self
                .read(Table::Input, *a, *n, MAX_READ)
                .map(Response::ReadInputRegisters),
            Request::WriteSingleRegister(a, w) => {
                self.write(*a, &[*w])?;
                Ok(Response::WriteSingleRegister(*a, *w))
            }
            Request::WriteMultipleRegisters(a, words) => {
                if words.is_empty() || words.len() > usize::from(MAX_WRITE) {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.write(*a, words)?;
                Ok(Response::WriteMultipleRegisters(*a, words.len() as u16))
            }
            Request::ReadWriteMultipleRegisters(ra, rn, wa, words) => {
                if words.is_empty()
                    || words.len() > usize::from(MAX_RW_WRITE)
                    || *rn == 0
                    || *rn > MAX_READ
                {
                    return Err(ExceptionCode::IllegalDataValue);
                }
                self.write(*wa, words)?;
                self.read(Table::Holding, *ra, *rn, MAX_READ)
                    .map(Response::ReadWriteMultipleRegisters)
            }
            _ => Err(ExceptionCode::IllegalFunction),
        }
    }

    /// The words of `count` registers from `start` in `table`.
    fn read(
        &self,
        table: Table,
        start: u16,
        count: u16,
        max: u16,
    ) -> Result<Vec<u16>, ExceptionCode> {
        if count == 0 || count > max {
            return Err(ExceptionCode::IllegalDataValue);
        }
        let st = self.state();
        let m = &self.map;
        let mut values: Vec<(std::ops::Range<u32>, Words)> = Vec::with_capacity(3);
        if m.setpoint.table == table {
            values.push((
                m.setpoint.span(),
                m.setpoint.encode_saturating(st.setpoint_pct, m.word_order),
            ));
        }
        if m.position.table == table {
            values.push((
                m.position.span(),
                m.position.encode_saturating(st.position_pct, m.word_order),
            ));
        }
        if let Some(s) = m.status.filter(|s| s.table == table) {
            let a = u32::from(s.address);
            values.push((a..a + 1, smallvec::smallvec![st.status]));
        }
        for &(_, a) in self.others.iter().filter(|(t, _)| *t == table) {
            values.push((u32::from(a)..u32::from(a) + 1, smallvec::smallvec![0]));
        }
        let start = u32::from(start);
        (start..start + u32::from(count))
            .map(|a| {
                values
                    .iter()
                    .find(|(span, _)| span.contains(&a))
                    .and_then(|(span, words)| words.get((a - span.start) as usize).copied())
                    .ok_or(ExceptionCode::IllegalDataAddress)
            })
            .collect()
    }

    /// Writes the set-point; only a write of exactly its registers is accepted.
    fn write(&self, start: u16, words: &[u16]) -> Result<(), ExceptionCode> {
        let sp = &self.map.setpoint;
        if start != sp.address || words.len() != usize::from(sp.format.width()) {
            return Err(ExceptionCode::IllegalDataAddress);
        }
        let pct = sp.decode("set-point", words, self.map.word_order).ok();
        let mut st = self.state();
        st.last_write = Some(Instant::now());
        let mask = self.map.status.map(|s| s.error_mask()).unwrap_or(0);
        match pct {
            Some(p) if p >= self.min_pct && p <= self.max_pct => {
                st.setpoint_pct = p;
                st.accepted += 1;
                st.status &= !mask;
                Ok(())
            }
            _ => {
                st.rejected += 1;
                match self.policy {
                    // With no status register there is no bit to raise: refused outright.
                    OutOfRange::KeepAndFlag if mask != 0 => {
                        st.status |= mask;
                        Ok(())
                    }
                    OutOfRange::KeepAndFlag | OutOfRange::Exception => {
                        Err(ExceptionCode::IllegalDataValue)
                    }
                }
            }
        }
    }
}

/// The PDU of a response (or exception) to function code `fc`.
pub fn response_pdu(fc: u8, result: &Result<Response, ExceptionCode>) -> Vec<u8> {
    let words = |w: &[u16]| {
        let mut out = Vec::with_capacity(2 + 2 * w.len());
        out.push(fc);
        // At most 125 registers are ever read, so the byte count fits in a u8.
        out.push((2 * w.len()).min(250) as u8);
        for v in w {
            out.extend_from_slice(&v.to_be_bytes());
        }
        out
    };
    let exception = |code: ExceptionCode| vec![fc | 0x80, u8::from(code)];
    match result {
        Ok(Response::ReadHoldingRegisters(w))
        | Ok(Response::ReadInputRegisters(w))
        | Ok(Response::ReadWriteMultipleRegisters(w)) => words(w),
        Ok(Response::WriteSingleRegister(a, v)) | Ok(Response::WriteMultipleRegisters(a, v)) => {
            let mut out = vec![fc];
            out.extend_from_slice(&a.to_be_bytes());
            out.extend_from_slice(&v.to_be_bytes());
            out
        }
        // The bank answers only the register functions above; anything else is a device failure.
        Ok(_) => exception(ExceptionCode::ServerDeviceFailure),
        Err(code) => exception(*code),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::{Format, Register, StatusRegister, WordOrder};
    use std::borrow::Cow;

    fn map() -> RegisterMap {
        RegisterMap {
            status: Some(StatusRegister {
                table: Table::Holding,
                address: 2,
                setpoint_error_bit: 3,
            }),
            ..RegisterMap::default()
        }
    }

    fn write(b: &RegisterBank, raw: u16) -> Result<Response, ExceptionCode> {
        b.handle(&Request::WriteMultipleRegisters(0, Cow::Owned(vec![raw])))
    }

    #[test]
    fn out_of_range_without_a_status_register_is_refused() {
        let b = RegisterBank::new(RegisterMap::default(), 0.0, 100.0, OutOfRange::KeepAndFlag);
        assert_eq!(write(&b, 420), Ok(Response::WriteMultipleRegisters(0, 1)));
        assert_eq!(write(&b, 65535), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(b.setpoint_pct(), 42.0, "kept");
    }

    #[test]
    fn a_profile_s_registers_and_functions_are_served() {
        let b = RegisterBank::new(RegisterMap::default(), 0.0, 100.0, OutOfRange::KeepAndFlag)
            .serving(&[(Table::Holding, 3), (Table::Input, 0)], &[3, 4, 6]);
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(0, 420)),
            Ok(Response::WriteSingleRegister(0, 420))
        );
        assert_eq!(write(&b, 420), Err(ExceptionCode::IllegalFunction));
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(0, 4)),
            Err(ExceptionCode::IllegalDataAddress),
            "register 2 is neither mapped nor the profile's"
        );
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(3, 1)),
            Ok(Response::ReadHoldingRegisters(vec![0]))
        );
        assert_eq!(
            b.handle(&Request::ReadInputRegisters(0, 1)),
            Ok(Response::ReadInputRegisters(vec![0]))
        );
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(3, 1)),
            Err(ExceptionCode::IllegalDataAddress),
            "not writable"
        );
    }

    #[test]
    fn out_of_range_keeps_last_value_and_flags() {
        let b = RegisterBank::new(map(), 0.0, 100.0, OutOfRange::KeepAndFlag);
        assert_eq!(write(&b, 420), Ok(Response::WriteMultipleRegisters(0, 1)));
        assert_eq!(b.setpoint_pct(), 42.0);
        assert_eq!(b.status(), 0);
        assert_eq!(write(&b, 1001), Ok(Response::WriteMultipleRegisters(0, 1)));
        assert_eq!(b.setpoint_pct(), 42.0, "kept");
        assert_eq!(b.status(), 0b1000, "flagged");
        assert_eq!(b.rejected(), 1);
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(0, 3)),
            Ok(Response::ReadHoldingRegisters(vec![420, 0, 8]))
        );
        assert_eq!(write(&b, 1000), Ok(Response::WriteMultipleRegisters(0, 1)));
        assert_eq!(b.status(), 0, "cleared by a valid set-point");
        assert!(b.last_write().is_some());
    }

    #[test]
    fn exception_policy_refuses_with_03() {
        let b = RegisterBank::new(map(), 10.0, 90.0, OutOfRange::Exception);
        assert_eq!(write(&b, 950), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(write(&b, 50), Err(ExceptionCode::IllegalDataValue));
        assert_eq!(write(&b, 500), Ok(Response::WriteMultipleRegisters(0, 1)));
        assert_eq!(b.setpoint_pct(), 50.0);
        assert_eq!(b.accepted(), (50.0, 1), "refused writes are not counted");
        assert_eq!(b.rejected(), 2);
    }

    #[test]
    fn report_sets_position_and_masked_status_bits_only() {
        let b = RegisterBank::new(map(), 0.0, 100.0, OutOfRange::KeepAndFlag).with_setpoint(30.0);
        assert_eq!(b.accepted(), (30.0, 0));
        assert_eq!(write(&b, 1001), Ok(Response::WriteMultipleRegisters(0, 1)));
        b.report(Some(12.3), 0b110, 0b111);
        assert_eq!(
            b.status(),
            0b1110,
            "error bit 3 kept, bit 0 outside the mask"
        );
        b.report(None, 0b110, 0b010);
        assert_eq!(b.status(), 0b1010);
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(0, 3)),
            Ok(Response::ReadHoldingRegisters(vec![300, 123, 0b1010]))
        );
    }

    #[test]
    fn addresses_and_quantities() {
        let b = RegisterBank::new(map(), 0.0, 100.0, OutOfRange::KeepAndFlag);
        b.set_position_pct(-0.3);
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(1, 1)),
            Ok(Response::ReadHoldingRegisters(vec![(-3i16) as u16]))
        );
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(1, 3)),
            Err(ExceptionCode::IllegalDataAddress)
        );
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(0, 0)),
            Err(ExceptionCode::IllegalDataValue)
        );
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(0, 126)),
            Err(ExceptionCode::IllegalDataValue)
        );
        assert_eq!(
            b.handle(&Request::ReadInputRegisters(0, 1)),
            Err(ExceptionCode::IllegalDataAddress)
        );
        // The position and the status are read-only.
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(1, 5)),
            Err(ExceptionCode::IllegalDataAddress)
        );
        assert_eq!(
            b.handle(&Request::ReadCoils(0, 1)),
            Err(ExceptionCode::IllegalFunction)
        );
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(0, 250)),
            Ok(Response::WriteSingleRegister(0, 250))
        );
        assert_eq!(b.setpoint_pct(), 25.0);
    }

    #[test]
    fn fc23_writes_before_reading() {
        let b = RegisterBank::new(map(), 0.0, 100.0, OutOfRange::KeepAndFlag);
        let r = b.handle(&Request::ReadWriteMultipleRegisters(
            0,
            3,
            0,
            Cow::Owned(vec![777]),
        ));
        assert_eq!(r, Ok(Response::ReadWriteMultipleRegisters(vec![777, 0, 0])));
        let r = b.handle(&Request::ReadWriteMultipleRegisters(
            0,
            1,
            1,
            Cow::Owned(vec![1]),
        ));
        assert_eq!(r, Err(ExceptionCode::IllegalDataAddress));
    }

    #[test]
    fn partial_writes_of_a_32_bit_set_point_are_refused() {
        let m = RegisterMap {
            setpoint: Register {
                table: Table::Holding,
                address: 10,
                format: Format::F32,
                scale: 1.0,
                offset: 0.0,
            },
            position: Register {
                table: Table::Input,
                address: 0,
                format: Format::F32,
                scale: 1.0,
                offset: 0.0,
            },
            word_order: WordOrder::Little,
            ..RegisterMap::default()
        };
        let b = RegisterBank::new(m, 0.0, 100.0, OutOfRange::KeepAndFlag);
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(10, 1)),
            Err(ExceptionCode::IllegalDataAddress)
        );
        let w = m.setpoint.encode("x", 33.5, WordOrder::Little).unwrap();
        b.handle(&Request::WriteMultipleRegisters(10, Cow::Owned(w.to_vec())))
            .unwrap();
        assert_eq!(b.setpoint_pct(), 33.5);
        // NaN is out of range: kept, and refused (no status register to flag it in).
        let nan = f32::NAN.to_bits();
        assert_eq!(
            b.handle(&Request::WriteMultipleRegisters(
                10,
                Cow::Owned(vec![nan as u16, (nan >> 16) as u16]),
            )),
            Err(ExceptionCode::IllegalDataValue)
        );
        assert_eq!(b.setpoint_pct(), 33.5);
        b.set_position_pct(12.25);
        let Ok(Response::ReadInputRegisters(words)) = b.handle(&Request::ReadInputRegisters(0, 2))
        else {
            panic!("input registers not readable")
        };
        assert_eq!(m.decode_position(&words), Ok(12.25));
    }
}
