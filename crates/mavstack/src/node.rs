//! [`Node`]: one MAVLink component with many links, the router core between them, and one
//! driver that owns every socket (the composition `docs/architecture.md` calls "One
//! composition"): a tokio task, or a thread of its own with its UDP sockets on its own
//! `epoll` ([`NodeBuilder::own_thread`], what `mavstack router` runs).
//!
//! ```text
//!  Node handle ── commands (stats, shutdown) ──►  driver task
//!                                                  │ poll every link (batched UDP reads)
//!                                                  ▼
//!      transport Link (udp/tcp/serial) ─peers─► Router (a channel per peer: version,
//!                                               signing; routes; conversion; queues)
//!                                                  │ poll_transmit
//!                                                  ▼
//!                                       Link::send (batched, never waits) ─► sockets
//! ```

use core::net::SocketAddr;
use core::time::Duration;
use std::collections::HashMap;
use std::path::PathBuf;

use mavstack_channel::{
    CommandEncoding, ConfigError, HandshakeError, HandshakeMethod, HandshakeOutcome, LinkVersion,
    ProtocolVersionAnswer, ReceivedFrame, Rejected, SigningConfig, SigningSetup, SwitchCause,
    Target,
};
use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_core::{MAX_PAYLOAD_LEN, Message, MessageSet};
use mavstack_router::systems::SystemInfo;
use mavstack_router::{
    Event, InfoFn, LinkConfig, LinkId, LinkMode, LinkRole, LocalDelivery, Router, RouterConfig,
    SendTo,
};
use mavstack_transport::protocol::Framing;
use mavstack_transport::{
    Dest, Input, Link, LinkError, LinkStats, OpenError, Options, PeerId, PeerInfo, clock, tlog,
};
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use crate::link_spec::LinkSpec;

/// Why a node could not start or ended badly.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NodeError {
    /// A link could not be opened.
    #[error("link \"{name}\": {source}")]
    Open {
        /// The link's name.
        name: String,
        /// Why.
        source: OpenError,
    },
    /// A link failed while running.
    #[error("link \"{name}\": {source}")]
    Link {
        /// The link's name.
        name: String,
        /// Why.
        source: LinkError,
    },
    /// The status page's address could not be bound.
    #[error("status page on {addr}: {source}")]
    Http {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// The traffic log could not be written.
    #[error("log {path}: {source}")]
    Log {
        /// The log file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The poll of a node on its own thread failed (see [`NodeBuilder::own_thread`]).
    #[error("poll: {source}")]
    Poll {
        /// Why.
        source: std::io::Error,
    },
    /// The driver task ended abnormally.
    #[error("node stopped: {0}")]
    Stopped(String),
}

/// Why a request to a running node failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RequestError {
    /// The handshake could not start on that link.
    #[error("handshake: {0}")]
    Handshake(#[from] HandshakeError),
    /// Signing could not be set up on that link.
    #[error("signing: {0}")]
    Signing(#[from] ConfigError),
    /// The node has stopped.
    #[error("the node has stopped")]
    Stopped,
}

/// One router link's counters, as the node reports them.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct LinkReport {
    /// The configured link's name.
    pub name: String,
    /// The router link of its peer (none for a server link without clients yet).
    pub link_id: Option<LinkId>,
    /// The peer (a UDP or TCP client of a server link, the target of `udpout`, ...), if
    /// any yet.
    pub peer: Option<String>,
    /// What it carries now: `"1"`, `"2"`, `"signed"` or `"auto"`.
    pub version: &'static str,
    /// Frames accepted from it.
    pub rx_frames: u64,
    /// Bytes accepted from it.
    pub rx_bytes: u64,
    /// Frames written to it.
    pub tx_frames: u64,
    /// Bytes written to it.
    pub tx_bytes: u64,
    /// Frames converted on their way to it.
    pub converted: u64,
    /// Conversions by kind: `to_mavlink1`, `to_mavlink2`, `signature_removed`, `signed`.
    pub conversions: [(&'static str, u64); 4],
    /// Non-zero drops by reason.
    pub dropped: Vec<(&'static str, u64)>,
    /// Frames lost, by sequence numbers, summed over the sources heard on it.
    pub seq_lost: u64,
    /// Per source heard on it: (sysid, compid, frames received, frames lost by sequence).
    pub sources: Vec<(u8, u8, u64, u64)>,
}

/// A snapshot of a node.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct NodeReport {
    /// Seconds since the node started.
    pub t_s: f64,
    /// One entry per router link; a server link without clients yet has one entry with no
    /// peer.
    pub links: Vec<LinkReport>,
    /// Routes: (sysid, compid, link name, peer, age in seconds).
    pub routes: Vec<(u8, u8, String, Option<String>, f64)>,
    /// The components heard, by (sysid, compid), each with its latest HEARTBEAT.
    pub systems: Vec<SystemReport>,
    /// The transport counters of each configured link: (name, counters).
    pub transport: Vec<(String, LinkStats)>,
    /// Frames a subscriber missed because it fell behind.
    pub subscriber_drops: u64,
}

/// A component a node has heard (its latest HEARTBEAT), as [`NodeReport::systems`] lists it.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct SystemReport {
    /// Its HEARTBEAT's fields, and when and where it came.
    pub heartbeat: SystemInfo,
    /// The configured link's name it came in on.
    pub link: String,
    /// The peer of that link it came from.
    pub peer: Option<String>,
    /// Milliseconds since that HEARTBEAT.
    pub age_ms: u64,
}

/// A frame that reached the node's own component (see [`Node::subscribe`]).
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Incoming {
    /// The name of the link it came in on.
    pub link: String,
    /// The router link (one peer of that link) it came from: answers sent with
    /// [`NodeHandle::send_on`] go back exactly there.
    pub link_id: LinkId,
    /// The frame, as the link's channel accepted it (version, signature, sequence, bytes).
    pub frame: ReceivedFrame,
}

/// Frames for the node, from [`Node::subscribe`]: a bounded queue; a subscriber that falls
/// more than 1,024 frames behind loses the newest ones (counted in
/// [`NodeReport::subscriber_drops`]).
pub type Subscription = mpsc::Receiver<Incoming>;

/// Something that happened on one of the node's links (see [`NodeHandle::events`]).
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct NodeEvent {
    /// The configured link's name.
    pub link: String,
    /// The router link (one peer of it).
    pub link_id: LinkId,
    /// What happened.
    pub kind: LinkEvent,
}

/// What [`NodeEvent`] reports.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum LinkEvent {
    /// A peer appeared (a UDP or TCP client of a server link, a connected `tcp` or
    /// `udpout` endpoint, a serial port opened).
    PeerAdded {
        /// Its address.
        peer: String,
    },
    /// A peer went away (a TCP client closed, a UDP client went quiet).
    PeerRemoved {
        /// Its address.
        peer: String,
    },
    /// The link's version changed.
    VersionChanged {
        /// Before.
        from: LinkVersion,
        /// After.
        to: LinkVersion,
        /// Why.
        cause: SwitchCause,
    },
    /// A vehicle link ([`LinkRole::Vehicle`]) was asked for PROTOCOL_VERSION.
    ProtocolVersionRequested {
        /// The requester (sysid, compid).
        from: (u8, u8),
        /// What the link answered.
        answer: ProtocolVersionAnswer,
    },
    /// A handshake started with [`NodeHandle::handshake`] ended.
    Handshake(HandshakeOutcome),
    /// A vehicle link applied a SETUP_SIGNING.
    SigningSetup {
        /// The sender (sysid, compid).
        from: (u8, u8),
        /// What changed.
        setup: SigningSetup,
    },
    /// The link refused a frame (bad signature, replay, unsigned on a signed link).
    Rejected(Rejected),
}

/// Events for the node's link events, from [`NodeHandle::events`]: a bounded queue like
/// [`Subscription`].
pub type EventSubscription = mpsc::Receiver<NodeEvent>;

/// How many frames a subscriber may fall behind.
const SUBSCRIPTION_DEPTH: usize = 1024;

/// Bytes as they arrived on a link, before any parsing (from [`NodeHandle::tap`]): a whole
/// datagram, or what one read of a stream returned.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Tapped {
    /// The router link of the peer they came from.
    pub link_id: LinkId,
    /// When they were read.
    pub at: Instant,
    /// The bytes.
    pub bytes: Vec<u8>,
    /// Whether they are a whole datagram (UDP: no frame continues in the next one) rather
    /// than a piece of a stream (TCP, serial).
    pub datagram: bool,
}

