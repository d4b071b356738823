//! The reading of a tlog as a state machine: [`Recovery`].

use crate::Crc16;
use crate::parse::CrcExtra;
use crate::wire::{MAX_FRAME_LEN, STX_V1, STX_V2};

use super::{RecordStats, TIMESTAMP_LEN};

/// Bytes a window must hold for [`Recovery::step`] to go on (unless the log ends within
/// them): a timestamp and the longest frame, with room to spare.
pub const STEP_LEN: usize = TIMESTAMP_LEN + PARSER_LEN;

/// The parser buffer: the longest frame plus what the parser may have been given beyond it.
const PARSER_LEN: usize = MAX_FRAME_LEN + 8;
/// How far from the last good timestamp (in seconds) a timestamp read after damage may be.
const PLAUSIBLE_S: f64 = 3.0 * 24.0 * 60.0 * 60.0;
/// The incompatibility flag of a signed frame.
const SIGNED: u8 = 0x01;
const HEADER_V1: usize = 6;
const HEADER_V2: usize = 10;
const CHECKSUM: usize = 2;
const SIGNATURE: usize = 13;

/// Where the frame of a [`Step::Frame`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameAt {
    /// In the window given to this step, from this index on.
    Window(usize),
    /// In the parser's buffer ([`Recovery::frame`]); `log_offset` is where it starts in the
    /// log when its bytes lie there in one piece (the bytes before the window are counted
    /// from the `base` of the steps that read them).
    Parser {
        /// The frame's offset in the log, when contiguous there.
        log_offset: Option<u64>,
    },
}

/// What one [`Recovery::step`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// A frame (checked when its id is known) and its timestamp.
    Frame {
        /// The timestamp: microseconds since the Unix epoch (MAVProxy keeps a link number in
        /// the low two bits).
        ts_us: u64,
        /// The frame's length.
        len: usize,
        /// Where its bytes are.
        at: FrameAt,
    },
    /// The window is used up and the log goes on: step again with the bytes that follow.
    More,
    /// The log ends here: no frame in what is left. (A log that grows may be stepped again.)
    End,
}

/// What one message of pymavlink's reading was.
enum Message {
    /// A frame, the need of more bytes, or the end.
    Step(Step),
    /// Damage (BAD_DATA), counted.
    Damage,
}

/// What a finished message was.
enum Parsed {
    /// A frame to return: its length and where.
    Frame(usize, FrameAt),
    /// Damage of this many bytes (the checksum was wrong when `bad_crc`).
    Damage(usize, bool),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    /// The next message's timestamp is next.
    Timestamp,
    /// Sliding byte by byte for a believable timestamp; the last eight bytes read.
    Scan(u64),
    /// The frame is next.
    Frame,
}

