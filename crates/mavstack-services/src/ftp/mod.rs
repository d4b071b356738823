//! MAVLink FTP (FILE_TRANSFER_PROTOCOL, message 110): the payload format.
//!
//! <https://mavlink.io/en/services/ftp.html>

pub mod payload;

pub use payload::{
    DirEntry, EntryKind, NakCode, Opcode, Payload, PayloadError, crc32, parse_entries,
};