/// What a [`NodeHandle::tap`] receives: a bounded queue like [`Subscription`] (a tap that
/// falls behind misses input rather than slowing the node).
pub type TapSubscription = mpsc::Receiver<Tapped>;

enum Command {
    Report(oneshot::Sender<NodeReport>),
    Send {
        to: SendTo,
        msg_id: u32,
        payload: Vec<u8>,
        done: oneshot::Sender<usize>,
    },
    Subscribe(mpsc::Sender<Incoming>, oneshot::Sender<()>),
    Events(mpsc::Sender<NodeEvent>, oneshot::Sender<()>),
    Tap(mpsc::Sender<Tapped>, oneshot::Sender<()>),
    SendBytes {
        link: LinkId,
        bytes: Vec<u8>,
        done: oneshot::Sender<bool>,
    },
    Handshake {
        link: LinkId,
        target: Target,
        method: HandshakeMethod,
        encoding: CommandEncoding,
        done: oneshot::Sender<Result<(), HandshakeError>>,
    },
    SetSigning {
        link: LinkId,
        signing: Option<SigningConfig>,
        done: oneshot::Sender<Result<(), ConfigError>>,
    },
    Shutdown,
}

/// How to build a [`Node`].
///
/// ```no_run
/// # async fn run() -> Result<(), Box<dyn std::error::Error>> {
/// use mavstack::{LinkSpec, Node};
/// let none = |_: &str| None;
/// let node = Node::builder()
///     .link(LinkSpec::parse("udpin:0.0.0.0:14550?name=gcs", &none)?)
///     .link(LinkSpec::parse("serial:/dev/ttyS1:57600?version=1&name=legacy", &none)?)
///     .start()
///     .await?;
/// println!("{:?}", node.report().await);
/// node.shutdown().await?;
/// # Ok(()) }
/// ```
#[derive(Debug)]
pub struct NodeBuilder {
    router: RouterConfig,
    dialect: InfoFn,
    links: Vec<NewLink>,
    log_dir: Option<PathBuf>,
    options: Options,
    heartbeat: Option<(Vec<u8>, Duration)>,
    role: Option<LinkRole>,
    moderation: InputModeration,
    own_thread: bool,
    http: Option<SocketAddr>,
    /// Taps and event subscribers registered before the node starts.
    taps: Vec<mpsc::Sender<Tapped>>,
    watchers: Vec<mpsc::Sender<NodeEvent>>,
}

/// A link of a node that has not started: one to open, or one opened by the caller.
#[derive(Debug)]
enum NewLink {
    Spec(LinkSpec),
    Open(LinkConfig, Box<Link>),
}

impl NodeBuilder {
    /// A tap ([`NodeHandle::tap`]) that sees every input from the node's first datagram on:
    /// [`NodeHandle::tap`] on a started node misses what a quick peer sent before it was
    /// registered.
    #[must_use]
    pub fn with_tap(mut self) -> (Self, TapSubscription) {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        self.taps.push(tx);
        (self, rx)
    }

    /// Link events ([`NodeHandle::events`]) from the node's start on, none missed.
    #[must_use]
    pub fn with_events(mut self) -> (Self, EventSubscription) {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        self.watchers.push(tx);
        (self, rx)
    }

    /// Adds a link.
    #[must_use]
    pub fn link(mut self, spec: LinkSpec) -> Self {
        self.links.push(NewLink::Spec(spec));
        self
    }

    /// Adds a link the caller opened (a fleet bridge's [`Link::external`]), with its
    /// options; it takes its place among the links in the order added.
    #[must_use]
    pub fn opened_link(mut self, config: LinkConfig, link: Link) -> Self {
        self.links.push(NewLink::Open(config, Box::new(link)));
        self
    }

    /// The router's settings (route TTL, dedup, ids).
    #[must_use]
    pub fn router(mut self, config: RouterConfig) -> Self {
        self.router = config;
        self
    }

    /// The node's own system and component id (default 1/191, an onboard computer's), and
    /// frames addressed to it (or broadcast) delivered to [`Node::subscribe`]. Router
    /// settings given with [`router`](Self::router) afterwards replace these.
    #[must_use]
    pub fn identity(mut self, system_id: u8, component_id: u8) -> Self {
        self.router.system_id = system_id;
        self.router.component_id = component_id;
        if self.router.local == LocalDelivery::None {
            self.router.local = LocalDelivery::Addressed;
        }
        self
    }

    /// Sends `heartbeat` as the node's own component every `period` (MAVLink components
    /// send one a second), on every link, each in its own version and signing.
    #[must_use]
    pub fn heartbeat(
        mut self,
        heartbeat: &mavstack_dialects::common::Heartbeat,
        period: Duration,
    ) -> Self {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = heartbeat.encode(&mut payload);
        self.heartbeat = Some((
            payload[..len].to_vec(),
            period.max(Duration::from_millis(10)),
        ));
        self
    }

    /// Input moderation (default [`InputModeration::Timer`]): under more than 5,000
    /// datagrams a second the node reads in bursts, a millisecond apart, instead of waking
    /// for each datagram (a router's CPU per frame drops several times; a frame waits at
    /// most that millisecond more). Below 2,500 a second every datagram is read as it comes.
    #[must_use]
    pub const fn input_moderation(mut self, mode: InputModeration) -> Self {
        self.moderation = mode;
        self
    }

    /// Runs the node on a thread of its own (default off: a task of the runtime). Its UDP
    /// sockets are then watched by that thread's own level-triggered `epoll` instead of the
    /// runtime's reactor: a datagram goes from the wake-up through one `recvfrom` to the
    /// forwarded frames' `sendto` with no scheduler in between (the least latency and CPU per
    /// frame), for a process whose main work is the node (the `mavstack router` daemon). TCP,
    /// serial and file links, the handles' requests and the subscriptions stay on the runtime
    /// and wake the thread. Both kinds of [`InputModeration`] sleep that thread between
    /// bursts. Linux only: elsewhere the node stays a task.
    #[must_use]
    pub const fn own_thread(mut self, on: bool) -> Self {
        self.own_thread = on;
        self
    }

