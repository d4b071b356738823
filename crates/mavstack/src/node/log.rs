//! The traffic log (`NodeBuilder::log_dir`): every frame the node accepts goes through a
//! bounded queue to the log's own writer thread ([`tlog::Spool`]), never to the disk from the
//! forwarding loop. Frames that do not fit in the queue are dropped from the log (they are
//! still forwarded) and counted per link, as `log_full` in its `dropped`.

use std::path::Path;

use mavstack_transport::{clock, tlog};

use super::NodeError;

/// A node's open traffic log.
#[derive(Debug)]
pub(super) struct TrafficLog {
    spool: tlog::Spool,
    /// Records of the batch being gathered, per configured link (the last entry: frames of a
    /// router link no configured link owns any more).
    pending: Vec<u64>,
    /// Records dropped from the log, per configured link (the same indices).
    dropped: Vec<u64>,
}

impl TrafficLog {
    /// A new log in `dir` named by the start time (`mavstack-YYYYmmdd-HHMMSS.tlog` in UTC,
    /// `-N` added when a log of the same second exists), for a node of `links` links.
    pub(super) fn open(dir: &Path, links: usize) -> Result<Self, NodeError> {
        let secs = clock::now().as_micros() / 1_000_000;
        let spool = tlog::Spool::create_in(dir, secs).map_err(|source| NodeError::Log {
            path: dir.to_owned(),
            source,
        })?;
        tracing::info!("logging to {}", spool.path().display());
        Ok(Self {
            spool,
            pending: vec![0; links + 1],
            dropped: vec![0; links + 1],
        })
    }

    /// Adds a frame that arrived on configured link `slot` (`None`: one no longer known) at
    /// `received_us`, with the link number in the timestamp's low two bits as MAVProxy does
    /// (0, 1, 2 for the first three links, 2 for the rest).
    pub(super) fn push(&mut self, slot: Option<usize>, received_us: u64, frame: &[u8]) {
        let bits = slot.map_or(2, |s| s.min(2)) as u64;
        self.spool.push_record((received_us & !3) | bits, frame);
        let i = slot.map_or(self.pending.len() - 1, |s| s.min(self.pending.len() - 1));
        self.pending[i] += 1;
    }

    /// Hands what was added to the writer thread, without waiting.
    ///
    /// # Errors
    /// [`NodeError::Log`]: the writer thread stopped on a write error (a full disk, a
    /// removed medium).
    pub(super) fn send(&mut self) -> Result<(), NodeError> {
        let sent = self.spool.send().map_err(|source| self.error(source))?;
        for (pending, dropped) in self.pending.iter_mut().zip(&mut self.dropped) {
            if !sent {
                *dropped += *pending;
            }
            *pending = 0;
        }
        Ok(())
    }

    /// Frames of configured link `slot` dropped from the log.
    pub(super) fn dropped(&self, slot: usize) -> u64 {
        self.dropped.get(slot).copied().unwrap_or(0)
    }

    /// Writes everything out and syncs the file (blocks until the writer thread is done).
    ///
    /// # Errors
    /// [`NodeError::Log`] naming the file.
    pub(super) fn finish(mut self) -> Result<(), NodeError> {
        self.send()?;
        let path = self.spool.path().to_owned();
        self.spool
            .finish()
            .map_err(|source| NodeError::Log { path, source })
    }

    fn error(&self, source: std::io::Error) -> NodeError {
        NodeError::Log {
            path: self.spool.path().to_owned(),
            source,
        }
    }
}
