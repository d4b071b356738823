//! Frames for the node handed over in batches ([`NodeHandle::subscribe_batched`]): for a
//! reader on a thread of its own (a Python interpreter's) that wants every frame at the
//! lowest cost per frame.
//!
//! ```text
//!  driver turn: Event::Local ─push─► staging FrameBatch (the driver's, no lock)
//!  end of the turn: one lock ─► pending FrameBatch (swapped whole when the reader took the
//!                               last one, else appended) ─► one wake-up if the reader waits
//!  reader: one lock ─► pending swapped whole with its own (emptied) batch
//! ```
//!
//! A batch is one byte arena holding the frames back to back and an index of
//! [`BatchEntry`]s; the three batches (the driver's staging one, the pending one and the
//! reader's) change hands whole, so once they have grown to the stream's burst size nothing
//! is allocated, and a frame's bytes are copied once on the way (into the arena). The reader
//! is woken (a condition variable) only when it waits, once per batch.
//!
//! [`NodeHandle::subscribe_batched`]: super::NodeHandle::subscribe_batched

use core::time::Duration;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use mavstack_channel::Authentication;
use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;
use mavstack_router::{LinkId, LocalFrame};

/// How many frames may wait for a batch reader; a reader that falls further behind loses
/// the newest ones (counted in [`NodeReport::subscriber_drops`](super::NodeReport)).
pub const BATCH_DEPTH: usize = 8192;

/// Where one frame of a [`FrameBatch`] is, and what the node knows of it.
#[derive(Clone, Copy, Debug)]
struct BatchEntry {
    /// Its first byte in the arena.
    start: u32,
    /// Its length.
    len: u16,
    link_id: LinkId,
    auth: Authentication,
    received_at: Instant,
}

/// Frames for the node, back to back in one buffer, with an index (see the module docs).
#[derive(Debug, Default)]
pub struct FrameBatch {
    bytes: Vec<u8>,
    entries: Vec<BatchEntry>,
}

/// One frame of a [`FrameBatch`].
#[derive(Clone, Copy, Debug)]
#[non_exhaustive]
pub struct BatchFrame<'a> {
    /// The router link (one peer of a link) it came from.
    pub link_id: LinkId,
    /// How the link's channel authenticated it.
    pub auth: Authentication,
    /// When its link's channel was handed its bytes.
    pub received_at: Instant,
    /// The whole frame, exactly as received (its checksum checked as the channel does).
    pub bytes: &'a [u8],
}

impl BatchFrame<'_> {
    /// The frame as a view (header, payload, signature).
    #[must_use]
    pub fn view(&self) -> Frame<&[u8]> {
        Frame::new_unchecked(self.bytes)
    }
}

impl FrameBatch {
    /// An empty batch (it allocates nothing until frames are put in).
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

    /// Frame `i`, in the order they were received.
    #[must_use]
    pub fn get(&self, i: usize) -> Option<BatchFrame<'_>> {
        let e = self.entries.get(i)?;
        let start = e.start as usize;
        Some(BatchFrame {
            link_id: e.link_id,
            auth: e.auth,
            received_at: e.received_at,
            bytes: self.bytes.get(start..start + usize::from(e.len))?,
        })
    }

    /// The frames in the order they were received.
    pub fn iter(&self) -> impl Iterator<Item = BatchFrame<'_>> {
        (0..self.len()).filter_map(|i| self.get(i))
    }

    /// Empties it, keeping what it had allocated.
    pub fn clear(&mut self) {
        self.bytes.clear();
        self.entries.clear();
    }

    /// Appends one frame; `false` (nothing appended) when it holds [`BATCH_DEPTH`] frames.
    fn push(&mut self, frame: &LocalFrame<'_>) -> bool {
        self.push_bytes(
            BatchEntry {
                start: 0,
                len: u16::try_from(frame.bytes.len()).unwrap_or(u16::MAX),
                link_id: frame.link,
                auth: frame.auth,
                received_at: frame.received_at,
            },
            frame.bytes,
        )
    }

    fn push_bytes(&mut self, mut entry: BatchEntry, bytes: &[u8]) -> bool {
        let Ok(start) = u32::try_from(self.bytes.len()) else {
            return false;
        };
        if self.entries.len() >= BATCH_DEPTH {
            return false;
        }
        entry.start = start;
        self.bytes.extend_from_slice(bytes);
        self.entries.push(entry);
        true
    }

    /// Appends `other`'s frames while there is room; how many did not fit.
    fn append(&mut self, other: &Self) -> u64 {
        let mut lost = 0;
        for (i, e) in other.entries.iter().enumerate() {
            let start = e.start as usize;
            let fits = other
                .bytes
                .get(start..start + usize::from(e.len))
                .is_some_and(|b| self.push_bytes(*e, b));
            if !fits {
                lost = (other.entries.len() - i) as u64;
                break;
            }
        }
        lost
    }
}

