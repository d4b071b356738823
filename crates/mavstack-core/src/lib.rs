//! # mavstack-core
//!
//! The `no_std`, allocation-free foundation of mavstack: what every other layer and every
//! generated dialect stands on.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!  XML dialects ──(mavstack-codegen)──► generated structs ──implement──► Message / MessageSet
//!                                                                         │
//!  bytes ◄── payload helpers (little-endian, zero-extended) ◄─────────────┘
//!        ◄── crc (CRC-16/MCRF4XX with CRC_EXTRA)
//! ```
//!
//! - [`crc`]: the X.25 / CRC-16/MCRF4XX checksum that guards every frame.
//! - [`message`]: the [`Message`] trait that every generated message implements and the
//!   [`MessageSet`] trait of a dialect's message enum, plus [`MessageInfo`], the per-id facts
//!   (CRC_EXTRA, lengths, target offsets) a parser needs.
//! - [`table`]: [`MessageTable`], a dialect's [`MessageInfo`] entries sorted by id: the one
//!   message-id lookup every layer takes.
//! - [`payload`]: the byte helpers generated code uses to read and write payload fields.
//! - [`text`]: `char[N]` fields as text.
//! - [`tlog`]: telemetry log records in a slice, zero-copy.
//!
//! ## Guarantees
//! - `#![no_std]`, no allocation, `#![forbid(unsafe_code)]`.
//! - Decoding a payload never fails: short payloads are zero-extended (MAVLink 2 truncation),
//!   longer ones are cut (a newer dialect's extensions), and enums are open.
//!
//! ## Features
//! - `std` (default): links `std`; nothing in the crate needs it.
//! - `serde`: serde support for generated messages, including arrays longer than 32.
//! - `testing`: [`testing`], the in-memory test network of the sans-IO crates' tests (for
//!   dev-dependencies; implies `std`).
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (the `fuzz_*` entry points and `fuzz_seeds`; implies `std`).
//!
//! MSRV: Rust 1.95 (the toolchain CI builds with).
#![no_std]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
extern crate std;

pub mod crc;
pub mod message;
pub mod parse;
pub mod payload;
#[cfg(feature = "serde")]
pub mod serde_arrays;
pub mod signing;
pub mod table;
#[cfg(feature = "testing")]
pub mod testing;
pub mod text;
pub mod time;
pub mod tlog;
pub mod wire;

pub use crc::Crc16;
pub use message::{MAX_PAYLOAD_LEN, Message, MessageInfo, MessageSet, UnknownMessage};
pub use table::MessageTable;

/// The seeds of fuzz target `target` (`fuzz/corpus/TARGET` in the source tree), in file-name
/// order, for the tests that replay them on stable.
///
/// # Panics
/// If the folder cannot be read or holds fewer than `at_least` seeds.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
#[must_use]
pub fn fuzz_seeds(target: &str, at_least: usize) -> std::vec::Vec<std::vec::Vec<u8>> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/corpus")
        .join(target);
    let mut paths: std::vec::Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("seed corpus {}: {e}", dir.display()))
        .map(|entry| entry.expect("a readable folder entry").path())
        .collect();
    paths.sort();
    assert!(
        paths.len() >= at_least,
        "{} seeds in {}, expected at least {at_least}",
        paths.len(),
        dir.display()
    );
    paths
        .iter()
        .map(|p| std::fs::read(p).unwrap_or_else(|e| panic!("seed {}: {e}", p.display())))
        .collect()
}

