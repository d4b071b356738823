//! Telemetry logs (`.tlog`): reading and writing.
//!
//! A tlog is a sequence of records with no file header. Each record is an 8-byte big-endian
//! timestamp (microseconds since the Unix epoch, the wall clock when the frame was received)
//! followed by one complete MAVLink frame, v1 or v2, signed or not, exactly as on the wire.
//! There is no length field: the frame's header gives its length. (Protocol digest §8;
//! pymavlink, MAVProxy, QGroundControl and mavlink-router write this format.)
//!
//! - [`Writer`] (over [`std::io::Write`]) appends records: the one tlog writer (the
//!   `record` command, the router's `--log`, file links). It buffers, and writes the buffer
//!   out at least once a second and whenever it reaches 64 KiB, so a crash loses at most the
//!   last second. Between records, call `flush_if_due` (or sleep until `flush_deadline`) so
//!   that an idle log is written out too.
//! - [`Spool`] runs a [`Writer`] over a file on a thread of its own behind a bounded queue,
//!   for writers that must never wait for the disk (a router's log, a file link); it also
//!   names a router's logs (`mavstack-YYYYmmdd-HHMMSS.tlog`, UTC, never overwriting one).
//! - [`Reader`] yields `(timestamp, frame)` records, and survives corruption: a record that
//!   does not hold a plausible frame is skipped byte by byte until one does (see
//!   [`Reader::with_crc_extra`] for what "plausible" means). A replayer gets each record's
//!   timestamp to pace the frames as they were recorded.
//!
//! ```
//! use mavstack_transport::tlog::{Reader, Writer};
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut writer = Writer::new(Vec::new());
//! for ts in [1_700_000_000_000_000u64, 1_700_000_000_250_000, 1_700_000_000_500_000] {
//!     writer.write_record(ts, &heartbeat)?;
//! }
//! let mut log = writer.into_inner()?;
//! log[29 + 8 + 5] ^= 0x40; // corrupt the second record's frame (its sysid)
//!
//! let mut reader = Reader::new(&log[..]).with_crc_extra(|id: u32| (id == 0).then_some(50u8));
//! let times: Vec<u64> = reader.by_ref().map(|r| r.map(|rec| rec.ts_us)).collect::<Result<_, _>>()?;
//! assert_eq!(times, [1_700_000_000_000_000, 1_700_000_000_500_000]); // the bad record is gone...
//! assert_eq!(reader.stats().skipped_bytes, 29); // ...and counted
//! # Ok::<(), std::io::Error>(())
//! ```

use core::time::Duration;
use std::io::{self, Read, Write};

use mavstack_core::parse::CrcExtra;
use mavstack_core::time::Instant;
use mavstack_core::tlog::{LOOKAHEAD, RecordStats, record_len};
use mavstack_core::wire::Frame;

use crate::frame::FrameBuf;

pub use mavstack_core::tlog::{MAX_RECORD_LEN, TIMESTAMP_LEN};
mod spool;

pub use spool::{OpenMode, QUEUE_BATCHES, Spool};

/// Buffered records are written out at least this often.
pub const FLUSH_INTERVAL: Duration = Duration::from_secs(1);
/// Buffered records are written out once they reach this many bytes.
pub const BUFFER_LEN: usize = 64 * 1024;

/// One record of a tlog.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// When the frame was received: microseconds since the Unix epoch.
    pub ts_us: u64,
    /// The frame.
    pub frame: FrameBuf,
}

impl Record {
    /// The timestamp as an [`Instant`] of the transport's clock (see [`crate::clock`]).
    #[must_use]
    pub fn time(&self) -> Instant {
        Instant::from_micros(self.ts_us)
    }
}

/// Buffered records, and when they must be written out.
#[derive(Debug)]
pub(crate) struct Buffer {
    bytes: Vec<u8>,
    /// When the oldest unwritten byte was buffered.
    dirty_since: Option<std::time::Instant>,
}

impl Buffer {
    pub(crate) fn new() -> Self {
        Self {
            bytes: Vec::with_capacity(BUFFER_LEN + MAX_RECORD_LEN),
            dirty_since: None,
        }
    }

    /// Appends bytes as they are.
    pub(crate) fn push_raw(&mut self, data: &[u8]) {
        if self.dirty_since.is_none() {
            self.dirty_since = Some(std::time::Instant::now());
        }
        self.bytes.extend_from_slice(data);
    }

