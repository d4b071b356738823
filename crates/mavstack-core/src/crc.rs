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
        let mut chunks = bytes.chunks_exact(SLICES);
        for c in chunks.by_ref() {
            let [lo, hi] = self.0.to_le_bytes();
            let t = &TABLES;
            let mut v =
                t[SLICES - 1][usize::from(c[0] ^ lo)] ^ t[SLICES - 2][usize::from(c[1] ^ hi)];
            for (k, &b) in c.iter().enumerate().skip(2) {
                v ^= t[SLICES - 1 - k][usize::from(b)];
            }
            self.0 = v;
        }
        for &b in chunks.remainder() {
            self.update_byte(b);
        }
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

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
