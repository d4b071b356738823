//! Frames for the router's own component ([`RouterConfig::local`](crate::RouterConfig)),
//! kept back to back in one buffer until the caller takes them
//! ([`Router::take_local`](crate::Router::take_local)).
//!
//! A frame's bytes are copied once, from the channel's event into the buffer, and only as
//! many as the frame has; what the channel knew of it is kept beside, in an index. Taking
//! swaps the caller's (emptied) [`LocalFrames`] with the router's, so once both have grown
//! to the burst size nothing is allocated. The same type carries frames further, whole, from
//! one thread to another (the `mavstack` node's batch subscriptions).

use alloc::vec::Vec;

use mavstack_channel::{Authentication, OwnedFrame, ProtocolVersionAnswer, ReceivedFrame};
use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;

use crate::router::LinkId;

/// How many frames a [`LocalFrames`] holds: more waiting for
/// [`Router::take_local`](crate::Router::take_local) are dropped and counted
/// ([`Router::events_dropped`](crate::Router::events_dropped)).
pub const LOCAL_CAPACITY: usize = 8192;

/// What the router knows of one local frame, and where its bytes are.
#[derive(Clone, Copy, Debug)]
struct Entry {
    start: u32,
    len: u16,
    link: LinkId,
    received_at: Instant,
    auth: Authentication,
    crc_checked: bool,
    answered: bool,
    protocol_version_request: Option<ProtocolVersionAnswer>,
}

/// Frames for the router's own component, in the order they were accepted.
#[derive(Debug, Default)]
pub struct LocalFrames {
    bytes: Vec<u8>,
    entries: Vec<Entry>,
}

/// One frame of [`LocalFrames`]: the fields of the channel's [`ReceivedFrame`] and the
/// link it came from, its bytes borrowed.
#[derive(Clone, Copy, Debug)]
#[non_exhaustive]
pub struct LocalFrame<'a> {
    /// The link it came from.
    pub link: LinkId,
    /// When its link's channel was handed its bytes.
    pub received_at: Instant,
    /// How the channel authenticated it.
    pub auth: Authentication,
    /// As [`ReceivedFrame::crc_checked`].
    pub crc_checked: bool,
    /// As [`ReceivedFrame::answered`].
    pub answered: bool,
    /// As [`ReceivedFrame::protocol_version_request`].
    pub protocol_version_request: Option<ProtocolVersionAnswer>,
    /// The whole frame, exactly as received.
    pub bytes: &'a [u8],
}

impl LocalFrame<'_> {
    /// The frame as a view (header, payload, signature).
    #[must_use]
    pub fn view(&self) -> Frame<&[u8]> {
        Frame::new_unchecked(self.bytes)
    }

    /// The frame as the channel gave it (a copy of its bytes).
    #[must_use]
    pub fn to_received(&self) -> Option<ReceivedFrame> {
        Some(ReceivedFrame {
            frame: OwnedFrame::new(self.bytes).ok()?,
            received_at: self.received_at,
            auth: self.auth,
            crc_checked: self.crc_checked,
            answered: self.answered,
            protocol_version_request: self.protocol_version_request,
        })
    }
}

impl LocalFrames {
    /// None (it allocates nothing until frames are put in).
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// How many frames it holds.
    #[must_use]
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether it holds no frame.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Frame `i`, in the order they were accepted.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<LocalFrame<'_>> {
        let e = self.entries.get(i)?;
        let start = e.start as usize;
        Some(LocalFrame {
            link: e.link,
            received_at: e.received_at,
            auth: e.auth,
            crc_checked: e.crc_checked,
            answered: e.answered,
            protocol_version_request: e.protocol_version_request,
            bytes: self.bytes.get(start..start + usize::from(e.len))?,
        })
    }

    /// The frames in the order they were accepted.
    pub fn iter(&self) -> impl Iterator<Item = LocalFrame<'_>> {
        (0..self.len()).filter_map(|i| self.get(i))
    }

    /// Empties it, keeping what it had allocated.
    pub fn clear(&mut self) {
        self.bytes.clear();
        self.entries.clear();
    }

    /// Appends `frame` from `link`; `false` (nothing appended) when it holds
    /// [`LOCAL_CAPACITY`] frames.
    pub fn push(&mut self, link: LinkId, frame: &ReceivedFrame) -> bool {
        self.push_frame(&LocalFrame {
            link,
            received_at: frame.received_at,
            auth: frame.auth,
            crc_checked: frame.crc_checked,
            answered: frame.answered,
            protocol_version_request: frame.protocol_version_request,
            bytes: frame.frame.as_bytes(),
        })
    }

    /// Appends a copy of `frame` (of another [`LocalFrames`]); `false` (nothing appended)
    /// when it holds [`LOCAL_CAPACITY`] frames.
    pub fn push_frame(&mut self, frame: &LocalFrame<'_>) -> bool {
        let (Ok(start), Ok(len)) = (
            u32::try_from(self.bytes.len()),
            u16::try_from(frame.bytes.len()),
        ) else {
            return false;
        };
        if self.entries.len() >= LOCAL_CAPACITY {
            return false;
        }
        self.bytes.extend_from_slice(frame.bytes);
        self.entries.push(Entry {
            start,
            len,
            link: frame.link,
            received_at: frame.received_at,
            auth: frame.auth,
            crc_checked: frame.crc_checked,
            answered: frame.answered,
            protocol_version_request: frame.protocol_version_request,
        });
        true
    }

    /// Appends `other`'s frames while there is room; how many did not fit.
    pub fn append(&mut self, other: &Self) -> u64 {
        let fits = other.iter().take_while(|f| self.push_frame(f)).count();
        (other.len() - fits) as u64
    }
}
