//! How the router and each of its links are set up.

use alloc::string::String;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_channel::{Config as ChannelConfig, GroundPolicy, SigningConfig, VehicleVersion};

/// Whose link it is: a router's, that forwards for others, or a vehicle's (any component
/// that answers the MAVLink 2 handshake for itself).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LinkRole {
    /// Forwards what others send and speaks for nobody: never answers a handshake, and
    /// SETUP_SIGNING is routed like any frame (from a `secure` link only).
    #[default]
    Relay,
    /// The link of the router's own component when it is a vehicle: its channel answers a
    /// request for PROTOCOL_VERSION addressed to it (PROTOCOL_VERSION in MAVLink 2, or a
    /// COMMAND_ACK failure in MAVLink 1 on a `version=1` link), applies a SETUP_SIGNING
    /// addressed to it on a `secure` link, and the MAV_PROTOCOL_CAPABILITY_MAVLINK2 bit of the
    /// component's own AUTOPILOT_VERSION is set exactly on the links that accept MAVLink 2.
    Vehicle {
        /// How it answers a request for PROTOCOL_VERSION.
        protocol_version: ProtocolVersionSupport,
    },
    /// The link of the router's own component when it is a ground station: it can run the
    /// MAVLink 2 handshake ([`crate::Router::start_handshake`]), and an `auto` link also
    /// switches to MAVLink 2 on an AUTOPILOT_VERSION with the MAVLINK2 capability. A
    /// `version=1` link never handshakes.
    GroundStation,
}

/// How a vehicle's link answers a request for PROTOCOL_VERSION (REQUEST_MESSAGE(300) or
/// MAV_CMD_REQUEST_PROTOCOL_VERSION).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum ProtocolVersionSupport {
    /// PROTOCOL_VERSION in MAVLink 2, as the versions documents describe (a NACK on a
    /// `version=1` link).
    #[default]
    Answer,
    /// Refused as ArduPilot refuses it: COMMAND_ACK FAILED for REQUEST_MESSAGE(300),
    /// UNSUPPORTED for command 519. A ground station then falls back to another message.
    Refuse,
    /// Neither ACK nor answer (a vehicle that ignores the request).
    Silent,
}

/// Which framing a link carries (the `version` link option).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum VersionMode {
    /// `version=1`: MAVLink 1 only. MAVLink 2 frames are converted to MAVLink 1 (base fields);
    /// ids above 255 cannot go.
    Mavlink1,
    /// `version=2`: MAVLink 2 from the start. MAVLink 1 frames are converted.
    Mavlink2,
    /// `version=auto`: the peer decides. Frames go out in the framing they arrived in until
    /// the peer's first MAVLink 2 frame; from then on the link is MAVLink 2.
    #[default]
    Auto,
    /// A fleet bridge's link (no link option spells it): every frame goes out byte for byte
    /// in the framing it arrived in, signature kept, never converted, so that what crosses
    /// the broker is what the vehicle sent. (With [`LinkConfig::monitor`] it also gets every
    /// frame of the network, as a vehicle's bridge link does.)
    Transparent,
}

impl VersionMode {
    /// The channel's version policy for this mode.
    #[must_use]
    pub const fn channel_policy(self) -> VehicleVersion {
        match self {
            Self::Mavlink1 => VehicleVersion::Mavlink1Only,
            Self::Mavlink2 => VehicleVersion::Mavlink2,
            Self::Auto | Self::Transparent => VehicleVersion::StartMavlink1,
        }
    }
}

/// An allow list and a block list of numbers (message ids, system or component ids).
/// A value passes when it is not blocked and, if there is an allow list, on it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct IdFilter {
    /// Only these pass (`None`: every value not blocked passes).
    pub allow: Option<Vec<u32>>,
    /// These never pass.
    pub block: Vec<u32>,
}

impl IdFilter {
    /// Whether `value` passes.
    #[must_use]
    #[inline]
    pub fn passes(&self, value: u32) -> bool {
        // Most links filter nothing: no search set up for empty lists.
        if self.is_open() {
            return true;
        }
        !self.block.contains(&value) && self.allow.as_ref().is_none_or(|a| a.contains(&value))
    }

