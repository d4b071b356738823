//! The same connections without async: for programs that have no tokio runtime.
//!
//! [`Connection`] starts a small tokio runtime (one worker thread) of its own and runs the
//! very same driver on it as [`crate::Connection`]; its methods block the calling thread
//! instead of returning futures. It has the async handle's surface, plus
//! [`Connection::recv_timeout`].
//!
//! ```
//! use core::time::Duration;
//! use mavstack_transport::blocking::Connection;
//! use mavstack_transport::frame::{FrameBuf, FrameCommand, FrameEvent, FrameProtocol, MessageTable};
//!
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let common = MessageTable::of::<mavstack_dialects::common::MavMessage>();
//! let mut server = Connection::open(&"udpin:127.0.0.1:0".parse()?, FrameProtocol::new(common))?;
//! let port = server.local_addr().unwrap().port();
//! let client = Connection::open(&format!("udpout:127.0.0.1:{port}").parse()?, FrameProtocol::new(common))?;
//! client.send(FrameCommand::to_all(FrameBuf::new(&heartbeat)?))?;
//! loop {
//!     match server.recv_timeout(Duration::from_secs(5))? {
//!         FrameEvent::Frame(f) => { assert_eq!(f.frame.as_bytes(), &heartbeat); break }
//!         _ => {} // the client appearing as a peer
//!     }
//! }
//! # Ok::<(), Box<dyn core::error::Error>>(())
//! ```

use core::net::SocketAddr;
use core::time::Duration;

use crate::conn::ConnSpec;
use crate::connection::{ConnectionStats, Options};
use crate::error::{
    LinkError, OpenError, Reason, RecvTimeoutError, SendError, TryRecvError, TrySendError,
};
use crate::protocol::{PeerInfo, Protocol};

/// A running connection driven on a runtime thread of its own; see the [module docs](self).
///
/// Its blocking methods must not be called from async code (they would block a runtime
/// thread; tokio panics when asked to).
pub struct Connection<P: Protocol> {
    /// `None` only while closing.
    inner: Option<crate::Connection<P>>,
    runtime: tokio::runtime::Runtime,
}

impl<P: Protocol> Connection<P> {
    /// Opens the link `spec` names with default [`Options`] and starts driving `protocol`.
    ///
    /// # Errors
    /// [`OpenError`], as [`crate::Connection::open`]; [`OpenError::Runtime`] if the runtime
    /// thread cannot start.
    ///
    /// # Panics
    /// When called from within an async runtime.
    pub fn open(spec: &ConnSpec, protocol: P) -> Result<Self, OpenError> {
        Self::open_with(spec, protocol, &Options::default())
    }

    /// [`Connection::open`] with explicit options.
    ///
    /// # Errors
    /// As [`Connection::open`].
    ///
    /// # Panics
    /// When called from within an async runtime.
    pub fn open_with(spec: &ConnSpec, protocol: P, options: &Options) -> Result<Self, OpenError> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("mavstack-link")
            .enable_all()
            .build()
            .map_err(|e| OpenError::Runtime {
                reason: Reason::from_io(&e),
            })?;
        let inner = runtime.block_on(crate::Connection::open_with(spec, protocol, options))?;
        Ok(Self {
            inner: Some(inner),
            runtime,
        })
    }

    fn inner(&self) -> &crate::Connection<P> {
        match &self.inner {
            Some(inner) => inner,
            None => unreachable!("the inner connection is only taken while closing"),
        }
    }

    fn inner_mut(&mut self) -> &mut crate::Connection<P> {
        match &mut self.inner {
            Some(inner) => inner,
            None => unreachable!("the inner connection is only taken while closing"),
        }
    }

    /// Hands a command to the protocol, blocking while the command queue is full.
    ///
    /// # Errors
    /// [`SendError::Closed`] once the driver has stopped.
    pub fn send(&self, command: P::Command) -> Result<(), SendError> {
        self.runtime.block_on(self.inner().send(command))
    }

    /// Hands a command to the protocol if there is room in the queue.
    ///
    /// # Errors
    /// [`TrySendError::Full`] or [`TrySendError::Closed`].
    pub fn try_send(&self, command: P::Command) -> Result<(), TrySendError> {
        self.inner().try_send(command)
    }

    /// The next event, blocking until one comes; `None` once the connection has ended and
    /// every event was taken.
    pub fn recv(&mut self) -> Option<P::Event> {
        let Some(inner) = &mut self.inner else {
            return None;
        };
        self.runtime.block_on(inner.recv())
    }

    /// The next event, waiting at most `timeout`.
    ///
    /// # Errors
    /// [`RecvTimeoutError::Timeout`], or [`RecvTimeoutError::Closed`] once the connection
    /// has ended and every event was taken.
    pub fn recv_timeout(&mut self, timeout: Duration) -> Result<P::Event, RecvTimeoutError> {
        let Some(inner) = &mut self.inner else {
            return Err(RecvTimeoutError::Closed);
        };
        match self
            .runtime
            .block_on(async { tokio::time::timeout(timeout, inner.recv()).await })
        {
            Ok(Some(event)) => Ok(event),
            Ok(None) => Err(RecvTimeoutError::Closed),
            Err(_) => Err(RecvTimeoutError::Timeout),
        }
    }

    /// Moves up to `limit` events into `buf`, blocking until at least one is there; returns
    /// how many (0 once the connection has ended).
    pub fn recv_many(&mut self, buf: &mut Vec<P::Event>, limit: usize) -> usize {
        let Some(inner) = &mut self.inner else {
            return 0;
        };
        self.runtime.block_on(inner.recv_many(buf, limit))
    }

    /// The next event if one is waiting.
    ///
    /// # Errors
    /// [`TryRecvError::Empty`] or [`TryRecvError::Closed`].
    pub fn try_recv(&mut self) -> Result<P::Event, TryRecvError> {
        self.inner_mut().try_recv()
    }

    /// The counters as the driver last published them.
    #[must_use]
    pub fn stats(&self) -> ConnectionStats<P::Stats> {
        self.inner().stats()
    }

    /// The peers the link has now.
    #[must_use]
    pub fn peers(&self) -> Vec<PeerInfo> {
        self.inner().peers()
    }

    /// The local address of a UDP socket or TCP listener (see
    /// [`crate::Connection::local_addr`]).
    #[must_use]
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.inner().local_addr()
    }

    /// Whether the driver has stopped.
    #[must_use]
    pub fn is_closed(&self) -> bool {
        self.inner().is_closed()
    }

    /// Stops the connection (see [`crate::Connection::close`]) and its runtime.
    ///
    /// # Errors
    /// How the link failed, if it did.
    pub fn close(mut self) -> Result<(), LinkError> {
        match self.inner.take() {
            Some(inner) => self.runtime.block_on(inner.close()),
            None => Ok(()),
        }
    }
}

impl<P: Protocol> core::fmt::Debug for Connection<P> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("blocking::Connection")
            .field("inner", &self.inner)
            .finish_non_exhaustive()
    }
}

impl<P: Protocol> Drop for Connection<P> {
    /// Closes the connection as [`Connection::close`] does (so that a file being written is
    /// written out), unless dropped inside an async runtime, where blocking is not allowed:
    /// then the runtime is just shut down.
    fn drop(&mut self) {
        if let Some(inner) = self.inner.take()
            && tokio::runtime::Handle::try_current().is_err()
            && let Err(e) = self.runtime.block_on(inner.close())
        {
            tracing::warn!("connection ended with an error: {e}");
        }
    }
}
