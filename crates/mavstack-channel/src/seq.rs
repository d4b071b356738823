//! Sequence numbers: received, lost and duplicated frames per source.
//!
//! Each sender keeps its own 8-bit counter per link, so loss is counted per
//! (sysid, compid), as mavutil does. For each source, a frame whose sequence number equals
//! the previous one is a duplicate; otherwise the numbers skipped in between (modulo 256)
//! are counted as lost. A frame that arrives late (reordered) therefore counts as a large
//! gap: the counters describe a link that does not reorder, which serial and radio links
//! do not.

/// How many sources a link tracks. Frames of further sources are counted in
/// [`crate::LinkStats::untracked_frames`].
pub const MAX_SOURCES: usize = 32;

/// Sequence statistics of one source.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct SourceStats {
    /// Sender's system id.
    pub sysid: u8,
    /// Sender's component id.
    pub compid: u8,
    /// Frames accepted from the source.
    pub received: u64,
    /// Sequence numbers skipped (frames lost on the way, modulo 256 per gap).
    pub lost: u64,
    /// Frames that repeated the previous sequence number.
    pub duplicates: u64,
    /// The last sequence number seen.
    pub last_seq: u8,
}

/// The per-source table.
#[derive(Clone, Debug)]
pub(crate) struct SeqTable {
    sources: [SourceStats; MAX_SOURCES],
    len: usize,
    pub(crate) untracked: u64,
}

impl SeqTable {
    pub(crate) const fn new() -> Self {
        Self {
            sources: [SourceStats {
                sysid: 0,
                compid: 0,
                received: 0,
                lost: 0,
                duplicates: 0,
                last_seq: 0,
            }; MAX_SOURCES],
            len: 0,
            untracked: 0,
        }
    }

    /// Counts a frame with sequence number `seq` from `(sysid, compid)`.
    pub(crate) fn record(&mut self, sysid: u8, compid: u8, seq: u8) {
        if let Some(s) = self.sources[..self.len]
            .iter_mut()
            .find(|s| s.sysid == sysid && s.compid == compid)
        {
            match seq.wrapping_sub(s.last_seq) {
                0 => s.duplicates += 1,
                gap => s.lost += u64::from(gap - 1),
            }
            s.received += 1;
            s.last_seq = seq;
            return;
        }
        if self.len == MAX_SOURCES {
            self.untracked += 1;
            return;
        }
        self.sources[self.len] = SourceStats {
            sysid,
            compid,
            received: 1,
            lost: 0,
            duplicates: 0,
            last_seq: seq,
        };
        self.len += 1;
    }

    pub(crate) fn sources(&self) -> &[SourceStats] {
        &self.sources[..self.len]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaps_wrap_modulo_256_and_repeats_are_duplicates() {
        let mut t = SeqTable::new();
        for seq in [250, 251, 253, 253, 2, 3] {
            t.record(1, 1, seq);
        }
        t.record(2, 1, 9);
        let s = t.sources()[0];
        assert_eq!(
            (s.received, s.lost, s.duplicates, s.last_seq),
            (6, 1 + 4, 1, 3)
        );
        assert_eq!(t.sources()[1].received, 1);
    }

    #[test]
    fn sources_beyond_capacity_are_counted_untracked() {
        let mut t = SeqTable::new();
        for id in 0..=u8::try_from(MAX_SOURCES).unwrap() {
            t.record(id, 1, 0);
        }
        assert_eq!((t.sources().len(), t.untracked), (MAX_SOURCES, 1));
    }
}
