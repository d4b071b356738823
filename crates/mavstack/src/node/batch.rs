//! Frames for the node handed over in batches ([`NodeHandle::subscribe_batched`]): for a
//! reader on a thread of its own (a Python interpreter's) that wants every frame at the
//! lowest cost per frame.
//!
//! ```text
//!  driver turn: the router's LocalFrames ─────► staging FrameBatch (the driver's, no lock;
//!               swapped whole for a lone reader, else copied)
//!  end of the turn: one lock ─► pending FrameBatch (swapped whole when the reader took the
//!                               last one, else appended) ─► one wake-up if the reader waits
//!  reader: one lock ─► pending swapped whole with its own (emptied) batch
//! ```
//!
//! A batch is the router's [`LocalFrames`]: one byte arena holding the frames back to back
//! and an index. The batches (the router's, the driver's staging one, the pending one and the
//! reader's) change hands whole, so once they have grown to the stream's burst size nothing
//! is allocated, and for a lone reader a frame's bytes are copied once on the way (into the
//! router's arena; once more into the staging one when other readers share it). The reader
//! is woken (a condition variable) only when it waits, once per batch.
//!
//! A reader that waits while the node's thread waits too would be woken only after that
//! thread was, and then by it: two wake-ups one after the other, each slow when its
//! processor sleeps (100 µs and more on a virtual machine). So while the node's input is
//! sparse (under 300 datagrams a second, see `moderation`; on Linux, with the node on a thread
//! of its own), such a reader waits on the node thread's own poll instead ([`NodeInput`]), is
//! woken by the same datagram beside that thread, and looks for the batch that thread is
//! about to publish for a while ([`NodeInput::SPIN`]) before it waits as before. That costs
//! the reader's processor the time between the two wake-ups for each sparse datagram, 5 % of
//! a processor at most ([`SpinBudget`]).
//!
//! [`NodeHandle::subscribe_batched`]: super::NodeHandle::subscribe_batched

#[cfg(target_os = "linux")]
use core::sync::atomic::{AtomicU64, Ordering};
use core::time::Duration;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use mavstack_router::local::LOCAL_CAPACITY;
use mavstack_router::{LocalFrame, LocalFrames};

#[cfg(target_os = "linux")]
mod beside;
#[cfg(target_os = "linux")]
pub(super) use beside::NodeInput;
#[cfg(target_os = "linux")]
use beside::SpinBudget;

/// How many frames may wait for a batch reader; a reader that falls further behind loses
/// the newest ones (counted in [`NodeReport::subscriber_drops`](super::NodeReport)).
pub const BATCH_DEPTH: usize = LOCAL_CAPACITY;

/// Frames for the node, back to back in one buffer, with an index (see the module docs).
pub type FrameBatch = LocalFrames;

/// One frame of a [`FrameBatch`]: its bytes, the router link it came from, and what its
/// link's channel knew of it.
pub type BatchFrame<'a> = LocalFrame<'a>;

/// What the driver and the reader share.
#[derive(Debug, Default)]
struct Shared {
    state: Mutex<Pending>,
    ready: Condvar,
    /// Batches published so far (changed with `state` held), for a reader looking beside the
    /// node's thread.
    #[cfg(target_os = "linux")]
    published: AtomicU64,
    /// The node thread's poll, when the node runs on a thread of its own.
    #[cfg(target_os = "linux")]
    input: std::sync::OnceLock<NodeInput>,
}

#[derive(Debug, Default)]
struct Pending {
    batch: FrameBatch,
    /// The reader waits on `ready`.
    waiting: bool,
    /// The reader waits on the node thread's poll (its `wake` tells it of a batch).
    #[cfg(target_os = "linux")]
    polling: bool,
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
    /// What the reader may still spend looking for batches beside the node's thread.
    #[cfg(target_os = "linux")]
    spin: SpinBudget,
}

