//! Finding frames in a byte stream: a resyncing parser that never loses a valid frame.
//!
//! The parser hunts for a start marker, reads the length from the header and checks the
//! checksum with the message's CRC_EXTRA. On a bad checksum it resumes at the byte **after**
//! the false start marker, not after the claimed frame, so a valid frame hidden behind a
//! stray `0xFD`/`0xFE` in noise is never swallowed. Every dropped byte and frame is counted
//! in [`Stats`]; nothing panics and nothing allocates.
//!
//! - [`SliceParser`] walks a complete buffer (a file, a UDP datagram) and yields frames that
//!   borrow from it: no copy at all.
//! - [`Deframer`] takes bytes in pieces as they arrive (a serial port, a TCP stream) into a
//!   fixed internal buffer and yields frames that borrow from it.
//!
//! A frame whose message id the dialect does not know cannot have its checksum checked. It
//! is reported as [`Item::Unknown`] when it is followed by a start marker (or the end of the
//! input) and no valid frame of a known message starts inside it; otherwise its start marker
//! is taken for noise, as after a bad checksum. So an unknown-id candidate never swallows a
//! valid frame.
//!
//! ```
//! use mavstack_core::parse::{Item, SliceParser};
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut stream = vec![0xfd, 0x55, 0x01]; // a false start in noise
//! stream.extend_from_slice(&heartbeat);
//! let crc_extra = |id: u32| (id == 0).then_some(50u8);
//! let mut parser = SliceParser::new(&stream, crc_extra);
//! let Some(Item::Frame(frame)) = parser.next() else { panic!("frame expected") };
//! assert_eq!(frame.as_bytes(), &heartbeat);
//! assert!(parser.next().is_none());
//! assert_eq!((parser.stats().frames, parser.stats().skipped_bytes), (1, 3));
//! ```

use crate::wire::{
    CHECKSUM_LEN, Frame, INCOMPAT_SIGNED, MAX_FRAME_LEN, SIGNATURE_LEN, STX_V1, STX_V2, Version,
};

/// Where the parser gets each message's CRC_EXTRA: `None` for an id the dialect does not
/// define. Implemented for closures `Fn(u32) -> Option<u8>`.
pub trait CrcExtra {
    /// The CRC_EXTRA of message `id`.
    fn crc_extra(&self, id: u32) -> Option<u8>;
}

impl<F: Fn(u32) -> Option<u8>> CrcExtra for F {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        self(id)
    }
}

/// What the parser found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Item<'a> {
    /// A frame of a known message with a good checksum (a signature, if any, is not checked
    /// here).
    Frame(Frame<&'a [u8]>),
    /// A complete frame of a message id the dialect does not define (checksum unchecked).
    Unknown(Frame<&'a [u8]>),
}

impl<'a> Item<'a> {
    /// The item for the frame in `bytes`: checked and known, or of an unknown id.
    fn new(bytes: &'a [u8], known: bool) -> Self {
        let frame = Frame::new_unchecked(bytes);
        if known {
            Self::Frame(frame)
        } else {
            Self::Unknown(frame)
        }
    }
}

/// Counts of everything the parser saw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Stats {
    /// Frames with a good checksum.
    pub frames: u64,
    /// Bytes fed in.
    pub bytes: u64,
    /// Candidates rejected for a bad checksum.
    pub bad_crc: u64,
    /// Frames of unknown message ids.
    pub unknown_id: u64,
    /// MAVLink 2 candidates with incompatibility flags this implementation does not know.
    pub bad_incompat: u64,
    /// Bytes that were part of no frame: noise, false starts, truncated frames.
    pub skipped_bytes: u64,
}

/// Adds the counts of another part of the same stream (a piece parsed with
/// [`SliceParser::partial`]).
impl core::ops::AddAssign for Stats {
    fn add_assign(&mut self, other: Self) {
        self.frames += other.frames;
        self.bytes += other.bytes;
        self.bad_crc += other.bad_crc;
        self.unknown_id += other.unknown_id;
        self.bad_incompat += other.bad_incompat;
        self.skipped_bytes += other.skipped_bytes;
    }
}

/// The counts between two points of the same stream: `self`, the counts at the later point,
/// less `earlier`'s. Each count of `earlier` must be at most `self`'s.
impl core::ops::Sub for Stats {
    type Output = Self;

