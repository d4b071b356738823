//! A UDP socket registered with the runtime for reading only.
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

/// A non-blocking UDP socket whose readiness for reading the runtime watches.
#[derive(Debug)]
pub(crate) struct UdpIo {
    #[cfg(unix)]
    fd: Registered,
    /// Off unix: the tokio socket is the registration (both directions), and a clone of
    /// the descriptor takes the direct calls.
    #[cfg(not(unix))]
    socket: tokio::net::UdpSocket,
    #[cfg(not(unix))]
    std: std::net::UdpSocket,
}

/// How long a send that found the socket buffer full waits before trying again.
const SEND_RETRY: Duration = Duration::from_millis(1);

impl UdpIo {
    /// Registers `socket` (non-blocking already) for reading.
    ///
    /// # Errors
    /// The runtime refused the registration.
    pub(crate) fn new(socket: std::net::UdpSocket) -> io::Result<Self> {
        #[cfg(unix)]
        {
            // `AsyncFd::with_interest` is deprecated because a `T` could report a
            // descriptor it does not own; `std::net::UdpSocket` owns its descriptor for as
            // long as the registration lives, which is what the safe constructor needs
            // (and `unsafe` is forbidden in this crate).
            #[allow(deprecated)]
            let fd = Registered::with_interest(socket, Interest::READABLE)?;
            Ok(Self { fd })
        }
        #[cfg(not(unix))]
        {
            Ok(Self {
                std: socket.try_clone()?,
                socket: tokio::net::UdpSocket::from_std(socket)?,
            })
        }
    }

    /// The socket itself, for system calls made directly.
    pub(crate) fn get_ref(&self) -> &std::net::UdpSocket {
        #[cfg(unix)]
        return self.fd.get_ref();
        #[cfg(not(unix))]
        return &self.std;
    }

    /// The address the socket is bound to.
    pub(crate) fn local_addr(&self) -> io::Result<SocketAddr> {
        self.get_ref().local_addr()
    }

    /// Ready when a datagram may be waiting; registers `cx` otherwise. Does not clear the
    /// readiness: [`UdpIo::try_read`] does, when a read finds nothing.
    pub(crate) fn poll_read_ready(&self, cx: &mut Context<'_>) -> Poll<()> {
        #[cfg(unix)]
        return self.fd.poll_read_ready(cx).map(|_| ());
        #[cfg(not(unix))]
        return self.socket.poll_recv_ready(cx).map(|_| ());
    }

    /// Runs a read on the socket; a "would block" from it clears the readiness, so the
    /// runtime watches for the next datagram. Returns "would block" without calling `read`
    /// when the socket is known to be drained.
    pub(crate) fn try_read<R>(
        &self,
        read: impl FnOnce(&std::net::UdpSocket) -> io::Result<R>,
    ) -> io::Result<R> {
        #[cfg(unix)]
        return self.fd.try_io(Interest::READABLE, read);
        #[cfg(not(unix))]
        return self.socket.try_io(Interest::READABLE, || read(&self.std));
    }

    /// Tells the runtime the socket is drained, after a read that took fewer datagrams than
    /// it asked for (cheaper than the read that would say so). A datagram that came in the
    /// meantime raised the readiness again after the read began: that is kept.
    pub(crate) fn drained(&self) {
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