/// What the driver and the reader share.
#[derive(Debug, Default)]
struct Shared {
    state: Mutex<Pending>,
    ready: Condvar,
}

#[derive(Debug, Default)]
struct Pending {
    batch: FrameBatch,
    /// The reader waits on `ready`.
    waiting: bool,
    /// The node has stopped: no frame will come.
    closed: bool,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Pending> {
        // Every update leaves the batch whole: a panic elsewhere cannot break it.
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// What [`BatchSubscription::wait`] found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum BatchWait {
    /// The batch holds frames.
    Frames,
    /// None came in time.
    TimedOut,
    /// The node has stopped and every frame was taken.
    Closed,
}

/// Frames for the node in batches, from [`NodeHandle::subscribe_batched`]: for a thread of
/// its own (it blocks that thread while it waits; never wait on a runtime's thread).
/// Dropping it unsubscribes.
///
/// [`NodeHandle::subscribe_batched`]: super::NodeHandle::subscribe_batched
#[derive(Debug)]
pub struct BatchSubscription {
    shared: Arc<Shared>,
}

impl BatchSubscription {
    /// Empties `batch` and fills it with every frame received since the last call, waiting
    /// up to `timeout` for one when there is none (`Duration::ZERO`: not at all).
    pub fn wait(&mut self, batch: &mut FrameBatch, timeout: Duration) -> BatchWait {
        batch.clear();
        let mut pending = self.shared.lock();
        if pending.batch.is_empty() && !pending.closed && !timeout.is_zero() {
            pending.waiting = true;
            pending = self
                .shared
                .ready
                .wait_timeout_while(pending, timeout, |p| p.batch.is_empty() && !p.closed)
                .unwrap_or_else(PoisonError::into_inner)
                .0;
            pending.waiting = false;
        }
        if !pending.batch.is_empty() {
            core::mem::swap(&mut pending.batch, batch);
            BatchWait::Frames
        } else if pending.closed {
            BatchWait::Closed
        } else {
            BatchWait::TimedOut
        }
    }
}

/// The driver's side of a [`BatchSubscription`]: frames are staged during a turn and
/// published at its end ([`publish`](Self::publish)).
#[derive(Debug)]
pub(super) struct BatchSink {
    shared: Arc<Shared>,
    staging: FrameBatch,
    /// Frames staged in this turn that did not fit.
    lost: u64,
}

impl BatchSink {
    /// A sink and the subscription it feeds.
    pub(super) fn new() -> (Self, BatchSubscription) {
        let shared = Arc::new(Shared::default());
        let sink = Self {
            shared: Arc::clone(&shared),
            staging: FrameBatch::new(),
            lost: 0,
        };
        (sink, BatchSubscription { shared })
    }

    /// Whether its subscription is still held.
    pub(super) fn is_open(&self) -> bool {
        Arc::strong_count(&self.shared) > 1
    }

    /// Stages one frame.
    pub(super) fn push(&mut self, frame: &LocalFrame<'_>) {
        if !self.staging.push(frame) {
            self.lost += 1;
        }
    }

    /// Hands what was staged to the reader, waking it if it waits; how many frames were
    /// lost (the reader was more than [`BATCH_DEPTH`] frames behind).
    pub(super) fn publish(&mut self) -> u64 {
        let mut lost = core::mem::take(&mut self.lost);
        if self.staging.is_empty() {
            return lost;
        }
        let wake = {
            let mut pending = self.shared.lock();
            if pending.batch.is_empty() {
                // The reader took the last batch: this one changes hands whole, and the
                // reader's old one (empty) is staged into next.
                core::mem::swap(&mut pending.batch, &mut self.staging);
            } else {
                lost += pending.batch.append(&self.staging);
            }
            pending.waiting
        };
        self.staging.clear();
        if wake {
            self.shared.ready.notify_one();
        }
        lost
    }
}

impl Drop for BatchSink {
    fn drop(&mut self) {
        let _ = self.publish();
        self.shared.lock().closed = true;
        self.shared.ready.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_channel::{OwnedFrame, ReceivedFrame};
    use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};

