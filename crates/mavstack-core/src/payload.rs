//! Little-endian byte helpers for generated payload code.
//!
//! Generated `decode` functions copy the received payload into a zeroed array of the full
//! message length and read every field at a constant offset with [`get`]; `encode` writes
//! with [`put`]. Offsets come from the validated dialect model, so the slices are always in
//! range; with constant offsets into fixed-size arrays the compiler removes the bounds checks.
//!
//! # Panics
//! [`get`] and [`put`] panic if `at + N` exceeds the buffer, which generated code never does.

/// Copies `N` bytes starting at `at`.
#[inline(always)]
#[must_use]
pub fn get<const N: usize>(buf: &[u8], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&buf[at..at + N]);
    out
}

/// Writes `bytes` starting at `at`.
#[inline(always)]
pub fn put(buf: &mut [u8], at: usize, bytes: &[u8]) {
    buf[at..at + bytes.len()].copy_from_slice(bytes);
}

/// Copies a received payload into a zeroed array of the full message length: shorter input
/// is zero-extended, longer input is cut.
#[inline(always)]
#[must_use]
pub fn zero_extended<const N: usize>(payload: &[u8]) -> [u8; N] {
    let mut out = [0u8; N];
    let n = payload.len().min(N);
    out[..n].copy_from_slice(&payload[..n]);
    out
}

/// The length of a MAVLink 2 payload after trailing-zero truncation: trailing zero bytes are
/// dropped, but at least one byte is kept.
///
/// ```
/// use mavstack_core::payload::truncated_len;
/// assert_eq!(truncated_len(&[1, 0, 2, 0, 0]), 3);
/// assert_eq!(truncated_len(&[0, 0]), 1);
/// ```
#[must_use]
pub fn truncated_len(payload: &[u8]) -> usize {
    let mut len = payload.len();
    while len > 1 && payload[len - 1] == 0 {
        len -= 1;
    }
    len
}