/// The reading of a tlog as a state machine: which bytes are the next timestamp, which the
/// next frame, and what damage costs.
///
/// A damaged log is read the way pymavlink's `mavlogfile` reads it (the reader every tlog tool
/// is compared with), step for step, so both give the same frames with the same timestamps,
/// except where pymavlink loses a valid record (below):
/// - A message starts with an 8-byte timestamp. After damage, a timestamp more than three days
///   away from the last good message's is not believed: reading slides on byte by byte until
///   one within three days is found (or the log ends).
/// - The frame parser asks for only the bytes it needs: first a shortest frame's worth (12
///   bytes after a MAVLink 2 frame, else 8), then the rest of what the length byte says.
///   Bytes it was given but did not use stay in its buffer and come before the log's next
///   bytes (after the next timestamp).
/// - Unlike pymavlink: a frame that starts right after its timestamp (the parser's buffer
///   empty) and is all in the log is read exactly as long as its header says, also when that
///   is less than the parser would first ask for. That is a MAVLink 1 frame with a payload
///   under 4 bytes (8 to 11 bytes) after a MAVLink 2 frame: pymavlink's `bytes_needed` asks
///   for 12 bytes, takes the next record's first timestamp bytes with the frame, reads the
///   next timestamp from the wrong place and the next frame as damage, and so loses a valid
///   record. Here that record is read like any other.
/// - A byte that cannot start a frame is damage, together with every following byte of the
///   buffer up to a start marker.
/// - A frame is taken whole as its length byte (and signature flag) says. It is damage when
///   its incompatibility flags hold a bit other than "signed", or when its message id is known
///   and its checksum is wrong. A frame of an unknown id cannot be checked and is kept.
///
/// [`Recovery::step`] takes a window of the log's bytes and gives one frame at a time, so the
/// same machine reads a log held in memory and one read from a stream in pieces.
///
/// ```
/// use mavstack_core::tlog::{FrameAt, Recovery, Step};
/// let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// let mut log = 1_700_000_000_000_000u64.to_be_bytes().to_vec();
/// log.extend_from_slice(&heartbeat);
/// let mut recovery = Recovery::new();
/// let lookup = |id: u32| (id == 0).then_some(50u8);
/// let (used, step) = recovery.step(&log, true, 0, Some(&lookup));
/// assert_eq!(used, log.len());
/// assert_eq!(
///     step,
///     Step::Frame { ts_us: 1_700_000_000_000_000, len: 21, at: FrameAt::Window(8) }
/// );
/// assert_eq!(recovery.step(&[], true, 29, Some(&lookup)), (0, Step::End));
/// ```
#[derive(Clone, Debug)]
pub struct Recovery {
    phase: Phase,
    /// The parser's buffer: bytes given to it and not used yet.
    buf: [u8; PARSER_LEN],
    len: usize,
    /// Where each byte of `buf` was in the log.
    offsets: [u64; PARSER_LEN],
    /// How many bytes the parser wants in its buffer.
    expected: usize,
    /// The last frame returned from the parser's buffer.
    out: [u8; MAX_FRAME_LEN],
    /// The timestamp of the message being read.
    ts_us: u64,
    /// Timestamp bytes read for the message being read (skipped if it is damage).
    ts_bytes: usize,
    /// Whether the last message was damage.
    after_damage: bool,
    /// The last good message's timestamp in seconds, as pymavlink computes it.
    last_good_s: Option<f64>,
    stats: RecordStats,
}

impl Default for Recovery {
    fn default() -> Self {
        Self::new()
    }
}

impl Recovery {
    /// A machine at the start of a log.
    #[must_use]
    pub const fn new() -> Self {
        Self {
            phase: Phase::Timestamp,
            buf: [0; PARSER_LEN],
            len: 0,
            offsets: [0; PARSER_LEN],
            expected: HEADER_V1 + CHECKSUM,
            out: [0; MAX_FRAME_LEN],
            ts_us: 0,
            ts_bytes: 0,
            after_damage: false,
            last_good_s: None,
            stats: RecordStats {
                records: 0,
                skipped_bytes: 0,
                bad_crc: 0,
                assembled: 0,
            },
        }
    }

    /// The counts so far.
    #[must_use]
    pub const fn stats(&self) -> &RecordStats {
        &self.stats
    }

    /// The bytes of the last frame found at [`FrameAt::Parser`].
    #[must_use]
    pub fn frame(&self, len: usize) -> &[u8] {
        &self.out[..len.min(MAX_FRAME_LEN)]
    }

    /// Reads from `window`, the log's bytes from offset `base` on (`end`: nothing follows
    /// them), until a frame is found, the window is used up, or the log ends. Returns how many
    /// bytes of the window were used and what was found. Unless `end`, the window should hold
    /// [`STEP_LEN`] bytes; a shorter one is used up to where a whole step no longer fits.
    pub fn step<L: CrcExtra + ?Sized>(
        &mut self,
        window: &[u8],
        end: bool,
        base: u64,
        lookup: Option<&L>,
    ) -> (usize, Step) {
        let mut at = 0;
        loop {
            let (used, message) = self.message(&window[at..], end, base + at as u64, lookup);
            // A frame found in the window is placed in it, not in the rest given to `message`.
            let step = match message {
                Message::Step(Step::Frame {
                    ts_us,
                    len,
                    at: FrameAt::Window(i),
                }) => Step::Frame {
                    ts_us,
                    len,
                    at: FrameAt::Window(at + i),
                },
                Message::Step(step) => step,
                Message::Damage => {
                    at += used;
                    continue;
                }
            };
            return (at + used, step);
        }
    }