    fn received(seq: u8) -> ReceivedFrame {
        let header = FrameHeader {
            version: Version::V2,
            seq,
            sysid: 1,
            compid: 1,
            signed: false,
        };
        let mut buf = [0u8; MAX_FRAME_LEN];
        let hb = mavstack_dialects::common::Heartbeat::default();
        let len = wire::emit_message(&header, &hb, &mut buf).expect("fits");
        ReceivedFrame {
            frame: OwnedFrame::new(&buf[..len]).expect("a frame"),
            received_at: Instant::from_micros(u64::from(seq)),
            auth: Authentication::Unsigned,
            crc_checked: true,
            answered: false,
            protocol_version_request: None,
        }
    }

    /// Stages `frame` from `link` as the driver does, from the router's local frames.
    fn push(sink: &mut BatchSink, link: LinkId, frame: &ReceivedFrame) {
        let mut local = mavstack_router::LocalFrames::new();
        assert!(local.push(link, frame));
        for f in local.iter() {
            sink.push(&f);
        }
    }

    fn seqs(batch: &FrameBatch) -> Vec<u8> {
        batch.iter().map(|f| f.view().seq()).collect()
    }

    #[test]
    fn batches_change_hands_whole_and_keep_order() {
        let (mut sink, mut sub) = BatchSink::new();
        let mut batch = FrameBatch::new();
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::TimedOut);
        for seq in 0..3 {
            push(&mut sink, LinkId::new(2), &received(seq));
        }
        assert_eq!(sink.publish(), 0);
        // A second turn before the reader looked: appended behind the first.
        push(&mut sink, LinkId::new(2), &received(3));
        assert_eq!(sink.publish(), 0);
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::Frames);
        assert_eq!(seqs(&batch), [0, 1, 2, 3]);
        let first = batch.get(0).expect("a frame");
        assert_eq!(first.link_id, LinkId::new(2));
        assert_eq!(first.received_at, Instant::from_micros(0));
        assert_eq!(first.bytes, received(0).frame.as_bytes());
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::TimedOut);
        assert!(batch.is_empty());
        push(&mut sink, LinkId::new(2), &received(4));
        drop(sink);
        // What was staged before the node stopped is still delivered, then the end.
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::Frames);
        assert_eq!(seqs(&batch), [4]);
        assert_eq!(
            sub.wait(&mut batch, Duration::from_secs(5)),
            BatchWait::Closed
        );
    }

    #[test]
    fn a_reader_behind_loses_the_newest_frames_and_they_are_counted() {
        let (mut sink, mut sub) = BatchSink::new();
        let extra = 5;
        for i in 0..BATCH_DEPTH + extra {
            push(&mut sink, LinkId::new(0), &received(i as u8));
        }
        assert_eq!(sink.publish(), extra as u64);
        push(&mut sink, LinkId::new(0), &received(1));
        assert_eq!(sink.publish(), 1, "the pending batch is full");
        let mut batch = FrameBatch::new();
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::Frames);
        assert_eq!(batch.len(), BATCH_DEPTH);
        assert_eq!(
            batch.get(BATCH_DEPTH - 1).map(|f| f.view().seq()),
            Some(((BATCH_DEPTH - 1) % 256) as u8)
        );
    }

    #[test]
    fn a_waiting_reader_is_woken_by_a_batch() {
        let (mut sink, mut sub) = BatchSink::new();
        let reader = std::thread::spawn(move || {
            let mut batch = FrameBatch::new();
            let got = sub.wait(&mut batch, Duration::from_secs(30));
            (got, seqs(&batch))
        });
        // Published only once the reader waits: it must be woken.
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while !sink.shared.lock().waiting {
            assert!(
                std::time::Instant::now() < deadline,
                "the reader never waited"
            );
            std::thread::yield_now();
        }
        push(&mut sink, LinkId::new(0), &received(7));
        assert_eq!(sink.publish(), 0);
        let (got, seqs) = reader.join().expect("the reader ends");
        assert_eq!((got, seqs), (BatchWait::Frames, vec![7]));
        assert!(!sink.is_open(), "the subscription was dropped");
    }
}
