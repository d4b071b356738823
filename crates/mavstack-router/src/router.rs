//! The [`Router`]: many links, learned routes, forwarding with conversion.

use alloc::boxed::Box;
use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_channel::{
    Channel, CommandEncoding, ConfigError, HandshakeError, HandshakeMethod, HandshakeOutcome,
    LinkVersion, ProtocolVersionAnswer, ReceivedFrame, Rejected, SigningConfig, SigningSetup,
    SwitchCause, Target,
};
use mavstack_core::MessageTable;
use mavstack_core::message::Message as _;
use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_dialects::common::{AutopilotVersion, MavProtocolCapability};

use crate::config::{LinkConfig, RouterConfig, VersionMode};
use crate::dedup::Dedup;
use crate::dialect::{is_control, target_of};
use crate::limit::Limiter;
use crate::local::LocalFrames;
use crate::log_readers::LogReaders;
use crate::queue::OutQueue;
use crate::route::{Route, Routes};

mod forward;
use crate::stats::{Counters, DropReason, LinkMode, LinkStatus};
use crate::systems::{SystemInfo, Systems};

/// How many events wait for [`Router::poll_event`]; more are dropped and counted
/// ([`Router::events_dropped`]).
pub const EVENT_CAPACITY: usize = 4096;
/// How often routes are swept for expiry.
const SWEEP: Duration = Duration::from_secs(1);

/// A link's handle within one router. Ids of removed links are reused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LinkId(u32);

impl LinkId {
    /// The id with index `n`.
    #[must_use]
    pub const fn new(n: u32) -> Self {
        Self(n)
    }

    /// Its index.
    #[must_use]
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

impl core::fmt::Display for LinkId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "link {}", self.0)
    }
}

/// What the router reports.
// Frames travel inline (no heap per frame); the other variants are rare.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
#[non_exhaustive]
pub enum Event {
    /// A link's version changed (an auto link's peer sent its first MAVLink 2 frame).
    VersionChanged {
        /// The link.
        link: LinkId,
        /// Before.
        from: LinkVersion,
        /// After.
        to: LinkVersion,
        /// Why.
        cause: SwitchCause,
    },
    /// A [`LinkRole::Vehicle`](crate::LinkRole::Vehicle) link was asked for
    /// PROTOCOL_VERSION; its answer is queued on the link.
    ProtocolVersionRequested {
        /// The link.
        link: LinkId,
        /// The requester (sysid, compid).
        from: (u8, u8),
        /// What the link answered.
        answer: ProtocolVersionAnswer,
    },
    /// A [`LinkRole::Vehicle`](crate::LinkRole::Vehicle) link applied a SETUP_SIGNING (it
    /// came on a `secure` link, addressed to the router's component).
    SigningSetup {
        /// The link.
        link: LinkId,
        /// The sender (sysid, compid).
        from: (u8, u8),
        /// What changed.
        setup: SigningSetup,
    },
    /// A signed link asks for its signing timestamp to be stored (see the channel's
    /// `Event::PersistTimestamp`).
    PersistTimestamp {
        /// The link.
        link: LinkId,
        /// The value to store.
        timestamp: u64,
    },
    /// A handshake started with [`Router::start_handshake`] ended.
    Handshake {
        /// The link.
        link: LinkId,
        /// How it ended.
        outcome: HandshakeOutcome,
    },
    /// A link's channel refused a frame (bad signature, replay, unsigned on a signed link).
    Rejected {
        /// The link.
        link: LinkId,
        /// What and why.
        rejected: Rejected,
    },
}

/// Where [`Router::send`] sends a message of the router's own component.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SendTo {
    /// Where the message's target fields lead: the links a known target was heard on; every
    /// link for a broadcast, a target not heard yet, or a message without target fields.
    Target,
    /// Onto this link only.
    Link(LinkId),
    /// Where component `(sysid, compid)` was heard, as if the message were addressed to it
    /// (an answer without target fields, such as PARAM_VALUE for a read); every link if it
    /// was not heard. Component 0 means any component of the system.
    Component(u8, u8),
}

/// A frame to send: `buf[..len]` onto `link`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[must_use = "the frame is in the buffer and must be sent"]
pub struct Transmit {
    /// The link.
    pub link: LinkId,
    /// The frame's length.
    pub len: usize,
}

