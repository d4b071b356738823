//! A log file's bytes (read into memory, never mapped) and the scan over them that finds each
//! good frame: tlog records or a raw stream, checksums checked, signatures verified with a
//! key, everything else counted.

use std::collections::HashMap;
use std::fs::File;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use mavstack_core::parse::{Item, SliceParser};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::tlog::Recovery;
use mavstack_core::wire::Frame;

use crate::dialect::Dialect;

/// How many bytes a scan goes between two looks at the file's length.
pub(crate) const CHECK_EVERY: usize = 1 << 20;

/// A log's bytes, read into memory when the log is opened, with the file kept open to notice
/// a log that another program shortens while it is read.
///
/// Read, not mapped: a mapped file that is truncated kills the process with SIGBUS at the
/// next access of a page past its new end, which no Python code can catch. Messages and
/// tables decode from these bytes later, so they must stay valid whatever happens to the
/// file.
pub(crate) struct LogBytes {
    bytes: Vec<u8>,
    /// The file (`None` for what has no length to watch: a pipe, a device).
    file: Option<File>,
    path: PathBuf,
}

impl core::ops::Deref for LogBytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        &self.bytes
    }
}

/// The log was shortened while it was read.
#[derive(Debug)]
pub(crate) struct Truncated {
    /// The log's path.
    pub(crate) path: PathBuf,
    /// The bytes read when it was opened.
    pub(crate) read: u64,
    /// Its length now.
    pub(crate) now: u64,
}

impl core::fmt::Display for Truncated {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{}: the file was truncated while it was read ({} bytes when opened, {} now); \
             copy a log that is still being written before reading it",
            self.path.display(),
            self.read,
            self.now
        )
    }
}

impl LogBytes {
    /// The bytes of the file at `path`.
    pub(crate) fn open(path: &Path) -> std::io::Result<Arc<Self>> {
        let mut file = File::open(path)?;
        let meta = file.metadata()?;
        let mut bytes = Vec::new();
        if meta.is_file() {
            bytes.reserve_exact(usize::try_from(meta.len()).unwrap_or(0));
        }
        file.read_to_end(&mut bytes)?;
        Ok(Arc::new(Self {
            bytes,
            file: meta.is_file().then_some(file),
            path: path.to_owned(),
        }))
    }

    /// `Err` when the file is now shorter than what was read (a log truncated by another
    /// program while it is read: what is in memory is no longer the file).
    pub(crate) fn check_length(&self) -> Result<(), Truncated> {
        let Some(file) = &self.file else {
            return Ok(());
        };
        let read = self.bytes.len() as u64;
        match file.metadata() {
            Ok(meta) if meta.len() < read => Err(Truncated {
                path: self.path.clone(),
                read,
                now: meta.len(),
            }),
            _ => Ok(()),
        }
    }
}

pub(crate) use mavstack_core::tlog::is_tlog_path as is_tlog;

/// What a scan counted besides the frames it returned.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ScanStats {
    /// Good frames returned.
    pub(crate) frames: u64,
    /// Candidates rejected for a bad checksum.
    pub(crate) bad_crc: u64,
    /// Frames of message ids the dialect does not define.
    pub(crate) unknown_id: u64,
    /// Signed frames whose signature did not verify with the key, or that replayed an older
    /// timestamp of their stream.
    pub(crate) bad_signature: u64,
    /// Bytes that were part of no frame.
    pub(crate) skipped_bytes: u64,
    /// Frames that carried a signature (verified or not).
    pub(crate) signed: u64,
}

/// One good frame found by a [`Scan`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct Found {
    /// Where the frame starts in the log.
    pub(crate) start: usize,
    /// Its length.
    pub(crate) len: usize,
    /// The tlog timestamp (µs since the Unix epoch, link bits included); 0 in a raw stream.
    pub(crate) ts_us: u64,
    /// The sender's system id.
    pub(crate) sysid: u8,
    /// The message's index in the dialect.
    pub(crate) message: usize,
    /// Whether the frame's signature was verified with the key.
    pub(crate) verified: bool,
}

