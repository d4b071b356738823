//! One link's protocol state: the [`Channel`].
//!
//! See the crate docs for the driving loop and the version rules; this module holds the
//! state machine itself: its state and public API here, the receive path (checks, version
//! rules, handshake answers, SETUP_SIGNING) in `receive`, the frames it writes in `transmit`.

use mavstack_core::MessageTable;
use mavstack_core::message::{MAX_PAYLOAD_LEN, Message, MessageInfo};
use mavstack_core::parse::Deframer;
use mavstack_core::signing::{MAX_TIMESTAMP, append_signature};
use mavstack_core::time::Instant;
use mavstack_core::wire::{EmitError, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{MavProtocolCapability, ProtocolVersion};

use crate::config::{Config, ConfigError, GroundPolicy, Role, VehiclePolicy, VehicleVersion};
use crate::dialect::{CommandEncoding, common_table};
use crate::event::{Event, EventRef, LinkVersion, SwitchCause};
use crate::handshake::{
    AwaitingAnswer, Handshake, HandshakeConfig, HandshakeMethod, HandshakeRequest, Target,
};
use crate::queue::Queue;
use crate::seq::{SeqTable, SourceStats};
use crate::signing::{LinkSigning, SigningConfig, SigningStream, WallClock};
use crate::stats::LinkStats;

mod receive;
mod transmit;

use transmit::{Control, Framing};

/// How many events the channel holds before input processing pauses.
pub const EVENT_CAPACITY: usize = 16;
/// How many control frames (answers, handshake requests) wait for
/// [`Channel::poll_transmit`]; more are dropped and counted
/// ([`LinkStats::control_dropped`]).
pub const TRANSMIT_CAPACITY: usize = 8;
/// The most events one frame can cause; a frame is only processed with this much room.
const EVENTS_PER_FRAME: usize = 5;

/// A frame written into the caller's buffer: send `buf[..len]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[must_use = "the frame is in the buffer and must be sent"]
pub struct Transmit {
    /// The frame's length.
    pub len: usize,
    /// Its version.
    pub version: Version,
    /// Whether it is signed.
    pub signed: bool,
    /// Its sequence number.
    pub seq: u8,
    /// Its message id.
    pub msg_id: u32,
}

/// Why a frame could not be sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[non_exhaustive]
pub enum SendError {
    /// A message id above 255 on a link that sends MAVLink 1: MAVLink 1 cannot carry it.
    #[error("message {msg_id} exists only in MAVLink 2 and the link sends MAVLink 1")]
    NeedsMavlink2 {
        /// The message id.
        msg_id: u32,
    },
    /// [`Channel::send_mavlink2`] on a vehicle with MAVLink 2 disabled.
    #[error("MAVLink 2 is disabled on this link")]
    Mavlink2Disabled,
    /// A message id wider than 24 bits.
    #[error("message id {msg_id} does not fit in 24 bits")]
    InvalidMessageId {
        /// The message id.
        msg_id: u32,
    },
    /// The frame could not be written (buffer too small, payload too long).
    #[error(transparent)]
    Emit(#[from] EmitError),
}

/// Why a handshake could not start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[non_exhaustive]
pub enum HandshakeError {
    /// Only a ground station runs the handshake; a vehicle answers it.
    #[error("only a ground-station channel runs the handshake")]
    NotGroundStation,
    /// A handshake is already running.
    #[error("a handshake is already running")]
    InProgress,
    /// [`HandshakeMethod::RequestMessageOther`] with an id below 256, which MAVLink 1 could
    /// carry: its arrival would prove nothing.
    #[error("message {msg_id} is not MAVLink 2-only (ids from 256 are)")]
    NotMavlink2Message {
        /// The id asked for.
        msg_id: u32,
    },
}

/// The sans-IO state of one MAVLink link.
///
/// Bytes come in with [`handle_input`](Self::handle_input), time with
/// [`handle_timeout`](Self::handle_timeout); events come out of
/// [`poll_event`](Self::poll_event) and the frames the channel sends on its own out of
/// [`poll_transmit`](Self::poll_transmit); [`poll_timeout`](Self::poll_timeout) says when to
/// call `handle_timeout` next. The caller's own frames are written by
/// [`send`](Self::send). The channel never reads a clock, sleeps or allocates.
///
/// CRC_EXTRA comes from a [`MessageTable`] (see [`crate::dialect`]); [`Channel::new`] uses
/// `common`'s.
#[derive(Clone)]
pub struct Channel {
    sysid: u8,
    compid: u8,
    role: Role,
    secure: bool,
    /// SETUP_SIGNING refused for now ([`Channel::hold_setup_signing`]).
    setup_signing_held: bool,
    handshake_config: HandshakeConfig,
    table: MessageTable,
    deframer: Deframer,
    /// The unsigned output version; a signing link always sends signed MAVLink 2.
    out_version: Version,
    signing: Option<LinkSigning>,
    seq: u8,
    events: Queue<Event, EVENT_CAPACITY>,
    transmits: Queue<(Control, Framing), TRANSMIT_CAPACITY>,
    handshake: Option<Handshake>,
    peer_protocol_version: Option<ProtocolVersion>,
    mavlink2_received: bool,
    input_pending: bool,
    /// The buffered input ends a datagram: nothing after it belongs to its frames.
    datagram_end: bool,
    last_input_at: Instant,
    seqs: SeqTable,
    stats: LinkStats,
}

impl Channel {
    /// A channel for the `common` dialect.
    ///
    /// # Errors
    /// [`ConfigError`] if `config` cannot work (see [`Config::validate`]).
    pub fn new(config: Config) -> Result<Self, ConfigError> {
        Self::with_table(config, common_table())
    }

    /// A channel that takes CRC_EXTRA from `table` (the messages the channel reads itself
    /// are always known).
    ///
    /// # Errors
    /// [`ConfigError`] if `config` cannot work (see [`Config::validate`]).
    pub fn with_table(config: Config, table: MessageTable) -> Result<Self, ConfigError> {
        config.validate()?;
        let out_version = match config.role {
            Role::Vehicle(VehiclePolicy {
                version: VehicleVersion::Mavlink2,
                ..
            })
            | Role::Relay(VehicleVersion::Mavlink2)
            | Role::GroundStation(GroundPolicy::Mavlink2) => Version::V2,
            _ if config.signing.is_some() => Version::V2,
            _ => Version::V1,
        };
        Ok(Self {
            sysid: config.system_id,
            compid: config.component_id,
            role: config.role,
            secure: config.secure,
            setup_signing_held: false,
            handshake_config: config.handshake,
            table,
            deframer: Deframer::new(),
            out_version,
            signing: config.signing.map(LinkSigning::new),
            seq: 0,
            events: Queue::new(),
            transmits: Queue::new(),
            handshake: None,
            peer_protocol_version: None,
            mavlink2_received: false,
            input_pending: false,
            datagram_end: false,
            last_input_at: Instant::ZERO,
            seqs: SeqTable::new(),
            stats: LinkStats::default(),
        })
    }

    // ----- driving ---------------------------------------------------------------------

    /// Feeds bytes received on the link at `now` (a piece of a serial or TCP stream, or a
    /// whole UDP datagram) and returns how many were taken.
    ///
    /// Frames are parsed, checked and turned into events at once. When the event queue
    /// fills up, processing pauses and fewer than `data.len()` bytes may be taken: drain
    /// [`poll_event`](Self::poll_event) (which resumes processing) and call again with the
    /// rest. Bad frames never stop the stream: they are counted and reported as events.
    #[must_use = "bytes not taken must be fed again after draining poll_event"]
    pub fn handle_input(&mut self, now: Instant, data: &[u8]) -> usize {
        self.last_input_at = now;
        let mut taken = 0;
        loop {
            if !self.process_buffered() || taken == data.len() {
                return taken;
            }
            let n = self.deframer.push(&data[taken..]);
            if n == 0 {
                return taken;
            }
            taken += n;
            self.input_pending = true;
        }
    }

    /// Feeds one whole UDP datagram (or another input whose end is a frame boundary), like
    /// [`handle_input`](Self::handle_input), and returns how many bytes were taken. Once all of
    /// it is taken, an incomplete frame at its end is dropped (counted as skipped bytes) at
    /// once instead of waiting for bytes that will never come, so a truncated datagram never
    /// delays the next one. Call again with the rest after draining
    /// [`poll_event`](Self::poll_event) if fewer were taken.
    #[must_use = "bytes not taken must be fed again after draining poll_event"]
    pub fn handle_datagram(&mut self, now: Instant, data: &[u8]) -> usize {
        let taken = self.handle_input(now, data);
        if taken == data.len() {
            self.datagram_end = true;
            self.input_pending = true;
            self.process_buffered();
        }
        taken
    }

    /// Lets time pass: call at (or after) the instant [`poll_timeout`](Self::poll_timeout)
    /// returned. Resends the handshake request or ends the handshake with a timeout.
    /// Does nothing while the event queue is nearly full; drain
    /// [`poll_event`](Self::poll_event) and call again.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.events.free() < EVENTS_PER_FRAME {
            return;
        }
        if let Some(state) = self.handshake.take() {
            let step = state.handle_timeout(now, &self.handshake_config);
            let (outcome, switch) = self.apply_step(step);
            for event in [outcome, switch].into_iter().flatten() {
                self.push_event(event);
            }
        }
    }

    /// The next event, or `None`. Call after every [`handle_input`](Self::handle_input) and
    /// [`handle_timeout`](Self::handle_timeout) until it returns `None`.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<Event> {
        if let Some(timestamp) = self.signing.as_mut().and_then(LinkSigning::take_persist) {
            return Some(Event::PersistTimestamp { timestamp });
        }
        if self.input_pending {
            self.process_buffered();
        }
        self.events.pop()
    }

    /// [`poll_event`](Self::poll_event) for a stream of frames: an accepted frame is lent
    /// where it lies instead of moved out ([`EventRef::Frame`], borrowed until the channel is
    /// used again; its place is then reused, so a frame costs one copy of its bytes into the
    /// channel). [`EventRef::Other`]: the next event is of another kind, for `poll_event`.
    #[must_use]
    pub fn poll_event_ref(&mut self) -> Option<EventRef<'_>> {
        if self.signing.as_ref().is_some_and(LinkSigning::has_persist) {
            return Some(EventRef::Other);
        }
        if self.input_pending {
            self.process_buffered();
        }
        match self.events.peek() {
            None => None,
            Some(Event::Frame(_)) => match self.events.pop_slot() {
                Some(Some(Event::Frame(frame))) => Some(EventRef::Frame(frame)),
                _ => None,
            },
            Some(_) => Some(EventRef::Other),
        }
    }

    /// Writes the next frame the channel sends on its own (a COMMAND_ACK, a PROTOCOL_VERSION,
    /// a handshake request) into `buf` and describes it, or returns `None`. Call after every
    /// `handle_*` and [`poll_event`](Self::poll_event) until it returns `None`; `now` dates
    /// the signature.
    #[must_use]
    pub fn poll_transmit(
        &mut self,
        now: Instant,
        buf: &mut [u8; MAX_FRAME_LEN],
    ) -> Option<Transmit> {
        while let Some((control, framing)) = self.transmits.pop() {
            // Only a bug could make these fail: the buffer holds any frame and every
            // control message fits its framing. Drop and count rather than panic.
            match self.write_control(now, &control, framing, buf) {
                Ok(t) => return Some(t),
                Err(_) => self.stats.control_dropped += 1,
            }
        }
        None
    }

    /// Whether [`poll_transmit`](Self::poll_transmit) has a frame to give.
    #[must_use]
    pub const fn has_transmits(&self) -> bool {
        self.transmits.len() > 0
    }

    /// When to call [`handle_timeout`](Self::handle_timeout) next, or `None` if no timer
    /// runs.
    #[must_use]
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.handshake.as_ref().map(Handshake::deadline)
    }

    // ----- sending ---------------------------------------------------------------------

    /// Writes `message` into `out` as the link's next frame: the link's version, our ids,
    /// the running sequence number, signed when the link signs.
    ///
    /// ```
    /// use mavstack_channel::{Channel, Config};
    /// use mavstack_core::time::Instant;
    /// use mavstack_dialects::common::Heartbeat;
    /// let mut vehicle = Channel::new(Config::vehicle(1, 1)).unwrap();
    /// let mut buf = [0u8; 280];
    /// let t = vehicle.send(Instant::ZERO, &Heartbeat::default(), &mut buf).unwrap();
    /// assert_eq!((buf[0], t.len, t.seq), (0xfe, 17, 0)); // starts in MAVLink 1
    /// ```
    ///
    /// # Errors
    /// [`SendError::NeedsMavlink2`] for a message id above 255 on a MAVLink 1 link;
    /// [`SendError::Emit`] if `out` is too small.
    pub fn send<M: Message>(
        &mut self,
        now: Instant,
        message: &M,
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.write(now, &M::INFO, &payload[..len], Framing::Link, out)
    }

    /// Like [`send`](Self::send), but in MAVLink 2 framing whatever the link's version: the
    /// one exception to a link's single version, for a vehicle's answer to
    /// MAV_CMD_REQUEST_MESSAGE for a message id of 256 or more (the handshake's
    /// "other message" method) on a link that still sends MAVLink 1.
    ///
    /// # Errors
    /// [`SendError::Mavlink2Disabled`] on a vehicle with MAVLink 2 disabled;
    /// [`SendError::Emit`] if `out` is too small.
    pub fn send_mavlink2<M: Message>(
        &mut self,
        now: Instant,
        message: &M,
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        if !self.accepts_mavlink2() {
            return Err(SendError::Mavlink2Disabled);
        }
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.write(now, &M::INFO, &payload[..len], Framing::Mavlink2, out)
    }

    /// Writes a message given as raw payload bytes (its full encoding; a MAVLink 2 frame
    /// truncates trailing zeros, a MAVLink 1 frame carries the bytes as given) with message
    /// id `msg_id` and its `crc_extra`, like [`send`](Self::send).
    ///
    /// # Errors
    /// [`SendError::InvalidMessageId`] for an id over 24 bits; [`SendError::NeedsMavlink2`]
    /// for an id above 255 on a MAVLink 1 link; [`SendError::Emit`] for a payload over
    /// 255 bytes or an `out` too small.
    pub fn send_raw(
        &mut self,
        now: Instant,
        msg_id: u32,
        crc_extra: u8,
        payload: &[u8],
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        if msg_id > 0xFF_FFFF {
            return Err(SendError::InvalidMessageId { msg_id });
        }
        let len = u8::try_from(payload.len()).map_err(|_| EmitError::PayloadTooLong {
            len: payload.len(),
            max: MAX_PAYLOAD_LEN,
        })?;
        let info = MessageInfo {
            id: msg_id,
            name: "",
            crc_extra,
            min_len: len,
            max_len: len,
            target_system_offset: None,
            target_component_offset: None,
        };
        self.write(now, &info, payload, Framing::Link, out)
    }

    /// Appends this link's signature to a MAVLink 2 frame someone else wrote (a router
    /// forwarding a frame onto a signed link): `out[..len]` holds the frame with its signed
    /// flag set and its checksum computed over that flag. The signature uses the link's
    /// primary key, link id and next timestamp, as [`send`](Self::send) does. Returns the
    /// signed frame's length, or `None` when the link does not sign or `out` has no room for
    /// the 13 signature bytes.
    pub fn sign_frame(&mut self, now: Instant, out: &mut [u8], len: usize) -> Option<usize> {
        let s = self.signing.as_mut()?;
        let timestamp = s.next_timestamp(now);
        let signed = append_signature(
            out,
            len,
            s.config.link_id,
            timestamp,
            s.config.primary_key(),
        )
        .ok()?;
        self.stats.sent += 1;
        Some(signed)
    }

    // ----- the handshake ---------------------------------------------------------------

    /// Starts the ground-station handshake with `target` at `now`: the request goes out
    /// (always in MAVLink 2 framing, signed when the link signs) through
    /// [`poll_transmit`](Self::poll_transmit), is resent per the configured
    /// [`HandshakeConfig`], and the outcome arrives as [`Event::Handshake`].
    ///
    /// # Errors
    /// [`HandshakeError`]: not a ground station, a handshake already running, or
    /// [`HandshakeMethod::RequestMessageOther`] with an id below 256.
    pub fn start_handshake(
        &mut self,
        now: Instant,
        target: Target,
        method: HandshakeMethod,
        encoding: CommandEncoding,
    ) -> Result<(), HandshakeError> {
        if !matches!(self.role, Role::GroundStation(_)) {
            return Err(HandshakeError::NotGroundStation);
        }
        if self.handshake.is_some() {
            return Err(HandshakeError::InProgress);
        }
        if let HandshakeMethod::RequestMessageOther { msg_id } = method
            && msg_id < 256
        {
            return Err(HandshakeError::NotMavlink2Message { msg_id });
        }
        let request = HandshakeRequest {
            target,
            method,
            encoding,
        };
        let state = AwaitingAnswer::start(now, request, &self.handshake_config);
        self.queue_control(
            Control::Request {
                request,
                attempt: 1,
            },
            Framing::Mavlink2,
        );
        self.handshake = Some(Handshake::AwaitingAnswer(state));
        Ok(())
    }

    /// The running handshake, if any.
    #[must_use]
    pub const fn handshake(&self) -> Option<&Handshake> {
        self.handshake.as_ref()
    }

    /// Abandons the running handshake (no outcome event) and returns its last state.
    pub const fn cancel_handshake(&mut self) -> Option<Handshake> {
        self.handshake.take()
    }

    /// The PROTOCOL_VERSION the peer reported in the last successful handshake.
    #[must_use]
    pub const fn peer_protocol_version(&self) -> Option<&ProtocolVersion> {
        self.peer_protocol_version.as_ref()
    }

    // ----- state -----------------------------------------------------------------------

    /// The framing the link sends now.
    #[must_use]
    pub const fn version(&self) -> LinkVersion {
        match (self.signing.is_some(), self.out_version) {
            (true, _) => LinkVersion::SignedMavlink2,
            (false, Version::V2) => LinkVersion::Mavlink2,
            (false, Version::V1) => LinkVersion::Mavlink1,
        }
    }

    /// Whether the link accepts MAVLink 2 (all but a vehicle or relay with MAVLink 2
    /// disabled).
    #[must_use]
    pub const fn accepts_mavlink2(&self) -> bool {
        !matches!(
            self.role,
            Role::Vehicle(VehiclePolicy {
                version: VehicleVersion::Mavlink1Only,
                ..
            }) | Role::Relay(VehicleVersion::Mavlink1Only)
        )
    }

    /// The protocol capabilities the link contributes to AUTOPILOT_VERSION:
    /// MAV_PROTOCOL_CAPABILITY_MAVLINK2 (8192) whenever MAVLink 2 would be accepted, even
    /// while the link still sends MAVLink 1. OR it into the vehicle's own capabilities.
    #[must_use]
    pub const fn capabilities(&self) -> MavProtocolCapability {
        if self.accepts_mavlink2() {
            MavProtocolCapability::MAVLINK2
        } else {
            MavProtocolCapability(0)
        }
    }

    /// Our system id.
    #[must_use]
    pub const fn system_id(&self) -> u8 {
        self.sysid
    }

    /// Our component id.
    #[must_use]
    pub const fn component_id(&self) -> u8 {
        self.compid
    }

    /// Our role and version policy.
    #[must_use]
    pub const fn role(&self) -> &Role {
        &self.role
    }

    /// Whether the link is marked secure (SETUP_SIGNING accepted).
    #[must_use]
    pub const fn is_secure(&self) -> bool {
        self.secure
    }

    /// Marks the link secure or not.
    pub const fn set_secure(&mut self, secure: bool) {
        self.secure = secure;
    }

    /// Refuses SETUP_SIGNING for now (`true`) or takes it again (`false`): a vehicle that
    /// will not change its key at the moment (ArduPilot ignores SETUP_SIGNING while armed)
    /// holds it; a held SETUP_SIGNING is a rejection ([`RejectReason::SetupSigningHeld`](crate::RejectReason::SetupSigningHeld)),
    /// for the vehicle to say why. Off by default.
    pub const fn hold_setup_signing(&mut self, held: bool) {
        self.setup_signing_held = held;
    }

    /// Whether SETUP_SIGNING is held ([`hold_setup_signing`](Self::hold_setup_signing)).
    #[must_use]
    pub const fn is_setup_signing_held(&self) -> bool {
        self.setup_signing_held
    }

    /// The counters.
    #[must_use]
    pub fn stats(&self) -> LinkStats {
        let mut stats = self.stats;
        stats.parser = *self.deframer.stats();
        for s in self.seqs.sources() {
            stats.received += s.received;
            stats.lost += s.lost;
            stats.duplicates += s.duplicates;
        }
        stats.untracked_frames = self.seqs.untracked;
        stats
    }

    /// Sequence statistics per source (up to [`crate::seq::MAX_SOURCES`]).
    #[must_use]
    pub fn sources(&self) -> &[SourceStats] {
        self.seqs.sources()
    }

    // ----- signing ---------------------------------------------------------------------

    /// The signing settings, if the link signs.
    #[must_use]
    pub fn signing(&self) -> Option<&SigningConfig> {
        self.signing.as_ref().map(|s| &s.config)
    }

    /// Turns signing on (the link sends signed MAVLink 2 from the next frame) or off (the
    /// link sends unsigned MAVLink 2), or changes its settings. A [`Event::VersionChanged`]
    /// reports a change of version. When the link already signs, its timestamp and replay
    /// table carry over: timestamps keep rising whatever `initial_timestamp` says.
    ///
    /// # Errors
    /// [`ConfigError::SigningNeedsMavlink2`] on a vehicle with MAVLink 2 disabled.
    pub fn set_signing(&mut self, signing: Option<SigningConfig>) -> Result<(), ConfigError> {
        if signing.is_some() && !self.accepts_mavlink2() {
            return Err(ConfigError::SigningNeedsMavlink2);
        }
        let before = self.version();
        let cause = if signing.is_some() {
            SwitchCause::SigningEnabled
        } else {
            SwitchCause::SigningDisabled
        };
        let previous = self.signing.take();
        self.signing = signing.map(|mut config| {
            if let Some(p) = &previous {
                config.initial_timestamp = config
                    .initial_timestamp
                    .max(p.last_timestamp().saturating_add(1))
                    .min(MAX_TIMESTAMP);
            }
            let mut next = LinkSigning::new(config);
            if let Some(p) = previous {
                next.replay = p.replay;
            }
            next
        });
        if self.signing.is_some() || before == LinkVersion::SignedMavlink2 {
            self.out_version = Version::V2;
        }
        let after = self.version();
        if before != after {
            let _ = self.events.push(Event::VersionChanged {
                from: before,
                to: after,
                cause,
            });
        }
        Ok(())
    }

    /// The largest signing timestamp issued or accepted (store it at shutdown), if the link
    /// signs.
    #[must_use]
    pub fn signing_timestamp(&self) -> Option<u64> {
        self.signing.as_ref().map(LinkSigning::last_timestamp)
    }

    /// Changes how `now` maps to wall-clock time for signing timestamps, e.g. when GPS time
    /// becomes known. Timestamps still never go backwards.
    pub fn set_wall_clock(&mut self, clock: WallClock) {
        if let Some(s) = &mut self.signing {
            s.config.wall_clock = clock;
        }
    }

    /// The signing streams seen, with their last accepted timestamps.
    #[must_use]
    pub fn signing_streams(&self) -> &[SigningStream] {
        self.signing.as_ref().map_or(&[], |s| s.replay.streams())
    }
}

impl core::fmt::Debug for Channel {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Channel")
            .field("sysid", &self.sysid)
            .field("compid", &self.compid)
            .field("role", &self.role)
            .field("secure", &self.secure)
            .field("setup_signing_held", &self.setup_signing_held)
            .field("version", &self.version())
            .field("seq", &self.seq)
            .field("handshake", &self.handshake)
            .field("events", &self.events.len())
            .field("transmits", &self.transmits.len())
            .finish_non_exhaustive()
    }
}