    /// One message as pymavlink's `recv_msg` reads it: a frame, damage (which pymavlink returns
    /// as BAD_DATA), or the need of more bytes, or the end.
    fn message<L: CrcExtra + ?Sized>(
        &mut self,
        window: &[u8],
        end: bool,
        base: u64,
        lookup: Option<&L>,
    ) -> (usize, Message) {
        let mut at = 0;
        loop {
            match self.phase {
                Phase::Timestamp => {
                    if window.len() - at < STEP_LEN && !end {
                        return (at, Message::Step(Step::More));
                    }
                    let rest = &window[at..];
                    if rest.len() >= TIMESTAMP_LEN {
                        let mut ts = [0; TIMESTAMP_LEN];
                        ts.copy_from_slice(&rest[..TIMESTAMP_LEN]);
                        let ts = u64::from_be_bytes(ts);
                        at += TIMESTAMP_LEN;
                        self.ts_bytes = TIMESTAMP_LEN;
                        let doubtful = self.after_damage
                            && self.last_good_s.is_some_and(|good| !plausible(ts, good));
                        if doubtful {
                            self.phase = Phase::Scan(ts);
                        } else {
                            self.ts_us = ts;
                            self.phase = Phase::Frame;
                        }
                    } else {
                        // A timestamp cut short by the end: read, and the last one stands.
                        at += rest.len();
                        self.ts_bytes = rest.len();
                        self.phase = Phase::Frame;
                    }
                }
                Phase::Scan(mut ts) => {
                    let good = self.last_good_s.unwrap_or(0.0);
                    while !plausible(ts, good) {
                        let Some(&byte) = window.get(at) else {
                            if end {
                                break;
                            }
                            self.phase = Phase::Scan(ts);
                            return (at, Message::Step(Step::More));
                        };
                        ts = (ts << 8) | u64::from(byte);
                        at += 1;
                        self.stats.skipped_bytes += 1;
                    }
                    self.ts_us = ts;
                    self.phase = Phase::Frame;
                }
                Phase::Frame => {
                    if window.len() - at < PARSER_LEN && !end {
                        return (at, Message::Step(Step::More));
                    }
                    let Some(parsed) = self.read_message(window, &mut at, base, lookup) else {
                        // Nothing more to give the parser: pymavlink's recv_msg returns None.
                        self.stats.skipped_bytes += self.ts_bytes as u64;
                        self.ts_bytes = 0;
                        self.phase = Phase::Timestamp;
                        return (at, Message::Step(Step::End));
                    };
                    self.phase = Phase::Timestamp;
                    let ts_bytes = core::mem::take(&mut self.ts_bytes);
                    return match parsed {
                        Parsed::Frame(len, frame_at) => {
                            self.after_damage = false;
                            // pymavlink: `tusec * 1.0e-6`, the same floating-point operation.
                            self.last_good_s = Some(self.ts_us as f64 * 1.0e-6);
                            self.stats.records += 1;
                            let step = Step::Frame {
                                ts_us: self.ts_us,
                                len,
                                at: frame_at,
                            };
                            (at, Message::Step(step))
                        }
                        Parsed::Damage(bytes, bad_crc) => {
                            self.after_damage = true;
                            self.stats.skipped_bytes += (bytes + ts_bytes) as u64;
                            self.stats.bad_crc += u64::from(bad_crc);
                            (at, Message::Damage)
                        }
                    };
                }
            }
        }
    }

