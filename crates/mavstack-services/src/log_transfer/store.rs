//! Where a [`LogServer`](super::LogServer) takes its logs from: the [`LogStore`] trait and
//! [`MemoryLogs`].

use alloc::vec::Vec;

use super::LogInfo;

/// Why a [`LogStore`] could not read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum StoreError {
    /// No log has this id.
    #[error("no such log")]
    NoSuchLog,
    /// The log could not be read (a file gone, an I/O error).
    #[error("log unreadable")]
    Unreadable,
}

/// The logs a [`LogServer`](super::LogServer) serves.
pub trait LogStore {
    /// The logs there are, in increasing id order, each id once.
    fn logs(&mut self) -> Vec<LogInfo>;

    /// Reads log `id` from `offset` into `buf`: the number of bytes read, fewer than
    /// `buf.len()` only at the end of the log (0 at or beyond it).
    ///
    /// # Errors
    ///
    /// [`StoreError`] when the log is not there or cannot be read.
    fn read(&mut self, id: u16, offset: u32, buf: &mut [u8]) -> Result<usize, StoreError>;

    /// Erases every log (LOG_ERASE).
    fn erase(&mut self);
}

/// Logs held in memory.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MemoryLogs {
    logs: Vec<(LogInfo, Vec<u8>)>,
}

impl MemoryLogs {
    /// No logs.
    #[must_use]
    pub const fn new() -> Self {
        Self { logs: Vec::new() }
    }

    /// Adds (or replaces) log `id` with `bytes`, started at `time_utc`. Returns false, and
    /// adds nothing, for a log of 4 GiB or more (LOG_ENTRY's size is 32 bits).
    pub fn insert(&mut self, id: u16, time_utc: u32, bytes: &[u8]) -> bool {
        let Ok(size) = u32::try_from(bytes.len()) else {
            return false;
        };
        let info = LogInfo { id, time_utc, size };
        match self.logs.binary_search_by_key(&id, |(i, _)| i.id) {
            Ok(at) => self.logs[at] = (info, bytes.to_vec()),
            Err(at) => self.logs.insert(at, (info, bytes.to_vec())),
        }
        true
    }

    /// Log `id`'s bytes.
    #[must_use]
    pub fn bytes(&self, id: u16) -> Option<&[u8]> {
        self.logs
            .iter()
            .find(|(i, _)| i.id == id)
            .map(|(_, b)| b.as_slice())
    }

    /// How many logs there are.
    #[must_use]
    pub fn len(&self) -> usize {
        self.logs.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.logs.is_empty()
    }
}

impl LogStore for MemoryLogs {
    fn logs(&mut self) -> Vec<LogInfo> {
        self.logs.iter().map(|(i, _)| *i).collect()
    }

    fn read(&mut self, id: u16, offset: u32, buf: &mut [u8]) -> Result<usize, StoreError> {
        let bytes = self.bytes(id).ok_or(StoreError::NoSuchLog)?;
        let rest = usize::try_from(offset)
            .ok()
            .and_then(|o| bytes.get(o..))
            .unwrap_or(&[]);
        let n = rest.len().min(buf.len());
        buf[..n].copy_from_slice(&rest[..n]);
        Ok(n)
    }

    fn erase(&mut self) {
        self.logs.clear();
    }
}