/// What choosing a frame's destinations needs of a link, kept apart from its state (a few
/// bytes per link, so that a broadcast among a thousand links reads one small table).
#[derive(Clone, Copy, Debug, Default)]
struct Member {
    /// A link has this index now.
    live: bool,
    /// [`LinkConfig::monitor`].
    monitor: bool,
    /// [`LinkConfig::group`].
    group: Option<u32>,
}

impl Member {
    /// Whether a frame from a link of `group` may go to this one.
    fn takes_from(self, group: Option<u32>) -> bool {
        self.live && (group.is_none() || self.group != group)
    }
}

struct LinkState {
    config: LinkConfig,
    channel: Channel,
    queue: OutQueue,
    limiter: Limiter,
    counters: Counters,
    ready: bool,
}

impl LinkState {
    fn mode(&self) -> LinkMode {
        if self.channel.signing().is_some() {
            return LinkMode::Signed;
        }
        match (self.config.version, self.channel.version()) {
            (VersionMode::Mavlink1, _) => LinkMode::Mavlink1,
            (VersionMode::Mavlink2, _) | (VersionMode::Auto, LinkVersion::Mavlink2) => {
                LinkMode::Mavlink2
            }
            (VersionMode::Auto, _) => LinkMode::Auto,
            (VersionMode::Transparent, _) => LinkMode::Transparent,
        }
    }
}

/// The sans-IO state of a router: a [`Channel`] per link (its version, signing and
/// statistics), learned routes, and a bounded queue per link.
///
/// Bytes come in with [`handle_datagram`](Self::handle_datagram) (a whole UDP datagram) or
/// [`handle_input`](Self::handle_input) (a piece of a stream), time with
/// [`handle_timeout`](Self::handle_timeout); frames to send come out of
/// [`poll_transmit`](Self::poll_transmit) (or per link,
/// [`poll_link_transmit`](Self::poll_link_transmit)), events out of
/// [`poll_event`](Self::poll_event), frames for its own component out of
/// [`take_local`](Self::take_local). It never reads a clock, sleeps or touches a socket, and
/// does not allocate per frame once its tables have grown.
///
/// ```
/// use mavstack_core::time::Instant;
/// use mavstack_router::{LinkConfig, MessageTable, Router, RouterConfig, VersionMode};
/// use mavstack_dialects::common::MavMessage;
///
/// let mut router = Router::new(RouterConfig::default(), MessageTable::of::<MavMessage>());
/// let vehicle = router.add_link(LinkConfig::new("vehicle")).unwrap();
/// let mut legacy = LinkConfig::new("legacy");
/// legacy.version = VersionMode::Mavlink1;
/// let legacy = router.add_link(legacy).unwrap();
///
/// // The protocol digest's golden MAVLink 2 HEARTBEAT, from the vehicle.
/// let hb = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// router.handle_datagram(Instant::from_secs(1), vehicle, &hb);
/// let mut buf = [0u8; 280];
/// let t = router.poll_transmit(&mut buf).unwrap();
/// assert_eq!(t.link, legacy);
/// // ...converted to MAVLink 1, the digest's golden MAVLink 1 HEARTBEAT.
/// assert_eq!(&buf[..t.len], [0xfe, 9, 0, 1, 1, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x81, 0xb7]);
/// ```
pub struct Router {
    config: RouterConfig,
    dialect: MessageTable,
    links: Vec<Option<LinkState>>,
    /// Per link index, beside `links`.
    members: Vec<Member>,
    /// Links whose channel may have a timer running (a handshake was started on them).
    timed: Vec<LinkId>,
    routes: Routes,
    systems: Systems,
    log_readers: LogReaders,
    dedup: Option<Dedup>,
    events: VecDeque<Event>,
    /// Frames for the router's own component, until [`Router::take_local`].
    local: LocalFrames,
    events_dropped: u64,
    ready: VecDeque<LinkId>,
    scratch: Vec<LinkId>,
    /// The frame being routed, copied out of its channel (kept for the next one).
    received: Option<Box<ReceivedFrame>>,
    next_sweep: Option<Instant>,
    /// SETUP_SIGNING held on every link ([`Router::hold_setup_signing`]).
    setup_signing_held: bool,
}

