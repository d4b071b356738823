//! A batch reader waiting beside the node's own thread while the input is sparse (Linux): the
//! node thread's poll as the reader sees it ([`NodeInput`]) and the processor time the reader
//! may spend looking for that thread's batch ([`SpinBudget`]). See the parent module's docs.

use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use core::time::Duration;
use std::sync::Arc;

/// The poll a node's own thread waits on, for a reader to wait beside that thread (see the
/// module docs).
#[derive(Debug)]
pub(in crate::node) struct NodeInput {
    /// A duplicate of the thread's `epoll`: readable when a socket has input, or the
    /// thread's waker or timer fired.
    poll: std::os::fd::OwnedFd,
    /// Set while the thread waits in that poll with its input sparse.
    idle: Arc<AtomicBool>,
    /// Written when a batch is published while the reader is in `poll` (it may have gone
    /// there after the node's thread had read the datagram), and when the node stops.
    wake: nix::sys::eventfd::EventFd,
}

impl NodeInput {
    /// How long a reader woken beside the node's thread looks for that thread's batch.
    pub(in crate::node) const SPIN: Duration = Duration::from_micros(500);

    /// A reader's view of the poll `poll` (duplicated) and the flag `idle`.
    ///
    /// # Errors
    /// The system refused to duplicate the poll or make an eventfd.
    pub(in crate::node) fn new(
        poll: std::os::fd::BorrowedFd<'_>,
        idle: &Arc<AtomicBool>,
    ) -> std::io::Result<Self> {
        use nix::sys::eventfd::{EfdFlags, EventFd};
        Ok(Self {
            poll: poll.try_clone_to_owned()?,
            idle: Arc::clone(idle),
            wake: EventFd::from_flags(EfdFlags::EFD_CLOEXEC | EfdFlags::EFD_NONBLOCK)?,
        })
    }

    /// Whether the node's thread waits with its input sparse.
    pub(super) fn idle(&self) -> bool {
        self.idle.load(Ordering::Acquire)
    }

    /// Waits up to `timeout` until the node's thread is woken (then up to [`Self::SPIN`]
    /// until `published` moves from `seen`), a batch is published or the node stops.
    /// Returns the time spent, and the part of it spent looking.
    pub(super) fn wait(
        &self,
        published: &AtomicU64,
        seen: u64,
        timeout: Duration,
    ) -> (Duration, Duration) {
        use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
        use std::os::fd::AsFd as _;
        let start = std::time::Instant::now();
        // Whole milliseconds, rounded up: a shorter wait would return at once and spin.
        let ms = timeout.as_micros().div_ceil(1000);
        let limit = PollTimeout::try_from(ms).unwrap_or(PollTimeout::MAX);
        let mut fds = [
            PollFd::new(self.poll.as_fd(), PollFlags::POLLIN),
            PollFd::new(self.wake.as_fd(), PollFlags::POLLIN),
        ];
        let woken = matches!(poll(&mut fds, limit), Ok(n) if n > 0);
        let mut spun = Duration::ZERO;
        if woken && !fds[1].any().unwrap_or(false) {
            let from = std::time::Instant::now();
            while published.load(Ordering::Acquire) == seen && spun < Self::SPIN {
                // The node's thread may share this processor.
                std::thread::yield_now();
                spun = from.elapsed();
            }
        }
        (start.elapsed(), spun)
    }

    /// Wakes the reader from its `poll`.
    pub(super) fn wake(&self) {
        // EAGAIN: the counter is full, so the reader is woken already.
        let _ = self.wake.write(1);
    }

    /// Forgets the wake-ups a `poll` has not consumed (the next one must wait).
    pub(super) fn clear(&self) {
        let _ = self.wake.read();
    }
}

/// The processor time a reader may spend looking for a batch beside the node's thread:
/// [`SpinBudget::SHARE`] of the time that passes, saved up to [`SpinBudget::CAP`]. Whatever
/// the input's rate, looking costs the reader at most that share of a processor; past it, it
/// waits as any reader.
#[derive(Debug)]
pub(super) struct SpinBudget {
    left: Duration,
    at: std::time::Instant,
}

impl SpinBudget {
    /// One part in twenty: 5 % of a processor at most.
    pub(super) const SHARE: u32 = 20;
    pub(super) const CAP: Duration = Duration::from_millis(50);

    pub(super) const fn new(now: std::time::Instant) -> Self {
        Self {
            left: Self::CAP,
            at: now,
        }
    }

    /// Whether a whole [`NodeInput::SPIN`] is left at `now`, after the time passed has added
    /// its share.
    pub(super) fn allows(&mut self, now: std::time::Instant) -> bool {
        let earned = now.saturating_duration_since(self.at) / Self::SHARE;
        self.left = (self.left + earned).min(Self::CAP);
        self.at = now;
        self.left >= NodeInput::SPIN
    }

    pub(super) fn spend(&mut self, spun: Duration) {
        self.left = self.left.saturating_sub(spun);
    }
}