/// Fuzzing entry point for the parsers: runs `data` through the slice parser and, split at
/// every byte boundary the data itself chooses, through the streaming deframer and through
/// the slice parser piece by piece, and checks that all find the same frames. Never panics unless they disagree (a bug).
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_deframer(data: &[u8]) {
    // A small fixed dialect: HEARTBEAT, COMMAND_LONG and one id above 255.
    let lookup = |id: u32| match id {
        0 => Some(50u8),
        76 => Some(152),
        300 => Some(217),
        _ => None,
    };
    let mut from_slice = [(0usize, 0u32); 64];
    let mut n_slice = 0;
    for item in parse::SliceParser::new(data, lookup).take(64) {
        let (parse::Item::Frame(f) | parse::Item::Unknown(f)) = item;
        from_slice[n_slice] = (f.frame_len(), f.msg_id());
        n_slice += 1;
    }
    let chunk = usize::from(data.first().copied().unwrap_or(1)).max(1);
    let mut deframer = parse::Deframer::new();
    let mut n_stream = 0;
    let mut record = |item: parse::Item<'_>| {
        let (parse::Item::Frame(f) | parse::Item::Unknown(f)) = item;
        if n_stream < n_slice {
            assert_eq!(
                from_slice[n_stream],
                (f.frame_len(), f.msg_id()),
                "deframer and slice parser disagree"
            );
        }
        n_stream += 1;
    };
    for piece in data.chunks(chunk) {
        let mut rest = piece;
        while !rest.is_empty() {
            let taken = deframer.push(rest);
            rest = &rest[taken..];
            while let Some(item) = deframer.next_item(&lookup) {
                record(item);
            }
        }
    }
    while let Some(item) = deframer.finish(&lookup) {
        record(item);
    }
    assert!(
        n_stream >= n_slice.min(64),
        "deframer found fewer frames than the slice parser"
    );
    // The slice parser over the same pieces, each parse continued from where the last one
    // stopped (how `mavstack decode` reads a file in fixed chunks): the same frames again.
    let mut buf = [0u8; 2 * wire::MAX_FRAME_LEN + 256];
    let (mut held, mut fed, mut n_pieces) = (0, 0, 0);
    loop {
        let take = chunk.min(data.len() - fed).min(buf.len() - held);
        buf[held..held + take].copy_from_slice(&data[fed..fed + take]);
        held += take;
        fed += take;
        let at_end = fed == data.len();
        let mut p = if at_end {
            parse::SliceParser::new(&buf[..held], lookup)
        } else {
            parse::SliceParser::partial(&buf[..held], lookup)
        };
        for item in p.by_ref() {
            let (parse::Item::Frame(f) | parse::Item::Unknown(f)) = item;
            if n_pieces < n_slice {
                assert_eq!(
                    from_slice[n_pieces],
                    (f.frame_len(), f.msg_id()),
                    "the slice parser over pieces disagrees with it over the whole"
                );
            }
            n_pieces += 1;
        }
        if at_end {
            break;
        }
        let keep = p.position();
        assert!(
            keep > 0 || take > 0,
            "the parser over pieces stopped making progress"
        );
        buf.copy_within(keep..held, 0);
        held -= keep;
    }
    assert!(
        n_pieces >= n_slice.min(64),
        "the slice parser over pieces found fewer frames than over the whole"
    );
}

