//! [`ChannelProtocol`]: a [`mavstack_channel::Channel`] per peer, run by a connection's driver.
//!
//! Each peer of a link (a UDP sender, a TCP client, the serial port) is one MAVLink link
//! with its own version, handshake, signing and sequence state, so each gets its own channel,
//! made from the configuration template when the peer appears and dropped when it goes.
//! Accepted frames, rejections, version changes and handshake outcomes come out as
//! [`ChannelEvent`]s tagged with the peer; application frames go in as [`ChannelCommand`]s and
//! are framed by the peer's channel (its version, sequence numbers, signature).
//!
//! ```no_run
//! use mavstack_channel::Config;
//! use mavstack_transport::Connection;
//! use mavstack_transport::channel_protocol::{ChannelProtocol, ChannelCommand, RawMessage};
//! use mavstack_dialects::common::Heartbeat;
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! let spec = "udpin:127.0.0.1:14560".parse()?;
//! let protocol = ChannelProtocol::new(Config::vehicle(1, 1))?;
//! let mut conn = Connection::open(&spec, protocol).await?;
//! conn.send(ChannelCommand::to_all(RawMessage::new(&Heartbeat::default()))).await?;
//! while let Some(event) = conn.recv().await {
//!     println!("{}: {:?}", event.peer, event.event);
//! }
//! # Ok(()) }
//! ```

use std::collections::{BTreeMap, VecDeque};

use mavstack_channel::{
    Channel, CommandEncoding, CommonCrc, Config, ConfigError, Event, HandshakeMethod, LinkStats,
    LinkVersion, SigningConfig, Target,
};
use mavstack_core::parse::CrcExtra;
use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_core::{MAX_PAYLOAD_LEN, Message, MessageSet};

use crate::frame::FrameBuf;
use crate::protocol::{Dest, PeerId, PeerInfo, Protocol, Transmit};

/// A message ready to be framed: id, CRC_EXTRA and payload (no allocation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawMessage {
    /// Message id.
    pub msg_id: u32,
    /// The message's CRC_EXTRA.
    pub crc_extra: u8,
    payload: [u8; MAX_PAYLOAD_LEN],
    len: u8,
    /// Length of the base (non-extension) fields: all a MAVLink 1 frame may carry.
    base_len: u8,
}

impl RawMessage {
    /// The encoding of a typed message.
    #[must_use]
    pub fn new<M: Message>(message: &M) -> Self {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload).min(MAX_PAYLOAD_LEN);
        Self {
            msg_id: M::ID,
            crc_extra: M::CRC_EXTRA,
            payload,
            // At most MAX_PAYLOAD_LEN (255): fits.
            len: u8::try_from(len).unwrap_or(u8::MAX),
            base_len: u8::try_from(M::MIN_LEN.min(len)).unwrap_or(u8::MAX),
        }
    }

    /// The encoding of a message of a whole message set (e.g. a dialect's `MavMessage`
    /// enum): what a service emitted, ready for the channel.
    ///
    /// ```
    /// use mavstack_dialects::common::{Heartbeat, MavMessage};
    /// use mavstack_transport::channel_protocol::RawMessage;
    /// let typed = RawMessage::new(&Heartbeat::default());
    /// let dynamic = RawMessage::of(&MavMessage::Heartbeat(Heartbeat::default()));
    /// assert_eq!(typed, dynamic);
    /// ```
    #[must_use]
    pub fn of<S: MessageSet>(message: &S) -> Self {
        let info = message.message_info();
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload).min(MAX_PAYLOAD_LEN);
        Self {
            msg_id: info.id,
            crc_extra: info.crc_extra,
            payload,
            len: u8::try_from(len).unwrap_or(u8::MAX),
            base_len: info.min_len.min(u8::try_from(len).unwrap_or(u8::MAX)),
        }
    }

    /// The payload (untruncated; the channel truncates MAVLink 2 payloads).
    #[must_use]
    pub fn payload(&self) -> &[u8] {
        &self.payload[..usize::from(self.len)]
    }

    /// The base fields alone: what a MAVLink 1 frame carries (never extensions).
    #[must_use]
    pub fn base_payload(&self) -> &[u8] {
        &self.payload[..usize::from(self.base_len)]
    }
}

