//! MAVLink frames on the wire: zero-copy views and a serializer.
//!
//! [`Frame`] is a view over the bytes of one frame, MAVLink 1 (`0xFE`) or MAVLink 2 (`0xFD`),
//! in any buffer `T: AsRef<[u8]>`. [`emit`] writes a frame into a caller's buffer.
//!
//! ```text
//!  v1: FE len seq sys comp id                 payload crc16 (8 + len bytes)
//!  v2: FD len inc cmp seq sys comp id id id   payload crc16 [link ts×6 sig×6] (12 + len [+13])
//! ```
//!
//! ## Panic contract
//! No accessor of a [`Frame`] panics once [`Frame::check_len`] (or [`Frame::new_checked`]) has
//! succeeded; [`Frame::new_unchecked`] skips that check, and accessors may then panic on a
//! short buffer. [`emit`] never panics: it returns [`EmitError::BufferTooSmall`] instead.
//!
//! ```
//! use mavstack_core::wire::{Frame, FrameHeader, Version, emit};
//! use mavstack_core::MessageInfo;
//! // HEARTBEAT (id 0, CRC_EXTRA 50), golden vector of the protocol digest.
//! let info = MessageInfo { id: 0, name: "HEARTBEAT", crc_extra: 50, min_len: 9, max_len: 9,
//!                          target_system_offset: None, target_component_offset: None };
//! let header = FrameHeader { version: Version::V2, seq: 0, sysid: 1, compid: 1, signed: false };
//! let mut buf = [0u8; mavstack_core::wire::MAX_FRAME_LEN];
//! let len = emit(&header, &info, &[0, 0, 0, 0, 2, 12, 0x51, 4, 3], &mut buf).unwrap();
//! assert_eq!(&buf[..len], &[0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0,
//!                          0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74]);
//! let frame = Frame::new_checked(&buf[..len]).unwrap();
//! assert!(frame.check_crc(50));
//! assert_eq!((frame.msg_id(), frame.sysid(), frame.payload()), (0, 1, &buf[10..19]));
//! ```

use crate::crc::Crc16;
use crate::message::{MAX_PAYLOAD_LEN, MessageInfo};
use crate::payload::truncated_len;

/// Start marker of a MAVLink 1 frame.
pub const STX_V1: u8 = 0xFE;
/// Start marker of a MAVLink 2 frame.
pub const STX_V2: u8 = 0xFD;
/// The only incompatibility flag defined: the frame carries a signature.
pub const INCOMPAT_SIGNED: u8 = 0x01;

/// Byte offsets of the header fields.
mod field {
    use core::ops::Range;
    pub(super) const MAGIC: usize = 0;
    pub(super) const LEN: usize = 1;
    // MAVLink 1
    pub(super) const V1_SEQ: usize = 2;
    pub(super) const V1_SYSID: usize = 3;
    pub(super) const V1_COMPID: usize = 4;
    pub(super) const V1_MSGID: usize = 5;
    pub(super) const V1_PAYLOAD: usize = 6;
    // MAVLink 2
    pub(super) const V2_INCOMPAT: usize = 2;
    pub(super) const V2_COMPAT: usize = 3;
    pub(super) const V2_SEQ: usize = 4;
    pub(super) const V2_SYSID: usize = 5;
    pub(super) const V2_COMPID: usize = 6;
    pub(super) const V2_MSGID: Range<usize> = 7..10;
    pub(super) const V2_PAYLOAD: usize = 10;
}

/// Header length of a MAVLink 1 frame, start marker included.
pub const HEADER_LEN_V1: usize = field::V1_PAYLOAD;
/// Header length of a MAVLink 2 frame, start marker included.
pub const HEADER_LEN_V2: usize = field::V2_PAYLOAD;
/// Length of the checksum.
pub const CHECKSUM_LEN: usize = 2;
/// Length of a signature block: link id, 48-bit timestamp, 48-bit signature.
pub const SIGNATURE_LEN: usize = 13;
/// The longest frame: a signed MAVLink 2 frame with a 255-byte payload (280 bytes).
pub const MAX_FRAME_LEN: usize = HEADER_LEN_V2 + MAX_PAYLOAD_LEN + CHECKSUM_LEN + SIGNATURE_LEN;

