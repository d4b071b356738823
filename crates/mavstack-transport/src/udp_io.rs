//! A UDP socket whose readiness for reading is watched: by the runtime (tokio's reactor), or
//! by a poll of the caller's own (a node on a thread of its own, see
//! [`crate::Link::watch_externally`]).
//!
//! tokio's `UdpSocket` registers for both directions, and an edge-triggered registration for
//! writes reports the socket writable again each time the receiver frees one of its
//! datagrams: on a router at 1 k frames/s that is a second `epoll_wait` per frame, whose
//! only effect is to tell the runtime what it does not need. Sends here never wait for
//! the socket (a full buffer drops the datagram and counts it, as a router must), so only
//! reads are registered; the rare send that finds the buffer full and has to wait retries
//! after a short sleep instead ([`UdpIo::send_to`]).

use core::net::SocketAddr;
use core::task::{Context, Poll};
use core::time::Duration;
use std::io;

use tokio::io::Interest;

#[cfg(unix)]
type Registered = tokio::io::unix::AsyncFd<std::net::UdpSocket>;

/// A non-blocking UDP socket and who watches its readiness for reading.
#[derive(Debug)]
pub(crate) struct UdpIo {
    watch: Watch,
}

#[derive(Debug)]
enum Watch {
    /// The runtime's reactor.
    #[cfg(unix)]
    Runtime(Registered),
    /// Off unix: the tokio socket is the registration (both directions), and a clone of
    /// the descriptor takes the direct calls.
    #[cfg(not(unix))]
    Runtime {
        socket: tokio::net::UdpSocket,
        std: std::net::UdpSocket,
    },
    /// A caller's level-triggered poll: `readable` is set when that poll reports the
    /// socket and cleared when a read finds it drained or may have drained it (the poll
    /// reports it again while a datagram waits).
    #[cfg(target_os = "linux")]
    Polled {
        socket: std::net::UdpSocket,
        readable: bool,
    },
}

/// How long a send that found the socket buffer full waits before trying again.
const SEND_RETRY: Duration = Duration::from_millis(1);

impl UdpIo {
    /// Registers `socket` (non-blocking already) with the runtime, for reading.
    ///
    /// # Errors
    /// The runtime refused the registration.
    pub(crate) fn new(socket: std::net::UdpSocket) -> io::Result<Self> {
        #[cfg(unix)]
        {
            Ok(Self {
                watch: Watch::Runtime(register_with_runtime(socket)?),
            })
        }
        #[cfg(not(unix))]
        {
            Ok(Self {
                watch: Watch::Runtime {
                    std: socket.try_clone()?,
                    socket: tokio::net::UdpSocket::from_std(socket)?,
                },
            })
        }
    }

