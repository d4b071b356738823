//! # mavstack-xml
//!
//! MAVLink message definitions ("dialects") from XML to a validated model, and a run-time
//! codec over that model.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!  XML file ──xml──► declarations ──loader──► includes resolved, merged ──layout──► Dialect
//!  (+ includes)      (positioned)             (duplicates, cycles checked)          │
//!                                                     wire order, CRC_EXTRA, lengths┘
//!                          Dialect ──codec──► decode / encode payloads of any message
//!                          Dialect ──mavstack-codegen──► Rust source
//! ```
//!
//! - [`Loader`] reads a root file and its include closure (relative to the including file)
//!   from the file system or from the definitions built into this crate, and returns a
//!   [`Dialect`]: messages sorted by id with fields in wire order, CRC_EXTRA, minimum and
//!   maximum payload lengths, target offsets; enums with entries merged across files.
//! - Every [`Error`] names the file, line and column and what is wrong.
//! - [`codec`] decodes a payload into [`codec::Value`]s and encodes values into a payload,
//!   for any message of a dialect loaded at run time.
//! - [`Dialect::message_table`] gives the dialect as the stack's
//!   [`MessageTable`](mavstack_core::MessageTable) (what the parser, channel and router take).
//! - `json` (feature `json`) writes frames as JSON lines and reads them back.
//!
//! ```
//! let dialect = mavstack_xml::load("ardupilotmega")?;
//! let m = dialect.message_by_name("COMMAND_ACK").expect("defined in common.xml");
//! assert_eq!((m.id, m.crc_extra, m.min_len, m.max_len), (77, 143, 3, 10));
//! # Ok::<(), mavstack_xml::Error>(())
//! ```
//!
//! ## Features
//! - `json`: frames as JSON lines ([`json`]).
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`fuzz_dialect_xml`, `json::fuzz_json_frames`).
//!
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

pub mod builtin;
pub mod codec;
mod error;
#[cfg(feature = "json")]
pub mod json;
pub mod layout;
mod loader;
pub mod model;
mod table;
mod xml;

pub use error::{Error, ErrorKind, Location};
pub use loader::{
    Builtin, EVENTS_SUPPLEMENT, FileSystem, Loader, PROTOCOL_VERSION_SUPPLEMENT,
    STANDARD_MODES_SUPPLEMENT, Source,
};
pub use model::{
    Deprecation, Dialect, Entry, EntryParam, Enum, Field, FieldType, FileInfo, Message,
    PrimitiveType,
};
pub use xml::MAX_MESSAGE_ID;

/// Loads a dialect by built-in name (`"common"`, `"ardupilotmega"`, ...; case does not
/// matter, so `"uavionix"` is `uAvionix`) or, when `name` is not one, as a path to an XML file
/// (includes resolved relative to it).
///
/// # Errors
/// An unknown name that is no readable file, or any problem in the definitions.
pub fn load(name: &str) -> Result<Dialect, Error> {
    let builtin = builtin::dialect_names();
    if let Some(found) = builtin.iter().find(|b| b.eq_ignore_ascii_case(name)) {
        return Loader::builtin().load(format!("{found}.xml"));
    }
    let path = std::path::Path::new(name);
    if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("xml"))
        || path.exists()
    {
        return Loader::filesystem().load(path);
    }
    Err(Error::new(
        Location {
            file: path.to_path_buf(),
            line: 1,
            column: 1,
        },
        ErrorKind::UnknownDialect {
            name: name.to_owned(),
            known: builtin.join(", "),
        },
    ))
}

/// Fuzzing entry point: loads `data` as a dialect XML file (with an include of itself and of a
/// missing file reachable, so cycles and read errors are exercised) and, if it loads, checks
/// that every message encodes and decodes to itself through the run-time codec: the values
/// decoded from a payload (the input's bytes, repeated) encode without error to the message's
/// full length, and decode from that encoding to the same values (compared as their
/// encoding, so a NaN equals itself). Errors while loading are the expected outcome; a
/// broken round trip panics.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_dialect_xml(data: &[u8]) {
    struct OneFile<'a>(&'a str);
    impl Source for OneFile<'_> {
        fn read(&self, path: &std::path::Path) -> std::io::Result<String> {
            if path == std::path::Path::new("fuzz.xml") {
                Ok(self.0.to_owned())
            } else {
                Err(std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "only fuzz.xml exists",
                ))
            }
        }
    }
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    let Ok(dialect) = Loader::new(OneFile(text)).load("fuzz.xml") else {
        return;
    };
    let mut payload = [0xA5u8; mavstack_core::MAX_PAYLOAD_LEN];
    for (slot, byte) in payload.iter_mut().zip(data.iter().cycle()) {
        *slot = *byte;
    }
    for m in &dialect.messages {
        let values = codec::decode(m, &payload[..m.max_len.min(payload.len())]);
        let mut first = [0u8; mavstack_core::MAX_PAYLOAD_LEN];
        let len = match codec::encode(m, &values, &mut first) {
            Ok(len) => len,
            Err(e) => panic!("{}: decoded values do not encode: {e}", m.name),
        };
        assert_eq!(len, m.max_len, "{}: encoded length", m.name);
        let again = codec::decode(m, &first[..len]);
        assert_eq!(
            again.len(),
            m.fields.len(),
            "{}: one value per field",
            m.name
        );
        let mut second = [0u8; mavstack_core::MAX_PAYLOAD_LEN];
        match codec::encode(m, &again, &mut second) {
            Ok(n) => assert_eq!(n, len, "{}: encoded length", m.name),
            Err(e) => panic!("{}: re-decoded values do not encode: {e}", m.name),
        }
        assert_eq!(
            first[..len],
            second[..len],
            "{}: values do not decode to themselves",
            m.name
        );
    }
}