    /// Appends one record.
    pub(crate) fn push_record(&mut self, ts_us: u64, frame: &[u8]) {
        self.push_raw(&ts_us.to_be_bytes());
        self.bytes.extend_from_slice(frame);
    }

    /// Whether the buffer must be written out now.
    pub(crate) fn due(&self) -> bool {
        self.bytes.len() >= BUFFER_LEN
            || self
                .dirty_since
                .is_some_and(|t| t.elapsed() >= FLUSH_INTERVAL)
    }

    /// When the buffer must be written out, if it holds anything.
    pub(crate) fn deadline(&self) -> Option<std::time::Instant> {
        self.dirty_since.map(|t| t + FLUSH_INTERVAL)
    }

    pub(crate) fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    pub(crate) fn clear(&mut self) {
        self.bytes.clear();
        self.dirty_since = None;
    }
}

/// Writes tlog records to a [`std::io::Write`]; see the [module docs](self).
///
/// Dropping the writer writes out what is buffered, ignoring errors; call
/// [`Writer::flush`] or [`Writer::into_inner`] to see them.
#[derive(Debug)]
pub struct Writer<W: Write> {
    inner: Option<W>,
    buffer: Buffer,
    records: u64,
}

impl<W: Write> Writer<W> {
    /// A writer appending to `inner` (which need not be buffered).
    pub fn new(inner: W) -> Self {
        Self {
            inner: Some(inner),
            buffer: Buffer::new(),
            records: 0,
        }
    }

    /// Appends a record: `ts_us` (microseconds since the Unix epoch) and `frame`, one
    /// complete frame as on the wire (not checked). Writes the buffer out if it is due.
    ///
    /// # Errors
    /// Errors of the underlying writer, when the buffer is written out.
    pub fn write_record(&mut self, ts_us: u64, frame: &[u8]) -> io::Result<()> {
        self.buffer.push_record(ts_us, frame);
        self.records += 1;
        self.flush_if_due().map(|_| ())
    }

    /// Appends bytes as they are, no timestamp (for raw captures written through the same
    /// buffering). Writes the buffer out if it is due.
    ///
    /// # Errors
    /// Errors of the underlying writer, when the buffer is written out.
    pub fn write_raw(&mut self, data: &[u8]) -> io::Result<()> {
        self.buffer.push_raw(data);
        self.records += 1;
        self.flush_if_due().map(|_| ())
    }

    /// Writes the buffer out if a second has passed since its oldest record was added (or it
    /// is full), and says whether it did. Call it now and then when no records come.
    ///
    /// # Errors
    /// Errors of the underlying writer.
    pub fn flush_if_due(&mut self) -> io::Result<bool> {
        if self.buffer.due() {
            self.flush()?;
            return Ok(true);
        }
        Ok(false)
    }

    /// When the buffer must next be written out (`None` when it is empty).
    #[must_use]
    pub fn flush_deadline(&self) -> Option<std::time::Instant> {
        self.buffer.deadline()
    }

    /// Writes the buffer out and flushes the underlying writer.
    ///
    /// # Errors
    /// Errors of the underlying writer.
    pub fn flush(&mut self) -> io::Result<()> {
        let Some(inner) = self.inner.as_mut() else {
            return Ok(());
        };
        inner.write_all(self.buffer.bytes())?;
        self.buffer.clear();
        inner.flush()
    }

    /// Records written so far.
    #[must_use]
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Writes the buffer out and returns the underlying writer.
    ///
    /// # Errors
    /// Errors of the underlying writer.
    pub fn into_inner(mut self) -> io::Result<W> {
        self.flush()?;
        self.inner
            .take()
            .ok_or_else(|| io::Error::other("tlog writer already taken apart"))
    }
}

impl<W: Write> Drop for Writer<W> {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            tracing::warn!("tlog: cannot write the last records: {e}");
        }
    }
}

/// What a [`Reader`] has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct ReaderStats {
    /// Records returned.
    pub records: u64,
    /// Bytes read.
    pub bytes: u64,
    /// Bytes skipped while looking for the next plausible record.
    pub skipped_bytes: u64,
    /// Candidate records rejected for a bad checksum.
    pub bad_crc: u64,
}

