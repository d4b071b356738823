//! The simulated vehicle's logs, served by log download (LOG_*) and over MAVFTP.
//!
//! With a [`LogDir`] ([`SimConfig::log_dir`](crate::SimConfig::log_dir), `mavstack vehicle
//! --log-dir DIR`) the logs are the directory's files, numbered from 1 in name order; over
//! MAVFTP they are `APM/LOGS/00000001.BIN`, ... as on ArduPilot. Without one the vehicle has
//! [`GENERATED`] logs: pseudo-random bytes made from each log's id
//! ([`generated_log`]), so that a download works out of the box and can be checked.
//!
//! LOG_ERASE makes the vehicle forget its logs (both views): the files on disk stay.

use core::sync::atomic::{AtomicBool, Ordering};
use std::fs::File;
use std::io::{self, Read as _, Seek as _, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::UNIX_EPOCH;

use mavstack_services::ftp::overlay::{dir_entry, file_entry};
use mavstack_services::ftp::{BackendError, DirEntry, Provider};
use mavstack_services::log_transfer::{LogInfo, LogStore, StoreError};

/// The generated logs of a vehicle without a [`LogDir`]: (id, time_utc, size).
pub const GENERATED: [(u16, u32, u32); 2] =
    [(1, 1_700_000_000, 300_000), (2, 1_700_003_600, 123_457)];

/// Where MAVFTP shows the logs of a [`LogDir`], as ArduPilot keeps them.
pub const FTP_DIR: &str = "APM/LOGS";

/// The MAVFTP path (from the root, without a leading `/`) of log `id`:
/// `APM/LOGS/00000001.BIN` for 1.
#[must_use]
pub fn ftp_path(id: u16) -> String {
    format!("{FTP_DIR}/{}", ftp_name(id))
}

fn ftp_name(id: u16) -> String {
    format!("{id:08}.BIN")
}

/// Eight pseudo-random bytes of a generated log (SplitMix64 of the id and the position).
fn block(id: u16, index: u64) -> [u8; 8] {
    let mut z = (u64::from(id) << 48 ^ index).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    (z ^ (z >> 31)).to_le_bytes()
}

/// The bytes of generated log `id` from `offset` into `buf` (as many as fit before its end).
fn generated_read(id: u16, size: u32, offset: u32, buf: &mut [u8]) -> usize {
    let n = (size.saturating_sub(offset) as usize).min(buf.len());
    for (i, b) in buf[..n].iter_mut().enumerate() {
        let at = u64::from(offset) + i as u64;
        *b = block(id, at / 8)[(at % 8) as usize];
    }
    n
}

/// Generated log `id`'s bytes ([`GENERATED`]), or `None` for an id it does not have.
#[must_use]
pub fn generated_log(id: u16) -> Option<Vec<u8>> {
    let &(_, _, size) = GENERATED.iter().find(|g| g.0 == id)?;
    let mut bytes = vec![0; size as usize];
    generated_read(id, size, 0, &mut bytes);
    Some(bytes)
}

#[derive(Clone, Debug, PartialEq, Eq)]
struct LogFile {
    path: PathBuf,
    size: u32,
    time_utc: u32,
}

/// The files of a directory as logs: every regular file (not hidden, below 4 GiB: the
/// protocol's sizes are 32 bits), numbered from 1 in name order, with its modification
/// time. The list is read once, by [`LogDir::new`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogDir {
    root: PathBuf,
    files: Vec<LogFile>,
}

impl LogDir {
    /// The files of `dir`.
    ///
    /// # Errors
    ///
    /// When `dir` cannot be read, or holds more than 65,535 files.
    pub fn new(dir: impl AsRef<Path>) -> io::Result<Self> {
        let root = dir.as_ref().to_path_buf();
        let mut named = Vec::new();
        for entry in std::fs::read_dir(&root)? {
            let entry = entry?;
            let name = entry.file_name();
            if name.to_string_lossy().starts_with('.') {
                continue;
            }
            // Following symbolic links: a link to a log is a log.
            let Ok(meta) = std::fs::metadata(entry.path()) else {
                continue;
            };
            let Ok(size) = u32::try_from(meta.len()) else {
                continue;
            };
            if !meta.is_file() {
                continue;
            }
            let time_utc = meta
                .modified()
                .ok()
                .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
                .and_then(|d| u32::try_from(d.as_secs()).ok())
                .unwrap_or(0);
            named.push((
                name,
                LogFile {
                    path: entry.path(),
                    size,
                    time_utc,
                },
            ));
        }
        if named.len() > usize::from(u16::MAX) {
            return Err(io::Error::other(format!(
                "{} files: log ids go to 65535",
                named.len()
            )));
        }
        named.sort_by(|a, b| a.0.cmp(&b.0));
        Ok(Self {
            root,
            files: named.into_iter().map(|(_, f)| f).collect(),
        })
    }

