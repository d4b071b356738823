//! Telemetry log (`.tlog`) records in memory: which bytes form the next record, and the
//! records of a whole log held in one slice (a file read or mapped), zero-copy.
//!
//! A tlog is a sequence of records with no file header: an 8-byte big-endian timestamp
//! (microseconds since the Unix epoch) followed by one complete MAVLink frame as it was on the
//! wire. A record that holds no plausible frame is skipped byte by byte until one does (see
//! [`record_len`]). `mavstack-transport`'s `tlog::Reader` reads the same records from a
//! stream; both decide with [`record_len`].
//!
//! ```
//! use mavstack_core::tlog::Records;
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut log = Vec::new();
//! for ts in [1_700_000_000_000_000u64, 1_700_000_000_500_000] {
//!     log.extend_from_slice(&ts.to_be_bytes());
//!     log.extend_from_slice(&heartbeat);
//! }
//! log.insert(29, 0x55); // a stray byte between the records
//! let mut records = Records::new(&log, Some(|id: u32| (id == 0).then_some(50u8)));
//! let found: Vec<(usize, u64)> = records.by_ref().map(|r| (r.offset, r.ts_us)).collect();
//! assert_eq!(found, [(0, 1_700_000_000_000_000), (30, 1_700_000_000_500_000)]);
//! assert_eq!(records.stats().skipped_bytes, 1);
//! ```

use crate::Crc16;
use crate::parse::CrcExtra;
use crate::wire::{Frame, MAX_FRAME_LEN, STX_V1, STX_V2};

/// Length of a record's timestamp.
pub const TIMESTAMP_LEN: usize = 8;
/// The longest record: a timestamp and the longest frame.
pub const MAX_RECORD_LEN: usize = TIMESTAMP_LEN + MAX_FRAME_LEN;
/// Bytes [`record_len`] must see (unless the log ends sooner): a whole record plus the next
/// record's timestamp and start marker, which tells whether a record of an unknown message
/// ends where its header says.
pub const LOOKAHEAD: usize = MAX_RECORD_LEN + TIMESTAMP_LEN + 1;

/// Whether `path` names a tlog: a `.tlog` extension, any case (how every mavstack tool and
/// the Python package tell a tlog from a raw capture).
#[cfg(feature = "std")]
#[must_use]
pub fn is_tlog_path(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("tlog"))
}

/// Counts of what record scanning rejected.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RecordStats {
    /// Records accepted.
    pub records: u64,
    /// Bytes skipped while looking for the next plausible record.
    pub skipped_bytes: u64,
    /// Candidate records rejected for a bad checksum.
    pub bad_crc: u64,
}

/// The frame length of the record at the start of `avail`, if it is plausible. `avail` must
/// hold at least [`LOOKAHEAD`] bytes unless the log ends within them.
///
/// A record is accepted when its frame's header is valid and the whole frame is there, and
/// then: for a message id `lookup` knows, when the checksum is right (a wrong one is counted
/// in `stats.bad_crc`); for an unknown id (or without a lookup), when the frame is followed by
/// the end of the log or by a record whose frame starts with a start marker, or when its
/// checksum is right for some CRC_EXTRA (which 1 in 256 random byte strings pass).
pub fn record_len<L: CrcExtra + ?Sized>(
    avail: &[u8],
    lookup: Option<&L>,
    stats: &mut RecordStats,
) -> Option<usize> {
    let bytes = avail.get(TIMESTAMP_LEN..)?;
    let frame = Frame::new_checked(bytes).ok()?;
    let len = frame.frame_len();
    if let Some(extra) = lookup.and_then(|l| l.crc_extra(frame.msg_id())) {
        if frame.check_crc(extra) {
            return Some(len);
        }
        stats.bad_crc += 1;
        return None;
    }
    let followed = match avail.get(TIMESTAMP_LEN + len..) {
        // The log ends with this record, or with fewer bytes than another record needs.
        Some(next) if next.len() <= TIMESTAMP_LEN => true,
        Some(next) => next[TIMESTAMP_LEN] == STX_V2 || next[TIMESTAMP_LEN] == STX_V1,
        None => false,
    };
    (followed || checksum_fits_some_crc_extra(&frame)).then_some(len)
}

/// Whether some CRC_EXTRA byte makes the frame's checksum right: true for 1 in 256 random
/// frames, and for every intact one whatever its dialect.
fn checksum_fits_some_crc_extra(frame: &Frame<&[u8]>) -> bool {
    let end = frame.version().header_len() + frame.payload_len();
    let mut crc = Crc16::new();
    crc.update(&frame.as_bytes()[1..end]);
    let want = frame.checksum();
    (0..=u8::MAX).any(|extra| {
        let mut c = crc;
        c.update_byte(extra);
        c.value() == want
    })
}

