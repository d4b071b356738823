//! The client's transfer states, as types: an upload's and a download's phases, each
//! consumed by value as the transfer moves on.

use alloc::vec::Vec;

use mavstack_core::time::Instant;
use mavstack_dialects::common::MissionItemInt;

/// An upload's phase.
#[derive(Debug)]
pub enum Upload {
    /// MISSION_COUNT (or the last item) sent; waiting for a request for item `next`.
    AwaitingRequest(AwaitingRequest),
    /// Every item sent; waiting for MISSION_ACK.
    AwaitingAck(AwaitingAck),
}

/// Waiting for the vehicle to request an item.
#[derive(Debug)]
pub struct AwaitingRequest {
    pub(super) items: Vec<MissionItemInt>,
    /// The last item sent (`None`: only MISSION_COUNT so far); with a window, the last item
    /// the vehicle asked for (it holds every item before it).
    pub(super) last: Option<u16>,
    pub(super) attempts: u8,
    pub(super) deadline: Instant,
    /// With a window: the next item to send (those from `last` up to it are on their way).
    pub(super) send_next: u16,
    /// With a window: how many items have gone out at least once.
    pub(super) sent_ever: u16,
    /// With a window: the item the window last went back to on a sign of loss (a repeated
    /// request or an INVALID_SEQUENCE), so that one loss makes one resend.
    pub(super) went_back: Option<u16>,
    /// Until when a vehicle that refuses to start the upload as busy is asked again (set at
    /// its first such refusal).
    pub(super) busy_until: Option<Instant>,
}

/// Waiting for the final MISSION_ACK.
#[derive(Debug)]
pub struct AwaitingAck {
    pub(super) items: Vec<MissionItemInt>,
    /// The last item sent (`None`: only MISSION_COUNT so far).
    pub(super) last: Option<u16>,
    pub(super) attempts: u8,
    pub(super) deadline: Instant,
}

/// A download's phase.
#[derive(Debug)]
pub enum Download {
    /// MISSION_REQUEST_LIST sent.
    AwaitingCount(AwaitingCount),
    /// Items `0..seq` received; item `seq` (and, with a window, the next few) requested.
    AwaitingItem(AwaitingItem),
}

/// Waiting for MISSION_COUNT.
#[derive(Debug)]
pub struct AwaitingCount {
    /// The first item to download (0: the whole plan).
    pub(super) first: u16,
    pub(super) attempts: u8,
    pub(super) deadline: Instant,
}

/// Waiting for item `seq`, the first not received yet.
#[derive(Debug)]
pub struct AwaitingItem {
    /// The first item not received (the items from the first asked for up to it are in).
    pub seq: u16,
    pub(super) count: u16,
    pub(super) items: Vec<MissionItemInt>,
    /// Items after `seq` that came before it (a windowed download; fewer than the window).
    pub(super) ahead: Vec<MissionItemInt>,
    /// The first item not requested yet (`seq + 1` without a window).
    pub(super) next: u16,
    /// With a window: every item before it that had not come when a later one came was asked
    /// for again then (the vehicle answers in order: its request or answer was lost). Each
    /// item is asked for so at most once; the timeout asks again after that.
    pub(super) asked_again: u16,
    pub(super) attempts: u8,
    pub(super) deadline: Instant,
}

impl AwaitingRequest {
    /// `last` sent (or only the count, `None`): the window starts after it.
    pub(super) fn new(
        items: Vec<MissionItemInt>,
        last: Option<u16>,
        attempts: u8,
        deadline: Instant,
    ) -> Self {
        let next = last.map_or(0, |l| l.saturating_add(1));
        Self {
            items,
            last,
            attempts,
            deadline,
            send_next: next,
            sent_ever: next,
            went_back: None,
            busy_until: None,
        }
    }

    /// How many items the upload has.
    #[must_use]
    pub fn count(&self) -> usize {
        self.items.len()
    }

    /// How many items have gone out (the vehicle asked for them).
    #[must_use]
    pub fn sent(&self) -> usize {
        self.last.map_or(0, |l| usize::from(l) + 1)
    }

    /// Whether the vehicle refused to start the upload as busy (another transfer open) and
    /// is being asked again (see [`BUSY_WAIT`](super::BUSY_WAIT)).
    #[must_use]
    pub fn refused_as_busy(&self) -> bool {
        self.busy_until.is_some()
    }
}

impl AwaitingAck {
    /// How many items the upload has (all sent).
    #[must_use]
    pub fn count(&self) -> usize {
        self.items.len()
    }
}

impl AwaitingItem {
    /// How many items the plan has.
    #[must_use]
    pub fn count(&self) -> u16 {
        self.count
    }
}