    /// The directory.
    #[must_use]
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The logs: id (from 1), time and size.
    #[must_use]
    pub fn logs(&self) -> Vec<LogInfo> {
        self.files
            .iter()
            .zip(1u16..)
            .map(|(f, id)| LogInfo {
                id,
                time_utc: f.time_utc,
                size: f.size,
            })
            .collect()
    }

    /// The file of log `id`.
    #[must_use]
    pub fn path(&self, id: u16) -> Option<&Path> {
        let index = usize::from(id).checked_sub(1)?;
        self.files.get(index).map(|f| f.path.as_path())
    }
}

/// Whether the logs were erased, shared by the two views of them.
type Erased = Arc<AtomicBool>;

/// The vehicle's logs for its [`LogServer`](mavstack_services::log_transfer::LogServer).
#[derive(Debug)]
pub(crate) struct SimLogs {
    dir: Option<LogDir>,
    erased: Erased,
    /// The file read last, kept open.
    open: Option<(u16, File)>,
}

impl SimLogs {
    /// The logs of `dir`, or the generated ones.
    pub(crate) fn new(dir: Option<LogDir>) -> Self {
        Self {
            dir,
            erased: Erased::default(),
            open: None,
        }
    }

    /// Their MAVFTP view (a [`LogDir`]'s files; none for generated logs).
    pub(crate) fn ftp_view(&self) -> LogFiles {
        LogFiles {
            dir: self.dir.clone(),
            erased: Arc::clone(&self.erased),
        }
    }

    fn erased(&self) -> bool {
        self.erased.load(Ordering::Relaxed)
    }

    fn read_file(&mut self, id: u16, offset: u32, buf: &mut [u8]) -> Result<usize, StoreError> {
        let dir = self.dir.as_ref().ok_or(StoreError::NoSuchLog)?;
        let path = dir.path(id).ok_or(StoreError::NoSuchLog)?;
        let file = match &mut self.open {
            Some((open_id, file)) if *open_id == id => file,
            _ => {
                let file = File::open(path).map_err(|_| StoreError::Unreadable)?;
                &mut self.open.insert((id, file)).1
            }
        };
        file.seek(SeekFrom::Start(u64::from(offset)))
            .map_err(|_| StoreError::Unreadable)?;
        let mut n = 0;
        while n < buf.len() {
            match file.read(&mut buf[n..]) {
                Ok(0) => break,
                Ok(k) => n += k,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(_) => return Err(StoreError::Unreadable),
            }
        }
        Ok(n)
    }
}

impl LogStore for SimLogs {
    fn logs(&mut self) -> Vec<LogInfo> {
        if self.erased() {
            return Vec::new();
        }
        match &self.dir {
            Some(dir) => dir.logs(),
            None => GENERATED
                .iter()
                .map(|&(id, time_utc, size)| LogInfo { id, time_utc, size })
                .collect(),
        }
    }

    fn read(&mut self, id: u16, offset: u32, buf: &mut [u8]) -> Result<usize, StoreError> {
        if self.erased() {
            return Err(StoreError::NoSuchLog);
        }
        if self.dir.is_some() {
            return self.read_file(id, offset, buf);
        }
        let &(_, _, size) = GENERATED
            .iter()
            .find(|g| g.0 == id)
            .ok_or(StoreError::NoSuchLog)?;
        Ok(generated_read(id, size, offset, buf))
    }

    fn erase(&mut self) {
        self.erased.store(true, Ordering::Relaxed);
        self.open = None;
    }
}

/// A [`LogDir`]'s files over MAVFTP, read-only: `APM/LOGS/00000001.BIN`, ... (a
/// [`Provider`] of virtual files: each file is read whole when a client opens it).
#[derive(Debug)]
pub(crate) struct LogFiles {
    dir: Option<LogDir>,
    erased: Erased,
}

impl LogFiles {
    fn shown(&self) -> Option<&LogDir> {
        self.dir
            .as_ref()
            .filter(|d| !d.files.is_empty() && !self.erased.load(Ordering::Relaxed))
    }

    /// The log id a path names: `APM/LOGS/00000001.BIN` is 1.
    fn id_of(&self, path: &str) -> Option<u16> {
        let dir = self.shown()?;
        let name = path.strip_prefix(FTP_DIR)?.strip_prefix('/')?;
        let id = name.strip_suffix(".BIN")?;
        if id.len() != 8 || !id.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        let id: u16 = id.parse().ok()?;
        dir.path(id).is_some().then_some(id)
    }
}

