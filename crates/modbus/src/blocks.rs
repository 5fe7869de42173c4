//! Several register banks on one Modbus server, one block of addresses each: bank `k` answers
//! the addresses `k × size .. (k + 1) × size`, at its map's addresses plus `k × size` (with a
//! size of 10 and the default map, valve 1's set-point is holding register 10, its position 11
//! and its status 12).
//!
//! A request must stay within one block (a read across two blocks gets exception 02, as a read
//! of unmapped registers does); inside it the bank answers as it would alone, and the addresses
//! of a write's echo are shifted back. Not here: what a bank holds ([`RegisterBank`]), serving.

use std::borrow::Cow;
use std::sync::Arc;

use tokio_modbus::{ExceptionCode, Request, Response};

use super::server::RegisterBank;

/// Banks served side by side, `size` registers apart.
#[derive(Debug, Clone)]
pub struct Blocks {
    banks: Vec<Arc<RegisterBank>>,
    size: u32,
}

impl Blocks {
    /// `banks` in order, block `k` starting at `k × size`; one bank alone is served at its
    /// map's addresses whatever `size` says.
    pub fn new(banks: Vec<Arc<RegisterBank>>, size: u16) -> Blocks {
        let size = if banks.len() == 1 {
            1 << 16
        } else {
            u32::from(size).max(1)
        };
        Blocks { banks, size }
    }

    /// The banks, in block order.
    pub fn banks(&self) -> &[Arc<RegisterBank>] {
        &self.banks
    }

    /// Answers `req` from the bank whose block holds its addresses.
    pub fn handle(&self, req: &Request<'_>) -> Result<Response, ExceptionCode> {
        let spans: Vec<(u16, usize)> = match req {
            Request::ReadHoldingRegisters(a, n) | Request::ReadInputRegisters(a, n) => {
                vec![(*a, usize::from(*n))]
            }
            Request::WriteSingleRegister(a, _) => vec![(*a, 1)],
            Request::WriteMultipleRegisters(a, w) => vec![(*a, w.len())],
            Request::ReadWriteMultipleRegisters(ra, rn, wa, w) => {
                vec![(*ra, usize::from(*rn)), (*wa, w.len())]
            }
            // Not a register function: any bank gives the same exception.
            _ => return self.bank(0)?.handle(req),
        };
        let k = u32::from(spans[0].0) / self.size;
        let base = k * self.size;
        for &(a, n) in &spans {
            let (a, n) = (u32::from(a), n.max(1) as u32);
            if a < base || a + n > base + self.size {
                return Err(ExceptionCode::IllegalDataAddress);
            }
        }
        let bank = self.bank(k as usize)?;
        // Within the block: base + offset fits a u16, so the offset does too.
        let at = |a: &u16| (u32::from(*a) - base) as u16;
        let back = |a: u16| (u32::from(a) + base) as u16;
        let local = match req {
            Request::ReadHoldingRegisters(a, n) => Request::ReadHoldingRegisters(at(a), *n),
            Request::ReadInputRegisters(a, n) => Request::ReadInputRegisters(at(a), *n),
            Request::WriteSingleRegister(a, w) => Request::WriteSingleRegister(at(a), *w),
            Request::WriteMultipleRegisters(a, w) => {
                Request::WriteMultipleRegisters(at(a), Cow::Borrowed(w.as_ref()))
            }
            Request::ReadWriteMultipleRegisters(ra, rn, wa, w) => {
                Request::ReadWriteMultipleRegisters(at(ra), *rn, at(wa), Cow::Borrowed(w.as_ref()))
            }
            _ => return bank.handle(req),
        };
        match bank.handle(&local)? {
            Response::WriteSingleRegister(a, w) => Ok(Response::WriteSingleRegister(back(a), w)),
            Response::WriteMultipleRegisters(a, n) => {
                Ok(Response::WriteMultipleRegisters(back(a), n))
            }
            other => Ok(other),
        }
    }

    fn bank(&self, k: usize) -> Result<&RegisterBank, ExceptionCode> {
        self.banks
            .get(k)
            .map(|b| b.as_ref())
            .ok_or(ExceptionCode::IllegalDataAddress)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::RegisterMap;
    use crate::server::OutOfRange;

    fn blocks(n: usize) -> Blocks {
        let banks = (0..n)
            .map(|_| {
                Arc::new(RegisterBank::new(
                    RegisterMap::device_default(),
                    0.0,
                    100.0,
                    OutOfRange::Exception,
                ))
            })
            .collect();
        Blocks::new(banks, 10)
    }

    #[test]
    fn each_block_is_its_own_bank() {
        let b = blocks(2);
        assert_eq!(
            b.handle(&Request::WriteSingleRegister(10, 420)),
            Ok(Response::WriteSingleRegister(10, 420))
        );
        assert_eq!(b.banks()[1].setpoint_pct(), 42.0);
        assert_eq!(b.banks()[0].accepted().1, 0, "block 0 untouched");
        b.banks()[1].set_position_pct(41.5);
        assert_eq!(
            b.handle(&Request::ReadHoldingRegisters(10, 3)),
            Ok(Response::ReadHoldingRegisters(vec![420, 415, 0]))
        );
        assert_eq!(
            b.handle(&Request::WriteMultipleRegisters(0, Cow::Owned(vec![300]))),
            Ok(Response::WriteMultipleRegisters(0, 1))
        );
        assert_eq!(b.banks()[0].setpoint_pct(), 30.0);
        assert_eq!(
            b.handle(&Request::ReadWriteMultipleRegisters(
                10,
                2,
                10,
                Cow::Owned(vec![500])
            )),
            Ok(Response::ReadWriteMultipleRegisters(vec![500, 415]))
        );
    }

    #[test]
    fn outside_the_blocks_or_across_two_is_exception_02() {
        let b = blocks(2);
        for req in [
            Request::ReadHoldingRegisters(20, 1),
            Request::ReadHoldingRegisters(9, 3),
            Request::ReadHoldingRegisters(3, 1),
            Request::ReadWriteMultipleRegisters(0, 1, 10, Cow::Owned(vec![1])),
        ] {
            assert_eq!(
                b.handle(&req),
                Err(ExceptionCode::IllegalDataAddress),
                "{req:?}"
            );
        }
        assert_eq!(
            b.handle(&Request::ReadCoils(0, 1)),
            Err(ExceptionCode::IllegalFunction)
        );
        // One bank alone keeps its map's addresses, however far up they are.
        let one = blocks(1);
        assert!(one.handle(&Request::ReadHoldingRegisters(2, 1)).is_ok());
        assert_eq!(
            one.handle(&Request::ReadHoldingRegisters(12, 1)),
            Err(ExceptionCode::IllegalDataAddress)
        );
    }
}