/// The protocol version of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Version {
    /// MAVLink 1 (`0xFE`).
    V1,
    /// MAVLink 2 (`0xFD`).
    V2,
}

impl Version {
    /// The version whose start marker is `byte`.
    #[must_use]
    pub const fn from_magic(byte: u8) -> Option<Self> {
        match byte {
            STX_V1 => Some(Self::V1),
            STX_V2 => Some(Self::V2),
            _ => None,
        }
    }

    /// The start marker.
    #[must_use]
    pub const fn magic(self) -> u8 {
        match self {
            Self::V1 => STX_V1,
            Self::V2 => STX_V2,
        }
    }

    /// The header length, start marker included.
    #[must_use]
    pub const fn header_len(self) -> usize {
        match self {
            Self::V1 => HEADER_LEN_V1,
            Self::V2 => HEADER_LEN_V2,
        }
    }

    /// 1 or 2.
    #[must_use]
    pub const fn number(self) -> u8 {
        match self {
            Self::V1 => 1,
            Self::V2 => 2,
        }
    }
}

/// Why bytes are not a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Error {
    /// The first byte is no start marker.
    NotAFrame {
        /// The byte found.
        byte: u8,
    },
    /// The buffer ends before the frame does.
    Truncated {
        /// Bytes the frame needs (so far as the header says).
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// A MAVLink 2 frame with incompatibility flags this implementation does not know: it
    /// must be dropped.
    UnknownIncompatFlags {
        /// The flags.
        flags: u8,
    },
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotAFrame { byte } => write!(f, "byte {byte:#04x} is not a start marker"),
            Self::Truncated { needed, available } => {
                write!(
                    f,
                    "truncated frame: {needed} bytes needed, {available} available"
                )
            }
            Self::UnknownIncompatFlags { flags } => {
                write!(f, "unknown incompatibility flags {flags:#04x}")
            }
        }
    }
}

impl core::error::Error for Error {}

