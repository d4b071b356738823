//! The FTP payload carried in FILE_TRANSFER_PROTOCOL's 251-byte `payload` field, its
//! opcodes and NAK codes, and the directory-listing entry format.

use alloc::string::String;
use alloc::vec::Vec;

/// Bytes of the payload header (seq_number .. offset).
pub const HEADER_LEN: usize = 12;
/// Bytes of data one payload can carry (251 − 12).
pub const MAX_DATA: usize = 239;
/// Bytes of the whole FILE_TRANSFER_PROTOCOL payload field.
pub const PAYLOAD_LEN: usize = 251;

/// An FTP opcode (header byte 3, and byte 5 `req_opcode` in replies). Unknown values are
/// kept as [`Opcode::Unknown`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Opcode {
    /// 0: ignored, always ACKed.
    None,
    /// 1: closes one session.
    TerminateSession,
    /// 2: closes every session.
    ResetSessions,
    /// 3: lists a directory from the entry index in `offset`.
    ListDirectory,
    /// 4: opens a file for reading; the ACK carries the session and the size.
    OpenFileRO,
    /// 5: reads `size` bytes at `offset` in a session.
    ReadFile,
    /// 6: creates (or truncates) a file for writing; the ACK carries the session.
    CreateFile,
    /// 7: writes `size` bytes at `offset` in a session.
    WriteFile,
    /// 8: removes a file.
    RemoveFile,
    /// 9: creates a directory.
    CreateDirectory,
    /// 10: removes an empty directory.
    RemoveDirectory,
    /// 11: opens a file for writing (created if missing, not truncated).
    OpenFileWO,
    /// 12: truncates a file to `offset` bytes.
    TruncateFile,
    /// 13: renames; data is `old\0new`.
    Rename,
    /// 14: CRC32 of a file; the ACK carries it as a little-endian u32.
    CalcFileCRC32,
    /// 15: streams a session's file from `offset` in ReadFile-like ACKs.
    BurstReadFile,
    /// 128: positive reply.
    Ack,
    /// 129: negative reply; data\[0\] is a [`NakCode`].
    Nak,
    /// Any other value.
    Unknown(u8),
}

impl Opcode {
    /// The opcode for a wire byte.
    #[must_use]
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0 => Self::None,
            1 => Self::TerminateSession,
            2 => Self::ResetSessions,
            3 => Self::ListDirectory,
            4 => Self::OpenFileRO,
            5 => Self::ReadFile,
            6 => Self::CreateFile,
            7 => Self::WriteFile,
            8 => Self::RemoveFile,
            9 => Self::CreateDirectory,
            10 => Self::RemoveDirectory,
            11 => Self::OpenFileWO,
            12 => Self::TruncateFile,
            13 => Self::Rename,
            14 => Self::CalcFileCRC32,
            15 => Self::BurstReadFile,
            128 => Self::Ack,
            129 => Self::Nak,
            v => Self::Unknown(v),
        }
    }

    /// The wire byte.
    #[must_use]
    pub const fn to_u8(self) -> u8 {
        match self {
            Self::None => 0,
            Self::TerminateSession => 1,
            Self::ResetSessions => 2,
            Self::ListDirectory => 3,
            Self::OpenFileRO => 4,
            Self::ReadFile => 5,
            Self::CreateFile => 6,
            Self::WriteFile => 7,
            Self::RemoveFile => 8,
            Self::CreateDirectory => 9,
            Self::RemoveDirectory => 10,
            Self::OpenFileWO => 11,
            Self::TruncateFile => 12,
            Self::Rename => 13,
            Self::CalcFileCRC32 => 14,
            Self::BurstReadFile => 15,
            Self::Ack => 128,
            Self::Nak => 129,
            Self::Unknown(v) => v,
        }
    }
}

/// A NAK's error code (data\[0\] of a NAK). Unknown values are kept as
/// [`NakCode::Unknown`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NakCode {
    /// 0: no error.
    None,
    /// 1: unspecified failure.
    Fail,
    /// 2: failure with an errno in data\[1\].
    FailErrno,
    /// 3: the payload's size is wrong for the opcode.
    InvalidDataSize,
    /// 4: no such session (or not the sender's).
    InvalidSession,
    /// 5: every session is in use.
    NoSessionsAvailable,
    /// 6: offset at or past the end of the file or listing.
    Eof,
    /// 7: unknown opcode.
    UnknownCommand,
    /// 8: the file or directory already exists.
    FileExists,
    /// 9: the file or directory is write protected.
    FileProtected,
    /// 10: no such file or directory.
    FileNotFound,
    /// Any other value.
    Unknown(u8),
}