    fn sub(self, earlier: Self) -> Self {
        Self {
            frames: self.frames - earlier.frames,
            bytes: self.bytes - earlier.bytes,
            bad_crc: self.bad_crc - earlier.bad_crc,
            unknown_id: self.unknown_id - earlier.unknown_id,
            bad_incompat: self.bad_incompat - earlier.bad_incompat,
            skipped_bytes: self.skipped_bytes - earlier.skipped_bytes,
        }
    }
}

fn is_magic(b: u8) -> bool {
    b == STX_V2 || b == STX_V1
}

/// Whether the checksum after `end` (header + payload) is right for `crc_extra`.
#[inline(always)]
fn crc_ok(frame: &[u8], end: usize, crc_extra: u8) -> bool {
    let mut crc = crate::Crc16::of_prefix(&frame[1..], end - 1);
    crc.update_byte(crc_extra);
    crc.value().to_le_bytes() == [frame[end], frame[end + 1]]
}

/// Whether a frame of a known message with a good checksum starts anywhere inside
/// `candidate` (after its first byte); `rest` is everything from the candidate's start.
/// `None`: one might, but its bytes have not all arrived yet.
fn known_frame_inside(
    candidate: &[u8],
    rest: &[u8],
    at_end: bool,
    lookup: &impl CrcExtra,
) -> Option<bool> {
    for (j, _) in candidate
        .iter()
        .enumerate()
        .skip(1)
        .filter(|&(_, &b)| is_magic(b))
    {
        let inner = &rest[j..];
        let version = if inner[0] == STX_V2 {
            Version::V2
        } else {
            Version::V1
        };
        if inner.len() < version.header_len() {
            return if at_end { Some(false) } else { None };
        }
        let frame = Frame::new_unchecked(inner);
        if version == Version::V2 && frame.incompat_flags() & !INCOMPAT_SIGNED != 0 {
            continue;
        }
        let Some(extra) = lookup.crc_extra(frame.msg_id()) else {
            continue;
        };
        let len = version.header_len() + frame.payload_len() + CHECKSUM_LEN;
        if inner.len() < len {
            if at_end {
                continue;
            }
            return None;
        }
        if frame.check_crc(extra) {
            return Some(true);
        }
    }
    Some(false)
}

/// The outcome of one scan.
enum Step {
    /// An item at `start` of `len` bytes; scanning continues after it.
    Found {
        start: usize,
        len: usize,
        known: bool,
    },
    /// Nothing more can be decided without more bytes; keep everything from `keep`.
    NeedMore { keep: usize },
}

/// Scans `buf` from `pos`. With `at_end`, no more bytes will come: a candidate that runs past
/// the end is noise.
fn scan(
    buf: &[u8],
    mut pos: usize,
    at_end: bool,
    lookup: &impl CrcExtra,
    stats: &mut Stats,
) -> Step {
    loop {
        // Frames usually follow each other directly: look at the next byte before searching.
        let next = if buf.get(pos).is_some_and(|&b| is_magic(b)) {
            Some(0)
        } else {
            memchr::memchr2(STX_V2, STX_V1, &buf[pos..])
        };
        let Some(offset) = next else {
            stats.skipped_bytes += (buf.len() - pos) as u64;
            return Step::NeedMore { keep: buf.len() };
        };
        stats.skipped_bytes += offset as u64;
        let start = pos + offset;
        let rest = &buf[start..];
        let version = if rest[0] == STX_V2 {
            Version::V2
        } else {
            Version::V1
        };
        let header = version.header_len();
        if rest.len() < header {
            if at_end {
                stats.skipped_bytes += rest.len() as u64;
                return Step::NeedMore { keep: buf.len() };
            }
            return Step::NeedMore { keep: start };
        }
        if version == Version::V2 && rest[2] & !INCOMPAT_SIGNED != 0 {
            stats.bad_incompat += 1;
            stats.skipped_bytes += 1;
            pos = start + 1;
            continue;
        }
        let signed = version == Version::V2 && rest[2] & INCOMPAT_SIGNED != 0;
        let len =
            header + usize::from(rest[1]) + CHECKSUM_LEN + if signed { SIGNATURE_LEN } else { 0 };
        if rest.len() < len {
            if at_end {
                // Runs past the end: a false start or a cut frame. Frames may hide inside.
                stats.skipped_bytes += 1;
                pos = start + 1;
                continue;
            }
            return Step::NeedMore { keep: start };
        }
        let frame = Frame::new_unchecked(&rest[..len]);
        match lookup.crc_extra(frame.msg_id()) {
            Some(extra) if crc_ok(rest, header + usize::from(rest[1]), extra) => {
                stats.frames += 1;
                return Step::Found {
                    start,
                    len,
                    known: true,
                };
            }
            Some(_) => stats.bad_crc += 1,
            None => match known_frame_inside(&rest[..len], rest, at_end, lookup) {
                // A valid frame starts inside the candidate: the candidate is noise.
                Some(true) => {}
                Some(false) => {
                    let followed = rest.get(len).map_or(at_end, |&b| is_magic(b));
                    if followed {
                        stats.unknown_id += 1;
                        return Step::Found {
                            start,
                            len,
                            known: false,
                        };
                    }
                    if rest.len() == len && !at_end {
                        // The next byte decides; wait for it.
                        return Step::NeedMore { keep: start };
                    }
                }
                None => return Step::NeedMore { keep: start },
            },
        }
        stats.skipped_bytes += 1;
        pos = start + 1;
    }
}