    /// Whether the filter lets everything through.
    #[must_use]
    #[inline]
    pub fn is_open(&self) -> bool {
        self.allow.is_none() && self.block.is_empty()
    }
}

/// Filters of one direction of a link, on the message id and the source system and
/// component ids.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DirectionFilters {
    /// On the message id.
    pub msg: IdFilter,
    /// On the source system id.
    pub src_sys: IdFilter,
    /// On the source component id.
    pub src_comp: IdFilter,
}

impl DirectionFilters {
    /// Whether a frame of message `msg_id` from `(sysid, compid)` passes.
    #[must_use]
    #[inline]
    pub fn passes(&self, msg_id: u32, sysid: u8, compid: u8) -> bool {
        self.msg.passes(msg_id)
            && self.src_sys.passes(u32::from(sysid))
            && self.src_comp.passes(u32::from(compid))
    }

    /// Whether nothing is filtered.
    #[must_use]
    pub fn is_open(&self) -> bool {
        self.msg.is_open() && self.src_sys.is_open() && self.src_comp.is_open()
    }
}

/// Rate limits on what a link sends. Control traffic ([`crate::is_control`]) is never
/// limited.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RateLimits {
    /// `(message id, maximum frames per second)`: per source (sysid, compid), frames of that
    /// message closer together than `1 / rate` are dropped.
    pub per_message: Vec<(u32, u32)>,
    /// A byte budget per second for the whole link (a slow radio); telemetry that does not
    /// fit is dropped. Control traffic always goes and uses the budget up.
    pub bytes_per_s: Option<u32>,
}

/// One link of the router.
///
/// ```
/// use mavstack_router::{LinkConfig, VersionMode};
/// let mut legacy = LinkConfig::new("legacy");
/// legacy.version = VersionMode::Mavlink1;
/// legacy.filters_out.msg.block.push(30); // no ATTITUDE for it
/// ```
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct LinkConfig {
    /// Its name in statistics and logs.
    pub name: String,
    /// Whose link it is (default [`LinkRole::Relay`]).
    pub role: LinkRole,
    /// The framing it carries.
    pub version: VersionMode,
    /// Signing: `Some` makes it a signed MAVLink 2 link (every frame out signed, every frame
    /// in verified and fresh).
    pub signing: Option<SigningConfig>,
    /// SETUP_SIGNING may be forwarded from this link.
    pub secure: bool,
    /// Unsigned frames from this link may be signed onto signed links. A link with a key is
    /// trusted for the frames that verify on it.
    pub trusted: bool,
    /// Filters on what the link receives.
    pub filters_in: DirectionFilters,
    /// Filters on what the link sends.
    pub filters_out: DirectionFilters,
    /// Rate limits on what it sends.
    pub limits: RateLimits,
    /// How many frames may wait to be sent, per priority (default 1024 telemetry, 256
    /// control). More are dropped and counted (`queue_full`).
    pub queue_frames: usize,
    /// The transport may pack several frames into one UDP datagram (the `pack` option, read
    /// by the driver, not the router; default off).
    pub pack: bool,
    /// The link gets every frame of the network, targeted ones included wherever their target
    /// is (a vehicle's fleet bridge link: the broker sees the whole network). Default off.
    pub monitor: bool,
    /// The peers of this link (the clients of a server link) forward nothing to each other:
    /// the `isolate_peers` option, read by the driver, which puts them all in one
    /// [`group`](Self::group). Default off.
    pub isolate_peers: bool,
    /// Links of one group forward nothing to each other, broadcast or targeted (`None`, the
    /// default: in no group). A fleet's vehicles sharing a port need not hear each other.
    pub group: Option<u32>,
}

impl LinkConfig {
    /// A link named `name` with every default: `version=auto`, no key, not secure, not
    /// trusted, no filters, no limits.
    #[must_use]
    pub fn new(name: impl Into<String>) -> Self {
        Self {
            name: name.into(),
            role: LinkRole::Relay,
            version: VersionMode::Auto,
            signing: None,
            secure: false,
            trusted: false,
            filters_in: DirectionFilters::default(),
            filters_out: DirectionFilters::default(),
            limits: RateLimits::default(),
            queue_frames: 1024,
            pack: false,
            monitor: false,
            isolate_peers: false,
            group: None,
        }
    }

