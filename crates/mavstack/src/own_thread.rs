//! What a node on a thread of its own waits with (see `NodeBuilder::own_thread`): an `epoll`
//! over its UDP sockets, an `eventfd` waker for everything that stays on the runtime (the
//! other links' tasks, the handles' requests), and a `timerfd` for its deadlines.
//!
//! The sockets are watched level-triggered, as mavlink-routerd does: a datagram that comes
//! alone is read with one `recvfrom` and forwarded at once, and the poll reports the socket
//! again if another one waits, so no read is spent finding the socket empty. The timer is
//! armed only when the deadline moves, so that the poll waits with no timeout: an
//! `epoll_wait` with one arms and cancels a kernel timer on every wake-up, which costs about
//! 3 µs per datagram on a virtual machine (the timer device is emulated), on the way to the
//! forwarded frames' `sendto` too.

use core::sync::atomic::{AtomicBool, Ordering};
use core::time::Duration;
use std::io;
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::sync::Arc;

use mavstack_core::time::Instant;
use nix::sys::epoll::{Epoll, EpollCreateFlags, EpollEvent, EpollFlags, EpollTimeout};
use nix::sys::eventfd::{EfdFlags, EventFd};
use nix::sys::time::TimeSpec;
use nix::sys::timerfd::{ClockId, Expiration, TimerFd, TimerFlags, TimerSetTimeFlags};

/// Token of the waker (the sockets' tokens are their slot indexes, far below).
const WAKER: u64 = u64::MAX;
/// Token of the deadline timer.
const TIMER: u64 = u64::MAX - 1;

/// The poll a node's own thread waits on.
pub(crate) struct Waiter {
    epoll: Epoll,
    events: [EpollEvent; 16],
    wake: Arc<PollWaker>,
    waker: core::task::Waker,
    timer: TimerFd,
    /// The deadline the timer is armed for (and has not fired yet).
    armed: Option<Instant>,
    /// The waker was woken since [`Waiter::take_woken`] last looked.
    woken: bool,
    /// Set while the thread waits in its poll with its input sparse: batch readers may then
    /// wait beside it (see `node::batch`).
    beside: Arc<AtomicBool>,
    /// The input is sparse ([`Waiter::set_sparse`]).
    sparse: bool,
}

impl Waiter {
    /// A poll with its waker and timer.
    ///
    /// # Errors
    /// The system refused an epoll, an eventfd or a timerfd.
    pub(crate) fn new() -> io::Result<Self> {
        let epoll = Epoll::new(EpollCreateFlags::EPOLL_CLOEXEC)?;
        let wake = Arc::new(PollWaker(EventFd::from_flags(
            EfdFlags::EFD_CLOEXEC | EfdFlags::EFD_NONBLOCK,
        )?));
        epoll.add(wake.0.as_fd(), EpollEvent::new(EpollFlags::EPOLLIN, WAKER))?;
        let timer = TimerFd::new(
            ClockId::CLOCK_MONOTONIC,
            TimerFlags::TFD_NONBLOCK | TimerFlags::TFD_CLOEXEC,
        )?;
        epoll.add(timer.as_fd(), EpollEvent::new(EpollFlags::EPOLLIN, TIMER))?;
        Ok(Self {
            epoll,
            events: [EpollEvent::empty(); 16],
            waker: core::task::Waker::from(Arc::clone(&wake)),
            wake,
            timer,
            armed: None,
            woken: false,
            beside: Arc::new(AtomicBool::new(false)),
            sparse: false,
        })
    }

    /// Watches `fd` (a socket, level-triggered, for reading) as slot `slot`.
    ///
    /// # Errors
    /// The poll refused it.
    pub(crate) fn watch(&self, fd: BorrowedFd<'_>, slot: usize) -> io::Result<()> {
        self.epoll
            .add(fd, EpollEvent::new(EpollFlags::EPOLLIN, slot as u64))?;
        Ok(())
    }

    /// For batch readers to wait beside the thread: a duplicate of the `epoll` (readable
    /// when the thread has something to wake for) and the flag set while the thread waits
    /// in it with its input sparse.
    ///
    /// # Errors
    /// The system refused to duplicate the poll.
    pub(crate) fn beside(&self) -> io::Result<(OwnedFd, Arc<AtomicBool>)> {
        Ok((self.epoll.0.try_clone()?, Arc::clone(&self.beside)))
    }