/// Reads tlog records from a [`std::io::Read`]; see the [module docs](self).
///
/// It is an [`Iterator`] of owned [`Record`]s; [`Reader::read_record`] borrows instead.
pub struct Reader<R> {
    inner: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    eof: bool,
    lookup: Option<Box<dyn CrcExtra + Send>>,
    stats: ReaderStats,
}

impl<R> core::fmt::Debug for Reader<R> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Reader")
            .field("stats", &self.stats)
            .field("checks_crc", &self.lookup.is_some())
            .finish_non_exhaustive()
    }
}

impl<R: Read> Reader<R> {
    /// A reader of `inner` (which need not be buffered).
    pub fn new(inner: R) -> Self {
        Self {
            inner,
            buf: vec![0; BUFFER_LEN.max(2 * LOOKAHEAD)],
            start: 0,
            end: 0,
            eof: false,
            lookup: None,
            stats: ReaderStats::default(),
        }
    }

    /// Checks each record's checksum with `lookup`, which makes resynchronisation after
    /// corruption reliable.
    ///
    /// A record is accepted when its frame's header is valid and the whole frame is there,
    /// and then: for a message id the lookup knows, when the checksum is right; for an
    /// unknown id (or without a lookup), when the frame is followed by the end of the file or
    /// by a record whose frame starts with a start marker, or when its checksum is right for
    /// some CRC_EXTRA (which 1 in 256 random byte strings pass). Without a lookup a record
    /// whose frame is damaged but whose length is intact is returned as it is: a parser
    /// downstream rejects it.
    #[must_use]
    pub fn with_crc_extra(mut self, lookup: impl CrcExtra + Send + 'static) -> Self {
        self.lookup = Some(Box::new(lookup));
        self
    }

    /// The counts so far.
    #[must_use]
    pub fn stats(&self) -> &ReaderStats {
        &self.stats
    }

    /// The next record as `(timestamp µs, frame bytes)`, borrowed from the reader's buffer;
    /// `None` at the end.
    ///
    /// # Errors
    /// Errors of the underlying reader (not corruption: that is skipped and counted).
    pub fn read_record(&mut self) -> io::Result<Option<(u64, &[u8])>> {
        loop {
            if self.end - self.start < LOOKAHEAD && !self.eof {
                self.fill()?;
                continue;
            }
            let avail = &self.buf[self.start..self.end];
            if avail.len() <= TIMESTAMP_LEN {
                self.stats.skipped_bytes += avail.len() as u64;
                self.start = self.end;
                return Ok(None);
            }
            let mut found = RecordStats::default();
            let len = record_len(avail, self.lookup.as_deref(), &mut found);
            self.stats.bad_crc += found.bad_crc;
            match len {
                Some(frame_len) => {
                    let mut ts = [0u8; TIMESTAMP_LEN];
                    ts.copy_from_slice(&avail[..TIMESTAMP_LEN]);
                    let from = self.start + TIMESTAMP_LEN;
                    self.start = from + frame_len;
                    self.stats.records += 1;
                    return Ok(Some((
                        u64::from_be_bytes(ts),
                        &self.buf[from..from + frame_len],
                    )));
                }
                None => {
                    self.start += 1;
                    self.stats.skipped_bytes += 1;
                }
            }
        }
    }