/// What the application asks of a [`ChannelProtocol`].
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum ChannelCommand {
    /// Frame `message` on each destination peer's channel and send it.
    Send {
        /// Where to.
        dest: Dest,
        /// What.
        message: RawMessage,
    },
    /// Start the MAVLink 2 handshake (ground station) on one peer's link.
    StartHandshake {
        /// The link.
        peer: PeerId,
        /// The system to ask.
        target: Target,
        /// Which request.
        method: HandshakeMethod,
        /// COMMAND_LONG or COMMAND_INT.
        encoding: CommandEncoding,
    },
    /// Turn signing on (or off, with `None`) on one peer's link, or on every link and for
    /// peers to come with `peer: None`.
    SetSigning {
        /// The link, or all.
        peer: Option<PeerId>,
        /// The new signing configuration.
        signing: Option<SigningConfig>,
    },
}

impl ChannelCommand {
    /// Send `message` to every peer.
    #[must_use]
    pub const fn to_all(message: RawMessage) -> Self {
        Self::Send {
            dest: Dest::All,
            message,
        }
    }
}

/// What a [`ChannelProtocol`] reports.
///
/// Channel events carry a whole frame inline (no allocation per frame), hence the size.
#[derive(Clone, Debug)]
#[non_exhaustive]
#[allow(clippy::large_enum_variant)]
pub enum ChannelEventKind {
    /// The peer's channel reported this.
    Channel(Event),
    /// A peer appeared (its channel was created).
    PeerAdded(PeerInfo),
    /// A peer went away (its channel was dropped).
    PeerRemoved,
    /// A command could not be carried out (no such peer, a message the link's version
    /// cannot carry, a handshake on a vehicle, ...): why, in one line.
    CommandFailed(String),
}

/// An event and the peer it concerns.
#[derive(Clone, Debug)]
pub struct ChannelEvent {
    /// The peer.
    pub peer: PeerId,
    /// What happened.
    pub event: ChannelEventKind,
}

/// Counters: each live peer's link statistics.
#[derive(Clone, Debug, Default)]
#[non_exhaustive]
pub struct ChannelStats {
    /// Live peers and their links' statistics.
    pub links: Vec<(PeerId, LinkStats)>,
}

/// One [`Channel`] per peer; see the [module docs](self).
pub struct ChannelProtocol<L = CommonCrc> {
    template: Config,
    lookup: L,
    channels: BTreeMap<PeerId, Channel<L>>,
    events: VecDeque<ChannelEvent>,
    outgoing: VecDeque<(PeerId, FrameBuf)>,
}

impl<L> core::fmt::Debug for ChannelProtocol<L> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ChannelProtocol")
            .field("peers", &self.channels.len())
            .finish_non_exhaustive()
    }
}

impl ChannelProtocol<CommonCrc> {
    /// Channels made from `config`, reading the common dialect.
    ///
    /// # Errors
    /// If `config` is not valid ([`Config::validate`]).
    pub fn new(config: Config) -> Result<Self, ConfigError> {
        Self::with_lookup(config, CommonCrc::default())
    }
}

