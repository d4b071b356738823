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
//!
//! One file per part: `builder` (what a node is made of, and opening it), `batch` (frames
//! handed to a reader thread in batches), `handle` (the
//! running [`Node`] and its [`NodeHandle`]s), `driver` (the driver's state and one turn of
//! it: reading, routing, forwarding, commands), `run_task` (the driver as a task of the
//! runtime), `run_thread` (the driver on a thread of its own, over an `epoll`),
//! `moderation` (reading in bursts under a steady stream), `heartbeat` (the node's own
//! HEARTBEAT timer), `log` (the traffic log) and `report` (the counters a node reports).

mod batch;
mod builder;
mod driver;
mod handle;
mod heartbeat;
mod log;
mod moderation;
mod report;
mod run_task;
#[cfg(target_os = "linux")]
mod run_thread;

pub use batch::{BATCH_DEPTH, BatchFrame, BatchSubscription, BatchWait, FrameBatch};
pub use builder::NodeBuilder;
pub use handle::{Node, NodeHandle};
pub use moderation::InputModeration;

use core::net::SocketAddr;
use std::path::PathBuf;

use mavstack_channel::{
    CommandEncoding, ConfigError, HandshakeError, HandshakeMethod, HandshakeOutcome, LinkVersion,
    ProtocolVersionAnswer, ReceivedFrame, Rejected, SigningConfig, SigningSetup, SwitchCause,
    Target,
};
use mavstack_core::time::Instant;
use mavstack_router::systems::SystemInfo;
use mavstack_router::{LinkId, SendTo};
use mavstack_transport::{LinkError, LinkStats, OpenError};
use tokio::sync::{mpsc, oneshot};

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
    /// A vehicle link ([`LinkRole::Vehicle`](crate::router::LinkRole::Vehicle)) was asked for PROTOCOL_VERSION.
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
    SubscribeBatched(batch::BatchSink, oneshot::Sender<()>),
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
    SetSigningAll {
        signing: Option<SigningConfig>,
        done: oneshot::Sender<Result<(), ConfigError>>,
    },
    HoldSetupSigning {
        held: bool,
        done: oneshot::Sender<()>,
    },
    Shutdown,
}
