//! The I/O side: one [`Link`] per connection, whatever its kind.
//!
//! A UDP link is read by the driver itself: it is the hot path (one socket, every peer on it),
//! and a datagram arrives whole, so there is nothing to wait for but the socket. Every other
//! kind runs small helper tasks (or, for reading a file, a thread) that do the blocking parts
//! (accepting, connecting and reconnecting, reading a stream, writing to a slow peer) and
//! talk to the driver over one channel of [`LinkMsg`]s; each stream peer gets a writer task
//! with a bounded queue, so a slow peer never stalls the driver: what does not fit is dropped
//! and counted.

use core::net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr};
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::{Context, Poll};
use core::time::Duration;
use std::collections::HashMap;
use std::io;
use std::sync::{Arc, Mutex, PoisonError};

use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;
use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::batch::{PACK_LIMIT, RECV_BATCH, RecvBatch, SendBatch};
use crate::clock;
use crate::conn::{ConnSpec, FileFormat};
use crate::connection::{FileMode, Options};
use crate::error::{LinkError, OpenError, Reason};
use crate::protocol::{Dest, Framing, Input, PeerAddr, PeerId, PeerInfo};
use crate::tlog;
use crate::udp_io::UdpIo;

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
    /// Peers that went away (disconnected, expired, or a file's end).
    pub peers_removed: u64,
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

/// The far end of a [`Link::external`]: the code that carries its frames.
#[derive(Debug)]
pub struct ExternalPeer {
    ids: PeerIds,
    first: Option<PeerId>,
    input: mpsc::Sender<LinkMsg>,
    output_tx: mpsc::Sender<(PeerId, Vec<u8>)>,
    output: mpsc::Receiver<(PeerId, Vec<u8>)>,
}

impl ExternalPeer {
    /// The peer the link started with, if it did.
    #[must_use]
    pub const fn first(&self) -> Option<PeerId> {
        self.first
    }

    /// Hands `bytes` (whole frames) to the link as one datagram from `peer`, waiting while
    /// the link's queue is full. False once the link has closed.
    pub async fn deliver(&self, peer: PeerId, bytes: Vec<u8>) -> bool {
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes,
        };
        self.input.send(msg).await.is_ok()
    }

    /// A new peer named `what` (a router link of its own); `None` once the link has closed.
    pub async fn add_peer(&self, what: impl Into<String>) -> Option<PeerId> {
        let id = self.ids.next();
        let info = PeerInfo {
            id,
            addr: PeerAddr::External(what.into()),
            framing: Framing::Datagram,
        };
        let writer = PeerWriter {
            queue: WriterQueue::Tagged(id, self.output_tx.clone()),
            task: None,
        };
        let msg = LinkMsg::PeerAdded {
            info,
            writer: Some(writer),
        };
        self.input.send(msg).await.ok().map(|()| id)
    }

    /// `peer` went away (its router link goes with it).
    pub async fn remove_peer(&self, peer: PeerId) {
        let _ = self.input.send(LinkMsg::PeerRemoved(peer)).await;
    }

    /// The next frame the link sends, and to which peer; `None` once the link has closed
    /// (and what it sent before has been taken).
    pub async fn recv(&mut self) -> Option<(PeerId, Vec<u8>)> {
        // This end keeps a sender for the peers it adds, so the queue alone never ends:
        // the link's end is its input queue closing.
        tokio::select! {
            biased;
            frame = self.output.recv() => frame,
            () = self.input.closed() => self.output.try_recv().ok(),
        }
    }

    /// A frame the link has sent, if one is waiting.
    pub fn try_recv(&mut self) -> Option<(PeerId, Vec<u8>)> {
        self.output.try_recv().ok()
    }
}

/// Where a peer's frames go: its writer task, or an external link's one queue (tagged).
#[derive(Debug)]
enum WriterQueue {
    Plain(mpsc::Sender<Vec<u8>>),
    Tagged(PeerId, mpsc::Sender<(PeerId, Vec<u8>)>),
}

