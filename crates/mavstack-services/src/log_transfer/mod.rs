//! Log download, the MAVLink guide's "Log (Dataflash) Download" protocol (the LOG_* messages),
//! in both roles: [`LogClient`] lists, downloads and erases a vehicle's logs, [`LogServer`]
//! serves the logs of a [`LogStore`].
//!
//! <https://mavlink.io/en/services/log.html> (messages 117–122):
//!
//! ```text
//!   client                                     server
//!   LOG_REQUEST_LIST(start, end)   ─────►
//!                                  ◄─────     LOG_ENTRY(id, num_logs, last_log_num, time_utc, size)  one per log
//!   LOG_REQUEST_DATA(id, ofs, count) ───►
//!                                  ◄─────     LOG_DATA(id, ofs, count ≤ 90, data[90])  a stream of chunks
//!   LOG_REQUEST_END                ─────►     (stop sending, resume logging)
//!   LOG_ERASE                      ─────►     (no answer)
//! ```
//!
//! What the peers do, and what these roles follow:
//!
//! - With no logs the list is one LOG_ENTRY with `id` and `num_logs` 0. Ids start at 1
//!   (ArduPilot) or 0 (PX4); `last_log_num` is the highest id. ArduPilot never lists an empty
//!   log.
//! - LOG_REQUEST_DATA asks for `count` bytes from `ofs` (MAVProxy asks for `0xFFFFFFFF`: the
//!   rest of the log; MAVSDK for 512 × 90 bytes at a time). The server streams chunks of 90
//!   bytes from `ofs` and stops at the end of the range or of the log; a chunk shorter than
//!   90 bytes is the log's last; a request at or beyond the end is answered with one chunk of
//!   count 0. ArduPilot sends nothing for a log id it does not have.
//! - LOG_DATA has no target fields: it is for whoever asked.
//! - A request while another is being served: ArduPilot (since 4.1) drops it until the first
//!   is done; [`LogServer`] lets it replace the first. Either way a client asks for one range
//!   at a time and asks again only when the stream has gone quiet.
//! - The announced size "may be approximate" (dataflash chips): a stream that ends early
//!   (a short chunk, or count 0, inside the range asked) ends the log there.

mod client;
#[cfg(feature = "fuzzing")]
mod fuzzing;
mod server;
mod store;

pub use client::{ClientConfig, LogClient, LogError, LogEvent, LogOutput, StartError};
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use fuzzing::fuzz_log_transfer;
pub use server::{LogServer, LogServerEvent, ServerConfig};
pub use store::{LogStore, MemoryLogs, StoreError};

/// Bytes of log data one LOG_DATA carries at most.
pub const CHUNK: usize = 90;

/// One log as LOG_ENTRY describes it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct LogInfo {
    /// Its id (from 0 or 1, as the vehicle numbers them).
    pub id: u16,
    /// When it was started: seconds since 1970 (UTC), 0 when not known.
    pub time_utc: u32,
    /// Its size in bytes (approximate on some vehicles).
    pub size: u32,
}