    /// Whether frames are forwarded between the node's links (default on; see
    /// `RouterConfig::forward`). Router settings given with [`router`](Self::router)
    /// afterwards replace this.
    #[must_use]
    pub const fn forwarding(mut self, on: bool) -> Self {
        self.router.forward = on;
        self
    }

    /// Whose links they are, for every link (default [`LinkRole::Relay`], or what each
    /// [`LinkSpec`] says): [`LinkRole::Vehicle`] makes the node's component answer the
    /// MAVLink 2 handshake and SETUP_SIGNING on each link by that link's rules.
    #[must_use]
    pub const fn role(mut self, role: LinkRole) -> Self {
        self.role = Some(role);
        self
    }

    /// The role set with [`role`](Self::role), if any.
    #[must_use]
    pub const fn link_role(&self) -> Option<LinkRole> {
        self.role
    }

    /// The dialect whose CRC_EXTRA, lengths and target offsets the links use (default
    /// `common`).
    #[must_use]
    pub const fn dialect(mut self, dialect: InfoFn) -> Self {
        self.dialect = dialect;
        self
    }

    /// Writes every accepted frame to a tlog in `dir` (`mavstack-YYYYmmdd-HHMMSS.tlog`,
    /// named by the start time), with the link number in the timestamps' low two bits as
    /// MAVProxy does (0, 1, 2 for the first three links, 2 for the rest).
    #[must_use]
    pub fn log_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.log_dir = Some(dir.into());
        self
    }

    /// Serves a read-only status page on `addr` (feature `http`): `GET /` a live page of
    /// the links (version, rates, drops, conversions), routes and systems heard;
    /// `GET /api/status` the same as one JSON object ([`crate::status::status_json`]);
    /// `GET /api/events` that object once a second as server-sent events. It has no
    /// authentication: give a loopback address unless the network is trusted.
    #[cfg(feature = "http")]
    #[must_use]
    pub const fn http(mut self, addr: SocketAddr) -> Self {
        self.http = Some(addr);
        self
    }

    /// Transport options (socket buffers, peer timeout, reconnect back-off).
    #[must_use]
    pub fn transport_options(mut self, options: Options) -> Self {
        self.options = options;
        self
    }

    /// Opens every link and starts the node's task on the current tokio runtime.
    ///
    /// # Errors
    /// [`NodeError::Open`] naming the first link that cannot be opened, or
    /// [`NodeError::Log`].
    ///
    /// # Panics
    /// Outside a tokio runtime.
    pub async fn start(self) -> Result<Node, NodeError> {
        let mut router_config = self.router;
        // The log sees every frame through local delivery; a node that wants none itself
        // only logs them.
        let log_local_only = self.log_dir.is_some() && router_config.local == LocalDelivery::None;
        if self.log_dir.is_some() {
            router_config.local = LocalDelivery::All;
        }
        let mut slots = Vec::new();
        let mut local_addrs = Vec::new();
        // A quiet UDP client stays a link (and keeps getting broadcasts) as long as its
        // routes would live.
        let mut options = self.options;
        options.peer_timeout = options.peer_timeout.max(router_config.route_ttl);
        // An endpoint that is not up yet is tried again, as mavlink-router does.
        options.keep_trying = true;
        for new in self.links {
            let (mut config, mut io) = match new {
                NewLink::Spec(spec) => {
                    let io = Link::open(&spec.conn, &options).await.map_err(|source| {
                        NodeError::Open {
                            name: spec.config.name.clone(),
                            source,
                        }
                    })?;
                    (spec.config, io)
                }
                NewLink::Open(config, io) => (config, *io),
            };
            if let Some(role) = self.role {
                config.role = role;
            }
            io.set_packing(config.pack);
            local_addrs.push(io.local_addr());
            slots.push(Slot {
                io,
                template: config,
                peers: PeerLinks::default(),
            });
        }
        let log = match self.log_dir {
            Some(dir) => Some(open_log(&dir)?),
            None => None,
        };
        let http = match self.http {
            Some(addr) => Some(
                tokio::net::TcpListener::bind(addr)
                    .await
                    .map_err(|source| NodeError::Http { addr, source })?,
            ),
            None => None,
        };
        let (tx, rx) = mpsc::channel(64);
        let driver = Driver {
            router: Router::new(router_config, self.dialect),
            slots,
            owners: Vec::new(),
            commands: rx,
            log,
            log_local_only,
            started: clock::now(),
            buf: [0; MAX_FRAME_LEN],
            subscribers: Vec::new(),
            subscriber_drops: 0,
            watchers: self.watchers,
            pending: Vec::new(),
            taps: self.taps,
            moderation: Moderation::new(self.moderation, clock::now()),
            heartbeat: self.heartbeat.map(|(payload, period)| Heartbeat {
                payload,
                period,
                next: clock::now(),
            }),
        };
        let identity = (
            driver.router.config().system_id,
            driver.router.config().component_id,
        );
        #[cfg(target_os = "linux")]
        let task = if self.own_thread {
            let runtime = tokio::runtime::Handle::current();
            tokio::task::spawn_blocking(move || driver.run_on_thread(&runtime))
        } else {
            tokio::spawn(driver.run())
        };
        #[cfg(not(target_os = "linux"))]
        let task = tokio::spawn(driver.run());
        let node = Node {
            commands: tx,
            task,
            local_addrs,
            identity,
            http_addr: http.as_ref().and_then(|l| l.local_addr().ok()),
        };
        #[cfg(feature = "http")]
        if let Some(listener) = http {
            tokio::spawn(crate::status::serve(listener, node.handle()));
        }
        #[cfg(not(feature = "http"))]
        drop(http);
        Ok(node)
    }
}

fn open_log(dir: &std::path::Path) -> Result<(PathBuf, tlog::Writer<std::fs::File>), NodeError> {
    let secs = clock::now().as_micros() / 1_000_000;
    let path = dir.join(format!("mavstack-{secs}.tlog"));
    let file = std::fs::File::create(&path).map_err(|source| NodeError::Log {
        path: path.clone(),
        source,
    })?;
    Ok((path, tlog::Writer::new(file)))
}

/// A running node: a handle on its task.
#[derive(Debug)]
pub struct Node {
    commands: mpsc::Sender<Command>,
    task: JoinHandle<Result<NodeReport, NodeError>>,
    local_addrs: Vec<Option<SocketAddr>>,
    identity: (u8, u8),
    http_addr: Option<SocketAddr>,
}

impl Node {
    /// How to build one.
    #[must_use]
    pub fn builder() -> NodeBuilder {
        NodeBuilder {
            router: RouterConfig::default(),
            dialect: InfoFn(|id| {
                <mavstack_dialects::common::MavMessage as MessageSet>::info(id).copied()
            }),
            links: Vec::new(),
            log_dir: None,
            options: Options::default(),
            heartbeat: None,
            role: None,
            moderation: InputModeration::Timer,
            own_thread: false,
            http: None,
            taps: Vec::new(),
            watchers: Vec::new(),
        }
    }