impl NakCode {
    /// The code for a wire byte.
    #[must_use]
    pub const fn from_u8(v: u8) -> Self {
        match v {
            0 => Self::None,
            1 => Self::Fail,
            2 => Self::FailErrno,
            3 => Self::InvalidDataSize,
            4 => Self::InvalidSession,
            5 => Self::NoSessionsAvailable,
            6 => Self::Eof,
            7 => Self::UnknownCommand,
            8 => Self::FileExists,
            9 => Self::FileProtected,
            10 => Self::FileNotFound,
            v => Self::Unknown(v),
        }
    }

    /// The wire byte.
    #[must_use]
    pub const fn to_u8(self) -> u8 {
        match self {
            Self::None => 0,
            Self::Fail => 1,
            Self::FailErrno => 2,
            Self::InvalidDataSize => 3,
            Self::InvalidSession => 4,
            Self::NoSessionsAvailable => 5,
            Self::Eof => 6,
            Self::UnknownCommand => 7,
            Self::FileExists => 8,
            Self::FileProtected => 9,
            Self::FileNotFound => 10,
            Self::Unknown(v) => v,
        }
    }
}

/// Why a payload could not be decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PayloadError {
    /// The size byte is larger than the data area (239).
    #[error("size {0} is larger than the {MAX_DATA}-byte data area")]
    SizeTooLarge(u8),
}

/// One decoded FTP payload.
///
/// `data` holds the `size` bytes in use; [`Payload::encode`] writes at most
/// [`MAX_DATA`] of them (a valid payload has no more).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Payload {
    /// Sequence number (bytes 0–1, little endian). A reply's is the request's + 1.
    pub seq: u16,
    /// Session id (byte 2).
    pub session: u8,
    /// Opcode (byte 3).
    pub opcode: Opcode,
    /// In a reply, the opcode of the request answered (byte 5).
    pub req_opcode: Opcode,
    /// Set on the last reply of a burst (byte 6).
    pub burst_complete: bool,
    /// Offset (bytes 8–11, little endian): file offset, or entry index when listing.
    pub offset: u32,
    /// The data (bytes 12.., `size` of them, byte 4).
    pub data: Vec<u8>,
}

impl Payload {
    /// A request: `opcode` with `data`, everything else zero.
    #[must_use]
    pub fn request(seq: u16, session: u8, opcode: Opcode, offset: u32, data: &[u8]) -> Self {
        Self {
            seq,
            session,
            opcode,
            req_opcode: Opcode::None,
            burst_complete: false,
            offset,
            data: data[..data.len().min(MAX_DATA)].to_vec(),
        }
    }

    /// The 251 bytes of FILE_TRANSFER_PROTOCOL.payload (padding byte 7 zero, unused data
    /// bytes zero).
    #[must_use]
    pub fn encode(&self) -> [u8; PAYLOAD_LEN] {
        let mut out = [0u8; PAYLOAD_LEN];
        let n = self.data.len().min(MAX_DATA);
        out[0..2].copy_from_slice(&self.seq.to_le_bytes());
        out[2] = self.session;
        out[3] = self.opcode.to_u8();
        // n <= 239 fits a byte.
        out[4] = u8::try_from(n).unwrap_or(u8::MAX);
        out[5] = self.req_opcode.to_u8();
        out[6] = u8::from(self.burst_complete);
        out[8..12].copy_from_slice(&self.offset.to_le_bytes());
        out[HEADER_LEN..HEADER_LEN + n].copy_from_slice(&self.data[..n]);
        out
    }