impl<L: CrcExtra + Clone + Send + 'static> ChannelProtocol<L> {
    /// Channels made from `config`, with CRC_EXTRA values from `lookup`.
    ///
    /// # Errors
    /// If `config` is not valid ([`Config::validate`]).
    pub fn with_lookup(config: Config, lookup: L) -> Result<Self, ConfigError> {
        config.validate()?;
        Ok(Self {
            template: config,
            lookup,
            channels: BTreeMap::new(),
            events: VecDeque::new(),
            outgoing: VecDeque::new(),
        })
    }

    fn channel(&mut self, peer: PeerId) -> Option<&mut Channel<L>> {
        if !self.channels.contains_key(&peer) {
            // The template was validated, so this cannot fail; a peer the driver never
            // announced still gets a link rather than losing its bytes.
            let channel = Channel::with_lookup(self.template.clone(), self.lookup.clone()).ok()?;
            self.channels.insert(peer, channel);
        }
        self.channels.get_mut(&peer)
    }

    fn drain_events(&mut self, peer: PeerId) {
        if let Some(channel) = self.channels.get_mut(&peer) {
            while let Some(event) = channel.poll_event() {
                self.events.push_back(ChannelEvent {
                    peer,
                    event: ChannelEventKind::Channel(event),
                });
            }
        }
    }

    fn fail(&mut self, peer: PeerId, why: String) {
        self.events.push_back(ChannelEvent {
            peer,
            event: ChannelEventKind::CommandFailed(why),
        });
    }

    fn send_on(&mut self, now: Instant, peer: PeerId, message: &RawMessage) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let Some(channel) = self.channels.get_mut(&peer) else {
            self.fail(peer, format!("no link to {peer}"));
            return;
        };
        let payload = if channel.version() == LinkVersion::Mavlink1 {
            message.base_payload()
        } else {
            message.payload()
        };
        match channel.send_raw(now, message.msg_id, message.crc_extra, payload, &mut buf) {
            Ok(t) => match FrameBuf::new(&buf[..t.len]) {
                Ok(frame) => self.outgoing.push_back((peer, frame)),
                Err(e) => self.fail(peer, e.to_string()),
            },
            Err(e) => self.fail(peer, format!("cannot send message {}: {e}", message.msg_id)),
        }
    }
}