    /// How to build a ground station's node: system `system_id`, component `component_id`,
    /// ground-station links (they run the MAVLink 2 handshake; [`LinkRole::GroundStation`]),
    /// and a ground station's HEARTBEAT (MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, ACTIVE) every
    /// second. Add links and start it.
    #[must_use]
    pub fn ground_station(system_id: u8, component_id: u8) -> NodeBuilder {
        use mavstack_dialects::common::{Heartbeat, MavAutopilot, MavState, MavType};
        let heartbeat = Heartbeat {
            r#type: MavType::GCS,
            autopilot: MavAutopilot::INVALID,
            system_status: MavState::ACTIVE,
            mavlink_version: 3,
            ..Heartbeat::default()
        };
        Self::builder()
            .identity(system_id, component_id)
            .role(LinkRole::GroundStation)
            .heartbeat(&heartbeat, Duration::from_secs(1))
    }

    /// The local address of each link, in the order they were added (UDP sockets and TCP
    /// listeners; useful after binding port 0).
    #[must_use]
    pub fn local_addrs(&self) -> &[Option<SocketAddr>] {
        &self.local_addrs
    }

    /// The address the status page listens on (see [`NodeBuilder::http`]), if any.
    #[must_use]
    pub const fn http_addr(&self) -> Option<SocketAddr> {
        self.http_addr
    }

    /// A snapshot of every link and route; `None` once the node has stopped.
    pub async fn report(&self) -> Option<NodeReport> {
        let (tx, rx) = oneshot::channel();
        self.commands.send(Command::Report(tx)).await.ok()?;
        rx.await.ok()
    }

    /// A handle for other tasks: it sends, subscribes and reports like the node, and can be
    /// cloned; the node stops only through [`shutdown`](Self::shutdown).
    #[must_use]
    pub fn handle(&self) -> NodeHandle {
        NodeHandle {
            commands: self.commands.clone(),
            identity: self.identity,
        }
    }

    /// See [`NodeHandle::send`].
    pub async fn send<M: Message>(&self, message: &M) -> usize {
        self.handle().send(message).await
    }

    /// See [`NodeHandle::subscribe`].
    pub async fn subscribe(&self) -> Subscription {
        self.handle().subscribe().await
    }

    /// Whether the node's task has ended (a link failed).
    #[must_use]
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Resolves when the node's task has ended on its own (a link failed); then
    /// [`shutdown`](Self::shutdown) says why.
    pub async fn closed(&self) {
        self.commands.closed().await;
    }

    /// Stops the node: queued frames go out, links close, the log is written out.
    /// Returns the final report.
    ///
    /// # Errors
    /// [`NodeError`] if a link failed or the log could not be written.
    pub async fn shutdown(self) -> Result<NodeReport, NodeError> {
        let _ = self.commands.send(Command::Shutdown).await;
        self.task
            .await
            .map_err(|e| NodeError::Stopped(e.to_string()))?
    }
}

/// A cloneable handle on a running [`Node`] (from [`Node::handle`]).
#[derive(Clone, Debug)]
pub struct NodeHandle {
    commands: mpsc::Sender<Command>,
    identity: (u8, u8),
}

impl NodeHandle {
    /// The node's own (system id, component id).
    #[must_use]
    pub const fn identity(&self) -> (u8, u8) {
        self.identity
    }

    /// Sends `message` as the node's own component: on the links its target fields lead to
    /// (every link for a broadcast or a system not heard yet), each link framing it in its
    /// own version and signing it when it signs (see `mavstack_router::Router::send`).
    /// Returns on how many links it was queued; 0 once the node has stopped.
    pub async fn send<M: Message>(&self, message: &M) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Target, M::ID, payload[..len].to_vec())
            .await
    }

    /// Like [`send`](Self::send), for a message of a dialect's enum (`MavMessage`).
    pub async fn send_message<S: MessageSet>(&self, message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Target, message.id(), payload[..len].to_vec())
            .await
    }

    /// Like [`send_message`](Self::send_message), sent where component `(sysid, compid)`
    /// was heard as if the message were addressed to it: an answer without target fields
    /// (PARAM_VALUE for a read or a set) goes back to the link the request came from.
    pub async fn send_answer<S: MessageSet>(&self, to: (u8, u8), message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(
            SendTo::Component(to.0, to.1),
            message.id(),
            payload[..len].to_vec(),
        )
        .await
    }

    /// Like [`send_message`](Self::send_message), onto one router link only (the one an
    /// [`Incoming`] or a [`NodeEvent`] names); 0 if it is gone.
    pub async fn send_on<S: MessageSet>(&self, link: LinkId, message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Link(link), message.id(), payload[..len].to_vec())
            .await
    }

    async fn send_payload(&self, to: SendTo, msg_id: u32, payload: Vec<u8>) -> usize {
        let (done, rx) = oneshot::channel();
        let command = Command::Send {
            to,
            msg_id,
            payload,
            done,
        };
        if self.commands.send(command).await.is_err() {
            return 0;
        }
        rx.await.unwrap_or(0)
    }

    /// Every frame that reaches the node's component from now on: addressed to it or
    /// broadcast (with [`NodeBuilder::identity`]; everything the router delivers locally
    /// otherwise). Dropping the receiver unsubscribes.
    pub async fn subscribe(&self) -> Subscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self
            .commands
            .send(Command::Subscribe(tx, done))
            .await
            .is_ok()
        {
            // Registered before this returns: nothing that arrives later is missed.
            let _ = registered.await;
        }
        rx
    }

    /// A copy of every input from now on, as it arrived on its link, before any parsing:
    /// for tools that judge the wire itself (checksums, framing, sequence numbers), such as
    /// `mavstack conform`. Dropping the receiver ends the tap.
    pub async fn tap(&self) -> TapSubscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self.commands.send(Command::Tap(tx, done)).await.is_ok() {
            let _ = registered.await;
        }
        rx
    }

    /// Writes `bytes` on `link` exactly as given: no framing by the link's version, no
    /// signing, no sequence number. For test tools that craft frames (a MAVLink 2 frame on a
    /// link still in MAVLink 1, a deliberately bad one); everything else goes through
    /// [`send_on`](Self::send_on). Returns whether the link exists.
    pub async fn send_bytes(&self, link: LinkId, bytes: &[u8]) -> bool {
        let (done, rx) = oneshot::channel();
        let command = Command::SendBytes {
            link,
            bytes: bytes.to_vec(),
            done,
        };
        if self.commands.send(command).await.is_err() {
            return false;
        }
        rx.await.unwrap_or(false)
    }

    /// Runs the MAVLink 2 handshake with `target` on `link` (a
    /// [`LinkRole::GroundStation`] link) and waits for its outcome: PROTOCOL_VERSION (the
    /// link is MAVLink 2 now), a NACK, or no answer after the retries.
    ///
    /// # Errors
    /// [`RequestError::Handshake`] if it cannot start there, [`RequestError::Stopped`].
    pub async fn handshake(
        &self,
        link: LinkId,
        target: Target,
        method: HandshakeMethod,
        encoding: CommandEncoding,
    ) -> Result<HandshakeOutcome, RequestError> {
        let mut events = self.events().await;
        let (done, started) = oneshot::channel();
        let command = Command::Handshake {
            link,
            target,
            method,
            encoding,
            done,
        };
        self.commands
            .send(command)
            .await
            .map_err(|_| RequestError::Stopped)?;
        started.await.map_err(|_| RequestError::Stopped)??;
        while let Some(event) = events.recv().await {
            if let NodeEvent {
                link_id,
                kind: LinkEvent::Handshake(outcome),
                ..
            } = event
                && link_id == link
            {
                return Ok(outcome);
            }
        }
        Err(RequestError::Stopped)
    }

    /// Turns signing on or off on `link` (after sending SETUP_SIGNING to the peer, for one).
    ///
    /// # Errors
    /// [`RequestError::Signing`] on a `version=1` link, [`RequestError::Stopped`].
    pub async fn set_signing(
        &self,
        link: LinkId,
        signing: Option<SigningConfig>,
    ) -> Result<(), RequestError> {
        let (done, rx) = oneshot::channel();
        self.commands
            .send(Command::SetSigning {
                link,
                signing,
                done,
            })
            .await
            .map_err(|_| RequestError::Stopped)?;
        Ok(rx.await.map_err(|_| RequestError::Stopped)??)
    }

    /// Every link event from now on (peers, version changes, handshakes answered, signing
    /// set up, frames refused). Dropping the receiver unsubscribes.
    pub async fn events(&self) -> EventSubscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self.commands.send(Command::Events(tx, done)).await.is_ok() {
            let _ = registered.await;
        }
        rx
    }

    /// A snapshot of every link and route; `None` once the node has stopped.
    pub async fn report(&self) -> Option<NodeReport> {
        let (tx, rx) = oneshot::channel();
        self.commands.send(Command::Report(tx)).await.ok()?;
        rx.await.ok()
    }

    /// Resolves when the node has stopped.
    pub async fn closed(&self) {
        self.commands.closed().await;
    }
}