    /// The reading state a tlog file opened with pymavlink's `mavutil.mavlink_connection` starts
    /// with. pymavlink opens an existing log file as a `mavmmaplog`, which first indexes it: it
    /// walks the records by the lengths their headers claim (byte by byte where no start
    /// marker is) and reads one message, with the reader it then reads the log with, at the
    /// first record of each known message id. Reading then starts at the log's first byte
    /// with the parser as that walk left it — which can cost or change the first messages of
    /// a damaged log. `read_at(offset, buf)` reads the log's bytes at `offset` (fewer at its
    /// end, `len` bytes long).
    ///
    /// # Errors
    /// The errors of `read_at`.
    #[cfg(feature = "std")]
    pub fn after_indexing<L: CrcExtra + ?Sized, E>(
        len: u64,
        mut read_at: impl FnMut(u64, &mut [u8]) -> Result<usize, E>,
        lookup: Option<&L>,
    ) -> Result<Self, E> {
        let mut recovery = Self::new();
        let mut seen = std::collections::HashSet::new();
        let mut window = std::vec![0u8; 4 * STEP_LEN];
        let mut ofs = 0u64;
        while ofs + 14 < len {
            let mut head = [0u8; 10];
            let got = read_full(&mut read_at, ofs + TIMESTAMP_LEN as u64, &mut head)?;
            let claimed = u64::from(head[1]) + 8;
            let (id, frame_len) = match head[0] {
                STX_V1 => (u32::from(head[5]), claimed + 8),
                STX_V2 => {
                    if ofs + 18 > len || got < 10 {
                        break;
                    }
                    let signed = if head[2] & SIGNED != 0 {
                        SIGNATURE as u64
                    } else {
                        0
                    };
                    (
                        u32::from_le_bytes([head[7], head[8], head[9], 0]),
                        claimed + 12 + signed,
                    )
                }
                _ => {
                    ofs += 1;
                    continue;
                }
            };
            if !seen.contains(&id) {
                if lookup.and_then(|l| l.crc_extra(id)).is_none() {
                    ofs += frame_len;
                    continue;
                }
                seen.insert(id);
                // One recv_msg from the record's start, with the reader's own state.
                let mut pos = ofs;
                loop {
                    let n = read_full(&mut read_at, pos, &mut window)?;
                    let end = pos + n as u64 >= len;
                    let (used, message) = recovery.message(&window[..n], end, pos, lookup);
                    pos += used as u64;
                    if !matches!(message, Message::Step(Step::More)) {
                        break;
                    }
                }
            }
            ofs += frame_len;
        }
        Ok(recovery)
    }

    /// The next frame of `log`, a whole log in memory, reading from `*pos` on (moved on):
    /// `(timestamp, frame offset, frame length)`. Frames not in one piece in the log are
    /// counted ([`RecordStats::assembled`]) and passed over.
    pub fn next_in<L: CrcExtra + ?Sized>(
        &mut self,
        log: &[u8],
        pos: &mut usize,
        lookup: Option<&L>,
    ) -> Option<(u64, usize, usize)> {
        loop {
            let window = log.get(*pos..)?;
            let start = *pos;
            let (used, step) = self.step(window, true, start as u64, lookup);
            *pos += used;
            match step {
                Step::Frame {
                    ts_us,
                    len,
                    at: FrameAt::Window(i),
                } => return Some((ts_us, start + i, len)),
                Step::Frame {
                    ts_us,
                    len,
                    at: FrameAt::Parser { log_offset },
                } => {
                    if let Some(o) = log_offset.and_then(|o| usize::try_from(o).ok()) {
                        return Some((ts_us, o, len));
                    }
                }
                Step::More | Step::End => return None,
            }
        }
    }

    /// Gives the parser the bytes it asks for until it has a message (a frame or damage);
    /// `None` when the window is used up without one.
    fn read_message<L: CrcExtra + ?Sized>(
        &mut self,
        window: &[u8],
        at: &mut usize,
        base: u64,
        lookup: Option<&L>,
    ) -> Option<Parsed> {
        loop {
            let rest = &window[*at..];
            if self.len == 0
                && let Some((len, header)) = whole_frame(rest)
            {
                // The usual case: the frame after a timestamp is all in the window. Read
                // exactly it (pymavlink reads more when it is shorter than `expected`, and
                // loses the next record), checked where it lies.
                let start = *at;
                *at += len;
                self.expected = header + CHECKSUM;
                return Some(match check(&rest[..len], lookup) {
                    Check::Good => Parsed::Frame(len, FrameAt::Window(start)),
                    Check::Damaged(bad_crc) => Parsed::Damage(len, bad_crc),
                });
            }
            let wanted = self.expected.saturating_sub(self.len).max(1);
            let take = wanted.min(rest.len()).min(PARSER_LEN - self.len);
            let offset = base + *at as u64;
            for (slot, o) in self.offsets[self.len..self.len + take]
                .iter_mut()
                .zip(offset..)
            {
                *slot = o;
            }
            self.buf[self.len..self.len + take].copy_from_slice(&rest[..take]);
            self.len += take;
            *at += take;
            if let Some(parsed) = self.parse(lookup) {
                return Some(parsed);
            }
            if take == 0 {
                return None;
            }
        }
    }

