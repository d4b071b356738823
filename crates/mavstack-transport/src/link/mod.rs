//! The I/O side: one [`Link`] per connection, whatever its kind.
//!
//! A UDP link is read by the driver itself: it is the hot path (one socket, every peer on it),
//! and a datagram arrives whole, so there is nothing to wait for but the socket. Every other
//! kind runs small helper tasks (or, for reading a file, a thread) that do the blocking parts
//! (accepting, connecting and reconnecting, reading a stream, writing to a slow peer) and
//! talk to the driver over one channel of [`LinkMsg`]s; each stream peer gets a writer task
//! with a bounded queue, so a slow peer never stalls the driver: what does not fit is dropped
//! and counted.
//!
//! One file per transport: [`udp`] (the socket the driver reads itself), [`tcp`] (server and
//! client), [`serial`], [`file`] (raw or tlog, read or written) and [`external`] (peers that
//! are the caller's code); what the helper-task links share is in [`tasks`] (the driver's side)
//! and [`stream`] (readers, writers and the reconnecting supervisor).

mod admission;
mod external;
mod file;
mod serial;
mod stream;
mod tasks;
mod tcp;
mod udp;

pub use external::{ExternalPeer, ExternalSender};

use core::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::{Context, Poll};
use core::time::Duration;
use std::io;
use std::sync::{Arc, Mutex, PoisonError};

use mavstack_core::time::Instant;
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::batch::PACK_LIMIT;
use crate::clock;
use crate::conn::ConnSpec;
use crate::connection::Options;
use crate::error::{LinkError, OpenError, Reason};
use crate::protocol::{Dest, Framing, Input, PeerAddr, PeerId, PeerInfo};

use file::open_file;
use serial::open_serial;
use stream::supervise;
use tasks::Tasks;
use tcp::{serve_tcp, tcp_connect, tcp_listener};
use udp::{Udp, udp_socket};

/// The largest UDP datagram, and so the driver's receive buffer.
pub(crate) const MAX_DATAGRAM: usize = 65_536;
/// Bytes a stream reader asks for at once.
const READ_CHUNK: usize = 16 * 1024;
/// Messages from helper tasks waiting for the driver.
const LINK_QUEUE: usize = 1024;
/// Inputs handled per wake-up before the driver looks at its other work.
const BATCH: usize = 256;
/// How long closing waits for writer tasks to drain their queues.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(2);

/// Counters of the link layer.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct LinkStats {
    /// Bytes received.
    pub rx_bytes: u64,
    /// Datagrams or stream reads received.
    pub rx_chunks: u64,
    /// Receive errors (the link went on).
    pub rx_errors: u64,
    /// Bytes handed to the operating system (or to a peer's writer queue).
    pub tx_bytes: u64,
    /// Datagrams or writes sent.
    pub tx_chunks: u64,
    /// Transmits dropped: no peer to send to (nobody connected yet, a TCP client
    /// reconnecting), an unknown or departed peer, or a full writer queue.
    pub tx_dropped: u64,
    /// Send errors (the link went on).
    pub tx_errors: u64,
    /// Peers that appeared (for a TCP client, each successful (re)connection).
    pub peers_added: u64,
    /// Peers that went away (disconnected, expired, made room for a new one, or a file's
    /// end).
    pub peers_removed: u64,
    /// UDP: datagrams from a source that is not a peer holding no MAVLink frame with a good
    /// checksum (dropped; they make no peer, see [`Link::admit_peers`]).
    pub rx_unadmitted: u64,
    /// UDP: new sources refused because the link had `max_peers` peers and none had been
    /// quiet long enough to make room (their datagrams are dropped).
    pub peers_refused: u64,
    /// UDP: peers removed to make room for a new source (counted in `peers_removed` too).
    pub peers_evicted: u64,
}

/// Hands out peer ids, unique within one connection.
#[derive(Clone, Debug, Default)]
pub(crate) struct PeerIds(Arc<AtomicU32>);

impl PeerIds {
    fn next(&self) -> PeerId {
        PeerId::new(self.0.fetch_add(1, Ordering::Relaxed) + 1)
    }
}

/// The live peers, readable by the user's handle.
#[derive(Debug, Default)]
pub(crate) struct PeerTable(Mutex<Vec<PeerInfo>>);

impl PeerTable {
    fn add(&self, info: PeerInfo) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(info);
    }

    fn remove(&self, id: PeerId) {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .retain(|p| p.id != id);
    }

    pub(crate) fn snapshot(&self) -> Vec<PeerInfo> {
        self.0
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }
}