/// A link's peers: their router link, framing and address, looked up per input (foldhash
/// instead of SipHash).
type PeerLinks = HashMap<PeerId, (LinkId, Framing, String), foldhash::fast::RandomState>;

/// One configured link and the router links of its peers.
struct Slot {
    io: Link,
    template: LinkConfig,
    peers: PeerLinks,
}

struct Driver {
    router: Router<InfoFn>,
    slots: Vec<Slot>,
    /// Router link → (slot, peer).
    owners: Vec<Option<(usize, PeerId)>>,
    commands: mpsc::Receiver<Command>,
    log: Option<(PathBuf, tlog::Writer<std::fs::File>)>,
    log_local_only: bool,
    started: Instant,
    buf: [u8; MAX_FRAME_LEN],
    subscribers: Vec<mpsc::Sender<Incoming>>,
    subscriber_drops: u64,
    watchers: Vec<mpsc::Sender<NodeEvent>>,
    /// Peer events of the last dispatch, for the watchers.
    pending: Vec<NodeEvent>,
    taps: Vec<mpsc::Sender<Tapped>>,
    heartbeat: Option<Heartbeat>,
    moderation: Moderation,
}

/// How a node reads under a steady stream of input (see [`NodeBuilder::input_moderation`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum InputModeration {
    /// Every datagram is read as it comes.
    Off,
    /// Woken by a datagram, the node waits a millisecond on a tokio timer for the next ones,
    /// then reads and forwards them all at once. Friendly to other tasks on the runtime; the
    /// thread still wakes for each datagram's readiness during the wait.
    #[default]
    Timer,
    /// After reading a burst, the node's thread sleeps a millisecond (blocking it: no
    /// wake-ups at all while datagrams pile up in the socket buffer), then reads them all.
    /// For a node on a runtime of its own (the `mavstack router` daemon): other tasks on that
    /// thread wait for the millisecond too.
    Sleep,
}

/// Input moderation, as network cards do it: under a steady stream of input (more than
/// [`Moderation::BUSY_ABOVE`] datagrams a second) the node reads in bursts, one wake-up for
/// many frames instead of one each, at the price of at most [`Moderation::PAUSE`] of added
/// latency while the stream lasts. Below [`Moderation::CALM_BELOW`] a second it reads each
/// datagram as it comes.
#[derive(Debug)]
struct Moderation {
    mode: InputModeration,
    /// Since when `inputs` counts.
    since: Instant,
    inputs: u64,
    busy: bool,
}

impl Moderation {
    /// Inputs per second from which the node moderates.
    const BUSY_ABOVE: u64 = 5_000;
    /// Inputs per second under which it stops.
    const CALM_BELOW: u64 = 2_500;
    /// How often the rate is measured (a stream that stops is seen within this).
    const MEASURE: Duration = Duration::from_millis(10);
    /// The wait (tokio's timers tick in milliseconds).
    const PAUSE: Duration = Duration::from_millis(1);
    /// Inputs in one turn from which the node reads on without sleeping (the stream brings
    /// more than this in a pause).
    const BIG_BURST: u64 = 128;

    const fn new(mode: InputModeration, now: Instant) -> Self {
        Self {
            mode,
            since: now,
            inputs: 0,
            busy: false,
        }
    }

    /// After a turn: whether [`InputModeration::Sleep`] sleeps through the next
    /// [`Moderation::PAUSE`] (busy, something was done, and the turn's burst was small
    /// enough for a pause to gather more; a burst of [`Moderation::BIG_BURST`] means the
    /// stream outruns the pause: read on).
    fn pause_after(&self, busy: bool, worked: bool, inputs_before: u64) -> bool {
        let burst = self.inputs.saturating_sub(inputs_before);
        busy && worked && burst < Self::BIG_BURST && self.mode == InputModeration::Sleep
    }

    /// Updates the rate; whether the stream is steady enough to read in bursts.
    fn busy(&mut self, now: Instant) -> bool {
        let elapsed = now.saturating_duration_since(self.since);
        if elapsed >= Self::MEASURE {
            let per_s = self.inputs.saturating_mul(1_000_000) / (elapsed.as_micros().max(1) as u64);
            self.busy = if self.busy {
                per_s >= Self::CALM_BELOW
            } else {
                per_s > Self::BUSY_ABOVE
            };
            self.since = now;
            self.inputs = 0;
        }
        self.mode != InputModeration::Off && self.busy
    }
}

/// What a driver turn leaves to do.
enum Turn {
    /// Wait for the next input; `worked`: the turn did something (it found input, a command
    /// or a due timer).
    Go { worked: bool },
    /// Shut down.
    Stop,
}

/// The node's own HEARTBEAT: its encoded payload, period and next time.
struct Heartbeat {
    payload: Vec<u8>,
    period: Duration,
    next: Instant,
}

/// The [`Input`] a slot's link feeds: peers become router links.
struct Feed<'a> {
    router: &'a mut Router<InfoFn>,
    slot: usize,
    template: &'a LinkConfig,
    peers: &'a mut PeerLinks,
    owners: &'a mut Vec<Option<(usize, PeerId)>>,
    /// Peer events, when someone watches.
    pending: Option<&'a mut Vec<NodeEvent>>,
    /// Inputs (datagrams, stream reads) fed, for [`Moderation`].
    inputs: &'a mut u64,
    /// Who gets a copy of every input.
    taps: &'a mut Vec<mpsc::Sender<Tapped>>,
}