impl WriterQueue {
    fn try_send(&self, data: &[u8]) -> Result<(), ()> {
        match self {
            Self::Plain(q) => q.try_send(data.to_vec()).map_err(|_| ()),
            Self::Tagged(id, q) => q.try_send((*id, data.to_vec())).map_err(|_| ()),
        }
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

    /// A link whose peers are code of the caller's (a fleet bridge's broker connection):
    /// what the link sends to them comes out of [`ExternalPeer::recv`], one frame each,
    /// tagged with the peer; what [`ExternalPeer::deliver`] is given comes in as a datagram
    /// from a peer. The link starts with one peer named `first` when given (known before the
    /// link starts, so nothing sent right away is lost); more come and go with
    /// [`ExternalPeer::add_peer`] and [`ExternalPeer::remove_peer`] (each a router link of
    /// its own). The link ends when the [`ExternalPeer`] is dropped.
    ///
    /// `queue` bounds the frames waiting for the caller (more are dropped and counted as
    /// [`LinkStats::tx_dropped`], like a full writer queue).
    #[must_use]
    pub fn external(first: Option<String>, queue: usize) -> (Self, ExternalPeer) {
        let ids = PeerIds::default();
        let (tx, rx) = mpsc::channel(LINK_QUEUE);
        let (wtx, wrx) = mpsc::channel(queue.max(1));
        let mut tasks = Tasks::new(rx);
        let first = first.map(|what| {
            let id = ids.next();
            tasks.writers.insert(
                id,
                PeerWriter {
                    queue: WriterQueue::Tagged(id, wtx.clone()),
                    task: None,
                },
            );
            tasks.initial.push(PeerInfo {
                id,
                addr: PeerAddr::External(what),
                framing: Framing::Datagram,
            });
            id
        });
        let link = Self {
            kind: Kind::Tasks(tasks),
            stats: LinkStats::default(),
            peers: Arc::new(PeerTable::default()),
            finished: None,
            local_addr: None,
        };
        (
            link,
            ExternalPeer {
                ids,
                first,
                input: tx,
                output_tx: wtx,
                output: wrx,
            },
        )
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
        // Dropping the queues lets each writer task write what is queued, then end.
        let writers: Vec<JoinHandle<()>> =
            tasks.writers.drain().filter_map(|(_, w)| w.task).collect();
        tasks.rx.close();
        let deadline = tokio::time::Instant::now() + DRAIN_TIMEOUT;
        for handle in writers {
            if tokio::time::timeout_at(deadline, handle).await.is_err() {
                tracing::debug!("a peer's writer did not finish in time");
            }
        }
        let mut result = Ok(());
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

/// A UDP socket bound to `addr` with big buffers.
fn udp_socket(addr: SocketAddr, broadcast: bool, options: &Options) -> io::Result<UdpIo> {
    use socket2::{Domain, Protocol as SockProtocol, Socket, Type};
    let socket = Socket::new(
        Domain::for_address(addr),
        Type::DGRAM,
        Some(SockProtocol::UDP),
    )?;
    if broadcast {
        socket.set_broadcast(true)?;
    }
    // Best effort: the kernel caps the sizes (net.core.rmem_max / wmem_max).
    if let Err(e) = socket.set_recv_buffer_size(options.socket_buffer) {
        tracing::debug!("cannot set SO_RCVBUF: {e}");
    }
    if let Err(e) = socket.set_send_buffer_size(options.socket_buffer) {
        tracing::debug!("cannot set SO_SNDBUF: {e}");
    }
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    UdpIo::new(socket.into())
}

/// A TCP listener on `addr` (with `SO_REUSEADDR`, so a restarted server can bind again while
/// old connections linger in TIME_WAIT).
fn tcp_listener(addr: SocketAddr) -> io::Result<TcpListener> {
    use socket2::{Domain, Protocol as SockProtocol, Socket, Type};
    let socket = Socket::new(
        Domain::for_address(addr),
        Type::STREAM,
        Some(SockProtocol::TCP),
    )?;
    socket.set_reuse_address(true)?;
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    socket.listen(128)?;
    TcpListener::from_std(socket.into())
}

/// A TCP connection to `addr`, given up after `timeout`.
async fn tcp_connect(addr: SocketAddr, timeout: Duration) -> Result<TcpStream, Reason> {
    match tokio::time::timeout(timeout, TcpStream::connect(addr)).await {
        Ok(Ok(stream)) => {
            if let Err(e) = stream.set_nodelay(true) {
                tracing::debug!("cannot set TCP_NODELAY: {e}");
            }
            Ok(stream)
        }
        Ok(Err(e)) => Err(Reason::from_io(&e)),
        Err(_) => Err(Reason::new(io::ErrorKind::TimedOut, "timed out")),
    }
}

/// An open serial port (8N1, no flow control).
fn open_serial(device: &str, baud: u32) -> Result<tokio_serial::SerialStream, Reason> {
    use tokio_serial::SerialPortBuilderExt as _;
    tokio_serial::new(device, baud)
        .open_native_async()
        .map_err(|e| Reason::from_serial(&e))
}

// ---------------------------------------------------------------------------------------------
// UDP

#[derive(Debug)]
struct Learned {
    addr: SocketAddr,
    last_seen: Instant,
}

#[derive(Debug)]
struct Udp {
    socket: UdpIo,
    rx: RecvBatch,
    tx: SendBatch,
    /// Pack frames for one peer into datagrams up to this many bytes (0: one per datagram).
    pack: usize,
    peers: UdpPeers,
}

/// A map looked up per datagram: foldhash (seeded per process) instead of SipHash, a tenth
/// of the cost for a socket address.
type FastMap<K, V> = HashMap<K, V, foldhash::fast::RandomState>;

/// The peers of one UDP socket.
#[derive(Debug)]
struct UdpPeers {
    /// `udpout`/`udpbcast`: the fixed destination, a peer that never expires.
    target: Option<(PeerId, SocketAddr)>,
    by_addr: FastMap<SocketAddr, PeerId>,
    learned: FastMap<PeerId, Learned>,
    peer_timeout: Duration,
    next_expiry: Option<Instant>,
    ids: PeerIds,
}

impl Udp {
    fn new(
        socket: UdpIo,
        target: Option<(PeerId, SocketAddr)>,
        ids: PeerIds,
        options: &Options,
    ) -> Self {
        Self {
            socket,
            rx: RecvBatch::new(),
            tx: SendBatch::default(),
            pack: 0,
            peers: UdpPeers {
                target,
                by_addr: FastMap::default(),
                learned: FastMap::default(),
                peer_timeout: options.peer_timeout,
                next_expiry: None,
                ids,
            },
        }
    }

    fn poll_ready(&self, cx: &mut Context<'_>) -> Poll<()> {
        // An error (ICMP and the like) shows as readiness too: the receive reports it.
        self.socket.poll_read_ready(cx)
    }

    fn dispatch<I: Input>(
        &mut self,
        input: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> usize {
        // Drain what is waiting, a batch per system call, before going back to the loop; a
        // datagram that came alone is handed on at once, and the next read waits for the
        // next call (after the caller has forwarded this one).
        let mut delivered = 0;
        for _ in 0..BATCH.div_ceil(RECV_BATCH) {
            let got = match self.rx.recv(&mut self.socket) {
                Ok(got) => got,
                Err(e) => {
                    stats.rx_errors += 1;
                    tracing::debug!("udp receive error: {e}");
                    return delivered;
                }
            };
            for i in 0..got.count {
                if let Some((bytes, from)) = self.rx.get(i) {
                    self.peers.deliver(input, bytes, from, stats, table);
                }
            }
            delivered += got.count;
            stats.rx_errors += core::mem::take(&mut self.rx.truncated);
            if !got.more || got.count == 1 {
                return delivered;
            }
        }
        delivered
    }

    /// Queues a datagram for the next [`Udp::flush`] (flushing at once when the batch is
    /// full).
    fn queue(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let mut full = false;
        let mut none = true;
        self.peers.each_dest(dest, |addr| {
            none = false;
            full |= self.tx.push(data, addr, self.pack);
        });
        if none {
            stats.tx_dropped += 1;
        }
        if full {
            self.flush(stats);
        }
    }

    fn flush(&mut self, stats: &mut LinkStats) {
        if self.tx.is_empty() {
            return;
        }
        let sent = self.tx.flush(&self.socket);
        stats.tx_chunks += sent.datagrams;
        stats.tx_bytes += sent.bytes;
        stats.tx_dropped += sent.dropped;
        stats.tx_errors += sent.errors;
    }

    async fn transmit(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let mut addrs = Vec::new();
        self.peers.each_dest(dest, |a| addrs.push(a));
        if addrs.is_empty() {
            stats.tx_dropped += 1;
        }
        for addr in addrs {
            send_to(&self.socket, data, addr, stats).await;
        }
    }
}

impl UdpPeers {
    fn deliver<I: Input>(
        &mut self,
        input: &mut I,
        data: &[u8],
        from: SocketAddr,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) {
        let now = clock::now();
        let id = match self.target {
            Some((id, addr)) if addr == from => id,
            _ => {
                if let Some(&id) = self.by_addr.get(&from) {
                    if let Some(peer) = self.learned.get_mut(&id) {
                        peer.last_seen = now;
                    }
                    id
                } else {
                    let id = self.ids.next();
                    let info = PeerInfo {
                        id,
                        addr: PeerAddr::Udp(from),
                        framing: Framing::Datagram,
                    };
                    tracing::debug!("udp peer {from} appeared as {id}");
                    self.by_addr.insert(from, id);
                    self.learned.insert(
                        id,
                        Learned {
                            addr: from,
                            last_seen: now,
                        },
                    );
                    self.next_expiry.get_or_insert(now + self.peer_timeout);
                    table.add(info.clone());
                    stats.peers_added += 1;
                    input.handle_peer_added(now, &info);
                    id
                }
            }
        };
        stats.rx_chunks += 1;
        stats.rx_bytes += data.len() as u64;
        input.handle_input(now, id, data);
    }

    fn expire<I: Input>(&mut self, input: &mut I, stats: &mut LinkStats, table: &PeerTable) {
        let now = clock::now();
        let timeout = self.peer_timeout;
        let gone: Vec<PeerId> = self
            .learned
            .iter()
            .filter(|(_, p)| now - p.last_seen >= timeout)
            .map(|(&id, _)| id)
            .collect();
        for id in gone {
            if let Some(peer) = self.learned.remove(&id) {
                tracing::debug!("udp peer {} ({id}) went quiet", peer.addr);
                self.by_addr.remove(&peer.addr);
                table.remove(id);
                stats.peers_removed += 1;
                input.handle_peer_removed(now, id);
            }
        }
        self.next_expiry = self.learned.values().map(|p| p.last_seen + timeout).min();
    }

    /// Calls `f` with every address `dest` names.
    fn each_dest(&self, dest: Dest, mut f: impl FnMut(SocketAddr)) {
        match dest {
            Dest::Peer(id) => {
                let addr = match self.target {
                    Some((t, addr)) if t == id => Some(addr),
                    _ => self.learned.get(&id).map(|p| p.addr),
                };
                if let Some(addr) = addr {
                    f(addr);
                }
            }
            Dest::All | Dest::AllExcept(_) => {
                let except = match dest {
                    Dest::AllExcept(id) => Some(id),
                    _ => None,
                };
                if let Some((id, addr)) = self.target {
                    if except != Some(id) {
                        f(addr);
                    }
                    return;
                }
                for (&id, peer) in &self.learned {
                    if except != Some(id) {
                        f(peer.addr);
                    }
                }
            }
        }
    }
}

async fn send_to(socket: &UdpIo, data: &[u8], addr: SocketAddr, stats: &mut LinkStats) {
    match socket.send_to(data, addr).await {
        Ok(n) => {
            stats.tx_chunks += 1;
            stats.tx_bytes += n as u64;
        }
        Err(e) => {
            stats.tx_errors += 1;
            tracing::debug!("udp send to {addr} failed: {e}");
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Links run by helper tasks: TCP, serial, files

#[derive(Debug)]
struct Tasks {
    rx: mpsc::Receiver<LinkMsg>,
    pending: Option<LinkMsg>,
    writers: HashMap<PeerId, PeerWriter>,
    /// File writers, awaited when the link closes so that nothing buffered is lost.
    sinks: Vec<JoinHandle<Result<(), LinkError>>>,
    /// Peers known when the link opened, announced by [`Link::start`].
    initial: Vec<PeerInfo>,
}

impl Tasks {
    fn new(rx: mpsc::Receiver<LinkMsg>) -> Self {
        Self {
            rx,
            pending: None,
            writers: HashMap::new(),
            sinks: Vec::new(),
            initial: Vec::new(),
        }
    }

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<()> {
        if self.pending.is_some() {
            return Poll::Ready(());
        }
        self.rx.poll_recv(cx).map(|msg| {
            self.pending = Some(msg.unwrap_or(LinkMsg::Closed(Ok(()))));
        })
    }

    fn dispatch<I: Input>(
        &mut self,
        proto: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> Option<Result<(), LinkError>> {
        let mut next = self.pending.take();
        for _ in 0..BATCH {
            let Some(msg) = next.take() else { break };
            if let Some(end) = self.apply(msg, proto, stats, table) {
                return Some(end);
            }
            next = self.rx.try_recv().ok();
        }
        None
    }

    fn apply<I: Input>(
        &mut self,
        msg: LinkMsg,
        proto: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> Option<Result<(), LinkError>> {
        match msg {
            LinkMsg::Data { peer, time, bytes } => {
                stats.rx_chunks += 1;
                stats.rx_bytes += bytes.len() as u64;
                proto.handle_input(time, peer, &bytes);
            }
            LinkMsg::Records { peer, bytes, parts } => {
                let mut from = 0;
                for (time, end) in parts {
                    let Some(part) = bytes.get(from..end) else {
                        break;
                    };
                    stats.rx_chunks += 1;
                    stats.rx_bytes += part.len() as u64;
                    proto.handle_input(time, peer, part);
                    from = end;
                }
            }
            LinkMsg::PeerAdded { info, writer } => {
                tracing::debug!("{} appeared as {}", info.addr, info.id);
                if let Some(w) = writer {
                    self.writers.insert(info.id, w);
                }
                table.add(info.clone());
                stats.peers_added += 1;
                proto.handle_peer_added(clock::now(), &info);
            }
            LinkMsg::PeerRemoved(id) => {
                tracing::debug!("{id} went away");
                self.writers.remove(&id);
                table.remove(id);
                stats.peers_removed += 1;
                proto.handle_peer_removed(clock::now(), id);
            }
            LinkMsg::Closed(end) => return Some(end),
        }
        None
    }

    fn transmit(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let mut send = |writer: &PeerWriter| match writer.queue.try_send(data) {
            Ok(()) => {
                stats.tx_chunks += 1;
                stats.tx_bytes += data.len() as u64;
            }
            Err(_) => stats.tx_dropped += 1,
        };
        match dest {
            Dest::Peer(id) => match self.writers.get(&id) {
                Some(w) => send(w),
                None => stats.tx_dropped += 1,
            },
            Dest::All | Dest::AllExcept(_) => {
                let mut sent = false;
                for (&id, w) in &self.writers {
                    if dest != Dest::AllExcept(id) {
                        send(w);
                        sent = true;
                    }
                }
                if !sent {
                    stats.tx_dropped += 1;
                }
            }
        }
    }
}

/// Reads a stream into [`LinkMsg::Data`] until it ends, fails or the link closes. Returns
/// why it ended, if by an error.
async fn read_stream<R: AsyncRead + Unpin>(
    mut reader: R,
    peer: PeerId,
    tx: &mpsc::Sender<LinkMsg>,
) -> Option<Reason> {
    loop {
        let mut buf = vec![0u8; READ_CHUNK];
        let n = tokio::select! {
            () = tx.closed() => return None,
            r = reader.read(&mut buf) => match r {
                Ok(0) => return None,
                Ok(n) => n,
                Err(e) => return Some(Reason::from_io(&e)),
            },
        };
        buf.truncate(n);
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes: buf,
        };
        if tx.send(msg).await.is_err() {
            return None;
        }
    }
}

/// Writes what the driver queues for one peer, coalescing queued transmits into one write.
async fn write_stream<W: AsyncWrite + Unpin>(
    mut writer: W,
    mut rx: mpsc::Receiver<Vec<u8>>,
    what: String,
) {
    let mut out = Vec::with_capacity(tlog::BUFFER_LEN);
    while let Some(first) = rx.recv().await {
        out.clear();
        out.extend_from_slice(&first);
        while out.len() < tlog::BUFFER_LEN {
            match rx.try_recv() {
                Ok(more) => out.extend_from_slice(&more),
                Err(_) => break,
            }
        }
        if let Err(e) = writer.write_all(&out).await {
            tracing::debug!("{what}: write failed: {e}");
            return;
        }
    }
    let _ = writer.shutdown().await;
}

/// Starts the writer task of a stream peer.
fn spawn_writer<W>(writer: W, what: String, queue: usize) -> PeerWriter
where
    W: AsyncWrite + Unpin + Send + 'static,
{
    let (wtx, wrx) = mpsc::channel(queue.max(1));
    PeerWriter {
        queue: WriterQueue::Plain(wtx),
        task: Some(tokio::spawn(write_stream(writer, wrx, what))),
    }
}

/// Reads a stream peer until it ends, then reports it gone. Returns false when the link has
/// closed.
async fn read_peer<R: AsyncRead + Unpin>(
    reader: R,
    id: PeerId,
    what: &str,
    tx: &mpsc::Sender<LinkMsg>,
) -> bool {
    match read_stream(reader, id, tx).await {
        Some(reason) => tracing::info!("{what}: {reason}"),
        None => tracing::debug!("{what}: closed"),
    }
    tx.send(LinkMsg::PeerRemoved(id)).await.is_ok()
}

/// A link over one stream that is reopened when it drops (a TCP client connection, a
/// serial port). `first`, when already open, becomes the first peer at once; without it the
/// supervisor starts by reconnecting.
fn supervise<S, F, Fut>(
    first: Option<S>,
    addr: PeerAddr,
    what: String,
    ids: PeerIds,
    options: &Options,
    reopen: F,
) -> Tasks
where
    S: AsyncRead + AsyncWrite + Send + 'static,
    F: FnMut() -> Fut + Send + 'static,
    Fut: Future<Output = Result<S, Reason>> + Send + 'static,
{
    let (tx, rx) = mpsc::channel(LINK_QUEUE);
    let mut tasks = Tasks::new(rx);
    let first_id = ids.next();
    let reader = first.map(|stream| {
        let info = PeerInfo {
            id: first_id,
            addr: addr.clone(),
            framing: Framing::Stream,
        };
        let (reader, writer) = tokio::io::split(stream);
        let writer = spawn_writer(writer, what.clone(), options.write_queue);
        tasks.writers.insert(info.id, writer);
        tasks.initial.push(info);
        reader
    });
    let supervisor = Supervisor {
        first_id,
        addr,
        what,
        ids,
        tx,
        options: options.clone(),
    };
    tokio::spawn(supervisor.run(reader, reopen));
    tasks
}

/// Keeps one stream up, reopening it with exponential back-off when it drops.
struct Supervisor {
    first_id: PeerId,
    addr: PeerAddr,
    what: String,
    ids: PeerIds,
    tx: mpsc::Sender<LinkMsg>,
    options: Options,
}

impl Supervisor {
    async fn run<S, F, Fut>(self, first: Option<tokio::io::ReadHalf<S>>, mut reopen: F)
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<S, Reason>>,
    {
        let min = self.options.reconnect_min.max(Duration::from_millis(1));
        let max = self.options.reconnect_max.max(min);
        let mut reader = first;
        let mut id = self.first_id;
        loop {
            if let Some(r) = reader.take()
                && !read_peer(r, id, &self.what, &self.tx).await
            {
                return;
            }
            let mut delay = min;
            let stream = loop {
                tracing::debug!("{}: reconnecting in {delay:?}", self.what);
                tokio::select! {
                    () = self.tx.closed() => return,
                    () = tokio::time::sleep(delay) => {}
                }
                let attempt = tokio::select! {
                    () = self.tx.closed() => return,
                    r = reopen() => r,
                };
                match attempt {
                    Ok(s) => {
                        tracing::info!("{}: connected again", self.what);
                        break s;
                    }
                    Err(reason) => {
                        tracing::debug!("{}: {reason}", self.what);
                        delay = (delay * 2).min(max);
                    }
                }
            };
            id = self.ids.next();
            let (r, w) = tokio::io::split(stream);
            let writer = spawn_writer(w, self.what.clone(), self.options.write_queue);
            let info = PeerInfo {
                id,
                addr: self.addr.clone(),
                framing: Framing::Stream,
            };
            let added = LinkMsg::PeerAdded {
                info,
                writer: Some(writer),
            };
            if self.tx.send(added).await.is_err() {
                return;
            }
            reader = Some(r);
        }
    }
}

/// Accepts TCP clients, each a peer, until the link closes.
async fn serve_tcp(listener: TcpListener, ids: PeerIds, tx: mpsc::Sender<LinkMsg>, queue: usize) {
    loop {
        let accepted = tokio::select! {
            () = tx.closed() => return,
            r = listener.accept() => r,
        };
        match accepted {
            Ok((stream, addr)) => {
                if let Err(e) = stream.set_nodelay(true) {
                    tracing::debug!("cannot set TCP_NODELAY: {e}");
                }
                let info = PeerInfo {
                    id: ids.next(),
                    addr: PeerAddr::Tcp(addr),
                    framing: Framing::Stream,
                };
                let tx = tx.clone();
                tokio::spawn(async move {
                    let (reader, writer) = stream.into_split();
                    let what = info.addr.to_string();
                    let id = info.id;
                    let writer = spawn_writer(writer, what.clone(), queue);
                    let added = LinkMsg::PeerAdded {
                        info,
                        writer: Some(writer),
                    };
                    if tx.send(added).await.is_ok() {
                        read_peer(reader, id, &what, &tx).await;
                    }
                });
            }
            Err(e) => {
                // Out of file descriptors and the like: wait a little, then go on.
                tracing::warn!("tcp accept failed: {e}");
                tokio::select! {
                    () = tx.closed() => return,
                    () = tokio::time::sleep(Duration::from_millis(100)) => {}
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Files

fn open_file(
    path: &std::path::Path,
    format: FileFormat,
    options: &Options,
    ids: PeerIds,
    tx: mpsc::Sender<LinkMsg>,
    tasks: &mut Tasks,
) -> Result<(), OpenError> {
    let file_err = |e: &io::Error| OpenError::File {
        path: path.display().to_string(),
        reason: Reason::from_io(e),
    };
    let id = ids.next();
    let info = PeerInfo {
        id,
        addr: PeerAddr::File(path.to_path_buf()),
        framing: match (options.file_mode, format) {
            (FileMode::Read, FileFormat::Tlog) => Framing::Datagram,
            _ => Framing::Stream,
        },
    };
    let what = format!("file {}", path.display());
    match options.file_mode {
        FileMode::Read => {
            let file = std::fs::File::open(path).map_err(|e| file_err(&e))?;
            if file.metadata().is_ok_and(|m| m.is_dir()) {
                return Err(OpenError::File {
                    path: path.display().to_string(),
                    reason: Reason::new(io::ErrorKind::IsADirectory, "is a directory"),
                });
            }
            std::thread::Builder::new()
                .name("mavstack-file".into())
                .spawn(move || read_file(file, format, info, what, &tx))
                .map_err(|e| file_err(&e))?;
        }
        FileMode::Write | FileMode::Append => {
            let mut open = std::fs::OpenOptions::new();
            if options.file_mode == FileMode::Append {
                open.append(true).create(true);
            } else {
                open.write(true).create(true).truncate(true);
            }
            let file = open.open(path).map_err(|e| file_err(&e))?;
            let (wtx, wrx) = mpsc::channel(options.write_queue.max(1));
            tasks.writers.insert(
                id,
                PeerWriter {
                    queue: WriterQueue::Plain(wtx),
                    task: None,
                },
            );
            tasks.initial.push(info);
            let sink = write_file(tokio::fs::File::from_std(file), format, wrx, what, tx);
            tasks.sinks.push(tokio::spawn(sink));
        }
    }
    Ok(())
}

/// Reads a file to its end (on its own thread: file reads block) and reports it closed.
fn read_file(
    file: std::fs::File,
    format: FileFormat,
    info: PeerInfo,
    what: String,
    tx: &mpsc::Sender<LinkMsg>,
) {
    let id = info.id;
    if tx
        .blocking_send(LinkMsg::PeerAdded { info, writer: None })
        .is_err()
    {
        return;
    }
    let result = match format {
        FileFormat::Raw => read_raw(file, id, tx),
        FileFormat::Tlog => read_tlog(file, id, tx),
    };
    let end = match result {
        Ok(true) => Ok(()),
        Ok(false) => return, // the connection was closed
        Err(e) => Err(LinkError::Read {
            what,
            reason: Reason::from_io(&e),
        }),
    };
    if tx.blocking_send(LinkMsg::PeerRemoved(id)).is_ok() {
        let _ = tx.blocking_send(LinkMsg::Closed(end));
    }
}

/// Ok(false): the link closed before the end.
fn read_raw(mut file: std::fs::File, peer: PeerId, tx: &mpsc::Sender<LinkMsg>) -> io::Result<bool> {
    use std::io::Read as _;
    loop {
        let mut buf = vec![0u8; tlog::BUFFER_LEN];
        let n = match file.read(&mut buf) {
            Ok(0) => return Ok(true),
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        buf.truncate(n);
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes: buf,
        };
        if tx.blocking_send(msg).is_err() {
            return Ok(false);
        }
    }
}

/// Ok(false): the link closed before the end.
fn read_tlog(file: std::fs::File, peer: PeerId, tx: &mpsc::Sender<LinkMsg>) -> io::Result<bool> {
    let mut reader = tlog::Reader::new(file);
    loop {
        let mut bytes = Vec::with_capacity(tlog::BUFFER_LEN);
        let mut parts = Vec::with_capacity(256);
        let mut done = false;
        while bytes.len() < tlog::BUFFER_LEN - tlog::MAX_RECORD_LEN {
            match reader.read_record()? {
                Some((ts, frame)) => {
                    bytes.extend_from_slice(frame);
                    parts.push((Instant::from_micros(ts), bytes.len()));
                }
                None => {
                    done = true;
                    break;
                }
            }
        }
        if !parts.is_empty()
            && tx
                .blocking_send(LinkMsg::Records { peer, bytes, parts })
                .is_err()
        {
            return Ok(false);
        }
        if done {
            let skipped = reader.stats().skipped_bytes;
            if skipped > 0 {
                tracing::info!("tlog: skipped {skipped} corrupt bytes");
            }
            return Ok(true);
        }
    }
}

/// Writes what is sent to a file: raw, or as tlog records stamped with the transport's clock.
/// Writes out at least once a second; writes everything out when the link closes.
async fn write_file(
    mut file: tokio::fs::File,
    format: FileFormat,
    mut rx: mpsc::Receiver<Vec<u8>>,
    what: String,
    link: mpsc::Sender<LinkMsg>,
) -> Result<(), LinkError> {
    let mut buffer = tlog::Buffer::new();
    let fail = |e: &io::Error| LinkError::Write {
        what: what.clone(),
        reason: Reason::from_io(e),
    };
    loop {
        let deadline = buffer.deadline().map(tokio::time::Instant::from_std);
        let flush = tokio::select! {
            data = rx.recv() => match data {
                Some(data) => {
                    append(&mut buffer, format, &data, &what);
                    buffer.due()
                }
                None => break,
            },
            () = sleep_until(deadline), if deadline.is_some() => true,
        };
        if flush && let Err(e) = write_out(&mut file, &mut buffer).await {
            let err = fail(&e);
            let _ = link.send(LinkMsg::Closed(Err(err.clone()))).await;
            return Err(err);
        }
    }
    write_out(&mut file, &mut buffer)
        .await
        .map_err(|e| fail(&e))?;
    file.sync_data().await.map_err(|e| fail(&e))
}

fn append(buffer: &mut tlog::Buffer, format: FileFormat, data: &[u8], what: &str) {
    match format {
        FileFormat::Raw => buffer.push_raw(data),
        FileFormat::Tlog => {
            let now = clock::now().as_micros();
            let mut rest = data;
            while !rest.is_empty() {
                let Ok(frame) = Frame::new_checked(rest) else {
                    tracing::warn!(
                        "{what}: {} bytes that are not a frame not logged",
                        rest.len()
                    );
                    return;
                };
                let len = frame.frame_len();
                buffer.push_record(now, &rest[..len]);
                rest = &rest[len..];
            }
        }
    }
}

async fn write_out(file: &mut tokio::fs::File, buffer: &mut tlog::Buffer) -> io::Result<()> {
    if buffer.bytes().is_empty() {
        return Ok(());
    }
    file.write_all(buffer.bytes()).await?;
    buffer.clear();
    file.flush().await
}

/// Sleeps until `deadline`, or forever without one.
pub(crate) async fn sleep_until(deadline: Option<tokio::time::Instant>) {
    match deadline {
        Some(d) => tokio::time::sleep_until(d).await,
        None => core::future::pending().await,
    }
}