impl Router {
    /// A router with no links.
    #[must_use]
    pub fn new(config: RouterConfig, dialect: MessageTable) -> Self {
        let dedup = config
            .dedup
            .map(|w| Dedup::new(config.dedup_capacity, w, config.dedup_hash));
        Self {
            config,
            dialect,
            links: Vec::new(),
            members: Vec::new(),
            timed: Vec::new(),
            routes: Routes::default(),
            systems: Systems::default(),
            log_readers: LogReaders::default(),
            dedup,
            events: VecDeque::new(),
            local: LocalFrames::new(),
            events_dropped: 0,
            ready: VecDeque::new(),
            scratch: Vec::new(),
            received: None,
            next_sweep: None,
            setup_signing_held: false,
        }
    }

    /// The router's settings.
    #[must_use]
    pub const fn config(&self) -> &RouterConfig {
        &self.config
    }

    // ----- links -----------------------------------------------------------------------

    /// Adds a link (a serial port, a UDP peer, a TCP client...).
    ///
    /// # Errors
    /// [`ConfigError`] if its channel cannot be set up (signing with `version=1`).
    pub fn add_link(&mut self, config: LinkConfig) -> Result<LinkId, ConfigError> {
        let mut channel = Channel::with_table(
            config.channel_config(self.config.system_id, self.config.component_id),
            self.dialect,
        )?;
        channel.hold_setup_signing(self.setup_signing_held);
        let member = Member {
            live: true,
            monitor: config.monitor,
            group: config.group,
        };
        let state = LinkState {
            limiter: Limiter::new(&config.limits),
            config,
            channel,
            queue: OutQueue::default(),
            counters: Counters::default(),
            ready: false,
        };
        let index = match self.members.iter().position(|m| !m.live) {
            Some(i) => {
                self.links[i] = Some(state);
                self.members[i] = member;
                i
            }
            None => {
                self.links.push(Some(state));
                self.members.push(member);
                self.links.len() - 1
            }
        };
        // Fewer than 2^32 links exist at once.
        Ok(LinkId(u32::try_from(index).unwrap_or(u32::MAX)))
    }

    /// Removes a link (its peer went away): its routes and queued frames go with it.
    /// Returns its final status counters, or `None` for an unknown id.
    pub fn remove_link(&mut self, link: LinkId) -> Option<Counters> {
        let state = self.links.get_mut(link.index())?.take()?;
        if let Some(m) = self.members.get_mut(link.index()) {
            *m = Member::default();
        }
        self.routes.remove_link(link);
        self.systems.forget_link(link);
        self.log_readers.forget_link(link);
        self.ready.retain(|&l| l != link);
        self.timed.retain(|&l| l != link);
        Some(state.counters)
    }