impl<L: CrcExtra + Clone + Send + 'static> Protocol for ChannelProtocol<L> {
    type Command = ChannelCommand;
    type Event = ChannelEvent;
    type Stats = ChannelStats;

    fn handle_peer_added(&mut self, _now: Instant, peer: &PeerInfo) {
        let _ = self.channel(peer.id);
        self.events.push_back(ChannelEvent {
            peer: peer.id,
            event: ChannelEventKind::PeerAdded(peer.clone()),
        });
    }

    fn handle_peer_removed(&mut self, _now: Instant, peer: PeerId) {
        if self.channels.remove(&peer).is_some() {
            self.events.push_back(ChannelEvent {
                peer,
                event: ChannelEventKind::PeerRemoved,
            });
        }
    }

    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]) {
        let mut rest = data;
        loop {
            let Some(channel) = self.channel(peer) else {
                return;
            };
            let taken = channel.handle_input(now, rest);
            self.drain_events(peer);
            rest = &rest[taken.min(rest.len())..];
            // Input pauses only while the channel's event queue is full, and it was just
            // drained; no progress at all would be a channel bug: stop rather than spin.
            if rest.is_empty() || taken == 0 {
                return;
            }
        }
    }

    fn handle_command(&mut self, now: Instant, command: ChannelCommand) {
        match command {
            ChannelCommand::Send { dest, message } => {
                let peers: Vec<PeerId> = match dest {
                    Dest::Peer(p) => vec![p],
                    Dest::All => self.channels.keys().copied().collect(),
                    Dest::AllExcept(x) => {
                        self.channels.keys().copied().filter(|&p| p != x).collect()
                    }
                };
                for peer in peers {
                    self.send_on(now, peer, &message);
                }
            }
            ChannelCommand::StartHandshake {
                peer,
                target,
                method,
                encoding,
            } => {
                let result = match self.channels.get_mut(&peer) {
                    Some(channel) => channel
                        .start_handshake(now, target, method, encoding)
                        .map_err(|e| e.to_string()),
                    None => Err(format!("no link to {peer}")),
                };
                if let Err(why) = result {
                    self.fail(peer, why);
                }
            }
            ChannelCommand::SetSigning { peer, signing } => {
                let peers: Vec<PeerId> = match peer {
                    Some(p) => vec![p],
                    None => {
                        self.template.signing = signing.clone();
                        self.channels.keys().copied().collect()
                    }
                };
                for p in peers {
                    let result = match self.channels.get_mut(&p) {
                        Some(channel) => channel
                            .set_signing(signing.clone())
                            .map_err(|e| e.to_string()),
                        None => Err(format!("no link to {p}")),
                    };
                    match result {
                        Ok(()) => self.drain_events(p),
                        Err(why) => self.fail(p, why),
                    }
                }
            }
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        let due: Vec<PeerId> = self
            .channels
            .iter()
            .filter(|(_, c)| c.poll_timeout().is_some_and(|t| t <= now))
            .map(|(&p, _)| p)
            .collect();
        for peer in due {
            if let Some(channel) = self.channels.get_mut(&peer) {
                channel.handle_timeout(now);
            }
            self.drain_events(peer);
        }
    }

    fn poll_transmit(&mut self, now: Instant, buf: &mut [u8]) -> Option<Transmit> {
        // The channels' own frames (answers, handshake requests) first, then the
        // application's, in order.
        let frame_buf: &mut [u8; MAX_FRAME_LEN] = buf.get_mut(..MAX_FRAME_LEN)?.try_into().ok()?;
        for (&peer, channel) in &mut self.channels {
            if let Some(t) = channel.poll_transmit(now, frame_buf) {
                return Some(Transmit {
                    dest: Dest::Peer(peer),
                    len: t.len,
                });
            }
        }
        let (peer, frame) = self.outgoing.pop_front()?;
        let bytes = frame.as_bytes();
        let out = buf.get_mut(..bytes.len())?;
        out.copy_from_slice(bytes);
        Some(Transmit {
            dest: Dest::Peer(peer),
            len: bytes.len(),
        })
    }

    fn poll_event(&mut self) -> Option<ChannelEvent> {
        self.events.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.channels
            .values()
            .filter_map(Channel::poll_timeout)
            .min()
    }

    fn stats(&self) -> ChannelStats {
        ChannelStats {
            links: self.channels.iter().map(|(&p, c)| (p, c.stats())).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{Framing, PeerAddr};
    use mavstack_dialects::common::{CommandAck, MavCmd, MavResult};

    fn peer() -> PeerInfo {
        PeerInfo {
            id: PeerId::new(1),
            addr: PeerAddr::Udp("127.0.0.1:14550".parse().expect("address")),
            framing: Framing::Datagram,
        }
    }

    fn sent(protocol: &mut ChannelProtocol, message: RawMessage) -> Vec<u8> {
        let now = Instant::from_secs(1_767_225_600);
        protocol.handle_command(now, ChannelCommand::to_all(message));
        let mut buf = [0u8; MAX_FRAME_LEN];
        let t = protocol.poll_transmit(now, &mut buf).expect("a frame");
        buf[..t.len].to_vec()
    }

    #[test]
    fn mavlink1_links_send_base_fields_only_and_mavlink2_links_the_extensions() {
        let ack = RawMessage::new(&CommandAck {
            command: MavCmd::REQUEST_MESSAGE,
            result: MavResult::UNSUPPORTED,
            progress: 7,
            target_system: 255,
            target_component: 190,
            ..CommandAck::default()
        });
        let mut v1 = ChannelProtocol::new(Config::vehicle(1, 1)).expect("valid");
        v1.handle_peer_added(Instant::ZERO, &peer());
        let frame = sent(&mut v1, ack);
        // MAVLink 1: 0xFE, payload of the 3 base bytes (command, result), no extensions.
        assert_eq!((frame[0], frame[1]), (0xFE, 3));

        let mut config = Config::vehicle(1, 1);
        if let Some(policy) = config.vehicle_policy_mut() {
            policy.version = mavstack_channel::VehicleVersion::Mavlink2;
        }
        let mut v2 = ChannelProtocol::new(config).expect("valid");
        v2.handle_peer_added(Instant::ZERO, &peer());
        let frame = sent(&mut v2, ack);
        // MAVLink 2: the extensions travel (progress, result_param2, target ids: 10 bytes).
        assert_eq!((frame[0], frame[1]), (0xFD, 10));
    }
}
