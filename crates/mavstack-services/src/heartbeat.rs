//! HEARTBEAT: our own at a fixed rate, and a table of the peers we hear.
//!
//! [`Heartbeats`] does both jobs of the heartbeat microservice: it emits our HEARTBEAT every
//! [`HeartbeatConfig::interval`] (1 Hz by default), and keeps one [`Peer`] per
//! (sysid, compid) heard, reporting [`HeartbeatEvent::New`] on the first heartbeat,
//! [`HeartbeatEvent::Changed`] when type, autopilot, mode or status change, and
//! [`HeartbeatEvent::Lost`] when no heartbeat came for [`HeartbeatConfig::timeout`]
//! (3 s by default, MAVSDK's value; QGC uses 3.5 s). A lost peer that comes back is new
//! again.
//!
//! ```
//! use core::time::Duration;
//! use mavstack_core::time::Instant;
//! use mavstack_dialects::common::{Heartbeat, MavAutopilot, MavMessage, MavType};
//! use mavstack_services::heartbeat::{HeartbeatConfig, HeartbeatEvent, Heartbeats};
//! use mavstack_services::{Address, Service};
//!
//! let mut gcs = Heartbeats::new(HeartbeatConfig::ground_station());
//! let hb = Heartbeat { r#type: MavType::QUADROTOR, autopilot: MavAutopilot::PX4, ..Default::default() };
//! let t0 = Instant::from_secs(10);
//! gcs.handle_message(t0, Address::new(1, 1), &MavMessage::Heartbeat(hb));
//! assert!(matches!(gcs.poll_event(), Some(HeartbeatEvent::New(p)) if p.autopilot == MavAutopilot::PX4));
//! gcs.handle_timeout(t0 + Duration::from_secs(4));
//! assert_eq!(gcs.poll_event(), Some(HeartbeatEvent::Lost(Address::new(1, 1))));
//! ```

use alloc::collections::{BTreeMap, VecDeque};
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    AutopilotVersion, Heartbeat, MavAutopilot, MavMessage, MavModeFlag, MavProtocolCapability,
    MavState, MavType,
};

use crate::{Address, Outgoing, Service, earliest};

/// What we send and how long we wait for others.
#[derive(Clone, Debug, PartialEq)]
pub struct HeartbeatConfig {
    /// Our HEARTBEAT; `None` to only track peers.
    pub own: Option<Heartbeat>,
    /// Time between our heartbeats (default 1 s).
    pub interval: Duration,
    /// A peer is lost after this long without a heartbeat (default 3 s, as MAVSDK).
    pub timeout: Duration,
}

impl Default for HeartbeatConfig {
    fn default() -> Self {
        Self {
            own: None,
            interval: Duration::from_secs(1),
            timeout: Duration::from_secs(3),
        }
    }
}

impl HeartbeatConfig {
    /// A ground station's heartbeat (type GCS, autopilot INVALID, state ACTIVE).
    #[must_use]
    pub fn ground_station() -> Self {
        Self {
            own: Some(Heartbeat {
                r#type: MavType::GCS,
                autopilot: MavAutopilot::INVALID,
                system_status: MavState::ACTIVE,
                mavlink_version: 3,
                ..Heartbeat::default()
            }),
            ..Self::default()
        }
    }
}

/// What we know about one peer component.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Peer {
    /// Its sysid/compid.
    pub address: Address,
    /// Its MAV_TYPE.
    pub mav_type: MavType,
    /// Its MAV_AUTOPILOT (INVALID for anything that is not a flight controller).
    pub autopilot: MavAutopilot,
    /// Its MAV_MODE_FLAG bits.
    pub base_mode: MavModeFlag,
    /// Its autopilot-specific mode.
    pub custom_mode: u32,
    /// Its MAV_STATE.
    pub system_status: MavState,
    /// The `mavlink_version` field of its heartbeat (3 for every current implementation).
    pub mavlink_version: u8,
    /// The MAVLink version (1 or 2) of the frame its last heartbeat came in, when the
    /// caller told us ([`Heartbeats::handle_heartbeat`]).
    pub frame_version: Option<u8>,
    /// Its MAV_PROTOCOL_CAPABILITY bits, once its AUTOPILOT_VERSION arrived
    /// ([`Heartbeats::handle_autopilot_version`]).
    pub capabilities: Option<MavProtocolCapability>,
    /// Its `flight_sw_version` (major<<24 | minor<<16 | patch<<8 | type), from the same
    /// message.
    pub flight_sw_version: Option<u32>,
    /// When its last heartbeat arrived.
    pub last_seen: Instant,
}

impl Peer {
    /// Whether it is a flight controller (`autopilot != INVALID`; never judge by compid).
    #[must_use]
    pub fn is_autopilot(&self) -> bool {
        self.autopilot != MavAutopilot::INVALID
    }

    /// Whether it advertised MAVLink 2 (capability bit MAVLINK2, 8192); `None` until its
    /// AUTOPILOT_VERSION arrived.
    #[must_use]
    pub fn supports_mavlink2(&self) -> Option<bool> {
        self.capabilities
            .map(|c| c.0 & MavProtocolCapability::MAVLINK2.0 != 0)
    }