impl BatchSubscription {
    /// Empties `batch` and fills it with every frame received since the last call, waiting
    /// up to `timeout` for one when there is none (`Duration::ZERO`: not at all).
    pub fn wait(&mut self, batch: &mut FrameBatch, timeout: Duration) -> BatchWait {
        batch.clear();
        let mut pending = self.shared.lock();
        #[cfg(target_os = "linux")]
        let timeout = match self.shared.input.get() {
            Some(input)
                if pending.batch.is_empty()
                    && !pending.closed
                    && !timeout.is_zero()
                    && input.idle()
                    && self.spin.allows(std::time::Instant::now()) =>
            {
                // From here on a batch published wakes the poll (see `BatchSink::publish`).
                pending.polling = true;
                let seen = self.shared.published.load(Ordering::Relaxed);
                drop(pending);
                let (spent, spun) = input.wait(&self.shared.published, seen, timeout);
                self.spin.spend(spun);
                pending = self.shared.lock();
                pending.polling = false;
                input.clear();
                timeout.saturating_sub(spent)
            }
            _ => timeout,
        };
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
        (
            sink,
            BatchSubscription {
                shared,
                #[cfg(target_os = "linux")]
                spin: SpinBudget::new(std::time::Instant::now()),
            },
        )
    }

    /// Lets the reader wait on the node thread's poll (see the module docs).
    #[cfg(target_os = "linux")]
    pub(super) fn watch_node(&self, input: NodeInput) {
        let _ = self.shared.input.set(input);
    }

    /// Whether its subscription is still held.
    pub(super) fn is_open(&self) -> bool {
        Arc::strong_count(&self.shared) > 1
    }

    /// Stages one frame.
    pub(super) fn push(&mut self, frame: &LocalFrame<'_>) {
        if !self.staging.push_frame(frame) {
            self.lost += 1;
        }
    }