    /// The ids of the links there are now.
    pub fn links(&self) -> impl Iterator<Item = LinkId> + '_ {
        self.members
            .iter()
            .enumerate()
            .filter(|(_, m)| m.live)
            .map(|(i, _)| LinkId(u32::try_from(i).unwrap_or(u32::MAX)))
    }

    /// A snapshot of a link's state and counters.
    #[must_use]
    pub fn link_status(&self, link: LinkId) -> Option<LinkStatus<'_>> {
        let l = self.link(link)?;
        Some(LinkStatus {
            name: &l.config.name,
            mode: l.mode(),
            counters: l.counters,
            channel: l.channel.stats(),
            queued: l.queue.len(),
        })
    }

    /// A link's channel (its version, signing state, per-source sequence statistics).
    #[must_use]
    pub fn channel(&self, link: LinkId) -> Option<&Channel> {
        self.link(link).map(|l| &l.channel)
    }

    /// A link's setup.
    #[must_use]
    pub fn link_config(&self, link: LinkId) -> Option<&LinkConfig> {
        self.link(link).map(|l| &l.config)
    }

    /// The learned routes.
    pub fn routes(&self) -> impl Iterator<Item = Route> + '_ {
        self.routes.iter()
    }

    /// The components heard, each with its latest HEARTBEAT (forgotten after the route
    /// TTL of silence, or when its link goes).
    pub fn systems(&self) -> impl Iterator<Item = &SystemInfo> + '_ {
        self.systems.iter()
    }

    /// Events and local frames dropped because nobody drained
    /// [`poll_event`](Self::poll_event) or [`take_local`](Self::take_local).
    #[must_use]
    pub const fn events_dropped(&self) -> u64 {
        self.events_dropped
    }

    fn link(&self, link: LinkId) -> Option<&LinkState> {
        self.links.get(link.index())?.as_ref()
    }

    fn link_mut(&mut self, link: LinkId) -> Option<&mut LinkState> {
        self.links.get_mut(link.index())?.as_mut()
    }

    // ----- input -----------------------------------------------------------------------

    /// Feeds one whole datagram received on `link` at `now` (UDP: frames never span two
    /// datagrams, so an incomplete frame at its end is dropped at once). Unknown links are
    /// ignored.
    pub fn handle_datagram(&mut self, now: Instant, link: LinkId, data: &[u8]) {
        self.feed(now, link, data, true);
    }

    /// Feeds the next piece of a byte stream received on `link` (TCP, serial).
    pub fn handle_input(&mut self, now: Instant, link: LinkId, data: &[u8]) {
        self.feed(now, link, data, false);
    }

    fn feed(&mut self, now: Instant, id: LinkId, mut data: &[u8], datagram: bool) {
        if self.next_sweep.is_none() {
            self.next_sweep = Some(now + SWEEP);
        }
        loop {
            let Some(l) = self.link_mut(id) else { return };
            let n = if datagram {
                l.channel.handle_datagram(now, data)
            } else {
                l.channel.handle_input(now, data)
            };
            data = &data[n..];
            let drained = self.drain_channel(now, id);
            self.drain_channel_transmits(now, id);
            if data.is_empty() || (n == 0 && !drained) {
                break;
            }
        }
        self.note_timer(id);
    }

    // ----- the router's own messages ------------------------------------------------------

    /// Sends a message of the router's own component ([`RouterConfig::system_id`] and
    /// [`RouterConfig::component_id`]), given as its id and encoded payload: each link frames
    /// it in its own version (MAVLink 1 on a `version=1` link or an `auto` link that has not
    /// heard MAVLink 2, MAVLink 2 otherwise), with its own sequence numbers, signed when the
    /// link signs. The message goes where its target fields (read through the dialect) lead:
    /// a broadcast, or a system not heard yet, to every link; a known system to the links it
    /// was heard on. `to` may name one link, or the component it answers, instead (see
    /// [`SendTo`]). The out-filters, rate limits and queues of
    /// the links apply as to forwarded frames. Returns how many links it was queued on.
    ///
    /// ```
    /// use mavstack_core::time::Instant;
    /// use mavstack_core::Message as _;
    /// use mavstack_router::{LinkConfig, MessageTable, Router, RouterConfig, SendTo, VersionMode};
    /// use mavstack_dialects::common::{Heartbeat, MavMessage};
    ///
    /// let mut router = Router::new(RouterConfig::default(), MessageTable::of::<MavMessage>());
    /// let mut legacy = LinkConfig::new("legacy");
    /// legacy.version = VersionMode::Mavlink1;
    /// router.add_link(legacy).unwrap();
    /// let mut v2 = LinkConfig::new("v2");
    /// v2.version = VersionMode::Mavlink2;
    /// router.add_link(v2).unwrap();
    ///
    /// let mut payload = [0u8; 255];
    /// let len = Heartbeat::default().encode(&mut payload);
    /// assert_eq!(router.send(Instant::ZERO, SendTo::Target, Heartbeat::ID, &payload[..len]), 2);
    /// let mut buf = [0u8; 280];
    /// let magics: Vec<u8> = core::iter::from_fn(|| router.poll_transmit(&mut buf).map(|_| buf[0])).collect();
    /// assert_eq!(magics, [0xfe, 0xfd]);
    /// ```
    pub fn send(&mut self, now: Instant, to: SendTo, msg_id: u32, payload: &[u8]) -> usize {
        let Some(info) = self.dialect.info(msg_id) else {
            return 0;
        };
        let mut dests = core::mem::take(&mut self.scratch);
        dests.clear();
        let target = match to {
            SendTo::Link(link) => {
                dests.push(link);
                None
            }
            SendTo::Target => Some(target_of(Some(info), payload)),
            SendTo::Component(sysid, compid) => Some((sysid, compid)),
        };
        if let Some((tsys, tcomp)) = target {
            let known = tsys != 0
                && self
                    .routes
                    .links_to(now, self.config.route_ttl, tsys, tcomp, &mut dests);
            if !known {
                dests.clear();
                dests.extend(self.links());
            }
        }
        let control = is_control(msg_id);
        let own = (self.config.system_id, self.config.component_id);
        let mut queued = 0;
        for &d in &dests {
            let Some(out) = self.link_mut(d) else {
                continue;
            };
            if !out.config.filters_out.passes(msg_id, own.0, own.1) {
                out.counters.dropped.count(DropReason::Filtered);
                continue;
            }
            if !control && !out.limiter.allow_message(now, own.0, own.1, msg_id) {
                out.counters.dropped.count(DropReason::RateLimited);
                continue;
            }
            let mut own_caps = [0u8; mavstack_core::MAX_PAYLOAD_LEN];
            let payload = if msg_id == AutopilotVersion::ID
                && matches!(out.config.role, crate::LinkRole::Vehicle { .. })
            {
                with_mavlink2_capability(payload, out.channel.accepts_mavlink2(), &mut own_caps)
            } else {
                payload
            };
            let mut buf = [0u8; MAX_FRAME_LEN];
            let len = match out
                .channel
                .send_raw(now, msg_id, info.crc_extra, payload, &mut buf)
            {
                Ok(t) => t.len,
                Err(_) => {
                    // An id above 255 on a MAVLink 1 link, or a payload over 255 bytes.
                    out.counters.dropped.count(DropReason::CannotConvert);
                    continue;
                }
            };
            if !out.limiter.spend(now, len, control) {
                out.counters.dropped.count(DropReason::RateLimited);
                continue;
            }
            if !out
                .queue
                .push(control, &buf[..len], out.config.queue_frames)
            {
                out.counters.dropped.count(DropReason::QueueFull);
                continue;
            }
            out.counters.tx_frames += 1;
            out.counters.tx_bytes += len as u64;
            queued += 1;
            if !out.ready {
                out.ready = true;
                self.ready.push_back(d);
            }
        }
        self.scratch = dests;
        queued
    }

    /// Starts the MAVLink 2 handshake with `target` on a
    /// [`LinkRole::GroundStation`](crate::LinkRole::GroundStation) link: the request goes out
    /// in MAVLink 2 (signed when the link signs), is retried on the link's timer, and the
    /// outcome comes as [`Event::Handshake`] (the link switches to MAVLink 2 when it
    /// succeeds).
    ///
    /// # Errors
    /// [`HandshakeError`]: not a ground-station link (or an unknown one), a handshake
    /// already running on it, or a message id below 256 asked for.
    pub fn start_handshake(
        &mut self,
        now: Instant,
        link: LinkId,
        target: Target,
        method: HandshakeMethod,
        encoding: CommandEncoding,
    ) -> Result<(), HandshakeError> {
        let l = self
            .link_mut(link)
            .ok_or(HandshakeError::NotGroundStation)?;
        l.channel.start_handshake(now, target, method, encoding)?;
        self.note_timer(link);
        self.drain_channel_transmits(now, link);
        Ok(())
    }

    /// Turns signing on (with `signing`) or off on `link`, as after a SETUP_SIGNING: every
    /// frame the link sends from now on is signed with that key, and only frames that verify
    /// are accepted.
    ///
    /// # Errors
    /// [`ConfigError::SigningNeedsMavlink2`] on a `version=1` link (nothing changes); an
    /// unknown link is ignored.
    pub fn set_signing(
        &mut self,
        now: Instant,
        link: LinkId,
        signing: Option<SigningConfig>,
    ) -> Result<(), ConfigError> {
        let Some(l) = self.link_mut(link) else {
            return Ok(());
        };
        l.channel.set_signing(signing)?;
        self.drain_channel(now, link);
        Ok(())
    }

    /// Holds SETUP_SIGNING on every link, those added later too (`true`), or takes it again
    /// (`false`): a vehicle holds it while it will not change its key (ArduPilot while
    /// armed). A held SETUP_SIGNING comes out as [`Event::Rejected`] with
    /// [`RejectReason::SetupSigningHeld`](mavstack_channel::RejectReason::SetupSigningHeld)
    /// and changes nothing.
    pub fn hold_setup_signing(&mut self, held: bool) {
        self.setup_signing_held = held;
        for l in self.links.iter_mut().flatten() {
            l.channel.hold_setup_signing(held);
        }
    }

    // ----- output ----------------------------------------------------------------------

    /// Moves the next frame to send into `buf`: links take turns, each link's control
    /// traffic first. Call until `None` after every `handle_*`.
    pub fn poll_transmit(&mut self, buf: &mut [u8; MAX_FRAME_LEN]) -> Option<Transmit> {
        while let Some(link) = self.ready.pop_front() {
            let Some(l) = self.link_mut(link) else {
                continue;
            };
            let Some(len) = l.queue.pop_into(buf) else {
                l.ready = false;
                continue;
            };
            if l.queue.is_empty() {
                l.ready = false;
            } else {
                self.ready.push_back(link);
            }
            return Some(Transmit { link, len });
        }
        None
    }

    /// Moves the next frame for `link` into `buf` (for a driver that writes per socket).
    pub fn poll_link_transmit(
        &mut self,
        link: LinkId,
        buf: &mut [u8; MAX_FRAME_LEN],
    ) -> Option<usize> {
        self.link_mut(link)?.queue.pop_into(buf)
    }

    /// Whether `link` has frames waiting.
    #[must_use]
    pub fn has_transmits(&self, link: LinkId) -> bool {
        self.link(link).is_some_and(|l| !l.queue.is_empty())
    }

    /// The next event, or `None`.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// Hands over the frames for the router's own component (see [`RouterConfig::local`])
    /// accepted since the last call, in order: `into` is emptied and swapped with the
    /// router's, so that neither allocates once both have grown to the burst size.
    pub fn take_local(&mut self, into: &mut LocalFrames) {
        into.clear();
        core::mem::swap(into, &mut self.local);
    }

    // ----- time ------------------------------------------------------------------------

    /// When to call [`handle_timeout`](Self::handle_timeout) next.
    #[must_use]
    pub fn poll_timeout(&self) -> Option<Instant> {
        let channels = self
            .timed
            .iter()
            .filter_map(|&id| self.link(id)?.channel.poll_timeout())
            .min();
        let sweep = self.next_sweep.filter(|_| !self.routes.is_empty());
        match (channels, sweep) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Lets time pass: expires quiet routes, runs the links' timers.
    pub fn handle_timeout(&mut self, now: Instant) {
        if self.next_sweep.is_some_and(|t| now >= t) {
            self.routes.expire(now, self.config.route_ttl);
            self.systems.expire(now, self.config.route_ttl);
            self.next_sweep = Some(now + SWEEP);
        }
        let mut timed = core::mem::take(&mut self.timed);
        for &id in &timed {
            let due = self
                .link(id)
                .and_then(|l| l.channel.poll_timeout())
                .is_some_and(|t| now >= t);
            if due {
                if let Some(l) = self.link_mut(id) {
                    l.channel.handle_timeout(now);
                }
                self.drain_channel(now, id);
                self.drain_channel_transmits(now, id);
            }
        }
        // Links whose timers have all ended leave the list.
        timed.retain(|&id| {
            self.link(id)
                .is_some_and(|l| l.channel.poll_timeout().is_some())
        });
        self.timed = timed;
    }

    /// Puts `id` on the list of links with a timer, if its channel has one now.
    fn note_timer(&mut self, id: LinkId) {
        if self
            .link(id)
            .is_some_and(|l| l.channel.poll_timeout().is_some())
            && !self.timed.contains(&id)
        {
            self.timed.push(id);
        }
    }
}

/// AUTOPILOT_VERSION's payload with MAV_PROTOCOL_CAPABILITY_MAVLINK2 set or cleared in its
/// `capabilities` (the first field, a little-endian u64), written into `buf`.
fn with_mavlink2_capability<'a>(payload: &[u8], on: bool, buf: &'a mut [u8]) -> &'a [u8] {
    let len = payload.len().clamp(8, buf.len());
    buf[..len].fill(0);
    let n = payload.len().min(len);
    buf[..n].copy_from_slice(&payload[..n]);
    let mut caps = [0u8; 8];
    caps.copy_from_slice(&buf[..8]);
    let mut caps = u64::from_le_bytes(caps);
    if on {
        caps |= MavProtocolCapability::MAVLINK2.0;
    } else {
        caps &= !MavProtocolCapability::MAVLINK2.0;
    }
    buf[..8].copy_from_slice(&caps.to_le_bytes());
    &buf[..len]
}

impl core::fmt::Debug for Router {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Router")
            .field("links", &self.links.iter().flatten().count())
            .field("routes", &self.routes.len())
            .field("events", &self.events.len())
            .field("local", &self.local.len())
            .finish_non_exhaustive()
    }
}
