//! CRC-16/MCRF4XX, the checksum MAVLink calls "X.25".
//!
//! Polynomial 0x1021 processed reflected (0x8408), initial value 0xFFFF, no final XOR. The
//! check value of ASCII `"123456789"` is `0x6F91`. MAVLink feeds the header (without the
//! start marker), the payload as transmitted and one CRC_EXTRA byte, and sends the result
//! low byte first.
//!
//! ```
//! use mavstack_core::Crc16;
//! let mut crc = Crc16::new();
//! crc.update(b"123456789");
//! assert_eq!(crc.value(), 0x6F91);
//! ```

/// The initial value of the accumulator.
pub const INIT: u16 = 0xFFFF;

/// How many bytes [`Crc16::update`] folds per step.
const SLICES: usize = 16;

/// Slicing-by-16 lookup tables (8 KiB), built at compile time from the bitwise definition:
/// `TABLES[0]` is the byte-at-a-time table, `TABLES[k][i]` the effect of byte `i` followed by
/// `k` zero bytes.
static TABLES: [[u16; 256]; SLICES] = build_tables();

/// `PRESET[r]`: the register value that `16 - r` zero bytes turn into [`INIT`]. Starting
/// from it, a 16-byte block of `16 - r` zeros followed by the first `r` bytes of a run has
/// the effect of those `r` bytes on a fresh checksum (see [`Crc16::of_prefix`]).
static PRESET: [u16; SLICES] = build_presets();

/// The inverse of feeding one zero byte. The high bytes of `TABLES[0]` are a permutation of
/// 0..=255 (a property of every CRC table), which identifies the low byte shifted out.
const fn unfeed_zero(after: u16, table: &[u16; 256]) -> u16 {
    let mut low = 0;
    while low < 256 {
        if table[low] >> 8 == after >> 8 {
            // `after = (before >> 8) ^ table[low]` with `low` the old low byte.
            return ((after ^ table[low]) << 8) | low as u16;
        }
        low += 1;
    }
    panic!("CRC table high bytes are not a permutation")
}

const fn build_presets() -> [u16; SLICES] {
    let table = build_tables();
    let mut presets = [0u16; SLICES];
    let mut r = 0;
    while r < SLICES {
        let mut state = INIT;
        let mut zeros = 0;
        while zeros < SLICES - r {
            state = unfeed_zero(state, &table[0]);
            zeros += 1;
        }
        presets[r] = state;
        r += 1;
    }
    presets
}

const fn build_tables() -> [[u16; 256]; SLICES] {
    let mut tables = [[0u16; 256]; SLICES];
    let mut i = 0;
    while i < 256 {
        // `i` is below 256, so the cast keeps every bit.
        tables[0][i] = step(0, i as u8);
        i += 1;
    }
    let mut k = 1;
    while k < SLICES {
        let mut i = 0;
        while i < 256 {
            let prev = tables[k - 1][i];
            tables[k][i] = (prev >> 8) ^ tables[0][(prev & 0xFF) as usize];
            i += 1;
        }
        k += 1;
    }
    tables
}

/// One byte of the reference algorithm (the one in the MAVLink C library's `checksum.h`).
const fn step(crc: u16, byte: u8) -> u16 {
    let mut t = byte ^ (crc & 0xFF) as u8;
    t ^= t << 4;
    let t = t as u16;
    (crc >> 8) ^ (t << 8) ^ (t << 3) ^ (t >> 4)
}

/// A running CRC-16/MCRF4XX accumulator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crc16(u16);

impl Default for Crc16 {
    fn default() -> Self {
        Self::new()
    }
}

impl Crc16 {
    /// A fresh accumulator (0xFFFF).
    #[must_use]
    pub const fn new() -> Self {
        Self(INIT)
    }

    /// Feeds one byte.
    #[inline]
    pub fn update_byte(&mut self, byte: u8) {
        let index = usize::from((self.0 as u8) ^ byte);
        self.0 = (self.0 >> 8) ^ TABLES[0][index];
    }