    /// Decodes the 251 bytes of FILE_TRANSFER_PROTOCOL.payload. The padding byte and data
    /// bytes past `size` are ignored; any non-zero `burst_complete` is `true`.
    ///
    /// # Errors
    ///
    /// [`PayloadError::SizeTooLarge`] if the size byte exceeds [`MAX_DATA`].
    pub fn decode(bytes: &[u8; PAYLOAD_LEN]) -> Result<Self, PayloadError> {
        let size = bytes[4];
        let n = usize::from(size);
        if n > MAX_DATA {
            return Err(PayloadError::SizeTooLarge(size));
        }
        Ok(Self {
            seq: u16::from_le_bytes([bytes[0], bytes[1]]),
            session: bytes[2],
            opcode: Opcode::from_u8(bytes[3]),
            req_opcode: Opcode::from_u8(bytes[5]),
            burst_complete: bytes[6] != 0,
            offset: u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]),
            data: bytes[HEADER_LEN..HEADER_LEN + n].to_vec(),
        })
    }

    /// A NAK's error code and, for [`NakCode::FailErrno`], its errno (`None` when the
    /// NAK carries no code at all).
    #[must_use]
    pub fn nak(&self) -> Option<(NakCode, Option<u8>)> {
        let code = NakCode::from_u8(*self.data.first()?);
        let errno = if code == NakCode::FailErrno {
            self.data.get(1).copied()
        } else {
            None
        };
        Some((code, errno))
    }
}

/// What a directory-listing entry names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum EntryKind {
    /// A file of this many bytes (`F<name>\t<size>\0`).
    File {
        /// The size in bytes.
        size: u64,
    },
    /// A directory (`D<name>\0`).
    Directory,
    /// An entry the server chose not to describe (`S\0`, or one not understood): it
    /// still counts for the next listing offset.
    Skip,
}

/// One directory-listing entry.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DirEntry {
    /// The entry's name (empty for [`EntryKind::Skip`]).
    pub name: String,
    /// What it is.
    pub kind: EntryKind,
}

impl DirEntry {
    /// Appends the entry in its wire form, NUL included. A name holding a NUL or a tab,
    /// which the format cannot carry, is written as a skip entry.
    pub fn encode_into(&self, out: &mut Vec<u8>) {
        let unsayable = self.name.bytes().any(|b| b == 0 || b == b'\t');
        match &self.kind {
            EntryKind::File { size } if !unsayable => {
                out.push(b'F');
                out.extend_from_slice(self.name.as_bytes());
                out.push(b'\t');
                out.extend_from_slice(alloc::format!("{size}").as_bytes());
            }
            EntryKind::Directory if !unsayable => {
                out.push(b'D');
                out.extend_from_slice(self.name.as_bytes());
            }
            _ => out.push(b'S'),
        }
        out.push(0);
    }

    /// The entry's wire length, NUL included.
    #[must_use]
    pub fn encoded_len(&self) -> usize {
        let mut v = Vec::new();
        self.encode_into(&mut v);
        v.len()
    }
}

/// Parses the entries of a ListDirectory ACK's data. Every non-empty NUL-terminated (or
/// trailing) piece is one entry; pieces not understood are [`EntryKind::Skip`] so the
/// count stays right for the next offset. Names that are not UTF-8 are converted lossily.
#[must_use]
pub fn parse_entries(data: &[u8]) -> Vec<DirEntry> {
    data.split(|&b| b == 0)
        .filter(|piece| !piece.is_empty())
        .map(parse_entry)
        .collect()
}

fn parse_entry(piece: &[u8]) -> DirEntry {
    let skip = DirEntry {
        name: String::new(),
        kind: EntryKind::Skip,
    };
    match piece.split_first() {
        Some((b'D', name)) if !name.is_empty() => DirEntry {
            name: String::from_utf8_lossy(name).into_owned(),
            kind: EntryKind::Directory,
        },
        Some((b'F', rest)) => {
            let Some(tab) = rest.iter().rposition(|&b| b == b'\t') else {
                return skip;
            };
            let (name, size) = (&rest[..tab], &rest[tab + 1..]);
            let size = core::str::from_utf8(size)
                .ok()
                .and_then(|s| s.trim().parse::<u64>().ok());
            match size {
                Some(size) if !name.is_empty() => DirEntry {
                    name: String::from_utf8_lossy(name).into_owned(),
                    kind: EntryKind::File { size },
                },
                _ => skip,
            }
        }
        _ => skip,
    }
}

