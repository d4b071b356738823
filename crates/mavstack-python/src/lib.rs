//! # mavstack-python
//!
//! The native part of the Python package `mavstack` (built with maturin, abi3):
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

mod connection;
mod dialect;
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

/// The names of the built-in dialects.
#[pyfunction]
fn dialects() -> Vec<&'static str> {
    mavstack_xml::builtin::dialect_names()
}

/// The native module.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(open_log, m)?)?;
    m.add_function(wrap_pyfunction!(tables::read_tlog, m)?)?;
    m.add_function(wrap_pyfunction!(dialects, m)?)?;
    m.add_class::<connection::LogConnection>()?;
    m.add_class::<connection::LatestMessages>()?;
    m.add_class::<message::Message>()?;
    m.add_class::<message::Header>()?;
    m.add_class::<tables::Table>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