/// A zero-copy view of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Frame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Frame<T> {
    /// Wraps a buffer without checking it (see the panic contract in the module docs).
    pub const fn new_unchecked(buffer: T) -> Self {
        Self { buffer }
    }

    /// Wraps a buffer that starts with a complete frame (it may hold more bytes after it).
    ///
    /// # Errors
    /// See [`Frame::check_len`].
    pub fn new_checked(buffer: T) -> Result<Self, Error> {
        let frame = Self::new_unchecked(buffer);
        frame.check_len()?;
        Ok(frame)
    }

    /// Checks that the buffer starts with a start marker and holds the whole frame, and that
    /// a MAVLink 2 frame sets no unknown incompatibility flag.
    ///
    /// # Errors
    /// [`Error::NotAFrame`], [`Error::Truncated`] or [`Error::UnknownIncompatFlags`].
    pub fn check_len(&self) -> Result<(), Error> {
        let b = self.buffer.as_ref();
        let available = b.len();
        let Some(&magic) = b.first() else {
            return Err(Error::Truncated {
                needed: 1,
                available,
            });
        };
        let version = Version::from_magic(magic).ok_or(Error::NotAFrame { byte: magic })?;
        let header = version.header_len();
        if available < header {
            return Err(Error::Truncated {
                needed: header,
                available,
            });
        }
        if version == Version::V2 && b[field::V2_INCOMPAT] & !INCOMPAT_SIGNED != 0 {
            return Err(Error::UnknownIncompatFlags {
                flags: b[field::V2_INCOMPAT],
            });
        }
        let needed = self.frame_len();
        if available < needed {
            return Err(Error::Truncated { needed, available });
        }
        Ok(())
    }

    /// The underlying buffer.
    pub fn into_inner(self) -> T {
        self.buffer
    }

    /// The protocol version.
    #[must_use]
    pub fn version(&self) -> Version {
        if self.buffer.as_ref()[field::MAGIC] == STX_V2 {
            Version::V2
        } else {
            Version::V1
        }
    }

    /// The payload length as transmitted (after MAVLink 2 truncation).
    #[must_use]
    pub fn payload_len(&self) -> usize {
        usize::from(self.buffer.as_ref()[field::LEN])
    }

    /// The whole frame's length: header, payload, checksum and signature.
    #[must_use]
    pub fn frame_len(&self) -> usize {
        let sig = if self.is_signed() { SIGNATURE_LEN } else { 0 };
        self.version().header_len() + self.payload_len() + CHECKSUM_LEN + sig
    }

    /// Incompatibility flags (always 0 for MAVLink 1).
    #[must_use]
    pub fn incompat_flags(&self) -> u8 {
        match self.version() {
            Version::V1 => 0,
            Version::V2 => self.buffer.as_ref()[field::V2_INCOMPAT],
        }
    }

    /// Compatibility flags (always 0 for MAVLink 1).
    #[must_use]
    pub fn compat_flags(&self) -> u8 {
        match self.version() {
            Version::V1 => 0,
            Version::V2 => self.buffer.as_ref()[field::V2_COMPAT],
        }
    }

    /// Whether the frame carries a signature.
    #[must_use]
    pub fn is_signed(&self) -> bool {
        self.incompat_flags() & INCOMPAT_SIGNED != 0
    }

    fn pick(&self, v1: usize, v2: usize) -> u8 {
        let b = self.buffer.as_ref();
        match self.version() {
            Version::V1 => b[v1],
            Version::V2 => b[v2],
        }
    }

    /// Sequence number.
    #[must_use]
    pub fn seq(&self) -> u8 {
        self.pick(field::V1_SEQ, field::V2_SEQ)
    }

    /// Sender's system id.
    #[must_use]
    pub fn sysid(&self) -> u8 {
        self.pick(field::V1_SYSID, field::V2_SYSID)
    }

    /// Sender's component id.
    #[must_use]
    pub fn compid(&self) -> u8 {
        self.pick(field::V1_COMPID, field::V2_COMPID)
    }

    /// Message id (8 bits in MAVLink 1, 24 in MAVLink 2).
    #[must_use]
    pub fn msg_id(&self) -> u32 {
        let b = self.buffer.as_ref();
        match self.version() {
            Version::V1 => u32::from(b[field::V1_MSGID]),
            Version::V2 => {
                let id = &b[field::V2_MSGID];
                u32::from_le_bytes([id[0], id[1], id[2], 0])
            }
        }
    }

    /// The payload as transmitted.
    #[must_use]
    pub fn payload(&self) -> &[u8] {
        let start = self.version().header_len();
        &self.buffer.as_ref()[start..start + self.payload_len()]
    }

    /// The checksum as transmitted.
    #[must_use]
    pub fn checksum(&self) -> u16 {
        let at = self.version().header_len() + self.payload_len();
        let b = self.buffer.as_ref();
        u16::from_le_bytes([b[at], b[at + 1]])
    }

    /// The checksum the frame should carry with `crc_extra`.
    #[must_use]
    pub fn compute_checksum(&self, crc_extra: u8) -> u16 {
        let end = self.version().header_len() + self.payload_len();
        let mut crc = Crc16::new();
        crc.update(&self.buffer.as_ref()[1..end]);
        crc.update_byte(crc_extra);
        crc.value()
    }

    /// Whether the checksum is right for a message with `crc_extra`.
    #[must_use]
    pub fn check_crc(&self, crc_extra: u8) -> bool {
        self.compute_checksum(crc_extra) == self.checksum()
    }

    /// The signature block, if the frame is signed.
    #[must_use]
    pub fn signature(&self) -> Option<Signature> {
        if !self.is_signed() {
            return None;
        }
        let at = HEADER_LEN_V2 + self.payload_len() + CHECKSUM_LEN;
        let s = &self.buffer.as_ref()[at..at + SIGNATURE_LEN];
        let mut ts = [0u8; 8];
        ts[..6].copy_from_slice(&s[1..7]);
        let mut value = [0u8; 6];
        value.copy_from_slice(&s[7..13]);
        Some(Signature {
            link_id: s[0],
            timestamp: u64::from_le_bytes(ts),
            value,
        })
    }

    /// The frame's bytes, signature included (the buffer may hold more after it).
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        &self.buffer.as_ref()[..self.frame_len()]
    }

    /// The bytes a signature covers after the key: the frame from the start marker through
    /// the checksum, then the link id and timestamp.
    #[must_use]
    pub fn signed_bytes(&self) -> Option<&[u8]> {
        self.is_signed()
            .then(|| &self.buffer.as_ref()[..HEADER_LEN_V2 + self.payload_len() + CHECKSUM_LEN + 7])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Frame<T> {
    /// Sets the sequence number (the checksum must then be recomputed with [`Frame::fill_checksum`]).
    pub fn set_seq(&mut self, seq: u8) {
        let at = match self.version() {
            Version::V1 => field::V1_SEQ,
            Version::V2 => field::V2_SEQ,
        };
        self.buffer.as_mut()[at] = seq;
    }

    /// Sets the sender's system id (the checksum must then be recomputed; a signature no
    /// longer verifies).
    pub fn set_sysid(&mut self, sysid: u8) {
        let at = match self.version() {
            Version::V1 => field::V1_SYSID,
            Version::V2 => field::V2_SYSID,
        };
        self.buffer.as_mut()[at] = sysid;
    }

    /// The payload, to change in place (the checksum must then be recomputed).
    pub fn payload_mut(&mut self) -> &mut [u8] {
        let start = self.version().header_len();
        let len = self.payload_len();
        &mut self.buffer.as_mut()[start..start + len]
    }

    /// Writes the checksum for `crc_extra`.
    pub fn fill_checksum(&mut self, crc_extra: u8) {
        let crc = self.compute_checksum(crc_extra);
        let at = self.version().header_len() + self.payload_len();
        self.buffer.as_mut()[at..at + CHECKSUM_LEN].copy_from_slice(&crc.to_le_bytes());
    }
}

/// A frame's signature block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Signature {
    /// The sender's link id.
    pub link_id: u8,
    /// 48-bit timestamp, in units of 10 µs since 2015-01-01 00:00:00 UTC.
    pub timestamp: u64,
    /// The first 6 bytes of SHA-256(key ‖ frame ‖ link id ‖ timestamp).
    pub value: [u8; 6],
}

