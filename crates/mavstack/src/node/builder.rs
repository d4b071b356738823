//! [`NodeBuilder`]: what a node is made of, and [`NodeBuilder::start`], which opens it.

use core::net::SocketAddr;
use core::time::Duration;
use std::path::PathBuf;

use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_core::{MAX_PAYLOAD_LEN, Message};
use mavstack_router::{
    LinkConfig, LinkRole, LocalDelivery, LocalFrames, MessageTable, Router, RouterConfig,
};
use mavstack_transport::{Link, Options, clock};
use tokio::sync::mpsc;

use crate::link_spec::LinkSpec;

use super::driver::{Driver, Heartbeat, PeerLinks, Slot};
use super::handle::Node;
use super::log::TrafficLog;
use super::moderation::{InputModeration, Moderation};
use super::{EventSubscription, NodeError, NodeEvent, SUBSCRIPTION_DEPTH, TapSubscription, Tapped};

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
    pub(super) router: RouterConfig,
    pub(super) dialect: MessageTable,
    pub(super) links: Vec<NewLink>,
    pub(super) log_dir: Option<PathBuf>,
    pub(super) options: Options,
    pub(super) heartbeat: Option<(Vec<u8>, Duration)>,
    pub(super) role: Option<LinkRole>,
    pub(super) moderation: InputModeration,
    pub(super) own_thread: bool,
    pub(super) http: Option<SocketAddr>,
    #[cfg(feature = "http")]
    pub(super) web: crate::web::WebOptions,
    /// Taps and event subscribers registered before the node starts.
    pub(super) taps: Vec<mpsc::Sender<Tapped>>,
    pub(super) watchers: Vec<mpsc::Sender<NodeEvent>>,
}

/// A link of a node that has not started: one to open, or one opened by the caller.
#[derive(Debug)]
pub(super) enum NewLink {
    Spec(LinkSpec),
    Open(LinkConfig, Box<Link>),
}

impl NodeBuilder {
    /// A tap ([`NodeHandle::tap`](crate::NodeHandle::tap)) that sees every input from the node's first datagram on:
    /// [`NodeHandle::tap`](crate::NodeHandle::tap) on a started node misses what a quick peer sent before it was
    /// registered.
    #[must_use]
    pub fn with_tap(mut self) -> (Self, TapSubscription) {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        self.taps.push(tx);
        (self, rx)
    }

    /// Link events ([`NodeHandle::events`](crate::NodeHandle::events)) from the node's start on, none missed.
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
    pub const fn dialect(mut self, dialect: MessageTable) -> Self {
        self.dialect = dialect;
        self
    }

    /// Writes every accepted frame to a tlog in `dir` (`mavstack-YYYYmmdd-HHMMSS.tlog`,
    /// named by the start time in UTC, with `-1`, `-2`, ... added when a log of that second
    /// exists: a log never overwrites another), with the link number in the timestamps' low
    /// two bits as MAVProxy does (0, 1, 2 for the first three links, 2 for the rest). The
    /// frames go through a bounded queue to the log's own writer thread: frames that do not
    /// fit are left out of the log and counted as `log_full`; a write error stops the node
    /// with [`NodeError::Log`] naming the file.
    #[must_use]
    pub fn log_dir(mut self, dir: impl Into<PathBuf>) -> Self {
        self.log_dir = Some(dir.into());
        self
    }

    /// Serves a status page and mavlink2rest 1.0.2's REST and WebSocket API on `addr`
    /// (feature `http`; [`crate::web`]): `GET /` a live page of the links (version, rates,
    /// drops, conversions), routes and vehicles heard (mode, battery, GPS, track, ...);
    /// `GET /api/status` the same as one JSON object ([`crate::status`]);
    /// `GET /api/events` that object once a second as server-sent events; `/mavlink`,
    /// `/ws/mavlink` and the rest of the API through a link of the node named `web`. Without
    /// a token ([`web`](Self::web)) it has no authentication: give a loopback address unless
    /// the network is trusted.
    #[cfg(feature = "http")]
    #[must_use]
    pub const fn http(mut self, addr: SocketAddr) -> Self {
        self.http = Some(addr);
        self
    }

    /// The web service's settings (token, limits, dialect; [`crate::web::WebOptions`]),
    /// for [`http`](Self::http).
    #[cfg(feature = "http")]
    #[must_use]
    pub fn web(mut self, options: crate::web::WebOptions) -> Self {
        self.web = options;
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
    #[cfg_attr(not(feature = "http"), allow(unused_mut))]
    pub async fn start(mut self) -> Result<Node, NodeError> {
        // The web API is a monitor link of the node, fed and read by the web service.
        #[cfg(feature = "http")]
        let web_peer = self.http.map(|_| {
            let (link, peer) = Link::external(Some("web".to_owned()), crate::web::LINK_QUEUE);
            let mut config = LinkConfig::new("web");
            config.monitor = true;
            self.links.push(NewLink::Open(config, Box::new(link)));
            peer
        });
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
        // A new UDP source becomes a peer (a router link) only with a frame whose checksum
        // holds in the node's dialect, and each link has at most its `max_peers`.
        let crc: std::sync::Arc<dyn mavstack_core::parse::CrcExtra + Send + Sync> =
            std::sync::Arc::new(self.dialect);
        for new in self.links {
            let (mut config, mut io) = match new {
                NewLink::Spec(spec) => {
                    let mut io = Link::open(&spec.conn, &options).await.map_err(|source| {
                        NodeError::Open {
                            name: spec.config.name.clone(),
                            source,
                        }
                    })?;
                    io.admit_peers(&spec.config.name, spec.max_peers, Some(crc.clone()));
                    (spec.config, io)
                }
                NewLink::Open(config, io) => (config, *io),
            };
            if let Some(role) = self.role {
                config.role = role;
            }
            io.set_packing(config.pack);
            if config.isolate_peers {
                // Every peer of the link is a router link made from this template: one group.
                config.group = u32::try_from(slots.len()).ok();
            }
            local_addrs.push(io.local_addr());
            slots.push(Slot {
                io,
                template: config,
                peers: PeerLinks::default(),
                polled: false,
            });
        }
        let log = match self.log_dir {
            Some(dir) => Some(TrafficLog::open(&dir, slots.len())?),
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
            batches: Vec::new(),
            local: LocalFrames::new(),
            subscriber_drops: 0,
            watchers: self.watchers,
            pending: Vec::new(),
            taps: self.taps,
            moderation: Moderation::new(self.moderation, clock::now()),
            #[cfg(target_os = "linux")]
            reader_poll: None,
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
        if let (Some(listener), Some(peer)) = (http, web_peer) {
            crate::web::spawn(listener, node.handle(), peer, self.web);
        }
        #[cfg(not(feature = "http"))]
        drop(http);
        Ok(node)
    }
}