    /// Whether the input is sparse now (batch readers wait beside the thread only then).
    pub(crate) const fn set_sparse(&mut self, sparse: bool) {
        self.sparse = sparse;
    }

    /// The waker to poll the runtime's side (tasks' queues, the command queue) with.
    pub(crate) const fn waker(&self) -> &core::task::Waker {
        &self.waker
    }

    /// Whether the waker was woken since the last call: something on the runtime's side
    /// (a command, a helper task's message) may be waiting. While it is not, that side need
    /// not be polled: what it registered the waker for has not happened.
    pub(crate) const fn take_woken(&mut self) -> bool {
        let woken = self.woken;
        self.woken = false;
        woken
    }

    /// Waits until a socket is reported, the waker is woken or `deadline` has passed (a
    /// spurious return is possible: the caller looks again). Calls `readable` with the slot
    /// index of each socket reported.
    ///
    /// # Errors
    /// The poll failed (an interruption is not an error: it returns).
    pub(crate) fn wait(
        &mut self,
        deadline: Option<Instant>,
        now: Instant,
        readable: impl FnMut(usize),
    ) -> io::Result<()> {
        self.arm(deadline, now)?;
        self.block(readable)
    }

    /// The deadline the timer is armed for and has not reported yet.
    pub(crate) const fn armed(&self) -> Option<Instant> {
        self.armed
    }

    /// Waits like [`Waiter::wait`] with the timer as it is (armed for [`Waiter::armed`]).
    ///
    /// # Errors
    /// The poll failed (an interruption is not an error: it returns).
    pub(crate) fn wait_armed(&mut self, readable: impl FnMut(usize)) -> io::Result<()> {
        self.block(readable)
    }

    /// Waits in the poll, the flag for batch readers set meanwhile when the input is sparse.
    fn block(&mut self, readable: impl FnMut(usize)) -> io::Result<()> {
        self.beside.store(self.sparse, Ordering::Release);
        let result = self.poll(EpollTimeout::NONE, readable);
        self.beside.store(false, Ordering::Release);
        result
    }

    /// Looks without waiting: calls `readable` with the slot index of each socket that has
    /// input. While one socket always has more (a flood), the thread never waits, and this
    /// is how it learns that others have input too.
    ///
    /// # Errors
    /// The poll failed.
    pub(crate) fn look(&mut self, readable: impl FnMut(usize)) -> io::Result<()> {
        self.poll(EpollTimeout::ZERO, readable)
    }

    fn poll(&mut self, timeout: EpollTimeout, mut readable: impl FnMut(usize)) -> io::Result<()> {
        let n = match self.epoll.wait(&mut self.events, timeout) {
            Ok(n) => n,
            Err(nix::errno::Errno::EINTR) => return Ok(()),
            Err(e) => return Err(e.into()),
        };
        for event in &self.events[..n] {
            match event.data() {
                WAKER => {
                    // Cleared before the caller looks at the runtime's side: a wake after
                    // this read wakes the next wait.
                    let _ = self.wake.0.read();
                    self.woken = true;
                }
                TIMER => {
                    let _ = self.timer.wait();
                    self.armed = None;
                }
                slot => readable(usize::try_from(slot).unwrap_or(usize::MAX)),
            }
        }
        Ok(())
    }

    /// Arms the timer for `deadline` if it is not armed for it already.
    fn arm(&mut self, deadline: Option<Instant>, now: Instant) -> io::Result<()> {
        if deadline == self.armed {
            return Ok(());
        }
        match deadline {
            // A zero expiry would disarm it: a deadline due now fires a microsecond on.
            Some(d) => self.timer.set(
                Expiration::OneShot(TimeSpec::from_duration(
                    d.saturating_duration_since(now)
                        .max(Duration::from_micros(1)),
                )),
                TimerSetTimeFlags::empty(),
            ),
            None => self.timer.unset(),
        }?;
        self.armed = deadline;
        Ok(())
    }
}

/// Wakes the thread from its poll.
struct PollWaker(EventFd);

impl std::task::Wake for PollWaker {
    fn wake(self: Arc<Self>) {
        self.wake_by_ref();
    }

    fn wake_by_ref(self: &Arc<Self>) {
        if let Err(e) = self.0.write(1) {
            // EAGAIN: the counter is full, so the thread is woken already.
            if e != nix::errno::Errno::EAGAIN {
                tracing::warn!("cannot wake the node's thread: {e}");
            }
        }
    }
}