impl Input for Feed<'_> {
    fn handle_peer_added(&mut self, _now: Instant, peer: &PeerInfo) {
        match self.router.add_link(self.template.clone()) {
            Ok(id) => {
                tracing::debug!("{}: {} is {id}", self.template.name, peer.addr);
                self.peers
                    .insert(peer.id, (id, peer.framing, peer.addr.to_string()));
                if self.owners.len() <= id.index() {
                    self.owners.resize(id.index() + 1, None);
                }
                self.owners[id.index()] = Some((self.slot, peer.id));
                if let Some(pending) = &mut self.pending {
                    pending.push(NodeEvent {
                        link: self.template.name.clone(),
                        link_id: id,
                        kind: LinkEvent::PeerAdded {
                            peer: peer.addr.to_string(),
                        },
                    });
                }
            }
            Err(e) => tracing::warn!("{}: {e}", self.template.name),
        }
    }

    fn handle_peer_removed(&mut self, _now: Instant, peer: PeerId) {
        if let Some((id, _, addr)) = self.peers.remove(&peer) {
            tracing::debug!("{}: {addr} went away", self.template.name);
            self.router.remove_link(id);
            if let Some(o) = self.owners.get_mut(id.index()) {
                *o = None;
            }
            if let Some(pending) = &mut self.pending {
                pending.push(NodeEvent {
                    link: self.template.name.clone(),
                    link_id: id,
                    kind: LinkEvent::PeerRemoved { peer: addr },
                });
            }
        }
    }

    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]) {
        *self.inputs += 1;
        if let Some(&(id, framing, _)) = self.peers.get(&peer) {
            if !self.taps.is_empty() {
                self.taps.retain(|t| !t.is_closed());
                for t in self.taps.iter() {
                    let _ = t.try_send(Tapped {
                        link_id: id,
                        at: now,
                        bytes: data.to_vec(),
                        datagram: framing == Framing::Datagram,
                    });
                }
            }
            match framing {
                Framing::Datagram => self.router.handle_datagram(now, id, data),
                Framing::Stream => self.router.handle_input(now, id, data),
            }
        }
    }
}

impl Driver {
    fn feed(&mut self, i: usize) -> (&mut Link, Feed<'_>) {
        let slot = &mut self.slots[i];
        (
            &mut slot.io,
            Feed {
                router: &mut self.router,
                slot: i,
                template: &slot.template,
                peers: &mut slot.peers,
                owners: &mut self.owners,
                pending: (!self.watchers.is_empty()).then_some(&mut self.pending),
                inputs: &mut self.moderation.inputs,
                taps: &mut self.taps,
            },
        )
    }

    fn start_links(&mut self) {
        for i in 0..self.slots.len() {
            let (io, mut feed) = self.feed(i);
            io.start(&mut feed);
        }
    }

    /// The node as a task of the runtime: the runtime's reactor watches the sockets.
    async fn run(mut self) -> Result<NodeReport, NodeError> {
        self.start_links();
        let mut ready = vec![false; self.slots.len()];
        let sleep = tokio::time::sleep(Duration::from_secs(3600));
        tokio::pin!(sleep);
        let mut armed: Option<Instant> = None;
        let mut timer_fired = false;
        let result = loop {
            let deadline = self.next_deadline(clock::now());
            // Re-arming the timer costs a trip through the runtime's timer wheel: only when the
            // deadline moved (or after it fired).
            if let Some(d) = deadline
                && (armed != Some(d) || timer_fired)
            {
                sleep.as_mut().reset(clock::to_tokio(d));
                armed = Some(d);
            }
            let mut command = None;
            let mut timer = false;
            let mut waited = false;
            core::future::poll_fn(|cx| {
                let mut any = self.poll_inputs(cx, &mut ready, &mut command);
                if deadline.is_some() && sleep.as_mut().poll(cx).is_ready() {
                    timer = true;
                    any = true;
                }
                if any {
                    core::task::Poll::Ready(())
                } else {
                    waited = true;
                    core::task::Poll::Pending
                }
            })
            .await;
            // Woken from idle under a steady stream: let the next datagrams arrive first.
            let input = ready.iter().any(|&r| r);
            let busy = input && self.moderation.busy(clock::now());
            let inputs_before = self.moderation.inputs;
            if busy && waited && self.moderation.mode == InputModeration::Timer {
                tokio::time::sleep(Moderation::PAUSE).await;
            }
            timer_fired = timer;
            let worked = match self.turn(&mut ready, command, timer) {
                Ok(Turn::Go { worked }) => worked,
                Ok(Turn::Stop) => break Ok(()),
                Err(e) => break Err(e),
            };
            if self.moderation.pause_after(busy, worked, inputs_before) {
                // Sleep through the next millisecond of the stream, then let the runtime
                // look at the sockets (the yield below) and read it all in one turn.
                std::thread::sleep(Moderation::PAUSE);
                tokio::task::yield_now().await;
            } else if !waited && worked {
                // Busy (a link always has input): let the runtime poll its I/O driver, so
                // the other sockets' readiness is seen, and run its other tasks (signals,
                // statistics). One flooding link cannot starve the rest. (A turn that found
                // nothing, a drained socket's last look, goes straight back to waiting.)
                tokio::task::yield_now().await;
            }
            if let Some(e) = self.failed() {
                break Err(e);
            }
        };
        self.finish(result).await
    }

    /// The node on a thread of its own (see [`NodeBuilder::own_thread`]): its UDP sockets
    /// move to an `epoll` this thread waits on; the other links' tasks, the handles' commands
    /// and the subscribers stay on `runtime`, and wake the poll through its waker.
    #[cfg(target_os = "linux")]
    fn run_on_thread(mut self, runtime: &tokio::runtime::Handle) -> Result<NodeReport, NodeError> {
        let result = self.run_polled();
        runtime.block_on(self.finish(result))
    }

    #[cfg(target_os = "linux")]
    fn run_polled(&mut self) -> Result<(), NodeError> {
        let polling = |source: std::io::Error| NodeError::Poll { source };
        let mut waiter = crate::own_thread::Waiter::new().map_err(polling)?;
        for (i, slot) in self.slots.iter_mut().enumerate() {
            if let Some(fd) = slot.io.watch_externally().map_err(polling)? {
                waiter.watch(fd, i).map_err(polling)?;
            }
        }
        let waker = waiter.waker().clone();
        let mut cx = core::task::Context::from_waker(&waker);
        self.start_links();
        let mut ready = vec![false; self.slots.len()];
        let mut bulk = false;
        loop {
            let mut command = None;
            let mut waited = false;
            // Waiting changes none of the node's deadlines: worked out once per turn.
            let mut deadline = None;
            let (timer, now) = loop {
                let any = self.poll_inputs(&mut cx, &mut ready, &mut command);
                let now = clock::now();
                let deadline = *deadline.get_or_insert_with(|| self.next_deadline(now));
                let due = deadline.is_some_and(|d| now >= d);
                let slots = &mut self.slots;
                let mut mark = |i: usize| {
                    if let Some(slot) = slots.get_mut(i) {
                        slot.io.set_readable();
                    }
                };
                if any || due {
                    if !waited {
                        // Input left from the last turn: the other sockets' readiness is
                        // looked at too, so that a link that always has more cannot starve
                        // them (one `epoll_wait` more per turn, only while input is left).
                        waiter.look(&mut mark).map_err(polling)?;
                        self.poll_inputs(&mut cx, &mut ready, &mut command);
                    }
                    break (due, now);
                }
                waited = true;
                waiter.wait(deadline, now, mark).map_err(polling)?;
            };
            let input = ready.iter().any(|&r| r);
            let busy = input && self.moderation.busy(now);
            // Under a steady stream the sockets are read in batches (one datagram per read
            // otherwise: the cheapest read, and the frame goes on at once).
            if self.moderation.busy != bulk {
                bulk = self.moderation.busy;
                for slot in &mut self.slots {
                    slot.io.set_bulk_reads(bulk);
                }
            }
            let inputs_before = self.moderation.inputs;
            // Under a steady stream the thread reads in bursts: nothing else runs on it, so
            // both kinds of moderation sleep it (no wake-ups while datagrams pile up).
            if busy && waited && self.moderation.mode == InputModeration::Timer {
                std::thread::sleep(Moderation::PAUSE);
            }
            let Turn::Go { worked } = self.turn(&mut ready, command, timer)? else {
                return Ok(());
            };
            if self.moderation.pause_after(busy, worked, inputs_before) {
                std::thread::sleep(Moderation::PAUSE);
            }
            if let Some(e) = self.failed() {
                return Err(e);
            }
        }
    }