/// The header of a frame to emit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FrameHeader {
    /// MAVLink 1 or 2.
    pub version: Version,
    /// Sequence number.
    pub seq: u8,
    /// Sender's system id.
    pub sysid: u8,
    /// Sender's component id.
    pub compid: u8,
    /// Set the signed flag (MAVLink 2 only); append the signature afterwards with
    /// [`crate::signing::append_signature`].
    pub signed: bool,
}

/// Why a frame could not be written.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum EmitError {
    /// Message ids above 255 exist only in MAVLink 2.
    IdTooLargeForV1 {
        /// The id.
        id: u32,
    },
    /// MAVLink 1 frames cannot be signed.
    SignedV1,
    /// The output buffer is too small.
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
        /// Bytes available.
        available: usize,
    },
    /// A payload longer than the message's full length.
    PayloadTooLong {
        /// Its length.
        len: usize,
        /// The message's full length.
        max: usize,
    },
}

impl core::fmt::Display for EmitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::IdTooLargeForV1 { id } => write!(
                f,
                "message id {id} cannot be sent as MAVLink 1 (ids above 255 are MAVLink 2 only)"
            ),
            Self::SignedV1 => f.write_str("MAVLink 1 frames cannot be signed"),
            Self::BufferTooSmall { needed, available } => {
                write!(
                    f,
                    "output buffer too small: {needed} bytes needed, {available} available"
                )
            }
            Self::PayloadTooLong { len, max } => write!(
                f,
                "payload of {len} bytes is longer than the message's {max}"
            ),
        }
    }
}

