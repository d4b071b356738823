//! Who may become a peer of a UDP link. A datagram from a source the link does not know yet
//! makes it a peer only if it holds at least one MAVLink frame with a good checksum (by the
//! dialect's CRC_EXTRA, when the link was given one: [`super::Link::admit_peers`]), and a link
//! has at most `max_peers` learned peers: at the limit, the peer quiet the longest makes room
//! if it has been quiet for [`IDLE_AFTER`]; when none has, the new source is refused, counted
//! in [`super::LinkStats::peers_refused`] and logged (a warning at most every
//! [`LOG_EVERY`]). Anyone who can reach the port cannot grow the link's state without bound.

use core::time::Duration;
use std::sync::Arc;

use mavstack_core::parse::{CrcExtra, Item, SliceParser};
use mavstack_core::time::Instant;

/// How many peers a UDP link keeps at most unless told otherwise (the `max_peers` link
/// option's default).
pub(super) const DEFAULT_MAX_PEERS: usize = 64;

/// A peer quiet this long may make room for a new one when the link is full (three missed
/// HEARTBEATs of a component that sends one a second).
pub(super) const IDLE_AFTER: Duration = Duration::from_secs(3);

/// At most one warning about refused sources per link this often.
pub(super) const LOG_EVERY: Duration = Duration::from_secs(10);

/// The admission rules of one UDP link.
pub(super) struct Admission {
    /// Most learned peers at once.
    pub(super) max_peers: usize,
    /// CRC_EXTRA lookup a new source's first datagram is checked with; `None`: any datagram.
    lookup: Option<Arc<dyn CrcExtra + Send + Sync>>,
    /// The link's name, for the log.
    name: String,
    /// Refusals since the last warning, and when that went out.
    unlogged: u64,
    logged_at: Option<Instant>,
}

impl core::fmt::Debug for Admission {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Admission")
            .field("max_peers", &self.max_peers)
            .field("checks_frames", &self.lookup.is_some())
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

impl Default for Admission {
    fn default() -> Self {
        Self::new("udp".to_owned(), DEFAULT_MAX_PEERS, None)
    }
}

impl Admission {
    pub(super) fn new(
        name: String,
        max_peers: usize,
        lookup: Option<Arc<dyn CrcExtra + Send + Sync>>,
    ) -> Self {
        Self {
            max_peers: max_peers.max(1),
            lookup,
            name,
            unlogged: 0,
            logged_at: None,
        }
    }

    /// Whether `data`, the first datagram of an unknown source, may make it a peer: it holds
    /// a frame of a message the dialect knows with a good checksum (anything, without a
    /// dialect).
    pub(super) fn holds_frame(&self, data: &[u8]) -> bool {
        let Some(lookup) = &self.lookup else {
            return true;
        };
        let crc = |id: u32| lookup.crc_extra(id);
        SliceParser::new(data, crc).any(|item| matches!(item, Item::Frame(_)))
    }

    /// A new source was refused at `now`: warns at once, then at most every [`LOG_EVERY`].
    pub(super) fn refused(&mut self, now: Instant, refused_in_all: u64) {
        self.unlogged += 1;
        if self
            .logged_at
            .is_some_and(|t| now.saturating_duration_since(t) < LOG_EVERY)
        {
            return;
        }
        tracing::warn!(
            "{}: {} new source(s) refused: {} peers (max_peers), none quiet for {} s \
             ({refused_in_all} refused in all)",
            self.name,
            self.unlogged,
            self.max_peers,
            IDLE_AFTER.as_secs()
        );
        self.unlogged = 0;
        self.logged_at = Some(now);
    }
}