/// One record found by [`Records`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record<'a> {
    /// Where the record (its timestamp) starts in the log.
    pub offset: usize,
    /// The timestamp: microseconds since the Unix epoch (MAVProxy keeps a link number in
    /// the low two bits).
    pub ts_us: u64,
    /// The frame's bytes, borrowed from the log.
    pub frame: &'a [u8],
}

/// The records of a whole log in one slice, in order, skipping damage byte by byte.
#[derive(Debug)]
pub struct Records<'a, L> {
    log: &'a [u8],
    pos: usize,
    lookup: Option<L>,
    stats: RecordStats,
}

impl<'a, L: CrcExtra> Records<'a, L> {
    /// The records of `log`, checksums checked with `lookup` when given.
    pub const fn new(log: &'a [u8], lookup: Option<L>) -> Self {
        Self::starting_at(log, 0, lookup)
    }

    /// The records of `log` from offset `pos` on (a position from [`Records::position`]).
    pub const fn starting_at(log: &'a [u8], pos: usize, lookup: Option<L>) -> Self {
        Self {
            log,
            pos,
            lookup,
            stats: RecordStats {
                records: 0,
                skipped_bytes: 0,
                bad_crc: 0,
            },
        }
    }

    /// The counts so far.
    #[must_use]
    pub const fn stats(&self) -> &RecordStats {
        &self.stats
    }

    /// The offset of the next byte to look at.
    #[must_use]
    pub const fn position(&self) -> usize {
        self.pos
    }
}

impl<'a, L: CrcExtra> Iterator for Records<'a, L> {
    type Item = Record<'a>;

    fn next(&mut self) -> Option<Record<'a>> {
        loop {
            let avail = self.log.get(self.pos..)?;
            if avail.len() <= TIMESTAMP_LEN {
                self.stats.skipped_bytes += avail.len() as u64;
                self.pos = self.log.len();
                return None;
            }
            let window = &avail[..avail.len().min(LOOKAHEAD)];
            if let Some(len) = record_len(window, self.lookup.as_ref(), &mut self.stats) {
                let mut ts = [0u8; TIMESTAMP_LEN];
                ts.copy_from_slice(&avail[..TIMESTAMP_LEN]);
                let offset = self.pos;
                self.pos += TIMESTAMP_LEN + len;
                self.stats.records += 1;
                return Some(Record {
                    offset,
                    ts_us: u64::from_be_bytes(ts),
                    frame: &avail[TIMESTAMP_LEN..TIMESTAMP_LEN + len],
                });
            }
            self.pos += 1;
            self.stats.skipped_bytes += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEARTBEAT: [u8; 21] = [
        0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
    ];

    fn known(id: u32) -> Option<u8> {
        (id == 0).then_some(50)
    }

    #[test]
    fn a_corrupt_record_is_skipped_and_counted() {
        let mut log = [0u8; 3 * 29];
        for (i, chunk) in log.chunks_mut(29).enumerate() {
            chunk[..8].copy_from_slice(&(1000 + i as u64).to_be_bytes());
            chunk[8..].copy_from_slice(&HEARTBEAT);
        }
        log[29 + 8 + 5] ^= 0x40;
        let mut records = Records::new(&log[..], Some(known));
        let times: [Option<u64>; 3] = core::array::from_fn(|_| records.next().map(|r| r.ts_us));
        assert_eq!(times, [Some(1000), Some(1002), None]);
        assert_eq!(records.stats().skipped_bytes, 29);
        assert_eq!(records.stats().bad_crc, 1);
        assert_eq!(records.position(), log.len());
    }

    #[test]
    fn an_unknown_id_is_kept_when_a_record_follows() {
        let mut log = [0u8; 2 * 29];
        for chunk in log.chunks_mut(29) {
            chunk[8..].copy_from_slice(&HEARTBEAT);
        }
        let none: Option<fn(u32) -> Option<u8>> = None;
        assert_eq!(Records::new(&log[..], none).count(), 2);
    }

    #[test]
    fn a_truncated_tail_is_skipped() {
        let mut log = [0u8; 29 + 20];
        log[8..29].copy_from_slice(&HEARTBEAT);
        log[29 + 8..].copy_from_slice(&HEARTBEAT[..12]);
        let mut records = Records::starting_at(&log[..], 0, Some(known));
        assert_eq!(records.by_ref().count(), 1);
        assert_eq!(records.stats().skipped_bytes, 20);
    }
}