    /// Takes the socket off the runtime's reactor: from now on the caller watches it
    /// (level-triggered, for reading) and calls [`UdpIo::set_readable`] when its poll
    /// reports it. Returns the descriptor to watch.
    ///
    /// # Errors
    /// The descriptor could not be duplicated; the socket then stays with the runtime.
    #[cfg(target_os = "linux")]
    pub(crate) fn watch_externally(&mut self) -> io::Result<std::os::fd::BorrowedFd<'_>> {
        use std::os::fd::AsFd as _;
        if let Watch::Runtime(fd) = &self.watch {
            // A second descriptor of the socket leaves the runtime; the runtime's
            // registration and its descriptor are dropped once that has worked.
            let socket = fd.get_ref().try_clone()?;
            // Whatever came before the caller's poll watches it is read on the first turn.
            self.watch = Watch::Polled {
                socket,
                readable: true,
            };
        }
        Ok(self.get_ref().as_fd())
    }

    /// Whether a caller's level-triggered poll watches the socket (see
    /// [`UdpIo::watch_externally`]): that poll reports it again while a datagram waits, so
    /// a read need not look for the next one.
    pub(crate) const fn level_triggered(&self) -> bool {
        #[cfg(target_os = "linux")]
        return matches!(self.watch, Watch::Polled { .. });
        #[cfg(not(target_os = "linux"))]
        return false;
    }

    /// Whether a caller's poll reported the socket and no read has found it drained since
    /// (always false for a socket the runtime watches: only polling it tells).
    pub(crate) const fn is_readable(&self) -> bool {
        #[cfg(target_os = "linux")]
        if let Watch::Polled { readable, .. } = &self.watch {
            return *readable;
        }
        false
    }

    /// The caller's poll reported the socket: a datagram may be waiting.
    pub(crate) fn set_readable(&mut self) {
        #[cfg(target_os = "linux")]
        if let Watch::Polled { readable, .. } = &mut self.watch {
            *readable = true;
        }
    }

    /// The socket itself, for system calls made directly.
    pub(crate) fn get_ref(&self) -> &std::net::UdpSocket {
        match &self.watch {
            #[cfg(unix)]
            Watch::Runtime(fd) => fd.get_ref(),
            #[cfg(not(unix))]
            Watch::Runtime { std, .. } => std,
            #[cfg(target_os = "linux")]
            Watch::Polled { socket, .. } => socket,
        }
    }

    /// The address the socket is bound to.
    pub(crate) fn local_addr(&self) -> io::Result<SocketAddr> {
        self.get_ref().local_addr()
    }

    /// Ready when a datagram may be waiting; registers `cx` otherwise (with the runtime; a
    /// socket on a caller's poll is woken by that poll, not through `cx`). Does not clear
    /// the readiness: [`UdpIo::try_read`] does, when a read finds nothing.
    pub(crate) fn poll_read_ready(&self, cx: &mut Context<'_>) -> Poll<()> {
        match &self.watch {
            #[cfg(unix)]
            Watch::Runtime(fd) => fd.poll_read_ready(cx).map(|_| ()),
            #[cfg(not(unix))]
            Watch::Runtime { socket, .. } => socket.poll_recv_ready(cx).map(|_| ()),
            #[cfg(target_os = "linux")]
            Watch::Polled { readable, .. } => {
                if *readable {
                    Poll::Ready(())
                } else {
                    Poll::Pending
                }
            }
        }
    }

    /// Runs a read on the socket; a "would block" from it clears the readiness, so the
    /// watcher waits for the next datagram. Returns "would block" without calling `read`
    /// when the socket is known to be drained.
    pub(crate) fn try_read<R>(
        &mut self,
        read: impl FnOnce(&std::net::UdpSocket) -> io::Result<R>,
    ) -> io::Result<R> {
        match &mut self.watch {
            #[cfg(unix)]
            Watch::Runtime(fd) => fd.try_io(Interest::READABLE, read),
            #[cfg(not(unix))]
            Watch::Runtime { socket, std } => socket.try_io(Interest::READABLE, || read(std)),
            #[cfg(target_os = "linux")]
            Watch::Polled { socket, readable } => {
                if !*readable {
                    return Err(io::Error::from(io::ErrorKind::WouldBlock));
                }
                let result = read(socket);
                if matches!(&result, Err(e) if e.kind() == io::ErrorKind::WouldBlock) {
                    *readable = false;
                }
                result
            }
        }
    }

    /// Tells the watcher the socket is drained, after a read that took fewer datagrams than
    /// it asked for (cheaper than the read that would say so). A datagram that came in the
    /// meantime raised the readiness again after the read began: that is kept (the
    /// runtime's edge-triggered poll reports every datagram's arrival, a caller's
    /// level-triggered one reports the socket while one waits).
    pub(crate) fn drained(&mut self) {
        let _ = self.try_read(|_| Err::<(), _>(io::Error::from(io::ErrorKind::WouldBlock)));
    }

    /// Sends one datagram if the socket buffer has room ("would block" otherwise).
    pub(crate) fn try_send_to(&self, data: &[u8], to: SocketAddr) -> io::Result<usize> {
        self.get_ref().send_to(data, to)
    }

    /// Sends one datagram, waiting while the socket buffer is full (the single-link
    /// driver's path; writes are not registered, so the wait is a retry after
    /// [`SEND_RETRY`]).
    pub(crate) async fn send_to(&self, data: &[u8], to: SocketAddr) -> io::Result<usize> {
        loop {
            match self.try_send_to(data, to) {
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    tokio::time::sleep(SEND_RETRY).await;
                }
                other => return other,
            }
        }
    }
}

/// `socket` registered with the runtime for reading only.
#[cfg(unix)]
fn register_with_runtime(socket: std::net::UdpSocket) -> io::Result<Registered> {
    // `AsyncFd::with_interest` is deprecated because a `T` could report a descriptor it
    // does not own; `std::net::UdpSocket` owns its descriptor for as long as the
    // registration lives, which is what the safe constructor needs (and `unsafe` is
    // forbidden in this crate).
    #[allow(deprecated)]
    Registered::with_interest(socket, Interest::READABLE)
}
