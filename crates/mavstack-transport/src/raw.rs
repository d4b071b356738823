//! Raw MAVLink captures (frames one after another, no timestamps), read from a
//! [`std::io::Read`] to its end: the counterpart of [`crate::tlog::Reader`] for raw streams.
//!
//! [`read_items`] parses the stream through one fixed buffer with
//! [`mavstack_core::parse::SliceParser`], so a file is never in memory whole and no frame is
//! copied: each item borrows from the buffer. A frame that a buffer's end cuts is parsed whole
//! with the bytes read after it, so the items and counts are those of the whole stream parsed
//! at once, however the reads come.
//!
//! ```
//! use mavstack_core::parse::Item;
//! use mavstack_transport::raw::read_items;
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut stream = heartbeat.to_vec();
//! stream.extend_from_slice(&[0x55, 0xfd, 0x01]); // noise
//! stream.extend_from_slice(&heartbeat);
//! let mut ids = Vec::new();
//! let stats = read_items(
//!     &stream[..],
//!     |id: u32| (id == 0).then_some(50u8),
//!     |item| {
//!         if let Item::Frame(f) = item {
//!             ids.push(f.msg_id());
//!         }
//!     },
//!     |_bytes_so_far| {},
//! )?;
//! assert_eq!(ids, [0, 0]);
//! assert_eq!((stats.frames, stats.skipped_bytes, stats.bytes), (2, 3, 45));
//! # Ok::<(), std::io::Error>(())
//! ```

use std::io::{self, Read};

use mavstack_core::parse::{CrcExtra, Item, SliceParser, Stats};
use mavstack_core::wire::MAX_FRAME_LEN;

mod split;

pub use split::count_items_split;
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use split::fuzz_raw_split;

/// Bytes [`read_items`] reads at a time.
pub const CHUNK_LEN: usize = 1 << 20;