/// What helper tasks tell the driver.
#[derive(Debug)]
pub(crate) enum LinkMsg {
    /// Bytes from a peer, received at `time`.
    Data {
        peer: PeerId,
        time: Instant,
        bytes: Vec<u8>,
    },
    /// Several inputs from one peer, each with its own time (tlog records): part `i` is
    /// `bytes[parts[i-1].1..parts[i].1]`.
    Records {
        peer: PeerId,
        bytes: Vec<u8>,
        parts: Vec<(Instant, usize)>,
    },
    /// A peer appeared; `writer` takes what is sent to it.
    PeerAdded {
        info: PeerInfo,
        writer: Option<PeerWriter>,
    },
    /// A peer went away.
    PeerRemoved(PeerId),
    /// The link ended (a file was read to its end), or failed.
    Closed(Result<(), LinkError>),
}

/// Where a peer's frames go: its writer task, an external link's one queue (tagged), or a
/// file's writer thread.
#[derive(Debug)]
enum WriterQueue {
    Plain(mpsc::Sender<Vec<u8>>),
    Tagged(PeerId, mpsc::Sender<(PeerId, Vec<u8>)>),
    File(Box<file::FileSink>),
}

/// What became of a transmit handed to a [`WriterQueue`].
enum Queued {
    Yes,
    /// The queue was full: dropped.
    Full,
    /// The writer failed: the link ends with this.
    Failed(LinkError),
}

impl WriterQueue {
    fn try_send(&mut self, data: &[u8]) -> Queued {
        let queued = match self {
            Self::Plain(q) => q.try_send(data.to_vec()).is_ok(),
            Self::Tagged(id, q) => q.try_send((*id, data.to_vec())).is_ok(),
            Self::File(sink) => match sink.write(data) {
                Ok(queued) => queued,
                Err(e) => return Queued::Failed(e),
            },
        };
        if queued { Queued::Yes } else { Queued::Full }
    }
}

/// The queue to a stream peer's writer task, and the task (awaited when the link closes, so
/// that what was queued is written).
#[derive(Debug)]
pub(crate) struct PeerWriter {
    queue: WriterQueue,
    task: Option<JoinHandle<()>>,
}

/// One link (a UDP socket, a TCP server or client, a serial port, a file) and its peers,
/// driven by polling: [`Link::poll_ready`] then [`Link::dispatch`] hand input to an
/// [`Input`]; [`Link::send`] and [`Link::flush`] write without waiting. A driver that runs
/// many links in one task (a router) uses this directly; [`crate::Connection`] runs one link
/// with a [`crate::Protocol`].
#[derive(Debug)]
pub struct Link {
    kind: Kind,
    stats: LinkStats,
    peers: Arc<PeerTable>,
    finished: Option<Result<(), LinkError>>,
    local_addr: Option<SocketAddr>,
}

#[derive(Debug)]
enum Kind {
    Udp(Box<Udp>),
    Tasks(Tasks),
}