    /// Stages every frame of `frames`, leaving it empty: the whole batch changes hands when
    /// nothing is staged yet (the usual case: one turn's frames), else each is copied.
    pub(super) fn stage_all(&mut self, frames: &mut FrameBatch) {
        if self.staging.is_empty() {
            core::mem::swap(&mut self.staging, frames);
        } else {
            self.lost += self.staging.append(frames);
            frames.clear();
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
            #[cfg(target_os = "linux")]
            {
                self.shared.published.fetch_add(1, Ordering::Release);
                if pending.polling
                    && let Some(input) = self.shared.input.get()
                {
                    input.wake();
                }
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
        #[cfg(target_os = "linux")]
        if let Some(input) = self.shared.input.get() {
            input.wake();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_channel::{Authentication, OwnedFrame, ReceivedFrame};
    use mavstack_core::time::Instant;
    use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};
    use mavstack_router::LinkId;

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
        let mut local = LocalFrames::new();
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
        assert_eq!(first.link, LinkId::new(2));
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
    fn a_turns_frames_staged_whole_keep_their_order_behind_those_already_staged() {
        let (mut sink, mut sub) = BatchSink::new();
        let mut turn = FrameBatch::new();
        for seq in 0..2 {
            assert!(turn.push(LinkId::new(1), &received(seq)));
        }
        sink.stage_all(&mut turn);
        assert!(turn.is_empty(), "the frames were handed over");
        // Staged again before a publish: appended behind.
        assert!(turn.push(LinkId::new(1), &received(2)));
        sink.stage_all(&mut turn);
        assert!(turn.is_empty());
        assert_eq!(sink.publish(), 0);
        let mut batch = FrameBatch::new();
        assert_eq!(sub.wait(&mut batch, Duration::ZERO), BatchWait::Frames);
        assert_eq!(seqs(&batch), [0, 1, 2]);
        assert_eq!(batch.get(2).map(|f| f.link), Some(LinkId::new(1)));
    }

    /// A reader beside an idle node: a stand-in for the node thread's poll (an eventfd made
    /// readable as a datagram would make the epoll), the flag set as the thread sets it.
    #[cfg(target_os = "linux")]
    fn beside_an_idle_node() -> (
        BatchSink,
        BatchSubscription,
        nix::sys::eventfd::EventFd,
        Arc<core::sync::atomic::AtomicBool>,
    ) {
        use nix::sys::eventfd::{EfdFlags, EventFd};
        use std::os::fd::AsFd as _;
        let (sink, sub) = BatchSink::new();
        let poll = EventFd::from_flags(EfdFlags::EFD_CLOEXEC).expect("an eventfd");
        let idle = Arc::new(core::sync::atomic::AtomicBool::new(true));
        sink.watch_node(NodeInput::new(poll.as_fd(), &idle).expect("a reader's view"));
        (sink, sub, poll, idle)
    }

    /// Runs `sub.wait` for up to ten minutes on a thread; its result on the channel.
    #[cfg(target_os = "linux")]
    fn waiting(mut sub: BatchSubscription) -> std::sync::mpsc::Receiver<(BatchWait, Vec<u8>)> {
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let mut batch = FrameBatch::new();
            let got = sub.wait(&mut batch, Duration::from_secs(600));
            let _ = tx.send((got, seqs(&batch)));
        });
        rx
    }

    /// Publishes one frame with sequence number `seq`, as a driver turn does.
    #[cfg(target_os = "linux")]
    fn publish_one(sink: &mut BatchSink, seq: u8) {
        push(sink, LinkId::new(0), &received(seq));
        assert_eq!(sink.publish(), 0);
    }

    /// What the waiting reader got, given a minute.
    #[cfg(target_os = "linux")]
    fn got(
        result: &std::sync::mpsc::Receiver<(BatchWait, Vec<u8>)>,
    ) -> Result<(BatchWait, Vec<u8>), std::sync::mpsc::RecvTimeoutError> {
        result.recv_timeout(Duration::from_secs(60))
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn looking_beside_the_node_is_held_to_a_twentieth_of_the_time() {
        let t0 = std::time::Instant::now();
        let mut budget = SpinBudget::new(t0);
        assert!(budget.allows(t0));
        budget.spend(SpinBudget::CAP);
        assert!(!budget.allows(t0), "all spent");
        let earned = NodeInput::SPIN * SpinBudget::SHARE;
        assert!(!budget.allows(t0 + earned / 2), "half a look earned");
        assert!(budget.allows(t0 + earned), "a whole look earned");
        // Saved up to the cap only.
        assert!(budget.allows(t0 + Duration::from_secs(3600)));
        budget.spend(SpinBudget::CAP);
        assert!(!budget.allows(t0 + Duration::from_secs(3600)));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_reader_beside_an_idle_node_takes_the_batch_its_wake_up_brings() {
        let (mut sink, sub, poll, idle) = beside_an_idle_node();
        let result = waiting(sub);
        // The datagram wakes the node's poll; the node's thread reads it and publishes.
        poll.write(1).expect("readable");
        idle.store(false, Ordering::Release);
        publish_one(&mut sink, 9);
        assert_eq!(got(&result), Ok((BatchWait::Frames, vec![9])));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_batch_published_before_the_reader_polls_still_wakes_it() {
        // The node's thread read the datagram (its poll is quiet again) and published the
        // batch just as the reader went to poll: the batch itself must wake the reader.
        let (mut sink, sub, _poll, _idle) = beside_an_idle_node();
        let result = waiting(sub);
        std::thread::sleep(Duration::from_millis(20));
        publish_one(&mut sink, 5);
        assert_eq!(got(&result), Ok((BatchWait::Frames, vec![5])));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_reader_beside_an_idle_node_hears_it_stop() {
        let (sink, sub, _poll, _idle) = beside_an_idle_node();
        let result = waiting(sub);
        // Its poll never becomes readable: the stop alone must end the ten minutes' wait.
        std::thread::sleep(Duration::from_millis(20));
        drop(sink);
        assert_eq!(got(&result), Ok((BatchWait::Closed, vec![])));
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn a_reader_woken_for_nothing_waits_on_for_the_batch() {
        let (mut sink, sub, poll, _idle) = beside_an_idle_node();
        // The node's poll is readable (its timer fired, say) but brings no frame: the reader
        // looks for a while, then waits as any reader, and the next batch wakes it.
        poll.write(1).expect("readable");
        let result = waiting(sub);
        std::thread::sleep(NodeInput::SPIN * 4);
        publish_one(&mut sink, 3);
        assert_eq!(got(&result), Ok((BatchWait::Frames, vec![3])));
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
