//! Serial ports.

use crate::error::Reason;

/// An open serial port (8N1, no flow control).
pub(super) fn open_serial(device: &str, baud: u32) -> Result<tokio_serial::SerialStream, Reason> {
    use tokio_serial::SerialPortBuilderExt as _;
    tokio_serial::new(device, baud)
        .open_native_async()
        .map_err(|e| Reason::from_serial(&e))
}