    /// Moves the unread bytes to the front and reads until the lookahead is full or the input
    /// ends.
    fn fill(&mut self) -> io::Result<()> {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        while self.end < LOOKAHEAD {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    break;
                }
                Ok(n) => {
                    self.end += n;
                    self.stats.bytes += n as u64;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

impl<R: Read> Iterator for Reader<R> {
    type Item = io::Result<Record>;

    fn next(&mut self) -> Option<io::Result<Record>> {
        match self.read_record() {
            Ok(Some((ts_us, frame))) => Some(Ok(Record {
                ts_us,
                frame: FrameBuf::from_frame(&Frame::new_unchecked(frame)),
            })),
            Ok(None) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

/// Fuzzing entry point for tlog records: `data` is read as a tlog, once from one slice, once
/// through a reader that hands it over in pieces whose sizes the data picks and once with
/// `mavstack_core::tlog::Records` over the whole slice, with the
/// checksums of HEARTBEAT, COMMAND_LONG and one id above 255 known. All three must give the same
/// records; every record must be a whole frame (with a right checksum when its id is
/// known); and the records and the skipped bytes must add up to the input.
#[doc(hidden)]
pub fn fuzz_tlog(data: &[u8]) {
    /// Hands the input over in pieces of 1 to 64 bytes, sizes cycling through the input.
    struct Pieces<'a> {
        data: &'a [u8],
        at: usize,
    }
    impl Read for Pieces<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            let rest = &self.data[self.at..];
            if rest.is_empty() {
                return Ok(0);
            }
            let size = usize::from(self.data[self.at % self.data.len()] & 63) + 1;
            let n = size.min(rest.len()).min(buf.len());
            buf[..n].copy_from_slice(&rest[..n]);
            self.at += n;
            Ok(n)
        }
    }
    let lookup = |id: u32| match id {
        0 => Some(50u8),
        76 => Some(152),
        300 => Some(217),
        _ => None,
    };
    let read_all = |reader: &mut dyn FnMut() -> Option<(u64, Vec<u8>)>| {
        let mut records = Vec::new();
        while let Some(record) = reader() {
            records.push(record);
        }
        records
    };
    let mut whole = Reader::new(data).with_crc_extra(lookup);
    let from_slice = read_all(&mut || {
        whole
            .read_record()
            .expect("a slice does not fail")
            .map(|(ts, f)| (ts, f.to_vec()))
    });
    let mut pieces = Reader::new(Pieces { data, at: 0 }).with_crc_extra(lookup);
    let from_pieces = read_all(&mut || {
        pieces
            .read_record()
            .expect("the pieces do not fail")
            .map(|(ts, f)| (ts, f.to_vec()))
    });
    assert_eq!(from_slice, from_pieces, "the records depend on the reads");
    // The zero-copy reader of a whole log in memory (mavstack's Python package) finds the
    // same records, and tells where each starts.
    let mut in_memory = mavstack_core::tlog::Records::new(data, Some(lookup));
    let mapped: Vec<(u64, Vec<u8>)> = in_memory
        .by_ref()
        .map(|r| {
            assert_eq!(
                &data[r.offset + TIMESTAMP_LEN..r.offset + TIMESTAMP_LEN + r.frame.len()],
                r.frame,
                "a record's offset is not where its frame is"
            );
            (r.ts_us, r.frame.to_vec())
        })
        .collect();
    assert_eq!(from_slice, mapped, "the in-memory records differ");
    assert_eq!(
        in_memory.stats().skipped_bytes,
        whole.stats().skipped_bytes,
        "the in-memory reader skips other bytes"
    );
    assert_eq!(
        whole.stats(),
        pieces.stats(),
        "the counts depend on the reads"
    );
    let mut used = whole.stats().skipped_bytes;
    for (_, bytes) in &from_slice {
        let frame = Frame::new_checked(&bytes[..]).expect("a record holds a frame");
        assert_eq!(
            frame.frame_len(),
            bytes.len(),
            "a record is one whole frame"
        );
        if let Some(extra) = lookup(frame.msg_id()) {
            assert!(frame.check_crc(extra), "a record with a bad checksum");
        }
        used += (TIMESTAMP_LEN + bytes.len()) as u64;
    }
    assert_eq!(
        used,
        data.len() as u64,
        "records and skipped bytes are not the input"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEARTBEAT: [u8; 21] = [
        0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
    ];
    const HEARTBEAT_V1: [u8; 17] = [
        0xfe, 9, 0, 1, 1, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x81, 0xb7,
    ];

    fn lookup(id: u32) -> Option<u8> {
        (id == 0).then_some(50)
    }

    fn log(n: usize) -> Vec<u8> {
        let mut w = Writer::new(Vec::new());
        for i in 0..n {
            let frame: &[u8] = if i % 2 == 0 {
                &HEARTBEAT
            } else {
                &HEARTBEAT_V1
            };
            w.write_record(1_000 + i as u64, frame).unwrap();
        }
        w.into_inner().unwrap()
    }

    fn read_all<R: Read>(r: Reader<R>) -> (Vec<u64>, ReaderStats) {
        let mut r = r;
        let ts = r.by_ref().map(|rec| rec.unwrap().ts_us).collect();
        (ts, *r.stats())
    }

    #[test]
    fn round_trip_through_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("x.tlog");
        {
            let mut w = Writer::new(std::fs::File::create(&path).unwrap());
            for i in 0..10_000u64 {
                w.write_record(i, &HEARTBEAT).unwrap();
            }
            assert_eq!(w.records(), 10_000);
        } // dropped: flushed
        let r = Reader::new(std::fs::File::open(&path).unwrap());
        let (ts, stats) = read_all(r);
        assert_eq!(ts, (0..10_000).collect::<Vec<_>>());
        assert_eq!(
            (stats.records, stats.bytes, stats.skipped_bytes),
            (10_000, 290_000, 0)
        );
    }

    #[test]
    fn records_keep_their_frames() {
        let data = log(4);
        let mut r = Reader::new(&data[..]);
        let recs: Vec<Record> = r.by_ref().map(Result::unwrap).collect();
        assert_eq!(recs.len(), 4);
        assert_eq!(recs[0].frame.as_bytes(), &HEARTBEAT);
        assert_eq!(recs[1].frame.as_bytes(), &HEARTBEAT_V1);
        assert_eq!(recs[3].time(), Instant::from_micros(1_003));
    }

    #[test]
    fn corruption_is_skipped_with_and_without_crc_checks() {
        let clean = log(6);
        // Garbage in the middle of record 2, with a false start marker.
        let mut dirty = clean.clone();
        let at = 8 + 21 + 8 + 17 + 8 + 3; // inside record 2's frame header
        dirty.splice(at..at + 4, [0xfd, 0xfe, 0x55, 0x00]);
        let (ts, stats) = read_all(Reader::new(&dirty[..]).with_crc_extra(lookup));
        assert_eq!(ts, [1_000, 1_001, 1_003, 1_004, 1_005]);
        assert!(stats.skipped_bytes > 0);
        // Without CRC checks the damaged record is still rejected: it is not followed by a
        // record where its header says it ends.
        let (ts, _) = read_all(Reader::new(&dirty[..]));
        assert!(!ts.contains(&1_002) || ts.len() == 6, "{ts:?}");
        assert!(ts.contains(&1_003) && ts.contains(&1_005), "{ts:?}");
        // Noise before the first record and a truncated last one.
        let mut noisy = vec![1, 2, 3, 0xfd, 9, 9];
        noisy.extend_from_slice(&clean);
        noisy.extend_from_slice(&clean[..20]);
        let (ts, stats) = read_all(Reader::new(&noisy[..]).with_crc_extra(lookup));
        assert_eq!(ts, [1_000, 1_001, 1_002, 1_003, 1_004, 1_005]);
        assert_eq!(stats.skipped_bytes, 6 + 20);
    }

    #[test]
    fn bit_flips_never_panic_and_lose_little() {
        let clean = log(200);
        let mut state = 0x2545_f491_4f6c_dd1du64;
        for _ in 0..50 {
            let mut dirty = clean.clone();
            for _ in 0..5 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let i = (state % dirty.len() as u64) as usize;
                dirty[i] ^= 1 << (state % 8);
            }
            let (ts, _) = read_all(Reader::new(&dirty[..]).with_crc_extra(lookup));
            // Each flip costs at most the record it hits and the one after it.
            assert!(ts.len() >= 190, "{}", ts.len());
        }
    }

    #[test]
    fn small_reads_are_fine() {
        struct Trickle<'a>(&'a [u8]);
        impl Read for Trickle<'_> {
            fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
                let n = buf.len().min(self.0.len()).min(3);
                buf[..n].copy_from_slice(&self.0[..n]);
                self.0 = &self.0[n..];
                Ok(n)
            }
        }
        let data = log(50);
        let (ts, _) = read_all(Reader::new(Trickle(&data)));
        assert_eq!(ts.len(), 50);
    }

    #[test]
    fn writer_flushes_within_a_second() {
        let mut w = Writer::new(Vec::new());
        w.write_record(1, &HEARTBEAT).unwrap();
        assert!(w.inner.as_ref().unwrap().is_empty());
        let deadline = w.flush_deadline().unwrap();
        assert!(deadline <= std::time::Instant::now() + FLUSH_INTERVAL);
        assert!(!w.flush_if_due().unwrap());
        w.buffer.dirty_since = Some(std::time::Instant::now() - FLUSH_INTERVAL);
        assert!(w.flush_if_due().unwrap());
        assert_eq!(w.inner.as_ref().unwrap().len(), 29);
        assert_eq!(w.flush_deadline(), None);
        // A full buffer goes out at once.
        for _ in 0..(BUFFER_LEN / 29 + 1) {
            w.write_record(2, &HEARTBEAT).unwrap();
        }
        assert!(w.inner.as_ref().unwrap().len() > BUFFER_LEN);
    }
}