    /// pymavlink's parsing of its buffer: a message when one is complete.
    fn parse<L: CrcExtra + ?Sized>(&mut self, lookup: Option<&L>) -> Option<Parsed> {
        let first = *self.buf[..self.len].first()?;
        let header = if first == STX_V2 {
            HEADER_V2
        } else {
            HEADER_V1
        };
        if first != STX_V1 && first != STX_V2 {
            let run = 1 + self.buf[1..self.len]
                .iter()
                .position(|&b| b == STX_V1 || b == STX_V2)
                .unwrap_or(self.len - 1);
            self.consume(run);
            self.expected = HEADER_V1 + CHECKSUM;
            return Some(Parsed::Damage(run, false));
        }
        if self.len >= 3 {
            self.expected = claimed_len(&self.buf[..3], header);
        }
        if self.expected < header + CHECKSUM || self.len < self.expected {
            return None;
        }
        let len = self.expected;
        self.expected = header + CHECKSUM;
        self.out[..len].copy_from_slice(&self.buf[..len]);
        // In one piece when its bytes were read one after another (not, say, some before a
        // timestamp and the rest after it); what was read after the frame does not matter.
        let first = self.offsets[0];
        let log_offset = (self.offsets[..len]
            .iter()
            .zip(first..)
            .all(|(&o, want)| o == want))
        .then_some(first);
        self.consume(len);
        Some(match check(&self.out[..len], lookup) {
            Check::Good => {
                if log_offset.is_none() {
                    self.stats.assembled += 1;
                }
                Parsed::Frame(len, FrameAt::Parser { log_offset })
            }
            Check::Damaged(bad_crc) => Parsed::Damage(len, bad_crc),
        })
    }

    /// Drops the first `n` bytes of the parser's buffer.
    fn consume(&mut self, n: usize) {
        self.buf.copy_within(n..self.len, 0);
        self.offsets.copy_within(n..self.len, 0);
        self.len -= n;
    }
}

/// Reads `buf.len()` bytes at `offset`, fewer only at the end.
#[cfg(feature = "std")]
fn read_full<E>(
    read_at: &mut impl FnMut(u64, &mut [u8]) -> Result<usize, E>,
    offset: u64,
    buf: &mut [u8],
) -> Result<usize, E> {
    let mut got = 0;
    while got < buf.len() {
        let n = read_at(offset + got as u64, &mut buf[got..])?;
        if n == 0 {
            break;
        }
        got += n;
    }
    Ok(got)
}

/// Whether a timestamp (µs) is within three days of `good_s` (s), as pymavlink decides it.
fn plausible(ts_us: u64, good_s: f64) -> bool {
    (ts_us as f64 * 1.0e-6 - good_s).abs() <= PLAUSIBLE_S
}

/// The length a frame's first three bytes claim (signature included) for a header of
/// `header` bytes.
fn claimed_len(start: &[u8], header: usize) -> usize {
    let signed = start[0] == STX_V2 && start[2] & SIGNED != 0;
    usize::from(start[1]) + header + CHECKSUM + if signed { SIGNATURE } else { 0 }
}

/// The length and header length of the frame at the start of `rest` (as its header says),
/// when it is all there.
fn whole_frame(rest: &[u8]) -> Option<(usize, usize)> {
    let first = *rest.first()?;
    let header = match first {
        STX_V2 => HEADER_V2,
        STX_V1 => HEADER_V1,
        _ => return None,
    };
    let len = claimed_len(rest.get(..3)?, header);
    (rest.len() >= len).then_some((len, header))
}

enum Check {
    Good,
    /// Damaged; with a wrong checksum when `true`.
    Damaged(bool),
}

/// A whole frame (its length as its header claims) judged as pymavlink judges it.
fn check<L: CrcExtra + ?Sized>(frame: &[u8], lookup: Option<&L>) -> Check {
    let v2 = frame[0] == STX_V2;
    if v2 && frame[2] & !SIGNED != 0 {
        return Check::Damaged(false);
    }
    let (header, id) = if v2 {
        (
            HEADER_V2,
            u32::from_le_bytes([frame[7], frame[8], frame[9], 0]),
        )
    } else {
        (HEADER_V1, u32::from(frame[5]))
    };
    let Some(extra) = lookup.and_then(|l| l.crc_extra(id)) else {
        return Check::Good;
    };
    let end = header + usize::from(frame[1]);
    let mut crc = Crc16::new();
    crc.update(&frame[1..end]);
    crc.update_byte(extra);
    if crc.value() == u16::from_le_bytes([frame[end], frame[end + 1]]) {
        Check::Good
    } else {
        Check::Damaged(true)
    }
}