/// A position in a log and what has been counted up to it.
pub(crate) struct Scan {
    pos: usize,
    tlog: bool,
    /// The tlog reading state (pymavlink's way past damage), kept between frames.
    recovery: Recovery,
    key: Option<SecretKey>,
    /// The last accepted signature timestamp per (link id, sysid, compid).
    streams: HashMap<(u8, u8, u8), u64>,
    /// The counts so far.
    pub(crate) stats: ScanStats,
}

impl Scan {
    /// A scan from the start of `log`. A tlog is read as pymavlink's
    /// `mavutil.mavlink_connection` reads it: after its indexing walk
    /// (`Recovery::after_indexing`), which can change how the start of a damaged log reads.
    pub(crate) fn new(log: &[u8], dialect: &Dialect, tlog: bool, key: Option<SecretKey>) -> Self {
        let lookup = |id: u32| dialect.crc_extra(id);
        let recovery = if tlog {
            let read_at = |at: u64, buf: &mut [u8]| -> Result<usize, core::convert::Infallible> {
                let rest = usize::try_from(at)
                    .ok()
                    .and_then(|at| log.get(at..))
                    .unwrap_or_default();
                let n = rest.len().min(buf.len());
                buf[..n].copy_from_slice(&rest[..n]);
                Ok(n)
            };
            match Recovery::after_indexing(log.len() as u64, read_at, Some(&lookup)) {
                Ok(recovery) => recovery,
                Err(never) => match never {},
            }
        } else {
            Recovery::new()
        };
        Self {
            pos: 0,
            tlog,
            recovery,
            key,
            streams: HashMap::new(),
            stats: ScanStats::default(),
        }
    }

    /// Where the scan is.
    pub(crate) const fn position(&self) -> usize {
        self.pos
    }

    /// The next good frame of a known message in `log`, or `None` at its end.
    pub(crate) fn next(&mut self, log: &[u8], dialect: &Dialect) -> Option<Found> {
        let lookup = |id: u32| dialect.crc_extra(id);
        loop {
            let (start, len, ts_us) = if self.tlog {
                let before = *self.recovery.stats();
                let record = self.recovery.next_in(log, &mut self.pos, Some(&lookup));
                let after = self.recovery.stats();
                self.stats.skipped_bytes += after.skipped_bytes - before.skipped_bytes;
                self.stats.bad_crc += after.bad_crc - before.bad_crc;
                let (ts_us, start, len) = record?;
                (start, len, ts_us)
            } else {
                let rest = log.get(self.pos..)?;
                let mut parser = SliceParser::new(rest, lookup);
                let item = parser.next();
                let s = *parser.stats();
                self.stats.skipped_bytes += s.skipped_bytes;
                self.stats.bad_crc += s.bad_crc;
                self.stats.unknown_id += s.unknown_id;
                let end = self.pos + parser.position();
                self.pos = end;
                match item? {
                    Item::Frame(f) => (end - f.as_bytes().len(), f.as_bytes().len(), 0),
                    Item::Unknown(_) => continue,
                }
            };
            let frame = Frame::new_unchecked(&log[start..start + len]);
            let Some(message) = dialect.index_of_id(frame.msg_id()) else {
                // A tlog record of an id the dialect does not know (a raw scan counted it).
                self.stats.unknown_id += 1;
                continue;
            };
            let mut verified = false;
            if let Some(sig) = frame.signature() {
                self.stats.signed += 1;
                if let Some(key) = &self.key {
                    let stream = (sig.link_id, frame.sysid(), frame.compid());
                    let fresh = self.streams.get(&stream).is_none_or(|&t| sig.timestamp > t);
                    if !fresh || signing::verify(&frame, key).is_err() {
                        self.stats.bad_signature += 1;
                        continue;
                    }
                    self.streams.insert(stream, sig.timestamp);
                    verified = true;
                }
            }
            self.stats.frames += 1;
            return Some(Found {
                start,
                len,
                ts_us,
                sysid: frame.sysid(),
                message,
                verified,
            });
        }
    }
}
