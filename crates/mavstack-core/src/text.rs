//! `char[N]` fields as text.
//!
//! MAVLink strings are bytes: NUL-terminated when shorter than the field, not terminated when
//! exactly as long. These helpers read up to the first NUL and write zero-filled.

/// The bytes of a `char[N]` field up to (not including) the first NUL.
///
/// ```
/// use mavstack_core::text::until_nul;
/// assert_eq!(until_nul(b"ALT\0\0\0"), b"ALT");
/// assert_eq!(until_nul(b"FULL"), b"FULL");
/// ```
#[must_use]
pub fn until_nul(field: &[u8]) -> &[u8] {
    let end = field.iter().position(|&b| b == 0).unwrap_or(field.len());
    &field[..end]
}

/// The field as UTF-8 text up to the first NUL, or `None` if those bytes are not UTF-8.
#[must_use]
pub fn as_str(field: &[u8]) -> Option<&str> {
    core::str::from_utf8(until_nul(field)).ok()
}

/// A `char[N]` field holding `text`, zero-filled; text longer than `N` bytes is cut.
///
/// ```
/// use mavstack_core::text::from_str;
/// let id: [u8; 16] = from_str("SYSID_THISMAV");
/// assert_eq!(&id[..14], b"SYSID_THISMAV\0");
/// ```
#[must_use]
pub fn from_str<const N: usize>(text: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let n = text.len().min(N);
    out[..n].copy_from_slice(&text.as_bytes()[..n]);
    out
}