    /// Polls every running link and the command queue with `cx`; marks the links that may
    /// have input in `ready` and takes a command. Whether anything was ready.
    fn poll_inputs(
        &mut self,
        cx: &mut core::task::Context<'_>,
        ready: &mut [bool],
        command: &mut Option<Option<Command>>,
    ) -> bool {
        let mut any = false;
        for (slot, r) in self.slots.iter_mut().zip(ready.iter_mut()) {
            if slot.io.finished().is_none() && slot.io.poll_ready(cx).is_ready() {
                *r = true;
                any = true;
            }
        }
        if command.is_none()
            && let core::task::Poll::Ready(c) = self.commands.poll_recv(cx)
        {
            *command = Some(c);
            any = true;
        }
        any
    }

    /// One turn after a wake-up: reads the ready links, runs what is due, forwards, and
    /// carries out `command` (`Some(None)`: every handle is gone).
    fn turn(
        &mut self,
        ready: &mut [bool],
        command: Option<Option<Command>>,
        timer: bool,
    ) -> Result<Turn, NodeError> {
        let mut worked = command.is_some() || timer;
        for (i, r) in ready.iter_mut().enumerate() {
            if core::mem::take(r) {
                let (io, mut feed) = self.feed(i);
                worked |= io.dispatch(&mut feed);
            }
        }
        let now = clock::now();
        if let Some(hb) = &mut self.heartbeat
            && now >= hb.next
        {
            hb.next = now + hb.period;
            self.router.send(
                now,
                SendTo::Target,
                mavstack_dialects::common::Heartbeat::ID,
                &hb.payload,
            );
        }
        if timer {
            self.router.handle_timeout(now);
            for i in 0..self.slots.len() {
                if self.slots[i]
                    .io
                    .next_housekeeping()
                    .is_some_and(|t| now >= t)
                {
                    let (io, mut feed) = self.feed(i);
                    io.housekeeping(&mut feed);
                }
            }
        }
        self.drain_events()?;
        self.flush();
        match command {
            Some(Some(Command::Report(tx))) => {
                let _ = tx.send(self.report(clock::now()));
            }
            Some(Some(Command::Send {
                to,
                msg_id,
                payload,
                done,
            })) => {
                let queued = self.router.send(clock::now(), to, msg_id, &payload);
                self.flush();
                let _ = done.send(queued);
            }
            Some(Some(Command::Subscribe(tx, done))) => {
                self.subscribers.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::Events(tx, done))) => {
                self.watchers.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::Tap(tx, done))) => {
                self.taps.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::SendBytes { link, bytes, done })) => {
                let sent = match self.owners.get(link.index()) {
                    Some(Some((slot, peer))) => {
                        let io = &mut self.slots[*slot].io;
                        io.send(Dest::Peer(*peer), &bytes);
                        io.flush();
                        true
                    }
                    _ => false,
                };
                let _ = done.send(sent);
            }
            Some(Some(Command::Handshake {
                link,
                target,
                method,
                encoding,
                done,
            })) => {
                let started =
                    self.router
                        .start_handshake(clock::now(), link, target, method, encoding);
                self.flush();
                let _ = done.send(started);
            }
            Some(Some(Command::SetSigning {
                link,
                signing,
                done,
            })) => {
                let set = self.router.set_signing(clock::now(), link, signing);
                self.drain_events()?;
                let _ = done.send(set);
            }
            Some(Some(Command::Shutdown) | None) => return Ok(Turn::Stop),
            None => {}
        }
        Ok(Turn::Go { worked })
    }

    /// The error of the first link that failed.
    fn failed(&self) -> Option<NodeError> {
        self.slots.iter().find_map(|s| match s.io.finished() {
            Some(Err(e)) => Some(NodeError::Link {
                name: s.template.name.clone(),
                source: e.clone(),
            }),
            _ => None,
        })
    }

    /// Sends what is queued, closes the links, writes out the log; the final report.
    async fn finish(mut self, result: Result<(), NodeError>) -> Result<NodeReport, NodeError> {
        self.flush();
        for slot in &mut self.slots {
            if let Err(e) = slot.io.shutdown().await {
                tracing::warn!("{}: {e}", slot.template.name);
            }
        }
        if let Some((path, log)) = &mut self.log {
            log.flush().map_err(|source| NodeError::Log {
                path: path.clone(),
                source,
            })?;
        }
        result.map(|()| self.report(clock::now()))
    }

    fn next_deadline(&self, now: Instant) -> Option<Instant> {
        let housekeeping = self
            .slots
            .iter()
            .filter_map(|s| s.io.next_housekeeping())
            .min();
        let log = self
            .log
            .as_ref()
            .and_then(|(_, w)| w.flush_deadline())
            .map(|_| now + Duration::from_secs(1));
        let heartbeat = self.heartbeat.as_ref().map(|h| h.next);
        [self.router.poll_timeout(), housekeeping, log, heartbeat]
            .into_iter()
            .flatten()
            .min()
    }

    fn drain_events(&mut self) -> Result<(), NodeError> {
        while let Some(event) = self.router.poll_event() {
            match event {
                Event::Local { link, frame } => {
                    if let Some((path, log)) = &mut self.log {
                        let slot = self
                            .owners
                            .get(link.index())
                            .copied()
                            .flatten()
                            .map_or(2, |(s, _)| s);
                        let bits = slot.min(2) as u64;
                        let ts = (frame.received_at.as_micros() & !3) | bits;
                        log.write_record(ts, frame.frame.as_bytes())
                            .map_err(|source| NodeError::Log {
                                path: path.clone(),
                                source,
                            })?;
                    }
                    if self.log_local_only || self.subscribers.is_empty() {
                        continue;
                    }
                    let name = self.link_label(link);
                    let incoming = Incoming {
                        link: name,
                        link_id: link,
                        frame,
                    };
                    self.subscribers.retain(|s| !s.is_closed());
                    for s in &self.subscribers {
                        if s.try_send(incoming.clone()).is_err() {
                            self.subscriber_drops += 1;
                        }
                    }
                }
                Event::VersionChanged {
                    link,
                    from,
                    to,
                    cause,
                } => {
                    tracing::info!("{}: {from} → {to} ({cause})", self.link_label(link));
                    self.tell(link, LinkEvent::VersionChanged { from, to, cause });
                }
                Event::Rejected { link, rejected } => {
                    tracing::debug!("{}: rejected {:?}", self.link_label(link), rejected.reason);
                    self.tell(link, LinkEvent::Rejected(rejected));
                }
                Event::ProtocolVersionRequested { link, from, answer } => {
                    tracing::info!("{}: handshake request: {answer}", self.link_label(link));
                    self.tell(link, LinkEvent::ProtocolVersionRequested { from, answer });
                }
                Event::Handshake { link, outcome } => {
                    tracing::info!(
                        "{}: handshake: {}",
                        self.link_label(link),
                        outcome.result.name()
                    );
                    self.tell(link, LinkEvent::Handshake(outcome));
                }
                Event::SigningSetup { link, from, setup } => {
                    tracing::info!("{}: SETUP_SIGNING applied", self.link_label(link));
                    self.tell(link, LinkEvent::SigningSetup { from, setup });
                }
                _ => {}
            }
        }
        let pending = core::mem::take(&mut self.pending);
        for event in pending {
            self.publish(event);
        }
        if let Some((path, log)) = &mut self.log {
            log.flush_if_due().map_err(|source| NodeError::Log {
                path: path.clone(),
                source,
            })?;
        }
        Ok(())
    }

    /// Tells the watchers what happened on `link`.
    fn tell(&mut self, link: LinkId, kind: LinkEvent) {
        if self.watchers.is_empty() {
            return;
        }
        let event = NodeEvent {
            link: self.link_label(link),
            link_id: link,
            kind,
        };
        self.publish(event);
    }

    fn publish(&mut self, event: NodeEvent) {
        self.watchers.retain(|w| !w.is_closed());
        for w in &self.watchers {
            if w.try_send(event.clone()).is_err() {
                self.subscriber_drops += 1;
            }
        }
    }

    fn link_label(&self, link: LinkId) -> String {
        self.router
            .link_config(link)
            .map_or_else(|| link.to_string(), |c| c.name.clone())
    }

    /// Writes every queued frame to its link, then sends the batches.
    fn flush(&mut self) {
        while let Some(t) = self.router.poll_transmit(&mut self.buf) {
            if let Some(Some((slot, peer))) = self.owners.get(t.link.index()) {
                self.slots[*slot]
                    .io
                    .send(Dest::Peer(*peer), &self.buf[..t.len]);
            }
        }
        for slot in &mut self.slots {
            slot.io.flush();
        }
    }

    fn report(&self, now: Instant) -> NodeReport {
        let mut links = Vec::new();
        let mut names: HashMap<LinkId, (String, Option<String>)> = HashMap::new();
        for slot in &self.slots {
            if slot.peers.is_empty() {
                links.push(LinkReport {
                    name: slot.template.name.clone(),
                    link_id: None,
                    peer: None,
                    version: mode_of(&slot.template).as_str(),
                    rx_frames: 0,
                    rx_bytes: 0,
                    tx_frames: 0,
                    tx_bytes: 0,
                    converted: 0,
                    conversions: conversions(&mavstack_router::Conversions::default()),
                    dropped: Vec::new(),
                    seq_lost: 0,
                    sources: Vec::new(),
                });
            }
            let mut peers: Vec<_> = slot.peers.values().collect();
            peers.sort_by_key(|(id, _, _)| *id);
            for (id, _, addr) in peers {
                let Some(status) = self.router.link_status(*id) else {
                    continue;
                };
                let peer = Some(addr.clone());
                names.insert(*id, (slot.template.name.clone(), peer.clone()));
                let c = &status.counters;
                links.push(LinkReport {
                    name: slot.template.name.clone(),
                    link_id: Some(*id),
                    peer,
                    version: status.mode.as_str(),
                    rx_frames: c.rx_frames,
                    rx_bytes: c.rx_bytes,
                    tx_frames: c.tx_frames,
                    tx_bytes: c.tx_bytes,
                    converted: c.converted,
                    conversions: conversions(&c.conversions),
                    dropped: status.drops().into_iter().filter(|(_, n)| *n > 0).collect(),
                    seq_lost: status.channel.lost,
                    sources: self.router.channel(*id).map_or_else(Vec::new, |ch| {
                        ch.sources()
                            .iter()
                            .map(|s| (s.sysid, s.compid, s.received, s.lost))
                            .collect()
                    }),
                });
            }
        }
        let routes = self
            .router
            .routes()
            .map(|r| {
                let (name, peer) = names.get(&r.link).cloned().unwrap_or_default();
                let age = now.saturating_duration_since(r.last_seen).as_secs_f64();
                (r.sysid, r.compid, name, peer, age)
            })
            .collect();
        let systems = self
            .router
            .systems()
            .map(|s| {
                let (link, peer) = names.get(&s.link).cloned().unwrap_or_default();
                let age = now.saturating_duration_since(s.last_seen);
                SystemReport {
                    heartbeat: *s,
                    link,
                    peer,
                    age_ms: u64::try_from(age.as_millis()).unwrap_or(u64::MAX),
                }
            })
            .collect();
        NodeReport {
            t_s: now.saturating_duration_since(self.started).as_secs_f64(),
            links,
            routes,
            systems,
            transport: self
                .slots
                .iter()
                .map(|s| (s.template.name.clone(), s.io.stats()))
                .collect(),
            subscriber_drops: self.subscriber_drops,
        }
    }
}

