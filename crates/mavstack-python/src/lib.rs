//! # mavstack-python
//!
//! The native part of the Python package `mavstack` (built with maturin, abi3):
//! - `mavstack.mavutil.mavlink_connection("udpin:0.0.0.0:14550")`: a live link with
//!   pymavlink's API (`live`: one `mavstack::Node` per connection, opened from the string by
//!   the stack's `LinkSpec` parser; receiving without the GIL while it waits);
//! - `mavstack.mavutil.mavlink_connection(path, dialect=..., key=...)`: a log read message by
//!   message with pymavlink's API (`recv_match`, `recv_msg`, iteration, `messages`), the
//!   messages pymavlink's (`get_type()`, `get_srcSystem()`, `_timestamp`, `to_dict()`,
//!   fields as attributes), decoded from the mapped file only when a field is read;
//! - `mavstack.read_tlog(path, types=None, dialect=..., key=None, progress=False)`: one Arrow
//!   table per message type through the Arrow C stream interface.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! The frames are found by the same code as `mavstack decode` and `mavstack log`:
//! `mavstack_core::parse::SliceParser` for raw logs, `mavstack_core::tlog::Records` for tlogs.

// `mavstack.aio`: its loop wake-up is a Unix socket pair.
#[cfg(unix)]
mod aio;
mod connection;
mod dialect;
mod live;
mod log_data;
mod message;
mod progress;
mod tables;

use std::path::PathBuf;

use pyo3::prelude::*;

/// Opens a log file: `.tlog` by its extension, anything else as raw MAVLink frames.
#[pyfunction]
#[pyo3(signature = (path, dialect="ardupilotmega", key=None))]
fn open_log(
    path: PathBuf,
    dialect: &str,
    key: Option<&Bound<'_, PyAny>>,
) -> PyResult<connection::LogConnection> {
    connection::LogConnection::open(path, dialect, connection::parse_key(key)?)
}

/// Opens a live link from a connection string (`udpin:0.0.0.0:14550`, `tcp:HOST:PORT`,
/// `serial:/dev/ttyUSB0:57600`, optionally followed by link options) as system
/// `source_system`, component `source_component`, signing with `key` (32 bytes or 64 hex
/// digits) when given.
#[pyfunction]
#[pyo3(signature = (device, source_system=255, source_component=0, dialect="ardupilotmega", key=None, link_id=0))]
fn open_live(
    py: Python<'_>,
    device: &str,
    source_system: u8,
    source_component: u8,
    dialect: &str,
    key: Option<&Bound<'_, PyAny>>,
    link_id: u8,
) -> PyResult<live::LiveLink> {
    let key = connection::parse_key(key)?;
    live::LiveLink::open(
        py,
        device,
        source_system,
        source_component,
        dialect,
        key,
        link_id,
    )
}

/// Every enum entry of `dialect` as (name, value), and every message's
/// `MAVLINK_MSG_ID_<NAME>`: pymavlink's module constants (`MAV_CMD_COMPONENT_ARM_DISARM`, ...).
#[pyfunction]
#[pyo3(signature = (dialect="ardupilotmega"))]
fn dialect_constants(dialect: &str) -> PyResult<Vec<(String, u64)>> {
    Ok(dialect::Dialect::load(dialect)?.constants.clone())
}

/// The names of the built-in dialects.
#[pyfunction]
fn dialects() -> Vec<&'static str> {
    mavstack_xml::builtin::dialect_names()
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(open_log, m)?)?;
    m.add_function(wrap_pyfunction!(open_live, m)?)?;
    m.add_function(wrap_pyfunction!(dialect_constants, m)?)?;
    m.add_function(wrap_pyfunction!(tables::read_tlog, m)?)?;
    m.add_function(wrap_pyfunction!(dialects, m)?)?;
    m.add_class::<connection::LogConnection>()?;
    m.add_class::<connection::LatestMessages>()?;
    m.add_class::<live::LiveLink>()?;
    m.add_class::<message::Message>()?;
    m.add_class::<message::Header>()?;
    m.add_class::<tables::Table>()?;
    #[cfg(unix)]
    aio::register(m)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