/// Fuzzing entry point for frame views and their serialisation: every accessor of a checked
/// frame, signature verification, and the property that a parsed frame re-serialises to
/// itself. [`wire::emit`] given the frame's header fields and payload writes the same header
/// and payload bytes, the checksum the frame carries (under the CRC_EXTRA that makes it
/// valid, when one does; else the one [`wire::Frame::compute_checksum`] gives), and
/// [`signing::append_signature`] the same link id and timestamp and the signature computed
/// over the same signed bytes. A frame that is not in the form `emit` writes (MAVLink 2
/// trailing zeros, compat flags or unknown incompat flags) re-serialises to that form: same
/// header fields, same payload once zero-extended. Panics when the property breaks.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_frame(data: &[u8]) {
    let Ok(frame) = wire::Frame::new_checked(data) else {
        return;
    };
    let _ = (frame.as_bytes(), frame.signed_bytes(), frame.compat_flags());
    let key = signing::SecretKey::new([0x5A; 32]);
    let _ = signing::verify(&frame, &key);

    let version = frame.version();
    let header_len = version.header_len();
    let payload = frame.payload();
    let len = payload.len();
    // The CRC_EXTRA under which the carried checksum is valid, if any: the CRC of the header
    // and payload, then each candidate byte.
    let mut crc = Crc16::new();
    crc.update(&frame.as_bytes()[1..header_len + len]);
    let crc_extra = (0..=u8::MAX)
        .find(|&e| {
            let mut c = crc;
            c.update_byte(e);
            c.value() == frame.checksum()
        })
        .unwrap_or(0);
    let header = wire::FrameHeader {
        version,
        seq: frame.seq(),
        sysid: frame.sysid(),
        compid: frame.compid(),
        signed: frame.is_signed(),
    };
    let len_byte = u8::try_from(len).unwrap_or(u8::MAX);
    let info = MessageInfo {
        id: frame.msg_id(),
        name: "FUZZ",
        crc_extra,
        min_len: len_byte,
        max_len: len_byte,
        target_system_offset: None,
        target_component_offset: None,
    };
    let mut out = [0u8; wire::MAX_FRAME_LEN];
    let written = match wire::emit(&header, &info, payload, &mut out) {
        Ok(n) => n,
        Err(e) => panic!("a parsed frame does not re-serialise: {e}"),
    };
    let written = match frame.signature() {
        Some(sig) => {
            match signing::append_signature(&mut out, written, sig.link_id, sig.timestamp, &key) {
                Ok(n) => n,
                Err(e) => panic!("a parsed signature does not re-serialise: {e}"),
            }
        }
        None => written,
    };
    let again = match wire::Frame::new_checked(&out[..written]) {
        Ok(f) => f,
        Err(e) => panic!("a re-serialised frame does not parse: {e:?}"),
    };
    assert_eq!(
        (again.version(), again.seq(), again.sysid(), again.compid()),
        (version, frame.seq(), frame.sysid(), frame.compid()),
        "header"
    );
    assert_eq!(again.msg_id(), frame.msg_id(), "message id");
    assert_eq!(again.is_signed(), frame.is_signed(), "signed flag");
    let shorter = again.payload().len().min(len);
    assert_eq!(&again.payload()[..shorter], &payload[..shorter], "payload");
    assert!(
        again.payload()[shorter..].iter().all(|&b| b == 0)
            && payload[shorter..].iter().all(|&b| b == 0),
        "payload beyond the shorter one is not zero"
    );
    assert!(
        again.check_crc(crc_extra),
        "checksum of the re-serialised frame"
    );
    if let (Some(a), Some(b)) = (again.signature(), frame.signature()) {
        assert_eq!(
            (a.link_id, a.timestamp),
            (b.link_id, b.timestamp),
            "signature block"
        );
    }
    let canonical = match version {
        wire::Version::V1 => true,
        wire::Version::V2 => {
            frame.compat_flags() == 0
                && frame.incompat_flags() & !wire::INCOMPAT_SIGNED == 0
                && payload::truncated_len(payload) == len
        }
    };
    if canonical {
        let end = header_len + len + wire::CHECKSUM_LEN;
        assert_eq!(
            &out[..header_len + len],
            &frame.as_bytes()[..header_len + len],
            "header and payload bytes"
        );
        assert_eq!(
            again.checksum(),
            frame.compute_checksum(crc_extra),
            "checksum"
        );
        // With a checksum valid under some CRC_EXTRA, the frame comes back byte for byte
        // through the checksum, and so do the bytes its signature covers.
        if frame.check_crc(crc_extra) {
            assert_eq!(
                &out[..end],
                &frame.as_bytes()[..end],
                "frame bytes through the checksum"
            );
            assert_eq!(again.signed_bytes(), frame.signed_bytes(), "signed bytes");
        }
    }
    // The signature appended is the one over the bytes it covers.
    if let (Some(a), Some(signed)) = (again.signature(), again.signed_bytes()) {
        assert_eq!(a.value, signing::compute(&key, signed), "signature value");
    }
}
