//! The user's handle on a running connection (async).

use core::net::SocketAddr;
use core::time::Duration;
use std::sync::{Arc, Mutex, PoisonError};

use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::conn::ConnSpec;
use crate::driver::{self, Published, Shared};
use crate::error::{LinkError, OpenError, SendError, TryRecvError, TrySendError};
use crate::link::{Link, LinkStats, PeerTable};
use crate::protocol::{PeerInfo, Protocol};

/// What a `file:` connection does with its file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum FileMode {
    /// Read it from the start to the end, as fast as events are taken; then the connection
    /// ends.
    #[default]
    Read,
    /// Create it (or truncate it) and write what is sent; a tlog stamps each frame with the
    /// time it was written.
    Write,
    /// Like [`FileMode::Write`], appending to what is there.
    Append,
}

/// How a connection behaves. `Options::default()` suits most uses; fields can be changed on
/// it:
///
/// ```
/// use core::time::Duration;
/// let mut options = mavstack_transport::Options::default();
/// options.peer_timeout = Duration::from_secs(30);
/// options.file_mode = mavstack_transport::FileMode::Write;
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Options {
    /// A UDP sender that has sent nothing for this long stops being a peer (default 10 s).
    pub peer_timeout: Duration,
    /// A TCP client, or a serial port that went away, retries after this long first
    /// (default 100 ms), doubling each time...
    pub reconnect_min: Duration,
    /// ...up to this (default 5 s).
    pub reconnect_max: Duration,
    /// A TCP connection attempt gives up after this long (default 5 s).
    pub connect_timeout: Duration,
    /// Events waiting for the user (default 8192); when full, the link is not read.
    pub event_capacity: usize,
    /// Commands waiting for the driver (default 1024).
    pub command_capacity: usize,
    /// Transmits waiting for one stream peer or file (default 1024); when full, more are
    /// dropped and counted ([`LinkStats::tx_dropped`]).
    pub write_queue: usize,
    /// `SO_RCVBUF` and `SO_SNDBUF` asked for UDP sockets (default 4 MiB; the kernel may
    /// grant less).
    pub socket_buffer: usize,
    /// Read or write a `file:` connection (default read).
    pub file_mode: FileMode,
    /// A TCP client whose first connection fails keeps trying in the background (with the
    /// reconnect back-off) instead of failing to open: a router's endpoint may come up later
    /// (default false: a refused first connection is an open error).
    pub keep_trying: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            peer_timeout: Duration::from_secs(10),
            reconnect_min: Duration::from_millis(100),
            reconnect_max: Duration::from_secs(5),
            connect_timeout: Duration::from_secs(5),
            event_capacity: 8192,
            command_capacity: 1024,
            write_queue: 1024,
            socket_buffer: 4 << 20,
            file_mode: FileMode::Read,
            keep_trying: false,
        }
    }
}

/// Counters of a connection: the link's and the protocol's.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct ConnectionStats<S> {
    /// The link layer's counters.
    pub link: LinkStats,
    /// The protocol's counters.
    pub protocol: S,
}

/// A running connection: a driver task that owns the link and the protocol `P`, and this
/// handle to talk to it.
///
/// Commands go in with [`Connection::send`], events come out of [`Connection::recv`]. The
/// connection ends when the handle is closed or dropped, or when the link ends by itself (a
/// file read to its end, a fatal error): then `recv` returns `None` once every event has
/// been taken, and [`Connection::close`] tells how it ended.
///
/// ```no_run
/// use mavstack_transport::{Connection, frame::{FrameEvent, FrameProtocol, MessageTable}};
/// use mavstack_dialects::common::MavMessage;
/// # async fn run() -> Result<(), Box<dyn core::error::Error>> {
/// let spec = "udpin:0.0.0.0:14550".parse()?;
/// let mut conn = Connection::open(&spec, FrameProtocol::new(MessageTable::of::<MavMessage>())).await?;
/// while let Some(event) = conn.recv().await {
///     if let FrameEvent::Frame(f) = event {
///         println!("{} from {}/{}", f.frame.msg_id(), f.frame.sysid(), f.frame.compid());
///     }
/// }
/// conn.close().await?;
/// # Ok(()) }
/// ```
pub struct Connection<P: Protocol> {
    commands: mpsc::Sender<P::Command>,
    events: mpsc::Receiver<P::Event>,
    shared: Shared<P::Stats>,
    peers: Arc<PeerTable>,
    local_addr: Option<SocketAddr>,
    task: JoinHandle<Result<(), LinkError>>,
}

impl<P: Protocol> core::fmt::Debug for Connection<P> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Connection")
            .field("local_addr", &self.local_addr)
            .field("closed", &self.task.is_finished())
            .finish_non_exhaustive()
    }
}