/// Parses a buffer in place; frames borrow from it.
///
/// [`SliceParser::new`] takes a complete input. [`SliceParser::partial`] takes one piece of
/// a longer stream read in chunks: it stops before a frame that the next piece may complete,
/// and [`SliceParser::position`] is then where the next piece must continue (move the bytes
/// from there to the front of the buffer, append more, parse again).
#[derive(Debug)]
pub struct SliceParser<'a, L> {
    buf: &'a [u8],
    pos: usize,
    lookup: L,
    stats: Stats,
    at_end: bool,
}

impl<'a, L: CrcExtra> SliceParser<'a, L> {
    /// A parser over `buf`, the whole input, with CRC_EXTRA from `lookup`.
    pub fn new(buf: &'a [u8], lookup: L) -> Self {
        Self {
            buf,
            pos: 0,
            lookup,
            stats: Stats {
                bytes: buf.len() as u64,
                ..Stats::default()
            },
            at_end: true,
        }
    }

    /// A parser over `buf`, a piece of an input that goes on after it. Its `bytes` count is
    /// the bytes it consumed, so the counts of consecutive pieces add up.
    pub fn partial(buf: &'a [u8], lookup: L) -> Self {
        Self {
            at_end: false,
            ..Self::new(buf, lookup)
        }
    }

    /// The counts so far.
    #[must_use]
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// The offset of the next byte to scan.
    #[must_use]
    pub fn position(&self) -> usize {
        self.pos
    }
}

impl<'a, L: CrcExtra> Iterator for SliceParser<'a, L> {
    type Item = Item<'a>;

    fn next(&mut self) -> Option<Item<'a>> {
        if self.pos >= self.buf.len() {
            return None;
        }
        match scan(
            self.buf,
            self.pos,
            self.at_end,
            &self.lookup,
            &mut self.stats,
        ) {
            Step::Found { start, len, known } => {
                self.pos = start + len;
                Some(Item::new(&self.buf[start..start + len], known))
            }
            Step::NeedMore { keep } => {
                self.pos = if self.at_end { self.buf.len() } else { keep };
                if !self.at_end {
                    self.stats.bytes = self.pos as u64;
                }
                None
            }
        }
    }
}

/// Room for the largest frame twice over: enough for the parser always to make progress.
pub const DEFRAMER_CAPACITY: usize = 4 * MAX_FRAME_LEN;

/// Parses a stream that arrives in pieces; frames borrow from its fixed internal buffer.
///
/// ```
/// use mavstack_core::parse::{Deframer, Item};
/// let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// let mut deframer = Deframer::new();
/// let lookup = |id: u32| (id == 0).then_some(50u8);
/// let mut found = 0;
/// for piece in heartbeat.chunks(4) {
///     let mut rest = piece;
///     while !rest.is_empty() {
///         let n = deframer.push(rest);
///         rest = &rest[n..];
///         while let Some(item) = deframer.next_item(&lookup) {
///             assert!(matches!(item, Item::Frame(f) if f.msg_id() == 0));
///             found += 1;
///         }
///     }
/// }
/// assert_eq!(found, 1);
/// ```
#[derive(Clone, Debug)]
pub struct Deframer {
    buf: [u8; DEFRAMER_CAPACITY],
    start: usize,
    end: usize,
    stats: Stats,
}

impl Default for Deframer {
    fn default() -> Self {
        Self::new()
    }
}