impl Provider for LogFiles {
    fn provides(&self, path: &str) -> bool {
        self.id_of(path).is_some()
    }

    fn contents(&mut self, path: &str) -> Result<Vec<u8>, BackendError> {
        let file = self
            .id_of(path)
            .and_then(|id| self.shown()?.path(id))
            .ok_or(BackendError::NotFound)?;
        std::fs::read(file).map_err(|e| match e.kind() {
            io::ErrorKind::NotFound => BackendError::NotFound,
            _ => BackendError::Fail,
        })
    }

    fn entries(&mut self, dir: &str) -> Vec<DirEntry> {
        let Some(logs) = self.shown() else {
            return Vec::new();
        };
        let (apm, sub) = FTP_DIR.split_once('/').unwrap_or((FTP_DIR, ""));
        match dir {
            "" => vec![dir_entry(apm)],
            d if d == apm => vec![dir_entry(sub)],
            d if d == FTP_DIR => logs
                .logs()
                .iter()
                .map(|l| file_entry(&ftp_name(l.id), l.size as usize))
                .collect(),
            _ => Vec::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_logs_are_the_same_every_time_and_differ_by_id() {
        let one = generated_log(1).unwrap();
        assert_eq!(one.len(), 300_000);
        assert_eq!(one, generated_log(1).unwrap());
        let two = generated_log(2).unwrap();
        assert_eq!(two.len(), 123_457);
        assert_ne!(one[..1000], two[..1000]);
        assert_eq!(generated_log(3), None);
        // Read at any offset, the same bytes.
        let mut logs = SimLogs::new(None);
        let mut buf = [0u8; 90];
        assert_eq!(logs.read(2, 123_400, &mut buf), Ok(57));
        assert_eq!(&buf[..57], &two[123_400..]);
        assert_eq!(logs.read(2, 123_457, &mut buf), Ok(0));
        assert_eq!(logs.read(2, u32::MAX, &mut buf), Ok(0));
        assert_eq!(logs.read(3, 0, &mut buf), Err(StoreError::NoSuchLog));
    }

    #[test]
    fn a_directory_is_numbered_in_name_order_and_erase_hides_both_views() {
        let dir = tempfile::tempdir().unwrap();
        for (name, n) in [
            ("b.bin", 91usize),
            ("a.bin", 1),
            (".hidden", 5),
            ("c.bin", 90),
        ] {
            std::fs::write(dir.path().join(name), vec![n as u8; n]).unwrap();
        }
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        let logs_dir = LogDir::new(dir.path()).unwrap();
        let sizes: Vec<(u16, u32)> = logs_dir.logs().iter().map(|l| (l.id, l.size)).collect();
        assert_eq!(sizes, [(1, 1), (2, 91), (3, 90)]);
        let mut logs = SimLogs::new(Some(logs_dir));
        let mut ftp = logs.ftp_view();
        let mut buf = [0u8; 90];
        assert_eq!(logs.read(2, 45, &mut buf), Ok(46));
        assert_eq!(&buf[..46], &[91u8; 46][..]);
        assert_eq!(logs.read(3, 0, &mut buf), Ok(90));
        assert_eq!(logs.read(4, 0, &mut buf), Err(StoreError::NoSuchLog));
        assert!(ftp.provides("APM/LOGS/00000002.BIN"));
        assert!(!ftp.provides("APM/LOGS/00000004.BIN"));
        assert!(!ftp.provides("APM/LOGS/2.BIN"));
        assert_eq!(ftp.contents("APM/LOGS/00000001.BIN"), Ok(vec![1]));
        let names = |e: Vec<DirEntry>| e.into_iter().map(|e| e.name).collect::<Vec<_>>();
        assert_eq!(names(ftp.entries("")), ["APM"]);
        assert_eq!(names(ftp.entries("APM")), ["LOGS"]);
        assert_eq!(
            names(ftp.entries("APM/LOGS")),
            ["00000001.BIN", "00000002.BIN", "00000003.BIN"]
        );
        logs.erase();
        assert!(logs.logs().is_empty());
        assert_eq!(logs.read(1, 0, &mut buf), Err(StoreError::NoSuchLog));
        assert!(!ftp.provides("APM/LOGS/00000001.BIN"));
        assert!(ftp.entries("").is_empty());
        assert!(dir.path().join("a.bin").exists(), "the files stay");
    }
}