    /// Feeds a run of bytes, sixteen at a time where it can.
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        let (chunks, mut rest) = bytes.as_chunks::<SLICES>();
        for c in chunks {
            self.fold(c);
        }
        // The tail in slices of 8, 4 and 2 bytes: a short dependency chain for short frames.
        if let Some((c, tail)) = rest.split_first_chunk::<8>() {
            self.fold(c);
            rest = tail;
        }
        if let Some((c, tail)) = rest.split_first_chunk::<4>() {
            self.fold(c);
            rest = tail;
        }
        if let Some((c, tail)) = rest.split_first_chunk::<2>() {
            self.fold(c);
            rest = tail;
        }
        if let Some(&b) = rest.first() {
            self.update_byte(b);
        }
    }

    /// Folds exactly `W` (2 ≤ `W` ≤ 16) bytes in with one table lookup per byte.
    #[inline(always)]
    fn fold<const W: usize>(&mut self, c: &[u8; W]) {
        let [lo, hi] = self.0.to_le_bytes();
        let t = &TABLES;
        let mut v = t[W - 1][usize::from(c[0] ^ lo)] ^ t[W - 2][usize::from(c[1] ^ hi)];
        for k in 2..W {
            v ^= t[W - 1 - k][usize::from(c[k])];
        }
        self.0 = v;
    }

    /// Feeds a run of bytes in a `const` context (slower; used for compile-time tables).
    #[must_use]
    pub const fn const_update(mut self, bytes: &[u8]) -> Self {
        let mut i = 0;
        while i < bytes.len() {
            self.0 = step(self.0, bytes[i]);
            i += 1;
        }
        self
    }

    /// The checksum of everything fed so far.
    #[must_use]
    pub const fn value(self) -> u16 {
        self.0
    }

    /// The checksum of `bytes` in one call.
    #[must_use]
    pub fn of(bytes: &[u8]) -> u16 {
        let mut crc = Self::new();
        crc.update(bytes);
        crc.value()
    }

    /// The checksum of `data[..len]`, computed with few branches: the first `len % 16` bytes
    /// go in as one 16-byte block behind zeros (from a precomputed register), the rest 16 at a time. The
    /// lengths of frames vary from one to the next, so this beats a loop whose tail the CPU
    /// mispredicts. Bytes of `data` past `len` are read but never affect the result.
    ///
    /// ```
    /// use mavstack_core::Crc16;
    /// let data = b"123456789 and more bytes that do not count";
    /// assert_eq!(Crc16::of_prefix(data, 9).value(), 0x6F91);
    /// ```
    ///
    /// # Panics
    ///
    /// If `len > data.len()`.
    #[inline]
    #[must_use]
    pub fn of_prefix(data: &[u8], len: usize) -> Self {
        let head = len % SLICES;
        let (Some(window), Some(body)) = (data.first_chunk::<SLICES>(), data.get(head..len)) else {
            // Under 16 bytes in all: byte at a time.
            let mut crc = Self::new();
            crc.update(&data[..len]);
            return crc;
        };
        // The head bytes at the end of the block, zeros in front: a shift, not a branch.
        let block = (u128::from_le_bytes(*window) << (8 * (SLICES - 1 - head))) << 8;
        let mut crc = Self(PRESET[head]);
        crc.fold(&block.to_le_bytes());
        let (chunks, _) = body.as_chunks::<SLICES>();
        for c in chunks {
            crc.fold(c);
        }
        crc
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn of_prefix_matches_byte_at_a_time(data in proptest::collection::vec(any::<u8>(), 0..300), cut in 0usize..300) {
            let len = cut.min(data.len());
            prop_assert_eq!(Crc16::of_prefix(&data, len).value(), Crc16::new().const_update(&data[..len]).value());
        }
    }

    #[test]
    fn presets_turn_into_init() {
        for (r, &preset) in PRESET.iter().enumerate() {
            let zeros = [0u8; SLICES];
            assert_eq!(
                Crc16(preset).const_update(&zeros[..SLICES - r]).value(),
                INIT
            );
        }
    }

    #[test]
    fn published_check_value() {
        assert_eq!(Crc16::of(b"123456789"), 0x6F91);
        assert_eq!(Crc16::new().const_update(b"123456789").value(), 0x6F91);
    }

    proptest! {
        #[test]
        fn matches_independent_implementation(data in proptest::collection::vec(any::<u8>(), 0..512)) {
            let oracle = crc::Crc::<u16>::new(&crc::CRC_16_MCRF4XX);
            prop_assert_eq!(Crc16::of(&data), oracle.checksum(&data));
            prop_assert_eq!(Crc16::new().const_update(&data).value(), oracle.checksum(&data));
        }
    }
}
