//! MAVLink FTP (FILE_TRANSFER_PROTOCOL, message 110): the payload format, the server
//! role over a [`Backend`] and the client role.
//!
//! <https://mavlink.io/en/services/ftp.html>

pub mod backend;
pub mod client;
#[cfg(feature = "std")]
pub mod dir;
#[cfg(feature = "fuzzing")]
mod fuzzing;
pub mod overlay;
pub mod param_pck;
pub mod payload;
pub mod server;

pub use backend::{Backend, BackendError, MemoryBackend, OpenMode, normalize_path};
pub use client::{ClientConfig, FtpClient, FtpError, FtpEvent, FtpOutput, StartError};
#[cfg(feature = "std")]
pub use dir::DirBackend;
pub use overlay::{Overlay, OverlayHandle, Provider};
pub use payload::{
    DirEntry, EntryKind, NakCode, Opcode, Payload, PayloadError, crc32, parse_entries,
};
pub use server::{FtpServer, ServerConfig};

#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use fuzzing::fuzz_ftp;

#[cfg(test)]
mod tests;