/// Parses the raw MAVLink stream read from `input` to its end ([`CHUNK_LEN`] bytes at a
/// time), checksums checked with `lookup`: calls `each` for every item, in stream order, and
/// `consumed` with the bytes parsed so far after each chunk (for a progress bar). Returns the
/// parser's counts over the whole stream.
///
/// # Errors
/// Errors of `input` (an interrupted read is retried).
pub fn read_items<L: CrcExtra + Copy>(
    input: impl Read,
    lookup: L,
    each: impl FnMut(Item<'_>),
    consumed: impl FnMut(u64),
) -> io::Result<Stats> {
    read_items_in(CHUNK_LEN, input, lookup, each, consumed)
}

/// [`read_items`] with a buffer of `chunk_len` bytes (at least two of the longest frame).
fn read_items_in<L: CrcExtra + Copy>(
    chunk_len: usize,
    mut input: impl Read,
    lookup: L,
    mut each: impl FnMut(Item<'_>),
    mut consumed: impl FnMut(u64),
) -> io::Result<Stats> {
    let mut pieces = Pieces::new(chunk_len);
    let mut total = Stats::default();
    loop {
        pieces.fill(&mut input)?;
        let mut parser = pieces.parser(lookup);
        for item in parser.by_ref() {
            each(item);
        }
        total += *parser.stats();
        consumed(total.bytes);
        if pieces.eof {
            return Ok(total);
        }
        let keep = parser.position();
        pieces.keep_from(keep);
    }
}

/// The buffer a stream is read into and parsed in, piece by piece.
struct Pieces {
    buf: Vec<u8>,
    /// Bytes of `buf` read and not yet parsed.
    filled: usize,
    /// The input has ended.
    eof: bool,
}

impl Pieces {
    /// A buffer of `chunk_len` bytes, at least two of the longest frame (the bytes kept for
    /// the next piece are at most one frame's: a full buffer always has room for more).
    fn new(chunk_len: usize) -> Self {
        Self {
            buf: vec![0; chunk_len.max(2 * MAX_FRAME_LEN)],
            filled: 0,
            eof: false,
        }
    }

    /// Reads until the buffer is full or the input ends (an interrupted read is retried).
    fn fill(&mut self, input: &mut impl Read) -> io::Result<()> {
        while !self.eof && self.filled < self.buf.len() {
            match input.read(&mut self.buf[self.filled..]) {
                Ok(0) => self.eof = true,
                Ok(n) => self.filled += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// The parser of the bytes read: of a piece, or of the input's last bytes.
    fn parser<L: CrcExtra>(&self, lookup: L) -> SliceParser<'_, L> {
        let piece = &self.buf[..self.filled];
        if self.eof {
            SliceParser::new(piece, lookup)
        } else {
            SliceParser::partial(piece, lookup)
        }
    }

    /// Keeps the bytes from `at` (where the parser stopped) for the next piece.
    fn keep_from(&mut self, at: usize) {
        self.buf.copy_within(at..self.filled, 0);
        self.filled -= at;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEARTBEAT: [u8; 21] = [
        0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
    ];

    fn lookup(id: u32) -> Option<u8> {
        (id == 0).then_some(50)
    }

    /// Hands its data over a few bytes at a time, with an interruption now and then.
    struct Trickle<'a> {
        data: &'a [u8],
        reads: usize,
    }

    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            self.reads += 1;
            if self.reads.is_multiple_of(5) {
                return Err(io::ErrorKind::Interrupted.into());
            }
            let n = buf.len().min(self.data.len()).min(1 + self.reads % 97);
            buf[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    /// An item's bytes, and whether its id is known.
    type Found = (Vec<u8>, bool);

    /// Every item, the counts, and the `consumed` values.
    fn read(chunk_len: usize, data: &[u8]) -> (Vec<Found>, Stats, Vec<u64>) {
        let mut items = Vec::new();
        let mut progress = Vec::new();
        let stats = read_items_in(
            chunk_len,
            Trickle { data, reads: 0 },
            lookup,
            |item| {
                items.push(match item {
                    Item::Frame(f) => (f.as_bytes().to_vec(), true),
                    Item::Unknown(f) => (f.as_bytes().to_vec(), false),
                });
            },
            |at| progress.push(at),
        )
        .unwrap();
        (items, stats, progress)
    }

    #[test]
    fn chunks_give_what_the_whole_stream_gives() {
        // Frames, damaged frames, an unknown id and noise, cut anywhere by small chunks.
        let mut data = Vec::new();
        for i in 0..400u32 {
            let mut f = HEARTBEAT;
            f[4] = i as u8;
            let mut crc = mavstack_core::Crc16::new();
            crc.update(&f[1..19]);
            crc.update_byte(50);
            f[19..].copy_from_slice(&crc.value().to_le_bytes());
            match i % 7 {
                3 => f[12] ^= 0x20, // a bad checksum
                5 => f[7] = 9,      // an id without a CRC_EXTRA here
                _ => {}
            }
            if i % 7 == 3 || i % 7 == 5 {
                data.extend_from_slice(&[0x00, 0xfd, 0x20][..(i % 4) as usize]);
            }
            data.extend_from_slice(&f);
        }
        let mut whole = SliceParser::new(&data[..], lookup);
        let want: Vec<Found> = whole
            .by_ref()
            .map(|item| match item {
                Item::Frame(f) => (f.as_bytes().to_vec(), true),
                Item::Unknown(f) => (f.as_bytes().to_vec(), false),
            })
            .collect();
        assert!(want.len() > 300);
        assert!(want.iter().any(|(_, known)| !known));
        for chunk_len in [0, 2 * MAX_FRAME_LEN + 1, 1000, CHUNK_LEN] {
            let (items, stats, progress) = read(chunk_len, &data);
            assert_eq!(items, want, "chunks of {chunk_len}");
            assert_eq!(stats, *whole.stats(), "chunks of {chunk_len}");
            assert!(progress.is_sorted(), "{progress:?}");
            assert_eq!(progress.last(), Some(&(data.len() as u64)));
        }
        // Small chunks are parsed as they come, not at the end only.
        assert!(read(1000, &data).2.len() > 5);
    }

    #[test]
    fn an_empty_stream_has_nothing() {
        let (items, stats, progress) = read(CHUNK_LEN, &[]);
        assert!(items.is_empty());
        assert_eq!(stats, Stats::default());
        assert_eq!(progress, [0]);
    }
}
