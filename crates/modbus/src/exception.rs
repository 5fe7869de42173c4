//! Modbus exception codes in words: what a device means by each, and what to check.
//!
//! Used wherever an exception reaches a person: the valve client's faults (and so the daemon's
//! log and summary) and `valve-bridge probe`. Nothing here talks to a device.

use tokio_modbus::ExceptionCode;

/// `exception 02 (illegal data address: ...)`: the code, its name and what to check.
pub fn explain(code: ExceptionCode) -> String {
    let raw = u8::from(code);
    let meaning = match raw {
        0x01 => {
            "illegal function: the device does not support this function code (for FC 23 set \
             [valve.registers] fc23 = false)"
        }
        0x02 => {
            "illegal data address: the device has no such register; check the addresses and \
             tables in [valve.registers] against its manual"
        }
        0x03 => {
            "illegal data value: the device refused the value or the register count; check the \
             format and scale in [valve.registers]"
        }
        0x04 => "server device failure: the device failed while handling the request",
        0x05 => "acknowledge: the device accepted a long request and is still working on it",
        0x06 => "server device busy: the device is busy with a long request; try again later",
        0x08 => "memory parity error: the device found an error in its memory",
        0x0A => {
            "gateway path unavailable: the gateway has no route to the unit id; check \
             unit_id / slave_id"
        }
        0x0B => {
            "gateway target failed to respond: the gateway got no answer from the device \
             behind it; check that device and its line"
        }
        _ => "not a standard Modbus exception; see the device's manual",
    };
    format!("exception {raw:02X} ({meaning})")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_are_named_with_what_to_check() {
        let e = explain(ExceptionCode::IllegalDataAddress);
        assert!(
            e.starts_with("exception 02 (illegal data address: ")
                && e.contains("[valve.registers]"),
            "{e}"
        );
        assert!(explain(ExceptionCode::ServerDeviceFailure)
            .starts_with("exception 04 (server device failure"));
        assert!(explain(ExceptionCode::Custom(0x42)).starts_with("exception 42 (not a standard"));
    }
}