impl Deframer {
    /// An empty deframer.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            buf: [0; DEFRAMER_CAPACITY],
            start: 0,
            end: 0,
            stats: Stats {
                frames: 0,
                bytes: 0,
                bad_crc: 0,
                unknown_id: 0,
                bad_incompat: 0,
                skipped_bytes: 0,
            },
        }
    }

    /// Copies as many of `data`'s bytes as fit and returns how many. Call
    /// [`Deframer::next_item`] until it returns `None` before pushing the rest.
    pub fn push(&mut self, data: &[u8]) -> usize {
        if self.start > 0 && self.end + data.len() > self.buf.len() {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        let n = data.len().min(self.buf.len() - self.end);
        self.buf[self.end..self.end + n].copy_from_slice(&data[..n]);
        self.end += n;
        self.stats.bytes += n as u64;
        n
    }

    /// The next frame in the bytes pushed so far, or `None` if more bytes are needed.
    pub fn next_item(&mut self, lookup: &impl CrcExtra) -> Option<Item<'_>> {
        self.step(lookup, false)
    }

    /// Ends the stream: a frame still incomplete is counted as skipped bytes, and any frame
    /// found behind it is returned by further calls until `None`.
    pub fn finish(&mut self, lookup: &impl CrcExtra) -> Option<Item<'_>> {
        self.step(lookup, true)
    }

    fn step(&mut self, lookup: &impl CrcExtra, at_end: bool) -> Option<Item<'_>> {
        let window = &self.buf[self.start..self.end];
        match scan(window, 0, at_end, lookup, &mut self.stats) {
            Step::Found { start, len, known } => {
                let from = self.start + start;
                self.start = from + len;
                Some(Item::new(&self.buf[from..from + len], known))
            }
            Step::NeedMore { keep } => {
                // At the end nothing is kept: what could not be a frame was counted as skipped.
                self.start = if at_end { self.end } else { self.start + keep };
                if self.start == self.end {
                    self.start = 0;
                    self.end = 0;
                }
                None
            }
        }
    }

    /// The counts so far.
    #[must_use]
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// Bytes pushed and not yet consumed.
    #[must_use]
    pub fn buffered(&self) -> usize {
        self.end - self.start
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A HEARTBEAT (CRC_EXTRA 50) from system `sys`.
    fn heartbeat(sys: u8) -> [u8; 21] {
        let mut f = [
            0xfd, 9, 0, 0, 0, sys, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0, 0,
        ];
        let mut crc = crate::Crc16::new();
        crc.update(&f[1..19]);
        crc.update_byte(50);
        f[19..].copy_from_slice(&crc.value().to_le_bytes());
        f
    }

    #[test]
    fn pieces_parse_as_the_whole() {
        let lookup = |id: u32| (id == 0).then_some(50u8);
        let mut stream = std::vec::Vec::new();
        for i in 0..200u8 {
            stream.extend_from_slice(&heartbeat(i));
            // Noise, false starts and a frame cut short between the frames.
            stream.extend_from_slice(&[0x11, 0xfe, 0x03][..usize::from(i % 4).min(3)]);
            if i % 9 == 0 {
                stream.extend_from_slice(&heartbeat(i)[..15]);
            }
        }
        let mut whole = SliceParser::new(&stream, lookup);
        let want: std::vec::Vec<u8> = whole
            .by_ref()
            .filter_map(|it| match it {
                Item::Frame(f) => Some(f.sysid()),
                Item::Unknown(_) => None,
            })
            .collect();
        for chunk in [64, 100, 333, 1000] {
            let mut buf = std::vec::Vec::new();
            let (mut got, mut stats, mut fed) = (std::vec::Vec::new(), Stats::default(), 0);
            loop {
                let take = chunk.min(stream.len() - fed);
                buf.extend_from_slice(&stream[fed..fed + take]);
                fed += take;
                let at_end = fed == stream.len();
                let mut p = if at_end {
                    SliceParser::new(&buf, lookup)
                } else {
                    SliceParser::partial(&buf, lookup)
                };
                got.extend(p.by_ref().filter_map(|it| match it {
                    Item::Frame(f) => Some(f.sysid()),
                    Item::Unknown(_) => None,
                }));
                stats += *p.stats();
                let keep = p.position();
                if at_end {
                    break;
                }
                buf.drain(..keep);
            }
            assert_eq!(got, want, "chunks of {chunk}");
            assert_eq!(stats.frames, whole.stats().frames);
            assert_eq!(stats.bytes, stream.len() as u64);
            assert_eq!(
                stats.skipped_bytes,
                whole.stats().skipped_bytes,
                "chunks of {chunk}"
            );
            assert_eq!(stats.bad_crc, whole.stats().bad_crc);
        }
    }
}