impl Link {
    /// Opens the link `spec` describes.
    ///
    /// # Errors
    /// [`OpenError`]: a name that does not resolve, an address in use, a refused TCP
    /// connection, a missing serial device or file.
    pub async fn open(spec: &ConnSpec, options: &Options) -> Result<Self, OpenError> {
        let ids = PeerIds::default();
        let peers = Arc::new(PeerTable::default());
        let hp = spec.host_port().unwrap_or_default();
        let (kind, local_addr) = match spec {
            ConnSpec::UdpIn { host, port } => {
                let what = format!("udp {hp}");
                let addr = resolve(host, *port, &what).await?;
                let socket = udp_socket(addr, false, options).map_err(|e| OpenError::Bind {
                    what,
                    reason: Reason::from_io(&e),
                })?;
                let local = socket.local_addr().ok();
                (
                    Kind::Udp(Box::new(Udp::new(socket, None, ids, options))),
                    local,
                )
            }
            ConnSpec::UdpOut { host, port } | ConnSpec::UdpBcast { host, port } => {
                let broadcast = matches!(spec, ConnSpec::UdpBcast { .. });
                let what = format!("udp {hp}");
                let target = resolve(host, *port, &what).await?;
                let any = match target.ip() {
                    IpAddr::V4(_) => IpAddr::V4(Ipv4Addr::UNSPECIFIED),
                    IpAddr::V6(_) => IpAddr::V6(Ipv6Addr::UNSPECIFIED),
                };
                let socket =
                    udp_socket(SocketAddr::new(any, 0), broadcast, options).map_err(|e| {
                        OpenError::Bind {
                            what,
                            reason: Reason::from_io(&e),
                        }
                    })?;
                let local = socket.local_addr().ok();
                let udp = Udp::new(socket, Some((ids.next(), target)), ids, options);
                (Kind::Udp(Box::new(udp)), local)
            }
            ConnSpec::Tcp { host, port } => {
                let what = format!("tcp {hp}");
                let addr = resolve(host, *port, &what).await?;
                let timeout = options.connect_timeout;
                let reconnect = move || tcp_connect(addr, timeout);
                match tcp_connect(addr, timeout).await {
                    Ok(stream) => {
                        let local = stream.local_addr().ok();
                        let tasks = supervise(
                            Some(stream),
                            PeerAddr::Tcp(addr),
                            what,
                            ids,
                            options,
                            reconnect,
                        );
                        (Kind::Tasks(tasks), local)
                    }
                    Err(reason) if options.keep_trying => {
                        tracing::info!("{what}: {reason}; trying again in the background");
                        let tasks = supervise::<TcpStream, _, _>(
                            None,
                            PeerAddr::Tcp(addr),
                            what,
                            ids,
                            options,
                            reconnect,
                        );
                        (Kind::Tasks(tasks), None)
                    }
                    Err(reason) => return Err(OpenError::Connect { what, reason }),
                }
            }
            ConnSpec::TcpIn { host, port } => {
                let what = format!("tcp {hp}");
                let addr = resolve(host, *port, &what).await?;
                let listener = tcp_listener(addr).map_err(|e| OpenError::Bind {
                    what: what.clone(),
                    reason: Reason::from_io(&e),
                })?;
                let local = listener.local_addr().ok();
                let (tx, rx) = mpsc::channel(LINK_QUEUE);
                tokio::spawn(serve_tcp(listener, ids, tx, options.write_queue));
                (Kind::Tasks(Tasks::new(rx)), local)
            }
            ConnSpec::Serial { device, baud } => {
                let port = open_serial(device, *baud).map_err(|reason| OpenError::Serial {
                    device: device.clone(),
                    reason,
                })?;
                let (device2, baud2) = (device.clone(), *baud);
                let reopen = move || {
                    let result = open_serial(&device2, baud2);
                    async move { result }
                };
                let addr = PeerAddr::Serial(device.clone());
                let what = format!("serial {device}");
                let tasks = supervise(Some(port), addr, what, ids, options, reopen);
                (Kind::Tasks(tasks), None)
            }
            ConnSpec::File { path, format } => {
                let (tx, rx) = mpsc::channel(LINK_QUEUE);
                let mut tasks = Tasks::new(rx);
                open_file(path, *format, options, ids, tx, &mut tasks)?;
                (Kind::Tasks(tasks), None)
            }
        };
        Ok(Self {
            kind,
            stats: LinkStats::default(),
            peers,
            finished: None,
            local_addr,
        })
    }

    /// How many peers a UDP link keeps at most unless [`Link::admit_peers`] says otherwise
    /// (the `max_peers` link option's default).
    pub const DEFAULT_MAX_PEERS: usize = admission::DEFAULT_MAX_PEERS;