/// CRC32 as MAVLink FTP servers compute it for CalcFileCRC32: the reflected IEEE
/// polynomial (0xEDB88320) from a zero seed with **no** final inversion (ArduPilot's
/// `crc_crc32(0, ..)`, PX4's `crc32part`, MAVSDK's `Crc32`). This is not zlib's
/// `crc32()`, which seeds with and finally inverts by 0xFFFFFFFF: the two relate as
/// `ftp = !zlib_with_seed(0xFFFFFFFF)`. Feed a file in pieces by passing the previous
/// value as `crc` (0 to start).
#[must_use]
pub fn crc32(mut crc: u32, data: &[u8]) -> u32 {
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            let mask = (crc & 1).wrapping_neg();
            crc = (crc >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    crc
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;
    use proptest::prelude::*;

    fn opcode() -> impl Strategy<Value = Opcode> {
        any::<u8>().prop_map(Opcode::from_u8)
    }

    prop_compose! {
        fn payload()(
            seq in any::<u16>(),
            session in any::<u8>(),
            opcode in opcode(),
            req_opcode in opcode(),
            burst_complete in any::<bool>(),
            offset in any::<u32>(),
            data in proptest::collection::vec(any::<u8>(), 0..=MAX_DATA),
        ) -> Payload {
            Payload { seq, session, opcode, req_opcode, burst_complete, offset, data }
        }
    }

    proptest! {
        #[test]
        fn decode_inverts_encode(p in payload()) {
            prop_assert_eq!(Payload::decode(&p.encode()), Ok(p));
        }

        #[test]
        fn decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), PAYLOAD_LEN)) {
            let mut a = [0u8; PAYLOAD_LEN];
            a.copy_from_slice(&bytes);
            match Payload::decode(&a) {
                Ok(p) => prop_assert_eq!(p.data.len(), usize::from(a[4])),
                Err(PayloadError::SizeTooLarge(s)) => prop_assert!(usize::from(s) > MAX_DATA),
            }
        }

        #[test]
        fn opcodes_and_codes_keep_every_byte(v in any::<u8>()) {
            prop_assert_eq!(Opcode::from_u8(v).to_u8(), v);
            prop_assert_eq!(NakCode::from_u8(v).to_u8(), v);
        }

        #[test]
        fn entries_never_panic(data in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = parse_entries(&data);
        }
    }

    #[test]
    fn layout_matches_the_spec() {
        let p = Payload {
            seq: 0x1234,
            session: 7,
            opcode: Opcode::ReadFile,
            req_opcode: Opcode::BurstReadFile,
            burst_complete: true,
            offset: 0xA1B2_C3D4,
            data: vec![9, 8, 7],
        };
        let b = p.encode();
        assert_eq!(
            &b[..12],
            &[0x34, 0x12, 7, 5, 3, 15, 1, 0, 0xD4, 0xC3, 0xB2, 0xA1]
        );
        assert_eq!(&b[12..16], &[9, 8, 7, 0]);
        assert_eq!(Opcode::Ack.to_u8(), 128);
        assert_eq!(Opcode::Nak.to_u8(), 129);
        assert_eq!(NakCode::FileNotFound.to_u8(), 10);
        let mut bad = b;
        bad[4] = 240;
        assert_eq!(Payload::decode(&bad), Err(PayloadError::SizeTooLarge(240)));
    }

    #[test]
    fn entries_round_trip() {
        let entries = vec![
            DirEntry {
                name: "a b.txt".into(),
                kind: EntryKind::File { size: 12 },
            },
            DirEntry {
                name: "sub".into(),
                kind: EntryKind::Directory,
            },
            DirEntry {
                name: String::new(),
                kind: EntryKind::Skip,
            },
        ];
        let mut wire = Vec::new();
        for e in &entries {
            e.encode_into(&mut wire);
        }
        assert_eq!(wire, b"Fa b.txt\t12\0Dsub\0S\0");
        assert_eq!(parse_entries(&wire), entries);
        // A name with a tab cannot be said: a skip entry keeps the count.
        let mut w = Vec::new();
        DirEntry {
            name: "x\ty".into(),
            kind: EntryKind::Directory,
        }
        .encode_into(&mut w);
        assert_eq!(w, b"S\0");
    }

    #[test]
    fn crc32_is_the_unfinished_ieee_crc() {
        // zlib.crc32(b"123456789", 0xffffffff) ^ 0xffffffff == 0x2dfd2d88 (what MAVProxy's
        // `crclocal` compares with a vehicle's answer); zlib's own value is 0xcbf43926.
        assert_eq!(crc32(0, b"123456789"), 0x2DFD_2D88);
        assert_eq!(!crc32(0xFFFF_FFFF, b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(crc32(0, b"1234"), b"56789"), 0x2DFD_2D88);
    }
}