/// What a link with no peer yet will carry.
const fn mode_of(config: &LinkConfig) -> LinkMode {
    if config.signing.is_some() {
        return LinkMode::Signed;
    }
    match config.version {
        mavstack_router::VersionMode::Mavlink1 => LinkMode::Mavlink1,
        mavstack_router::VersionMode::Mavlink2 => LinkMode::Mavlink2,
        mavstack_router::VersionMode::Auto => LinkMode::Auto,
        mavstack_router::VersionMode::Transparent => LinkMode::Transparent,
    }
}

const fn conversions(c: &mavstack_router::Conversions) -> [(&'static str, u64); 4] {
    [
        ("to_mavlink1", c.to_mavlink1),
        ("to_mavlink2", c.to_mavlink2),
        ("signature_removed", c.signature_removed),
        ("signed", c.signed),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moderation_starts_above_5000_inputs_a_second_and_stops_below_2500() {
        let t0 = Instant::from_secs(1);
        let ms = Duration::from_millis;
        let mut m = Moderation::new(InputModeration::Timer, t0);
        m.inputs = 40; // 4,000/s: not yet
        assert!(!m.busy(t0 + ms(10)));
        m.inputs = 60; // 6,000/s
        assert!(m.busy(t0 + ms(20)));
        m.inputs = 30; // 3,000/s: still, by hysteresis
        assert!(m.busy(t0 + ms(30)));
        m.inputs = 20; // 2,000/s
        assert!(!m.busy(t0 + ms(40)));
        // A stream that stopped is seen as soon as the next input comes.
        m.inputs = 60;
        assert!(m.busy(t0 + ms(50)));
        m.inputs = 1;
        assert!(!m.busy(t0 + ms(1050)));
        let mut off = Moderation::new(InputModeration::Off, t0);
        off.inputs = 1_000;
        assert!(!off.busy(t0 + ms(10)));
    }
}
