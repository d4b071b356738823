//! [`Spool`]: a log file written on a thread of its own through a bounded queue, so that a
//! slow or failing disk never holds up whoever produces the records (a router's forwarding
//! loop, a file link's driver). What does not fit in the queue is dropped and counted; the
//! first write error ends the thread, and the next [`Spool::send`] (or [`Spool::finish`])
//! returns it.

use std::fs::{File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;

use super::{FLUSH_INTERVAL, Writer};

/// How [`Spool::open`] opens its file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum OpenMode {
    /// A new file; an existing one is an error (a log never overwrites another).
    CreateNew,
    /// Created, or truncated if it exists.
    Truncate,
    /// Created, or appended to if it exists.
    Append,
}

/// Batches waiting for the writer thread; with each batch a driver turn's records (or one
/// write of a file link), this is several seconds of a busy router.
pub const QUEUE_BATCHES: usize = 1024;

/// Records (or raw bytes) pushed since the last [`Spool::send`]: `bytes`, and where each
/// part ends with its timestamp (`None`: raw bytes, no record).
#[derive(Debug, Default)]
struct Batch {
    bytes: Vec<u8>,
    parts: Vec<(Option<u64>, usize)>,
}

/// A log file written on a thread of its own, behind a bounded queue: records that do not fit
/// are counted, never waited for.
///
/// ```
/// use mavstack_transport::tlog::{OpenMode, Reader, Spool};
/// let dir = std::env::temp_dir().join(format!("spool-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// let mut log = Spool::create_in(&dir, 1_700_000_000)?;
/// assert!(log.path().ends_with("mavstack-20231114-221320.tlog"));
/// log.push_record(1_700_000_000_000_000, &heartbeat);
/// log.send()?;
/// let path = log.path().to_owned();
/// log.finish()?;
/// // A second log in the same second gets a name of its own.
/// let second = Spool::create_in(&dir, 1_700_000_000)?;
/// assert!(second.path().ends_with("mavstack-20231114-221320-1.tlog"));
/// second.finish()?;
/// let records = Reader::new(std::fs::File::open(&path)?).count();
/// assert_eq!(records, 1);
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), std::io::Error>(())
/// ```
#[derive(Debug)]
pub struct Spool {
    path: PathBuf,
    batch: Batch,
    /// Records in `batch`.
    records: u64,
    tx: Option<SyncSender<Batch>>,
    thread: Option<JoinHandle<io::Result<()>>>,
    dropped: u64,
}

impl Spool {
    /// Opens `path` as `mode` says and starts its writer thread.
    ///
    /// # Errors
    /// The file cannot be opened (or, with [`OpenMode::CreateNew`], exists), or the thread
    /// cannot be started.
    pub fn open(path: &Path, mode: OpenMode) -> io::Result<Self> {
        let mut options = OpenOptions::new();
        match mode {
            OpenMode::CreateNew => options.write(true).create_new(true),
            OpenMode::Truncate => options.write(true).create(true).truncate(true),
            OpenMode::Append => options.append(true).create(true),
        };
        let file = options.open(path)?;
        if file.metadata().is_ok_and(|m| m.is_dir()) {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory",
            ));
        }
        Self::start(path.to_owned(), file)
    }

    /// A new tlog in `dir` named by `unix_secs` (the start time), in UTC:
    /// `mavstack-YYYYmmdd-HHMMSS.tlog`, or with `-1`, `-2`, ... added before `.tlog` when that
    /// name is taken. An existing file is never opened.
    ///
    /// # Errors
    /// The directory cannot be written.
    pub fn create_in(dir: &Path, unix_secs: u64) -> io::Result<Self> {
        let stem = format!("mavstack-{}", utc_stamp(unix_secs));
        for n in 0u32.. {
            let name = if n == 0 {
                format!("{stem}.tlog")
            } else {
                format!("{stem}-{n}.tlog")
            };
            match Self::open(&dir.join(name), OpenMode::CreateNew) {
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
                other => return other,
            }
        }
        Err(io::Error::other("no free log name"))
    }

    fn start(path: PathBuf, file: File) -> io::Result<Self> {
        let (tx, rx) = sync_channel(QUEUE_BATCHES);
        let thread = std::thread::Builder::new()
            .name("mavstack-log".into())
            .spawn(move || write_batches(file, &rx))?;
        Ok(Self {
            path,
            batch: Batch::default(),
            records: 0,
            tx: Some(tx),
            thread: Some(thread),
            dropped: 0,
        })
    }

    /// The file.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Adds a record (`ts_us`, microseconds since the Unix epoch, and one whole frame) to
    /// the batch [`Spool::send`] hands to the writer thread.
    pub fn push_record(&mut self, ts_us: u64, frame: &[u8]) {
        self.batch.bytes.extend_from_slice(frame);
        self.batch.parts.push((Some(ts_us), self.batch.bytes.len()));
        self.records += 1;
    }

    /// Adds bytes written as they are (a raw capture).
    pub fn push_raw(&mut self, data: &[u8]) {
        self.batch.bytes.extend_from_slice(data);
        self.batch.parts.push((None, self.batch.bytes.len()));
        self.records += 1;
    }

    /// Hands the batch to the writer thread without waiting; a full queue drops it (counted
    /// in [`Spool::dropped`]). Returns false when it was dropped.
    ///
    /// # Errors
    /// The writer thread has stopped: the write error that stopped it.
    pub fn send(&mut self) -> io::Result<bool> {
        if self.batch.parts.is_empty() {
            return Ok(true);
        }
        let batch = core::mem::take(&mut self.batch);
        let records = core::mem::take(&mut self.records);
        let Some(tx) = &self.tx else {
            return Err(self.stopped());
        };
        match tx.try_send(batch) {
            Ok(()) => Ok(true),
            Err(TrySendError::Full(_)) => {
                self.dropped += records;
                Ok(false)
            }
            Err(TrySendError::Disconnected(_)) => Err(self.stopped()),
        }
    }

    /// Records (or raw writes) dropped because the queue was full.
    #[must_use]
    pub const fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Hands on what is left, waiting for room, then lets the thread write everything out
    /// and sync the file.
    ///
    /// # Errors
    /// A write error of the thread.
    pub fn finish(mut self) -> io::Result<()> {
        if !self.batch.parts.is_empty()
            && let Some(tx) = &self.tx
        {
            // The thread has ended when this fails: its error is what counts.
            let _ = tx.send(core::mem::take(&mut self.batch));
        }
        self.tx = None;
        self.join()
    }

    /// The thread ended early: its error.
    fn stopped(&mut self) -> io::Error {
        self.tx = None;
        match self.join() {
            Err(e) => e,
            Ok(()) => io::Error::other("the log writer has stopped"),
        }
    }

    fn join(&mut self) -> io::Result<()> {
        match self.thread.take() {
            Some(thread) => thread
                .join()
                .unwrap_or_else(|_| Err(io::Error::other("the log writer panicked"))),
            None => Ok(()),
        }
    }
}