impl<P: Protocol> Connection<P> {
    /// Opens the link `spec` names with default [`Options`] and starts driving `protocol` on
    /// it, in a task of the current tokio runtime.
    ///
    /// # Errors
    /// [`OpenError`]: a name that does not resolve, an address in use, a refused TCP
    /// connection, a missing serial device or file.
    ///
    /// # Panics
    /// Outside a tokio runtime (as `tokio::spawn` does).
    pub async fn open(spec: &ConnSpec, protocol: P) -> Result<Self, OpenError> {
        Self::open_with(spec, protocol, &Options::default()).await
    }

    /// [`Connection::open`] with explicit options.
    ///
    /// # Errors
    /// As [`Connection::open`].
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub async fn open_with(
        spec: &ConnSpec,
        protocol: P,
        options: &Options,
    ) -> Result<Self, OpenError> {
        let link = Link::open(spec, options).await?;
        tracing::debug!("opened {spec}");
        let (cmd_tx, cmd_rx) = mpsc::channel(options.command_capacity.max(1));
        let (ev_tx, ev_rx) = mpsc::channel(options.event_capacity.max(1));
        let shared: Shared<P::Stats> = Arc::new(Mutex::new(Published::default()));
        let peers = link.peer_table();
        let local_addr = link.local_addr();
        let task = tokio::spawn(driver::run(
            link,
            protocol,
            cmd_rx,
            ev_tx,
            Arc::clone(&shared),
        ));
        Ok(Self {
            commands: cmd_tx,
            events: ev_rx,
            shared,
            peers,
            local_addr,
            task,
        })
    }

    /// Hands a command to the protocol, waiting while the command queue is full.
    ///
    /// # Errors
    /// [`SendError::Closed`] once the driver has stopped.
    pub async fn send(&self, command: P::Command) -> Result<(), SendError> {
        self.commands
            .send(command)
            .await
            .map_err(|_| SendError::Closed)
    }

    /// Hands a command to the protocol if there is room in the queue.
    ///
    /// # Errors
    /// [`TrySendError::Full`] or [`TrySendError::Closed`].
    pub fn try_send(&self, command: P::Command) -> Result<(), TrySendError> {
        self.commands.try_send(command).map_err(|e| match e {
            mpsc::error::TrySendError::Full(_) => TrySendError::Full,
            mpsc::error::TrySendError::Closed(_) => TrySendError::Closed,
        })
    }

    /// The next event; `None` once the connection has ended and every event was taken.
    /// Cancel-safe.
    pub async fn recv(&mut self) -> Option<P::Event> {
        self.events.recv().await
    }

    /// Waits for at least one event and moves up to `limit` waiting events into `buf`;
    /// returns how many (0 once the connection has ended). Cancel-safe. Cheaper than `recv`
    /// per event at high rates.
    pub async fn recv_many(&mut self, buf: &mut Vec<P::Event>, limit: usize) -> usize {
        self.events.recv_many(buf, limit).await
    }

    /// The next event if one is waiting.
    ///
    /// # Errors
    /// [`TryRecvError::Empty`] or, once the connection has ended and every event was taken,
    /// [`TryRecvError::Closed`].
    pub fn try_recv(&mut self) -> Result<P::Event, TryRecvError> {
        self.events.try_recv().map_err(|e| match e {
            mpsc::error::TryRecvError::Empty => TryRecvError::Empty,
            mpsc::error::TryRecvError::Disconnected => TryRecvError::Closed,
        })
    }

    /// The counters as the driver last published them (after its latest step).
    #[must_use]
    pub fn stats(&self) -> ConnectionStats<P::Stats> {
        let published = self.shared.lock().unwrap_or_else(PoisonError::into_inner);
        ConnectionStats {
            link: published.link,
            protocol: published.protocol.clone(),
        }
    }

    /// The peers the link has now.
    #[must_use]
    pub fn peers(&self) -> Vec<PeerInfo> {
        self.peers.snapshot()
    }

    /// The local address of a UDP socket, a TCP listener, or a TCP client's first
    /// connection (useful after binding port 0).
    #[must_use]
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// Whether the driver has stopped.
    #[must_use]
    pub fn is_closed(&self) -> bool {
        self.task.is_finished()
    }

    /// Stops the connection: commands already sent are handled, what the protocol has to
    /// send goes out, writer queues drain (a file being written is written out and synced),
    /// and the link closes. Events not yet received are dropped.
    ///
    /// # Errors
    /// How the link failed, if it did ([`LinkError`]).
    pub async fn close(self) -> Result<(), LinkError> {
        let Self {
            commands,
            events,
            task,
            ..
        } = self;
        drop(commands);
        // The driver may be waiting for room for an event: let it go.
        drop(events);
        match task.await {
            Ok(result) => result,
            Err(e) => Err(LinkError::Driver {
                reason: e.to_string(),
            }),
        }
    }
}
