//! Telemetry log (`.tlog`) records: the format, and the reading of a whole log held in one
//! slice (a file read or mapped), zero-copy.
//!
//! A tlog is a sequence of records with no file header: an 8-byte big-endian timestamp
//! (microseconds since the Unix epoch) followed by one complete MAVLink frame as it was on the
//! wire. Damage is read past as pymavlink reads past it ([`Recovery`], which
//! `mavstack-transport`'s `tlog::Reader` uses too), so a damaged log gives the same frames with
//! the same timestamps in every mavstack tool and in pymavlink. A valid record is never lost,
//! though: pymavlink loses the record after a MAVLink 1 frame with a payload under 4 bytes
//! (when a MAVLink 2 frame came before it), and mavstack reads it.
//!
//! ```
//! use mavstack_core::tlog::Records;
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut log = Vec::new();
//! for ts in [1_700_000_000_000_000u64, 1_700_000_000_500_000, 1_700_000_001_000_000] {
//!     log.extend_from_slice(&ts.to_be_bytes());
//!     log.extend_from_slice(&heartbeat);
//! }
//! log[29 + 8 + 16] ^= 0x01; // the second record's frame is damaged
//! let mut records = Records::new(&log, Some(|id: u32| (id == 0).then_some(50u8)));
//! let found: Vec<(usize, u64)> = records.by_ref().map(|r| (r.frame_offset, r.ts_us)).collect();
//! assert_eq!(found, [(8, 1_700_000_000_000_000), (66, 1_700_000_001_000_000)]);
//! assert_eq!(records.stats().bad_crc, 1);
//! assert_eq!(records.stats().skipped_bytes, 29);
//! ```

mod recovery;

pub use recovery::{FrameAt, Recovery, STEP_LEN, Step};

use crate::parse::CrcExtra;
use crate::wire::MAX_FRAME_LEN;

/// Length of a record's timestamp.
pub const TIMESTAMP_LEN: usize = 8;
/// The longest record: a timestamp and the longest frame.
pub const MAX_RECORD_LEN: usize = TIMESTAMP_LEN + MAX_FRAME_LEN;
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
    /// Bytes that were damage, or timestamps of damage, or slid over to a believable
    /// timestamp.
    pub skipped_bytes: u64,
    /// Frames rejected for a bad checksum.
    pub bad_crc: u64,
    /// Frames whose bytes were not in one piece in the log (a frame made of the bytes left in
    /// the parser after damage and of the bytes after the next timestamp, as pymavlink reads
    /// them): a reader of a stream returns them; [`Records`] counts them and goes on.
    pub assembled: u64,
}

/// One record found by [`Records`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record<'a> {
    /// Where the frame starts in the log.
    pub frame_offset: usize,
    /// The timestamp: microseconds since the Unix epoch (MAVProxy keeps a link number in
    /// the low two bits).
    pub ts_us: u64,
    /// The frame's bytes, borrowed from the log.
    pub frame: &'a [u8],
}

/// The records of a whole log in one slice, in order, read past damage as [`Recovery`] does.
#[derive(Debug)]
pub struct Records<'a, L> {
    log: &'a [u8],
    pos: usize,
    lookup: Option<L>,
    recovery: Recovery,
}

impl<'a, L: CrcExtra> Records<'a, L> {
    /// The records of `log`, checksums checked with `lookup` when given.
    pub const fn new(log: &'a [u8], lookup: Option<L>) -> Self {
        Self {
            log,
            pos: 0,
            lookup,
            recovery: Recovery::new(),
        }
    }

    /// The counts so far.
    #[must_use]
    pub const fn stats(&self) -> &RecordStats {
        self.recovery.stats()
    }

    /// The offset of the next byte to read.
    #[must_use]
    pub const fn position(&self) -> usize {
        self.pos
    }
}

impl<'a, L: CrcExtra> Iterator for Records<'a, L> {
    type Item = Record<'a>;

