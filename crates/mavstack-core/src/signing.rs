//! MAVLink 2 message signing primitives.
//!
//! A signature is the first 48 bits of SHA-256 over the 32-byte secret key, the frame from
//! its start marker through the checksum, the link id and the 48-bit timestamp (10 µs units
//! since 2015-01-01 UTC). These are the stateless primitives; replay protection (per-stream
//! timestamps) belongs to the channel layer.
//!
//! - Verification compares in constant time ([`subtle`]).
//! - [`SecretKey`] wipes itself on drop ([`zeroize`]) and never prints its bytes.
//!
//! ```
//! use mavstack_core::signing::{SecretKey, append_signature, verify};
//! use mavstack_core::wire::{Frame, FrameHeader, Version, emit, MAX_FRAME_LEN};
//! use mavstack_core::MessageInfo;
//! let key = SecretKey::new(core::array::from_fn(|i| i as u8)); // 00 01 .. 1f
//! let info = MessageInfo { id: 0, name: "HEARTBEAT", crc_extra: 50, min_len: 9, max_len: 9,
//!                          target_system_offset: None, target_component_offset: None };
//! let header = FrameHeader { version: Version::V2, seq: 0, sysid: 1, compid: 1, signed: true };
//! let mut buf = [0u8; MAX_FRAME_LEN];
//! let len = emit(&header, &info, &[0, 0, 0, 0, 2, 12, 0x51, 4, 3], &mut buf).unwrap();
//! let len = append_signature(&mut buf, len, 1, 0x0102030405, &key).unwrap();
//! // The protocol digest's golden signed HEARTBEAT.
//! assert_eq!(&buf[len - 15..len], &[0xfc, 0x8c, 1, 5, 4, 3, 2, 1, 0, 0xb6, 0x81, 0xa6, 0xe1, 0x10, 0x5b]);
//! assert_eq!(verify(&Frame::new_checked(&buf[..len]).unwrap(), &key), Ok(()));
//! ```

use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;
use zeroize::Zeroize;

use crate::wire::{CHECKSUM_LEN, Frame, HEADER_LEN_V2, SIGNATURE_LEN, Version};

/// Seconds from the Unix epoch to the signing epoch, 2015-01-01 00:00:00 UTC.
pub const EPOCH_UNIX_SECS: u64 = 1_420_070_400;

/// The largest timestamp (48 bits).
pub const MAX_TIMESTAMP: u64 = (1 << 48) - 1;

/// The signing timestamp for a time in microseconds since the Unix epoch.
#[must_use]
pub const fn timestamp_from_unix_micros(micros: u64) -> u64 {
    let since = micros.saturating_sub(EPOCH_UNIX_SECS * 1_000_000) / 10;
    if since > MAX_TIMESTAMP {
        MAX_TIMESTAMP
    } else {
        since
    }
}

/// A 32-byte signing key. Wiped from memory on drop; `Debug` does not show it.
#[derive(Clone)]
pub struct SecretKey([u8; 32]);

impl SecretKey {
    /// A key from its bytes.
    #[must_use]
    pub const fn new(bytes: [u8; 32]) -> Self {
        Self(bytes)
    }

    /// The key as 64 hex digits, e.g. from a command line.
    ///
    /// # Errors
    /// [`KeyError`] naming what is wrong with the text.
    pub fn from_hex(text: &str) -> Result<Self, KeyError> {
        let t = text.trim();
        if t.len() != 64 {
            return Err(KeyError::Length { digits: t.len() });
        }
        let mut out = [0u8; 32];
        for (i, pair) in t.as_bytes().chunks(2).enumerate() {
            let digit = |c: u8| match c {
                b'0'..=b'9' => Some(c - b'0'),
                b'a'..=b'f' => Some(c - b'a' + 10),
                b'A'..=b'F' => Some(c - b'A' + 10),
                _ => None,
            };
            match (digit(pair[0]), digit(pair[1])) {
                (Some(h), Some(l)) => out[i] = h << 4 | l,
                _ => return Err(KeyError::NotHex { position: i * 2 }),
            }
        }
        Ok(Self(out))
    }

    /// The key's bytes.
    #[must_use]
    pub const fn as_bytes(&self) -> &[u8; 32] {
        &self.0
    }
}

impl Drop for SecretKey {
    fn drop(&mut self) {
        self.0.zeroize();
    }
}

impl core::fmt::Debug for SecretKey {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("SecretKey(..)")
    }
}