    /// Whether it reports itself armed.
    #[must_use]
    pub fn is_armed(&self) -> bool {
        self.base_mode.0 & MavModeFlag::SAFETY_ARMED.0 != 0
    }

    fn same_state(&self, other: &Self) -> bool {
        (
            self.mav_type,
            self.autopilot,
            self.base_mode,
            self.custom_mode,
            self.system_status,
            self.frame_version,
        ) == (
            other.mav_type,
            other.autopilot,
            other.base_mode,
            other.custom_mode,
            other.system_status,
            other.frame_version,
        )
    }
}

/// What happened to the peer table.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum HeartbeatEvent {
    /// A component was heard for the first time (or again after being lost).
    New(Peer),
    /// A known component's type, autopilot, mode, status, frame version, capabilities or
    /// firmware version changed.
    Changed(Peer),
    /// No heartbeat from this component for the configured timeout; it left the table.
    Lost(Address),
}

/// The heartbeat emitter and peer table.
#[derive(Debug)]
pub struct Heartbeats {
    config: HeartbeatConfig,
    next_send: Instant,
    peers: BTreeMap<Address, Peer>,
    events: VecDeque<HeartbeatEvent>,
    out: VecDeque<Outgoing>,
}

impl Heartbeats {
    /// A new emitter and empty table; the first own heartbeat goes out at the first
    /// [`Service::handle_timeout`].
    #[must_use]
    pub fn new(config: HeartbeatConfig) -> Self {
        Self {
            config,
            next_send: Instant::ZERO,
            peers: BTreeMap::new(),
            events: VecDeque::new(),
            out: VecDeque::new(),
        }
    }

    /// Replaces our own heartbeat (new mode, status, ...); it goes out at the next tick.
    pub fn set_own(&mut self, own: Option<Heartbeat>) {
        self.config.own = own;
    }

    /// The peers heard and not lost, by address.
    pub fn peers(&self) -> impl Iterator<Item = &Peer> {
        self.peers.values()
    }

    /// One peer, if known.
    #[must_use]
    pub fn peer(&self, address: Address) -> Option<&Peer> {
        self.peers.get(&address)
    }

    /// Feeds one HEARTBEAT from `from`, with the MAVLink version (1 or 2) of the frame it
    /// came in if the caller knows it.
    pub fn handle_heartbeat(
        &mut self,
        now: Instant,
        from: Address,
        heartbeat: &Heartbeat,
        frame_version: Option<u8>,
    ) {
        let known = self.peers.get(&from);
        let peer = Peer {
            capabilities: known.and_then(|p| p.capabilities),
            flight_sw_version: known.and_then(|p| p.flight_sw_version),
            address: from,
            mav_type: heartbeat.r#type,
            autopilot: heartbeat.autopilot,
            base_mode: heartbeat.base_mode,
            custom_mode: heartbeat.custom_mode,
            system_status: heartbeat.system_status,
            mavlink_version: heartbeat.mavlink_version,
            frame_version,
            last_seen: now,
        };
        match self.peers.insert(from, peer) {
            None => self.events.push_back(HeartbeatEvent::New(peer)),
            Some(old) if !old.same_state(&peer) => {
                self.events.push_back(HeartbeatEvent::Changed(peer));
            }
            Some(_) => {}
        }
    }

    /// Feeds one AUTOPILOT_VERSION from `from`: records its capabilities and firmware
    /// version ([`HeartbeatEvent::Changed`] when they change). Returns whether `from` is a
    /// known peer (messages from unknown ones are ignored).
    pub fn handle_autopilot_version(&mut self, from: Address, version: &AutopilotVersion) -> bool {
        let Some(peer) = self.peers.get_mut(&from) else {
            return false;
        };
        let new = (Some(version.capabilities), Some(version.flight_sw_version));
        if (peer.capabilities, peer.flight_sw_version) != new {
            (peer.capabilities, peer.flight_sw_version) = new;
            self.events.push_back(HeartbeatEvent::Changed(*peer));
        }
        true
    }

    /// The next peer-table event, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<HeartbeatEvent> {
        self.events.pop_front()
    }
}

impl Service for Heartbeats {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::Heartbeat(hb) => {
                self.handle_heartbeat(now, from, hb, None);
                true
            }
            MavMessage::AutopilotVersion(v) => self.handle_autopilot_version(from, v),
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        if let Some(own) = self.config.own
            && now >= self.next_send
        {
            self.out.push_back(Outgoing {
                target: Address::BROADCAST,
                message: MavMessage::Heartbeat(own),
            });
            // Keep the cadence; after a long gap, restart it from now.
            let next = self.next_send + self.config.interval;
            self.next_send = if next > now {
                next
            } else {
                now + self.config.interval
            };
        }
        let timeout = self.config.timeout;
        let lost: alloc::vec::Vec<Address> = self
            .peers
            .values()
            .filter(|p| now.saturating_duration_since(p.last_seen) >= timeout)
            .map(|p| p.address)
            .collect();
        for address in lost {
            self.peers.remove(&address);
            self.events.push_back(HeartbeatEvent::Lost(address));
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let send = self.config.own.map(|_| self.next_send);
        let lost = self
            .peers
            .values()
            .map(|p| p.last_seen + self.config.timeout)
            .min();
        earliest(send, lost)
    }
}
