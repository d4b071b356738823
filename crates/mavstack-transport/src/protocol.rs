//! The sans-IO side of a connection: peers, and the [`Protocol`] trait a driver runs.
//!
//! A link (a UDP socket, a TCP server, a serial port, a file) has one or more **peers**: the
//! other ends it exchanges bytes with. Each gets a small [`PeerId`] when it appears (a new UDP
//! sender, an accepted TCP client, a (re)connection) and keeps it until it goes away. A
//! [`Protocol`] is told about peers, fed their bytes, and asked for bytes to send to them. It
//! never touches the link, a clock or a task; the driver in this crate does (quinn-proto's
//! shape).

use core::fmt;
use core::net::SocketAddr;
use std::path::PathBuf;

use mavstack_core::time::Instant;

/// The id of one peer of a connection: unique within the connection for its lifetime, never
/// reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PeerId(u32);

impl PeerId {
    /// The id with number `n` (ids are handed out by the driver; this is for tests and for
    /// state machines that keep their own tables).
    #[must_use]
    pub const fn new(n: u32) -> Self {
        Self(n)
    }

    /// Its number.
    #[must_use]
    pub const fn get(self) -> u32 {
        self.0
    }
}

impl fmt::Display for PeerId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "peer {}", self.0)
    }
}

/// Where a peer is.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum PeerAddr {
    /// A UDP address (a sender on a listening socket, or the target of `udpout`/`udpbcast`).
    Udp(SocketAddr),
    /// A TCP connection's remote address.
    Tcp(SocketAddr),
    /// A serial device.
    Serial(String),
    /// A file.
    File(PathBuf),
    /// Another program part that carries the frames (a fleet bridge's broker connection),
    /// named by it.
    External(String),
}

impl fmt::Display for PeerAddr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Udp(a) => write!(f, "udp {a}"),
            Self::Tcp(a) => write!(f, "tcp {a}"),
            Self::Serial(d) => write!(f, "serial {d}"),
            Self::File(p) => write!(f, "file {}", p.display()),
            Self::External(what) => f.write_str(what),
        }
    }
}

/// How a peer's bytes arrive.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Framing {
    /// Each input is one whole datagram (UDP) or one tlog record: frames never span two.
    Datagram,
    /// Inputs are pieces of one byte stream (TCP, serial, a raw file): a frame may be split
    /// across any number of them.
    Stream,
}

/// A peer as the driver announces it.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PeerInfo {
    /// Its id.
    pub id: PeerId,
    /// Where it is.
    pub addr: PeerAddr,
    /// How its bytes arrive.
    pub framing: Framing,
}

/// Where a transmit goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dest {
    /// One peer.
    Peer(PeerId),
    /// Every peer the link has: every live sender of a UDP listener, every TCP client, the
    /// target of `udpout`/`udpbcast`, the serial port, the file.
    All,
    /// Every peer but one (forwarding what that one sent).
    AllExcept(PeerId),
}

/// Bytes to send: the first `len` bytes of the buffer given to
/// [`Protocol::poll_transmit`], to `dest`. On a datagram link they go out as one datagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[must_use]
pub struct Transmit {
    /// Where to.
    pub dest: Dest,
    /// How many bytes of the buffer.
    pub len: usize,
}

/// What a [`crate::Link`] hands its input to: peers appearing and going, and their bytes.
/// Every [`Protocol`] is one; a driver of many links implements it to route each peer's
/// bytes.
pub trait Input {
    /// A peer appeared. Called before its first [`Input::handle_input`].
    fn handle_peer_added(&mut self, now: Instant, peer: &PeerInfo);
    /// A peer went away; no input from it follows.
    fn handle_peer_removed(&mut self, now: Instant, peer: PeerId);
    /// Bytes from `peer`: one datagram, or the next piece of its stream (see [`Framing`]).
    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]);
}

impl<P: Protocol> Input for P {
    fn handle_peer_added(&mut self, now: Instant, peer: &PeerInfo) {
        Protocol::handle_peer_added(self, now, peer);
    }
    fn handle_peer_removed(&mut self, now: Instant, peer: PeerId) {
        Protocol::handle_peer_removed(self, now, peer);
    }
    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]) {
        Protocol::handle_input(self, now, peer, data);
    }
}

/// A sans-IO protocol state machine that a connection's driver runs: time comes in, work is
/// pulled out.
///
/// The driver owns one link and one `Protocol`. It calls, in one task:
///
/// - [`handle_peer_added`](Protocol::handle_peer_added) before a peer's first input, and
///   [`handle_peer_removed`](Protocol::handle_peer_removed) after its last;
/// - [`handle_input`](Protocol::handle_input) with every piece of bytes the link receives;
/// - [`handle_command`](Protocol::handle_command) with every command the user sends;
/// - [`handle_timeout`](Protocol::handle_timeout) once [`poll_timeout`](Protocol::poll_timeout)'s
///   deadline has passed;
///
/// and after each of those, drains [`poll_transmit`](Protocol::poll_transmit) (writing to the
/// link) and [`poll_event`](Protocol::poll_event) (forwarding to the user), then asks
/// [`poll_timeout`](Protocol::poll_timeout) again. Implementations must never block, sleep,
/// read a clock or do I/O.
///
/// Time (`now`) is the transport's [`crate::clock`]; for a tlog file being read, inputs carry
/// the time recorded in the file instead.
pub trait Protocol: Send + 'static {
    /// What the user asks of the protocol (e.g. "send this frame").
    type Command: Send + 'static;
    /// What the protocol reports to the user (e.g. "a frame arrived").
    type Event: Send + 'static;
    /// Counters the user can read at any time (copied out by the driver after each step).
    type Stats: Clone + Default + Send + 'static;

    /// A peer appeared. Called before its first [`Protocol::handle_input`].
    fn handle_peer_added(&mut self, now: Instant, peer: &PeerInfo);

    /// A peer went away (a TCP client disconnected, a UDP sender went quiet, a file ended).
    /// No input from it follows.
    fn handle_peer_removed(&mut self, now: Instant, peer: PeerId);

    /// Bytes from `peer`: one datagram, or the next piece of its stream (see [`Framing`]).
    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]);

    /// A command from the user.
    fn handle_command(&mut self, now: Instant, command: Self::Command);

    /// The deadline from [`Protocol::poll_timeout`] has passed. Call it with the current
    /// time; it may be called late, or when nothing is due.
    fn handle_timeout(&mut self, now: Instant);

    /// The next bytes to send: writes them into `buf` and says where they go. Call until it
    /// returns `None` after every `handle_*` call. A transmit longer than `buf` cannot be
    /// made; implementations keep it for a larger buffer or drop and count it.
    #[must_use]
    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<Transmit>;

    /// The next event for the user. Call until it returns `None` after every `handle_*` call.
    #[must_use]
    fn poll_event(&mut self) -> Option<Self::Event>;

    /// When [`Protocol::handle_timeout`] should next be called, if ever. Ask again after
    /// every `handle_*` call.
    #[must_use]
    fn poll_timeout(&self) -> Option<Instant>;

    /// A copy of the protocol's counters.
    #[must_use]
    fn stats(&self) -> Self::Stats;
}