    /// Sets who may become a peer of a UDP link (no effect on other kinds): a datagram from a
    /// source that is not a peer yet makes it one only if it holds a MAVLink frame with a
    /// good checksum by `lookup`'s CRC_EXTRA (any datagram without a lookup), and the link
    /// keeps at most `max_peers` (at least 1) learned peers: at the limit the peer quiet the
    /// longest makes room if it has been quiet for 3 s, else the new source is refused
    /// ([`LinkStats::peers_refused`], a warning naming `name` at most every 10 s). Without
    /// this call: [`Link::DEFAULT_MAX_PEERS`], any datagram.
    pub fn admit_peers(
        &mut self,
        name: &str,
        max_peers: usize,
        lookup: Option<Arc<dyn mavstack_core::parse::CrcExtra + Send + Sync>>,
    ) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.peers.admission = admission::Admission::new(name.to_owned(), max_peers, lookup);
        }
    }

    /// The peers table the user's handle reads.
    pub(crate) fn peer_table(&self) -> Arc<PeerTable> {
        Arc::clone(&self.peers)
    }

    /// The bound local address (UDP sockets, TCP listeners, a TCP client's first connection).
    #[must_use]
    pub fn local_addr(&self) -> Option<SocketAddr> {
        self.local_addr
    }

    /// The link layer's counters.
    #[must_use]
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The peers the link has now.
    #[must_use]
    pub fn peers(&self) -> Vec<PeerInfo> {
        self.peers.snapshot()
    }

    /// Announces the peers a link has from the start: the target of `udpout`/`udpbcast`,
    /// a TCP client's first connection, a serial port, a file being written. They are known
    /// before `open` returns, so that what is sent right after opening is not dropped.
    pub fn start<I: Input>(&mut self, input: &mut I) {
        let initial = match &mut self.kind {
            Kind::Udp(udp) => udp
                .peers
                .target
                .map(|(id, addr)| PeerInfo {
                    id,
                    addr: PeerAddr::Udp(addr),
                    framing: Framing::Datagram,
                })
                .into_iter()
                .collect(),
            Kind::Tasks(tasks) => core::mem::take(&mut tasks.initial),
        };
        for info in initial {
            self.peers.add(info.clone());
            self.stats.peers_added += 1;
            input.handle_peer_added(clock::now(), &info);
        }
    }

    /// How the link ended, once it has (a file read to its end, a fatal error).
    #[must_use]
    pub fn finished(&self) -> Option<&Result<(), LinkError>> {
        self.finished.as_ref()
    }

    pub(crate) fn take_result(&mut self) -> Result<(), LinkError> {
        self.finished.take().unwrap_or(Ok(()))
    }

    /// Waits for input; [`Link::dispatch`] then takes it. Cancel-safe.
    pub(crate) async fn wait(&mut self) {
        core::future::poll_fn(|cx| self.poll_ready(cx)).await;
    }

    /// Ready when input may be waiting for [`Link::dispatch`] (a spurious wake-up is
    /// harmless: dispatch then finds nothing). Registers `cx` for the next input otherwise.
    pub fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<()> {
        match &mut self.kind {
            Kind::Udp(udp) => udp.poll_ready(cx),
            Kind::Tasks(tasks) => tasks.poll_ready(cx),
        }
    }

    /// Like [`Link::poll_ready`], without polling anything or registering a waker: whether
    /// input is known to be waiting now (a socket the caller's poll reported, see
    /// [`Link::set_readable`]; a helper task's message taken already; a writer that failed).
    /// A driver whose waker has not been woken since [`Link::poll_ready`] last returned
    /// pending learns all it can with this.
    #[must_use]
    pub fn ready_now(&self) -> bool {
        match &self.kind {
            Kind::Udp(udp) => udp.socket.is_readable(),
            Kind::Tasks(tasks) => tasks.pending.is_some() || tasks.failed.is_some(),
        }
    }

    /// Takes a UDP link's socket off the runtime's reactor, for a driver on a thread of its
    /// own that waits on its own poll (one `epoll_wait` per wake-up and no runtime between
    /// it and the socket). Returns the descriptor that poll is to watch, level-triggered,
    /// for reading; from then on [`Link::poll_ready`] is ready only after
    /// [`Link::set_readable`], which the caller calls when its poll reports the descriptor.
    /// Other links stay with the runtime (`None`): their helper tasks wake the waker given
    /// to [`Link::poll_ready`], whatever thread it belongs to.
    ///
    /// # Errors
    /// The socket's descriptor could not be duplicated; the link stays as it was.
    #[cfg(target_os = "linux")]
    pub fn watch_externally(&mut self) -> io::Result<Option<std::os::fd::BorrowedFd<'_>>> {
        match &mut self.kind {
            Kind::Udp(udp) => udp.socket.watch_externally().map(Some),
            Kind::Tasks(_) => Ok(None),
        }
    }

    /// Whether reads take many datagrams at once (a UDP link under a steady stream; the
    /// driver knows the rate). Off, a link whose socket the caller watches (see
    /// [`Link::watch_externally`]) reads one datagram per wake-up: the cheapest read, and
    /// the frame goes on at once.
    pub fn set_bulk_reads(&mut self, on: bool) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.rx.bulk = on;
        }
    }

    /// The caller's poll reported this link's socket (see [`Link::watch_externally`]):
    /// input may be waiting.
    pub fn set_readable(&mut self) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.socket.set_readable();
        }
    }

    /// Hands whatever input is ready (a bounded batch) to `input`. Returns false when
    /// nothing was ready after all (a UDP socket that had been drained already).
    pub fn dispatch<I: Input>(&mut self, input: &mut I) -> bool {
        match &mut self.kind {
            Kind::Udp(udp) => udp.dispatch(input, &mut self.stats, &self.peers) > 0,
            Kind::Tasks(tasks) => {
                if let Some(end) = tasks.dispatch(input, &mut self.stats, &self.peers) {
                    self.finished = Some(end);
                }
                true
            }
        }
    }

    /// Sends `data` to `dest`, waiting for the socket (the single-link driver's path).
    pub(crate) async fn transmit(&mut self, dest: Dest, data: &[u8]) {
        match &mut self.kind {
            Kind::Udp(udp) => udp.transmit(dest, data, &mut self.stats).await,
            Kind::Tasks(tasks) => tasks.transmit(dest, data, &mut self.stats),
        }
    }

    /// Sends `data` to `dest` without ever waiting: UDP datagrams are batched until
    /// [`Link::flush`] (or a full batch) and go out many per system call; stream peers get
    /// it in their writer's queue. What cannot go (a full socket buffer or queue, no peer)
    /// is dropped and counted in [`LinkStats::tx_dropped`].
    pub fn send(&mut self, dest: Dest, data: &[u8]) {
        match &mut self.kind {
            Kind::Udp(udp) => udp.queue(dest, data, &mut self.stats),
            Kind::Tasks(tasks) => tasks.transmit(dest, data, &mut self.stats),
        }
    }

    /// Lets [`Link::send`] pack the frames waiting for one UDP peer into shared datagrams
    /// (up to 1472 bytes) instead of one frame per datagram: far fewer datagrams at high
    /// rates, at no cost in latency (only frames already waiting are packed). Every MAVLink
    /// parser reads several frames from a datagram; a receiver that reads only the first
    /// (some do) must not get packed datagrams. No effect on other links.
    pub fn set_packing(&mut self, on: bool) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.pack = if on { PACK_LIMIT } else { 0 };
        }
    }

    /// Sends what [`Link::send`] batched.
    pub fn flush(&mut self) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.flush(&mut self.stats);
        }
    }

    /// When [`Link::housekeeping`] is next due (expiring quiet UDP peers).
    #[must_use]
    pub fn next_housekeeping(&self) -> Option<Instant> {
        match &self.kind {
            Kind::Udp(udp) if !udp.peers.learned.is_empty() => udp.peers.next_expiry,
            _ => None,
        }
    }

    /// Expires UDP peers that have been quiet for [`Options::peer_timeout`].
    pub fn housekeeping<I: Input>(&mut self, input: &mut I) {
        if let Kind::Udp(udp) = &mut self.kind {
            udp.peers.expire(input, &mut self.stats, &self.peers);
        }
    }

    /// Stops the link: what is batched is sent, writer tasks get to drain their queues (a
    /// file sink writes out its buffer) for a short while.
    ///
    /// # Errors
    /// A write error of a file being written.
    pub async fn shutdown(&mut self) -> Result<(), LinkError> {
        self.flush();
        let Kind::Tasks(tasks) = &mut self.kind else {
            return Ok(());
        };
        // Dropping the queues lets each writer task write what is queued, then end; files
        // are written out and synced by their writer threads.
        let mut writers: Vec<JoinHandle<()>> = Vec::new();
        for (_, w) in tasks.writers.drain() {
            match w.queue {
                WriterQueue::File(sink) => tasks
                    .sinks
                    .push(tokio::task::spawn_blocking(move || sink.finish())),
                _ => writers.extend(w.task),
            }
        }
        tasks.rx.close();
        let deadline = tokio::time::Instant::now() + DRAIN_TIMEOUT;
        for handle in writers {
            if tokio::time::timeout_at(deadline, handle).await.is_err() {
                tracing::debug!("a peer's writer did not finish in time");
            }
        }
        let mut result = tasks.failed.take().map_or(Ok(()), |e| Err(*e));
        for handle in tasks.sinks.drain(..) {
            match tokio::time::timeout(DRAIN_TIMEOUT, handle).await {
                Ok(Ok(Ok(()))) => {}
                Ok(Ok(Err(e))) => result = Err(e),
                Ok(Err(e)) => {
                    result = Err(LinkError::Driver {
                        reason: e.to_string(),
                    });
                }
                Err(_) => tracing::warn!("a file writer did not finish in time"),
            }
        }
        // A write error the sink reported while running.
        while let Ok(msg) = tasks.rx.try_recv() {
            if let LinkMsg::Closed(Err(e)) = msg {
                result = Err(e);
            }
        }
        result
    }
}

/// The first address `host:port` resolves to.
async fn resolve(host: &str, port: u16, what: &str) -> Result<SocketAddr, OpenError> {
    let resolve_err = |reason| OpenError::Resolve {
        what: what.to_owned(),
        reason,
    };
    let mut addrs = tokio::net::lookup_host((host, port))
        .await
        .map_err(|e| resolve_err(Reason::from_io(&e)))?;
    addrs
        .next()
        .ok_or_else(|| resolve_err(Reason::new(io::ErrorKind::NotFound, "no address")))
}

/// Sleeps until `deadline`, or forever without one.
pub(crate) async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => core::future::pending().await,
    }
}
