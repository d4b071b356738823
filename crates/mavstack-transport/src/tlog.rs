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
//! - [`Reader`] yields `(timestamp, frame)` records, and reads past damage as pymavlink does
//!   (`mavstack_core::tlog::Recovery`), so a damaged log gives the frames and timestamps
//!   pymavlink gives, and never loses a valid record where pymavlink does (the record after a
//!   MAVLink 1 frame with a payload under 4 bytes). A replayer gets each record's timestamp to
//!   pace the frames as they were recorded.
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
use mavstack_core::tlog::{FrameAt, Recovery, STEP_LEN, Step};
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
    /// Bytes that were damage (and the timestamps read for it), or slid over to a believable
    /// timestamp.
    pub skipped_bytes: u64,
    /// Frames rejected for a bad checksum.
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
    /// Where `buf[start]` is in the input.
    offset: u64,
    recovery: Recovery,
    lookup: Option<Box<dyn CrcExtra + Send>>,
    bytes: u64,
}

impl<R> core::fmt::Debug for Reader<R> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Reader")
            .field("stats", &self.stats())
            .field("checks_crc", &self.lookup.is_some())
            .finish_non_exhaustive()
    }
}

impl<R> Reader<R> {
    /// The counts so far.
    #[must_use]
    pub fn stats(&self) -> ReaderStats {
        let r = self.recovery.stats();
        ReaderStats {
            records: r.records,
            bytes: self.bytes,
            skipped_bytes: r.skipped_bytes,
            bad_crc: r.bad_crc,
        }
    }
}

impl<R: Read> Reader<R> {
    /// A reader of `inner` (which need not be buffered).
    pub fn new(inner: R) -> Self {
        Self {
            inner,
            buf: vec![0; BUFFER_LEN.max(2 * STEP_LEN)],
            start: 0,
            end: 0,
            eof: false,
            offset: 0,
            recovery: Recovery::new(),
            lookup: None,
            bytes: 0,
        }
    }

    /// Checks each frame's checksum with `lookup`: a frame of a message id it knows is damage
    /// when its checksum is wrong. Frames of other ids (all of them without a lookup) cannot
    /// be checked and are returned when their header is sound, as pymavlink returns them.
    #[must_use]
    pub fn with_crc_extra(mut self, lookup: impl CrcExtra + Send + 'static) -> Self {
        self.lookup = Some(Box::new(lookup));
        self
    }

    /// Reads the log as pymavlink's `mavutil.mavlink_connection` reads a tlog file: from the
    /// state its indexing walk leaves (`mavstack_core::tlog::Recovery::after_indexing`), so a
    /// damaged log gives pymavlink's frames from its first record on. `file` is the log this
    /// reader reads (walked here with positional reads, before any record is read); set the
    /// checksum lookup first.
    ///
    /// # Errors
    /// Errors reading `file`.
    #[cfg(unix)]
    pub fn indexed_as_pymavlink_opens(mut self, file: &std::fs::File) -> io::Result<Self> {
        use std::os::unix::fs::FileExt;
        let len = file.metadata()?.len();
        // The walk reads a few bytes at each record: through a block of the file at a time.
        let mut block = vec![0u8; BUFFER_LEN];
        let (mut block_at, mut block_len) = (0u64, 0usize);
        let read_at = |at: u64, buf: &mut [u8]| -> io::Result<usize> {
            if at < block_at || at + buf.len() as u64 > block_at + block_len as u64 {
                if buf.len() > block.len() {
                    return file.read_at(buf, at);
                }
                block_at = at;
                block_len = 0;
                while block_len < block.len() {
                    match file.read_at(&mut block[block_len..], at + block_len as u64) {
                        Ok(0) => break,
                        Ok(n) => block_len += n,
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                        Err(e) => return Err(e),
                    }
                }
            }
            let from = usize::try_from(at - block_at)
                .unwrap_or(usize::MAX)
                .min(block_len);
            let n = buf.len().min(block_len - from);
            buf[..n].copy_from_slice(&block[from..from + n]);
            Ok(n)
        };
        self.recovery = Recovery::after_indexing(len, read_at, self.lookup.as_deref())?;
        Ok(self)
    }