impl Drop for Spool {
    fn drop(&mut self) {
        self.tx = None;
        if let Err(e) = self.join() {
            tracing::warn!("{}: {e}", self.path.display());
        }
    }
}

/// The writer thread: every batch through one [`Writer`], written out at least once a second,
/// everything written out and synced when the queue closes.
fn write_batches(file: File, rx: &Receiver<Batch>) -> io::Result<()> {
    let mut writer = Writer::new(file);
    loop {
        let wait = writer.flush_deadline().map_or(FLUSH_INTERVAL, |d| {
            d.saturating_duration_since(std::time::Instant::now())
        });
        match rx.recv_timeout(wait) {
            Ok(batch) => {
                let mut from = 0;
                for (ts, end) in batch.parts {
                    let Some(part) = batch.bytes.get(from..end) else {
                        break;
                    };
                    match ts {
                        Some(ts) => writer.write_record(ts, part)?,
                        None => writer.write_raw(part)?,
                    }
                    from = end;
                }
            }
            Err(RecvTimeoutError::Timeout) => {
                writer.flush_if_due()?;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    writer.into_inner()?.sync_data()
}

/// `YYYYmmdd-HHMMSS` of `unix_secs`, in UTC.
fn utc_stamp(unix_secs: u64) -> String {
    let days = unix_secs / 86_400;
    let secs = unix_secs % 86_400;
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        secs / 3600,
        secs / 60 % 60,
        secs % 60
    )
}

/// The proleptic Gregorian date of `days` since 1970-01-01 (H. Hinnant's `civil_from_days`).
const fn civil_from_days(days: u64) -> (u64, u64, u64) {
    let z = days + 719_468;
    let era = z / 146_097;
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + if m <= 2 { 1 } else { 0 };
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_names() {
        assert_eq!(utc_stamp(0), "19700101-000000");
        assert_eq!(utc_stamp(951_782_400), "20000229-000000"); // a leap day
        assert_eq!(utc_stamp(1_709_251_199), "20240229-235959");
        assert_eq!(utc_stamp(1_735_689_600), "20250101-000000");
        assert_eq!(utc_stamp(4_102_444_800), "21000101-000000"); // 2100 is not a leap year
    }

    #[test]
    fn a_full_queue_drops_and_counts() {
        let dir = std::env::temp_dir().join(format!("spool-full-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.raw");
        // A queue nobody reads: the thread is replaced by one that waits for the test.
        let (tx, rx) = sync_channel(1);
        let (go_tx, go_rx) = sync_channel::<()>(0);
        let file = File::create(&path).unwrap();
        let thread = std::thread::spawn(move || {
            let _ = go_rx.recv();
            write_batches(file, &rx)
        });
        let mut spool = Spool {
            path: path.clone(),
            batch: Batch::default(),
            records: 0,
            tx: Some(tx),
            thread: Some(thread),
            dropped: 0,
        };
        spool.push_raw(b"one");
        assert!(spool.send().unwrap());
        spool.push_raw(b"two");
        spool.push_raw(b"three");
        assert!(!spool.send().unwrap(), "the queue holds one batch");
        assert_eq!(spool.dropped(), 2);
        go_tx.send(()).unwrap();
        spool.finish().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"one");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
