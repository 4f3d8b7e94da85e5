//! Opening a serial line from its `[device.serial]` table: one place for the
//! line settings of every protocol that runs over a serial port (Modbus RTU,
//! DNP3), so they cannot drift apart.

use gridscada_config::{Parity, SerialConfig};
use tokio_serial::SerialPortBuilderExt;

/// Opens the port with the configured baud rate, parity, data and stop bits.
/// The error names the port and the operating system's reason.
pub fn open_serial(c: &SerialConfig) -> Result<tokio_serial::SerialStream, String> {
    let port = c.port.get_ref();
    tokio_serial::new(port, c.baud)
        .parity(match c.parity {
            Parity::None => tokio_serial::Parity::None,
            Parity::Even => tokio_serial::Parity::Even,
            Parity::Odd => tokio_serial::Parity::Odd,
        })
        .data_bits(match c.data_bits.get_ref() {
            5 => tokio_serial::DataBits::Five,
            6 => tokio_serial::DataBits::Six,
            7 => tokio_serial::DataBits::Seven,
            _ => tokio_serial::DataBits::Eight,
        })
        .stop_bits(if *c.stop_bits.get_ref() == 2 {
            tokio_serial::StopBits::Two
        } else {
            tokio_serial::StopBits::One
        })
        .open_native_async()
        .map_err(|e| format!("cannot open serial port {port}: {e}"))
}