    /// The next record as `(timestamp µs, frame bytes)`, borrowed from the reader's buffer;
    /// `None` at the end.
    ///
    /// # Errors
    /// Errors of the underlying reader (not damage: that is skipped and counted).
    pub fn read_record(&mut self) -> io::Result<Option<(u64, &[u8])>> {
        loop {
            if self.end - self.start < STEP_LEN && !self.eof {
                self.fill()?;
            }
            let window = &self.buf[self.start..self.end];
            let (used, step) =
                self.recovery
                    .step(window, self.eof, self.offset, self.lookup.as_deref());
            let from = self.start;
            self.start += used;
            self.offset += used as u64;
            match step {
                Step::Frame {
                    ts_us,
                    len,
                    at: FrameAt::Window(i),
                } => return Ok(Some((ts_us, &self.buf[from + i..from + i + len]))),
                Step::Frame { ts_us, len, .. } => {
                    return Ok(Some((ts_us, self.recovery.frame(len))));
                }
                Step::More => {}
                Step::End => return Ok(None),
            }
        }
    }

    /// Moves the unread bytes to the front and reads until a step's worth is there or the
    /// input ends.
    fn fill(&mut self) -> io::Result<()> {
        if self.start > 0 {
            self.buf.copy_within(self.start..self.end, 0);
            self.end -= self.start;
            self.start = 0;
        }
        while self.end < STEP_LEN {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    break;
                }
                Ok(n) => {
                    self.end += n;
                    self.bytes += n as u64;
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
/// `mavstack_core::tlog::Records` over the whole slice, with the checksums of HEARTBEAT,
/// COMMAND_LONG and one id above 255 known. The three must agree (the in-memory reader passes
/// over frames not in one piece in the log, and only those); every record is a whole frame
/// with a sound header and a right checksum when its id is known; every input byte is read;
/// and the same log with the damage cut out gives the records between the damage unchanged.
#[cfg(feature = "fuzzing")]
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
    assert_eq!(
        whole.stats(),
        pieces.stats(),
        "the counts depend on the reads"
    );
    assert_eq!(
        whole.stats().bytes,
        data.len() as u64,
        "not every byte was read"
    );
    // The zero-copy reader of a whole log in memory (mavstack's Python package).
    let mut in_memory = mavstack_core::tlog::Records::new(data, Some(lookup));
    let mapped: Vec<(u64, Vec<u8>)> = in_memory
        .by_ref()
        .map(|r| (r.ts_us, r.frame.to_vec()))
        .collect();
    assert_eq!(
        in_memory.position(),
        data.len(),
        "the in-memory reader stopped short"
    );
    let assembled = usize::try_from(in_memory.stats().assembled).unwrap_or(usize::MAX);
    assert_eq!(
        mapped.len() + assembled,
        from_slice.len(),
        "the in-memory reader passed over other frames"
    );
    let mut rest = from_slice.iter();
    for record in &mapped {
        assert!(
            rest.any(|r| r == record),
            "the in-memory reader found a record the stream reader did not"
        );
    }
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
    }
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
        (ts, r.stats())
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
    fn a_damaged_frame_costs_its_record() {
        let clean = log(6);
        // A flipped payload bit in record 2 (a v2 HEARTBEAT after a v1 one).
        let mut dirty = clean.clone();
        dirty[8 + 21 + 8 + 17 + 8 + 12] ^= 0x10;
        let (ts, stats) = read_all(Reader::new(&dirty[..]).with_crc_extra(lookup));
        assert_eq!(ts, [1_000, 1_001, 1_003, 1_004, 1_005]);
        assert_eq!((stats.skipped_bytes, stats.bad_crc), (29, 1));
        // Without checksums it cannot be told from a good one.
        let (ts, _) = read_all(Reader::new(&dirty[..]));
        assert_eq!(ts.len(), 6);
        // A truncated last record costs itself.
        let mut cut = clean.clone();
        cut.extend_from_slice(&clean[..20]);
        let (ts, stats) = read_all(Reader::new(&cut[..]).with_crc_extra(lookup));
        assert_eq!(ts, [1_000, 1_001, 1_002, 1_003, 1_004, 1_005]);
        assert_eq!(stats.skipped_bytes, 8);
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
            // A flip in a length byte can make a frame swallow the few records after it
            // (pymavlink reads it the same way); nothing else costs more than its record.
            assert!(ts.len() >= 170, "{}", ts.len());
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