    fn next(&mut self) -> Option<Record<'a>> {
        let (ts_us, frame_offset, len) =
            self.recovery
                .next_in(self.log, &mut self.pos, self.lookup.as_ref())?;
        Some(Record {
            frame_offset,
            ts_us,
            frame: &self.log[frame_offset..frame_offset + len],
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    const HEARTBEAT: [u8; 21] = [
        0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
    ];

    /// HEARTBEAT (0) and PARAM_REQUEST_LIST (21, a 2-byte payload).
    fn known(id: u32) -> Option<u8> {
        match id {
            0 => Some(50),
            21 => Some(159),
            _ => None,
        }
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
    fn without_a_lookup_every_whole_frame_is_kept() {
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
        let mut records = Records::new(&log[..], Some(known));
        assert_eq!(records.by_ref().count(), 1);
        // The timestamp is skipped; the 12 bytes of frame wait in the parser for more.
        assert_eq!(records.stats().skipped_bytes, 8);
        assert_eq!(records.position(), log.len());
    }

    /// Records of HEARTBEAT at `ts`, one after another.
    fn log_of(times: &[u64]) -> Vec<u8> {
        let mut log = Vec::new();
        for ts in times {
            log.extend_from_slice(&ts.to_be_bytes());
            log.extend_from_slice(&HEARTBEAT);
        }
        log
    }

    #[test]
    fn after_damage_a_timestamp_days_away_is_slid_over() {
        let day = 86_400_000_000;
        let times = [
            1_700_000_000_000_000,
            1_700_000_000_100_000,
            1_700_000_000_200_000,
        ];
        let mut log = log_of(&times);
        // The second frame's start marker is damaged: the parser takes the bytes up to the
        // next start marker as damage, then reads a "timestamp" from inside the frame, which
        // is not believed; sliding on finds the third record's.
        log[29 + 8] = 0x00;
        let found: Vec<u64> = Records::new(&log[..], Some(known))
            .map(|r| r.ts_us)
            .collect();
        assert_eq!(found, [times[0], times[2]]);
        // Without damage before it, a timestamp is believed whatever it says.
        let log = log_of(&[times[0], times[0] + 10 * day]);
        let found: Vec<u64> = Records::new(&log[..], Some(known))
            .map(|r| r.ts_us)
            .collect();
        assert_eq!(found, [times[0], times[0] + 10 * day]);
    }

    #[test]
    fn a_stream_read_in_pieces_gives_what_the_whole_slice_gives() {
        let mut log = log_of(&[1_000_000, 2_000_000, 3_000_000, 4_000_000]);
        log[29 + 8 + 1] = 200; // a length byte
        log.insert(90, 0x55);
        let whole: Vec<(u64, usize)> = Records::new(&log[..], Some(known))
            .map(|r| (r.ts_us, r.frame_offset))
            .collect();
        let mut recovery = Recovery::new();
        let (mut pos, mut found) = (0usize, Vec::new());
        for end in (0..=log.len()).step_by(7).chain([log.len()]) {
            loop {
                let (used, step) =
                    recovery.step(&log[pos..end], end == log.len(), pos as u64, Some(&known));
                let start = pos;
                pos += used;
                match step {
                    Step::Frame {
                        ts_us,
                        at: FrameAt::Window(i),
                        ..
                    } => found.push((ts_us, start + i)),
                    Step::Frame {
                        ts_us,
                        at: FrameAt::Parser { log_offset },
                        ..
                    } => {
                        found.push((ts_us, log_offset.map_or(usize::MAX, |o| o as usize)));
                    }
                    Step::More | Step::End => break,
                }
            }
        }
        assert_eq!(found, whole);
        assert!(!whole.is_empty());
    }

    /// A v2 frame of message `id` (one [`known`] knows) with `payload`, or a v1 one.
    fn frame(id: u8, payload: &[u8], seq: u8, v1: bool) -> Vec<u8> {
        let len = u8::try_from(payload.len()).unwrap();
        let mut f = if v1 {
            std::vec![0xfe, len, seq, 1, 1, id]
        } else {
            std::vec![0xfd, len, 0, 0, seq, 1, 1, id, 0, 0]
        };
        f.extend_from_slice(payload);
        let mut crc = crate::Crc16::new();
        crc.update(&f[1..]);
        crc.update_byte(known(id.into()).unwrap());
        f.extend_from_slice(&crc.value().to_le_bytes());
        f
    }

    /// A log of `frames`, their timestamps 1 ms apart.
    fn log_of_frames(frames: &[Vec<u8>]) -> (Vec<u8>, Vec<(u64, Vec<u8>)>) {
        let mut log = Vec::new();
        let mut want = Vec::new();
        for (i, f) in frames.iter().enumerate() {
            let ts = 1_765_000_000_000_000 + 1000 * i as u64;
            log.extend_from_slice(&ts.to_be_bytes());
            log.extend_from_slice(f);
            want.push((ts, f.clone()));
        }
        (log, want)
    }

    fn read(log: &[u8]) -> Vec<(u64, Vec<u8>)> {
        Records::new(log, Some(known))
            .map(|r| (r.ts_us, r.frame.to_vec()))
            .collect()
    }

    #[test]
    fn a_short_mavlink_1_frame_after_a_mavlink_2_one_costs_nothing() {
        // PARAM_REQUEST_LIST in MAVLink 1 is 10 bytes: fewer than the 12 pymavlink's parser
        // asks for after a MAVLink 2 frame. pymavlink's reader takes the next record's first
        // two timestamp bytes with it and loses that record; every one is read here.
        let short = |seq| frame(21, &[1, 1], seq, true);
        let heartbeat = |seq, v1| frame(0, &[0, 0, 0, 0, 2, 12, 81, 4, 3], seq, v1);
        let frames = [
            short(0),
            heartbeat(1, false),
            short(2),
            heartbeat(3, false),
            short(4),
            short(5),
            heartbeat(6, true),
            short(7),
            frame(21, &[1], 8, true), // a 1-byte payload (a MAVLink 2 sender's truncation)
            heartbeat(9, false),
            frame(21, &[], 10, true),
            heartbeat(11, false),
            short(12),
        ];
        assert_eq!(short(0).len(), 10);
        let (log, want) = log_of_frames(&frames);
        let mut records = Records::new(&log[..], Some(known));
        let found: Vec<(u64, Vec<u8>)> = records
            .by_ref()
            .map(|r| (r.ts_us, r.frame.to_vec()))
            .collect();
        assert_eq!(found, want);
        assert_eq!(
            *records.stats(),
            RecordStats {
                records: 13,
                ..RecordStats::default()
            }
        );
        // A damaged short frame costs itself, not the record after it.
        let mut damaged = log.clone();
        let fifth = frames[..4]
            .iter()
            .map(|f| TIMESTAMP_LEN + f.len())
            .sum::<usize>();
        damaged[fifth + TIMESTAMP_LEN + 6] ^= 0x04; // its payload
        let mut want = want;
        want.remove(4);
        assert_eq!(read(&damaged), want);
    }

    #[test]
    fn a_frame_in_one_piece_is_returned_when_the_parser_finished_it_later() {
        // A byte of garbage before a record whose frame is 11 bytes, after a MAVLink 2 frame:
        // the garbage and the timestamp's first 7 bytes are read as a timestamp, then the 12
        // bytes the parser asks for are the timestamp's last byte (damage) and the whole
        // frame. The parser has it only once the next timestamp and one byte more are read:
        // pymavlink 2.4.50 returns it then, with that next timestamp, and then a frame of an
        // unknown id made of that byte and bytes after the timestamp after it.
        let heartbeat = |seq| frame(0, &[0, 0, 0, 0, 2, 12, 81, 4, 3], seq, false);
        let short = frame(21, &[1, 1, 0], 1, true);
        let t: Vec<u64> = (0..5)
            .map(|i| 1_765_000_000_000_000 + 1000 * i + 0x11)
            .collect();
        let mut log = Vec::new();
        log.extend_from_slice(&t[0].to_be_bytes());
        log.extend_from_slice(&heartbeat(0));
        log.push(0x55);
        for (ts, f) in t[1..]
            .iter()
            .zip([short.clone(), heartbeat(2), heartbeat(3), heartbeat(4)])
        {
            log.extend_from_slice(&ts.to_be_bytes());
            log.extend_from_slice(&f);
        }
        let mut records = Records::new(&log[..], Some(known));
        let found: Vec<(u64, Vec<u8>)> = records
            .by_ref()
            .map(|r| (r.ts_us, r.frame.to_vec()))
            .collect();
        assert_eq!(found, [(t[0], heartbeat(0)), (t[2], short)]);
        // The frame of the unknown id is not in one piece in the log: counted, not returned.
        assert_eq!(records.stats().assembled, 1);
    }

    proptest::proptest! {
        /// A log read whole gives every record; with one record's payload or checksum
        /// damaged, it gives every other record, unchanged, with its timestamp. Payloads of
        /// 0 to 9 bytes: MAVLink 1 frames shorter than a MAVLink 2 header and checksum too.
        #[test]
        fn a_damaged_payload_costs_its_record_and_nothing_else(
            records in proptest::collection::vec(
                (
                    proptest::collection::vec(proptest::prelude::any::<u8>(), 0..=9),
                    proptest::prelude::any::<bool>(),
                    0u64..5_000_000,
                ),
                1..40,
            ),
            hit in proptest::prelude::any::<proptest::sample::Index>(),
            byte in 0usize..11,
            bit in 0u8..8,
        ) {
            let mut log = Vec::new();
            let mut want = Vec::new();
            let mut ts = 1_700_000_000_000_000u64;
            let mut starts = Vec::new();
            for (i, (payload, v1, gap)) in records.iter().enumerate() {
                ts += gap;
                let f = frame(0, payload, i as u8, *v1);
                starts.push(log.len() + TIMESTAMP_LEN + if *v1 { 6 } else { 10 });
                want.push((ts, f.clone()));
                log.extend_from_slice(&ts.to_be_bytes());
                log.extend_from_slice(&f);
            }
            proptest::prop_assert_eq!(read(&log), want.clone());
            let i = hit.index(records.len());
            // A byte of the payload or of the checksum.
            log[starts[i] + byte % (records[i].0.len() + 2)] ^= 1 << bit;
            want.remove(i);
            proptest::prop_assert_eq!(read(&log), want);
        }
    }
}