impl core::error::Error for EmitError {}

/// Writes a frame of message `info` with `payload` (its full, untruncated encoding, or
/// shorter: the rest is taken as zeros) into `out` and returns the frame's length.
///
/// MAVLink 2 payloads are truncated (trailing zeros dropped, at least one byte kept);
/// MAVLink 1 payloads carry exactly the base fields, never extensions. With
/// `header.signed`, the signed flag is set (and covered by the checksum) and room for the
/// signature is required: append it with [`crate::signing::append_signature`].
///
/// # Errors
/// [`EmitError`]: an id over 255 or a signature in MAVLink 1, a short buffer, a payload
/// longer than the message.
pub fn emit(
    header: &FrameHeader,
    info: &MessageInfo,
    payload: &[u8],
    out: &mut [u8],
) -> Result<usize, EmitError> {
    let max = usize::from(info.max_len);
    if payload.len() > max.max(usize::from(info.min_len)) {
        return Err(EmitError::PayloadTooLong {
            len: payload.len(),
            max,
        });
    }
    let (len, header_len) = match header.version {
        Version::V1 => {
            if info.id > 255 {
                return Err(EmitError::IdTooLargeForV1 { id: info.id });
            }
            if header.signed {
                return Err(EmitError::SignedV1);
            }
            (usize::from(info.min_len), HEADER_LEN_V1)
        }
        Version::V2 => (truncated_len(payload), HEADER_LEN_V2),
    };
    let sig = if header.signed { SIGNATURE_LEN } else { 0 };
    let needed = header_len + len + CHECKSUM_LEN + sig;
    if out.len() < needed {
        return Err(EmitError::BufferTooSmall {
            needed,
            available: out.len(),
        });
    }
    // The length fits a byte: it is at most the message's length, which is at most 255.
    let len_byte = u8::try_from(len).unwrap_or(u8::MAX);
    out[field::MAGIC] = header.version.magic();
    out[field::LEN] = len_byte;
    match header.version {
        Version::V1 => {
            out[field::V1_SEQ] = header.seq;
            out[field::V1_SYSID] = header.sysid;
            out[field::V1_COMPID] = header.compid;
            out[field::V1_MSGID] = info.id.to_le_bytes()[0];
        }
        Version::V2 => {
            out[field::V2_INCOMPAT] = if header.signed { INCOMPAT_SIGNED } else { 0 };
            out[field::V2_COMPAT] = 0;
            out[field::V2_SEQ] = header.seq;
            out[field::V2_SYSID] = header.sysid;
            out[field::V2_COMPID] = header.compid;
            out[field::V2_MSGID].copy_from_slice(&info.id.to_le_bytes()[..3]);
        }
    }
    let body = &mut out[header_len..header_len + len];
    let copied = payload.len().min(len);
    body[..copied].copy_from_slice(&payload[..copied]);
    body[copied..].fill(0);
    let mut crc = Crc16::new();
    crc.update(&out[1..header_len + len]);
    crc.update_byte(info.crc_extra);
    out[header_len + len..header_len + len + CHECKSUM_LEN]
        .copy_from_slice(&crc.value().to_le_bytes());
    Ok(header_len + len + CHECKSUM_LEN)
}

/// Writes a frame of a typed message; see [`emit`].
///
/// # Errors
/// As [`emit`].
pub fn emit_message<M: crate::Message>(
    header: &FrameHeader,
    message: &M,
    out: &mut [u8],
) -> Result<usize, EmitError> {
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let len = message.encode(&mut payload);
    emit(header, &M::INFO, &payload[..len], out)
}
