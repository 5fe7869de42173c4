//! Opening a serial port with the settings of a `[valve.modbus-rtu]` link: the one place that
//! turns an [`RtuLink`] into a tokio serial stream, for the valve client and for sim-device.
//!
//! The port is opened non-blocking for tokio, with the link's baud rate, parity, data and stop
//! bits, and whatever the driver still holds from before (a late reply to an earlier process) is
//! discarded. Not here: Modbus framing, timeouts, the bus budget.

use tokio_serial::{SerialPort, SerialPortBuilderExt, SerialStream};

use super::link::{Parity, RtuLink};

/// Opens `link.port` with the link's line settings and empties its buffers. A port that is a
/// link to a device that is gone (a pseudo-terminal whose server stopped, an unplugged
/// adapter's by-id name) says so.
pub fn open(link: &RtuLink) -> std::io::Result<SerialStream> {
    open_port(link).map_err(|e| {
        let e = std::io::Error::from(e);
        match std::fs::read_link(&link.port) {
            Ok(target) if e.kind() == std::io::ErrorKind::NotFound => std::io::Error::new(
                e.kind(),
                format!(
                    "it is a link to {}, which does not exist (the device behind it is gone)",
                    target.display()
                ),
            ),
            _ => e,
        }
    })
}

fn open_port(link: &RtuLink) -> tokio_serial::Result<SerialStream> {
    let stream = tokio_serial::new(&link.port, link.baud)
        .parity(match link.parity {
            Parity::None => tokio_serial::Parity::None,
            Parity::Even => tokio_serial::Parity::Even,
            Parity::Odd => tokio_serial::Parity::Odd,
        })
        .data_bits(if link.data_bits == 7 {
            tokio_serial::DataBits::Seven
        } else {
            tokio_serial::DataBits::Eight
        })
        .stop_bits(if link.stop_bits == 2 {
            tokio_serial::StopBits::Two
        } else {
            tokio_serial::StopBits::One
        })
        .open_native_async()?;
    stream.clear(tokio_serial::ClearBuffer::All)?;
    Ok(stream)
}