/// A signing key that cannot be read from text.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum KeyError {
    /// Not 64 hex digits.
    Length {
        /// How many characters there were.
        digits: usize,
    },
    /// A character that is not a hex digit.
    NotHex {
        /// Its position, from 0.
        position: usize,
    },
}

impl core::fmt::Display for KeyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Length { digits } => {
                write!(f, "a signing key is 64 hex digits, got {digits} characters")
            }
            Self::NotHex { position } => write!(
                f,
                "a signing key is 64 hex digits: not a hex digit at position {position}"
            ),
        }
    }
}

impl core::error::Error for KeyError {}

/// Why a frame's signature was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum SignatureError {
    /// The frame is not signed (MAVLink 1, or MAVLink 2 without the flag).
    Unsigned,
    /// The signature does not match the key.
    BadSignature,
}

impl core::fmt::Display for SignatureError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Unsigned => f.write_str("frame is not signed"),
            Self::BadSignature => f.write_str("signature does not match the key"),
        }
    }
}

impl core::error::Error for SignatureError {}

/// The 48-bit signature of `signed_bytes` (frame through checksum, link id, timestamp).
#[must_use]
pub fn compute(key: &SecretKey, signed_bytes: &[u8]) -> [u8; 6] {
    let mut hash = Sha256::new();
    hash.update(key.0);
    hash.update(signed_bytes);
    let digest = hash.finalize();
    let mut out = [0u8; 6];
    out.copy_from_slice(&digest[..6]);
    out
}

/// Appends the signature block to the unsigned-length frame at the start of `buf` (written
/// by [`crate::wire::emit`] with `signed: true`) and returns the signed frame's length.
///
/// # Errors
/// [`crate::wire::EmitError::BufferTooSmall`] if `buf` has no room for the 13 bytes;
/// [`crate::wire::EmitError::SignedV1`] if the frame is not a MAVLink 2 frame with the
/// signed flag set.
pub fn append_signature(
    buf: &mut [u8],
    frame_len: usize,
    link_id: u8,
    timestamp: u64,
    key: &SecretKey,
) -> Result<usize, crate::wire::EmitError> {
    let needed = frame_len + SIGNATURE_LEN;
    if buf.len() < needed || frame_len < HEADER_LEN_V2 + CHECKSUM_LEN {
        return Err(crate::wire::EmitError::BufferTooSmall {
            needed,
            available: buf.len(),
        });
    }
    let frame = Frame::new_unchecked(&buf[..]);
    if frame.version() != Version::V2 || !frame.is_signed() {
        return Err(crate::wire::EmitError::SignedV1);
    }
    buf[frame_len] = link_id;
    buf[frame_len + 1..frame_len + 7]
        .copy_from_slice(&timestamp.min(MAX_TIMESTAMP).to_le_bytes()[..6]);
    let value = compute(key, &buf[..frame_len + 7]);
    buf[frame_len + 7..needed].copy_from_slice(&value);
    Ok(needed)
}

/// Checks a signed frame's signature against `key`, in constant time.
///
/// # Errors
/// [`SignatureError::Unsigned`] or [`SignatureError::BadSignature`].
pub fn verify<T: AsRef<[u8]>>(frame: &Frame<T>, key: &SecretKey) -> Result<(), SignatureError> {
    let (Some(signed), Some(sig)) = (frame.signed_bytes(), frame.signature()) else {
        return Err(SignatureError::Unsigned);
    };
    let expected = compute(key, signed);
    if bool::from(expected.ct_eq(&sig.value)) {
        Ok(())
    } else {
        Err(SignatureError::BadSignature)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_from_hex() {
        let k =
            SecretKey::from_hex("000102030405060708090a0b0c0d0e0f101112131415161718191A1B1C1D1E1F")
                .unwrap();
        assert_eq!(k.as_bytes()[31], 0x1f);
        assert!(matches!(
            SecretKey::from_hex("00"),
            Err(KeyError::Length { digits: 2 })
        ));
        assert!(matches!(
            SecretKey::from_hex(&"zz".repeat(32)),
            Err(KeyError::NotHex { position: 0 })
        ));
        assert_eq!(std::format!("{k:?}"), "SecretKey(..)");
    }

    #[test]
    fn timestamps() {
        assert_eq!(
            timestamp_from_unix_micros(EPOCH_UNIX_SECS * 1_000_000 + 25),
            2
        );
        assert_eq!(timestamp_from_unix_micros(0), 0);
        assert_eq!(timestamp_from_unix_micros(u64::MAX), MAX_TIMESTAMP);
    }
}