    /// The channel setup of this link for a router with ids `(sysid, compid)`.
    #[must_use]
    pub fn channel_config(&self, sysid: u8, compid: u8) -> ChannelConfig {
        let mut config = match self.role {
            LinkRole::Relay => ChannelConfig::relay(sysid, compid, self.version.channel_policy()),
            LinkRole::Vehicle { protocol_version } => {
                let mut config = ChannelConfig::vehicle(sysid, compid);
                if let Some(policy) = config.vehicle_policy_mut() {
                    policy.version = self.version.channel_policy();
                    if protocol_version != ProtocolVersionSupport::Answer {
                        policy.protocol_version = None;
                        policy.refuse_unsupported =
                            protocol_version == ProtocolVersionSupport::Refuse;
                    }
                }
                config
            }
            LinkRole::GroundStation => match self.version {
                VersionMode::Mavlink1 => {
                    ChannelConfig::relay(sysid, compid, VehicleVersion::Mavlink1Only)
                }
                VersionMode::Mavlink2 => {
                    let mut config = ChannelConfig::ground_station(sysid, compid);
                    config.role = mavstack_channel::Role::GroundStation(GroundPolicy::Mavlink2);
                    config
                }
                VersionMode::Auto | VersionMode::Transparent => {
                    ChannelConfig::ground_station(sysid, compid)
                }
            },
        };
        config.signing.clone_from(&self.signing);
        config.secure = self.secure;
        config
    }
}

/// How the router as a whole behaves.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct RouterConfig {
    /// The router's own system id, used for the frames its links send themselves (default
    /// 1; a router sends none unless a node's services do).
    pub system_id: u8,
    /// The router's own component id (default 191, MAV_COMP_ID_ONBOARD_COMPUTER: a router
    /// usually runs on a companion computer).
    pub component_id: u8,
    /// A route not refreshed for this long is forgotten (default 30 s).
    pub route_ttl: Duration,
    /// A system heard on a second link replaces the first one only if it has not been heard
    /// there for this long (default 1 s); otherwise both links lead to it (redundant paths,
    /// or an echo that must not cut it off).
    pub route_move_after: Duration,
    /// Drop a frame whose exact bytes were seen within this window; each sighting renews it
    /// (default off).
    pub dedup: Option<Duration>,
    /// Entries in the dedup table (default 8192; older entries are evicted first). Each
    /// keeps its frame's bytes (up to 280), so that frames are told apart by their bytes,
    /// not by a hash alone.
    pub dedup_capacity: usize,
    /// The hash the dedup table files frames under (`None`, the default: its own). Tests
    /// force collisions with it; whatever it returns, only equal bytes are duplicates.
    #[doc(hidden)]
    pub dedup_hash: Option<fn(&[u8]) -> u64>,
    /// Frames for the router itself ([`crate::Router::take_local`]): none, the ones addressed to
    /// it or broadcast, or every frame (a sniffer).
    pub local: LocalDelivery,
    /// Whether frames are forwarded between links (default on). Off, the links only carry
    /// the router's own component's traffic: a ground station with two radios to the same
    /// vehicle, which must not loop them into each other.
    pub forward: bool,
}

/// Which frames the router hands to its own component.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LocalDelivery {
    /// None (a pure router).
    #[default]
    None,
    /// Broadcasts and frames addressed to the router's system (and component).
    Addressed,
    /// Every accepted frame.
    All,
}

impl Default for RouterConfig {
    fn default() -> Self {
        Self {
            system_id: 1,
            component_id: 191,
            route_ttl: Duration::from_secs(30),
            route_move_after: Duration::from_secs(1),
            dedup: None,
            dedup_capacity: 8192,
            dedup_hash: None,
            local: LocalDelivery::None,
            forward: true,
        }
    }
}
