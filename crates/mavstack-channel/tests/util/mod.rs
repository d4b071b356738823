//! A deterministic simulation harness for channel tests, after quinn-proto's `Pair`: a
//! vehicle and a ground-station channel (and optionally a radio between them) over the
//! shared in-memory test network (`mavstack_core::testing::Link`: virtual clock, loss,
//! duplication and latency knobs, a seeded RNG), plus a "drop MAVLink 2" knob (a path that
//! mangles MAVLink 2).
//!
//! ```text
//!   gcs ──► [radio A → B] ──► vehicle        (without a radio: gcs ──► vehicle)
//!   gcs ◄── [radio A ← B] ◄── vehicle
//! ```
#![allow(
    dead_code,
    unreachable_pub,
    reason = "each test binary uses a part of the harness"
)]

use core::time::Duration;

use mavstack_channel::{
    Channel, Config, Event, HandshakeOutcome, Radio, RadioConfig, RadioEvent, ReceivedFrame,
    Rejected, Side,
};
use mavstack_core::message::Message;
pub use mavstack_core::testing::{Knobs, Link};
use mavstack_core::time::Instant;
use mavstack_core::wire::{MAX_FRAME_LEN, STX_V2};

/// 2026-01-01 00:00:00 UTC as a Unix-epoch instant: the virtual clock starts here, so
/// signing timestamps derived from it are realistic.
pub const T0: Instant = Instant::from_secs(1_767_225_600);

/// Where bytes go.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Node {
    Gcs,
    Vehicle,
    /// The radio, bytes arriving on side A (the ground side).
    RadioA,
    /// The radio, bytes arriving on side B (the air side).
    RadioB,
}

/// Who wrote a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Origin {
    Gcs,
    Vehicle,
    Radio,
}

/// A frame some node wrote.
#[derive(Clone, Debug)]
pub struct Sent {
    pub from: Origin,
    pub at: Instant,
    pub bytes: Vec<u8>,
}

impl Sent {
    pub fn is_v2(&self) -> bool {
        self.bytes[0] == STX_V2
    }

    pub fn is_signed(&self) -> bool {
        self.is_v2() && self.bytes[2] & 1 != 0
    }

    pub fn msg_id(&self) -> u32 {
        if self.is_v2() {
            u32::from_le_bytes([self.bytes[7], self.bytes[8], self.bytes[9], 0])
        } else {
            u32::from(self.bytes[5])
        }
    }

    pub fn payload(&self) -> &[u8] {
        let start = if self.is_v2() { 10 } else { 6 };
        &self.bytes[start..start + usize::from(self.bytes[1])]
    }
}

pub struct Pair {
    pub now: Instant,
    pub vehicle: Channel,
    pub gcs: Channel,
    pub radio: Option<Radio>,
    /// Everything on the way, to whom (knobs, faults and seed are the link's).
    pub link: Link<(Node, Vec<u8>)>,
    /// Drop every MAVLink 2 frame (a path that mangles MAVLink 2).
    pub drop_v2: bool,
    /// MAVLink 2 frames dropped by [`Pair::drop_v2`].
    pub dropped_v2: u64,
    pub vehicle_events: Vec<Event>,
    pub gcs_events: Vec<Event>,
    pub radio_events: Vec<RadioEvent>,
    pub sent: Vec<Sent>,
    /// Both applications send a HEARTBEAT at this interval (None: they stay quiet).
    pub heartbeats: Option<Duration>,
    next_heartbeat: Instant,
    /// Stored PersistTimestamp values, per side.
    pub vehicle_persisted: Vec<u64>,
    pub gcs_persisted: Vec<u64>,
}

impl Pair {
    /// A vehicle and a ground station, directly connected, with default knobs and seed 1.
    pub fn new(vehicle: Config, gcs: Config) -> Self {
        Self {
            now: T0,
            vehicle: Channel::new(vehicle).unwrap(),
            gcs: Channel::new(gcs).unwrap(),
            radio: None,
            link: Link::new(Knobs::default(), 1),
            drop_v2: false,
            dropped_v2: 0,
            vehicle_events: Vec::new(),
            gcs_events: Vec::new(),
            radio_events: Vec::new(),
            sent: Vec::new(),
            heartbeats: None,
            next_heartbeat: T0,
            vehicle_persisted: Vec::new(),
            gcs_persisted: Vec::new(),
        }
    }

    /// The default vehicle (1/1) and ground station (255/190).
    pub fn default_pair() -> Self {
        Self::new(Config::vehicle(1, 1), Config::ground_station(255, 190))
    }

    /// Puts a radio between the two (side A towards the ground station).
    pub fn with_radio(mut self, config: RadioConfig) -> Self {
        self.radio = Some(Radio::new(config));
        self
    }

    pub fn seed(mut self, seed: u64) -> Self {
        self.link.rng = mavstack_core::testing::Rng::new(seed);
        self
    }

    // ----- sending from the applications ---------------------------------------------

    /// The vehicle application sends `message` on its link.
    pub fn vehicle_send<M: Message>(&mut self, message: &M) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let t = self.vehicle.send(self.now, message, &mut buf).unwrap();
        self.transmit(Origin::Vehicle, &buf[..t.len]);
    }

    /// The ground-station application sends `message` on its link.
    pub fn gcs_send<M: Message>(&mut self, message: &M) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let t = self.gcs.send(self.now, message, &mut buf).unwrap();
        self.transmit(Origin::Gcs, &buf[..t.len]);
    }

    /// Raw bytes onto the wire as if `from` had sent them (an attacker, a foreign peer).
    pub fn inject(&mut self, from: Origin, bytes: &[u8]) {
        self.transmit(from, bytes);
    }

    /// Raw bytes straight into a node, bypassing the knobs.
    pub fn deliver_now(&mut self, to: Node, bytes: &[u8]) {
        self.deliver(to, bytes);
        self.flush();
    }

    // ----- the simulation ------------------------------------------------------------

    fn route(&self, from: Origin, side: Option<Side>) -> Node {
        match (from, self.radio.is_some(), side) {
            (Origin::Gcs, true, _) => Node::RadioA,
            (Origin::Gcs, false, _) => Node::Vehicle,
            (Origin::Vehicle, true, _) => Node::RadioB,
            (Origin::Vehicle, false, _) => Node::Gcs,
            (Origin::Radio, _, Some(Side::B)) => Node::Vehicle,
            (Origin::Radio, _, _) => Node::Gcs,
        }
    }

    fn transmit(&mut self, from: Origin, bytes: &[u8]) {
        self.transmit_side(from, None, bytes);
    }

    fn transmit_side(&mut self, from: Origin, side: Option<Side>, bytes: &[u8]) {
        self.sent.push(Sent {
            from,
            at: self.now,
            bytes: bytes.to_vec(),
        });
        let to = self.route(from, side);
        if self.drop_v2 && bytes.first() == Some(&STX_V2) {
            self.dropped_v2 += 1;
            return;
        }
        self.link.send(self.now, (to, bytes.to_vec()));
    }

    fn deliver(&mut self, to: Node, bytes: &[u8]) {
        let now = self.now;
        let mut rest = bytes;
        let mut stalls = 0;
        while !rest.is_empty() {
            let n = match to {
                Node::Gcs => self.gcs.handle_input(now, rest),
                Node::Vehicle => self.vehicle.handle_input(now, rest),
                Node::RadioA | Node::RadioB => {
                    let side = if to == Node::RadioA { Side::A } else { Side::B };
                    self.radio.as_mut().unwrap().handle_input(now, side, rest)
                }
            };
            rest = &rest[n..];
            stalls = if n == 0 { stalls + 1 } else { 0 };
            assert!(
                stalls < 3,
                "{to:?} takes no input even with its queues drained"
            );
            self.flush();
        }
    }

    /// Drains every node's events and transmits; returns whether anything was sent.
    pub fn flush(&mut self) -> bool {
        let mut sent = false;
        let mut buf = [0u8; MAX_FRAME_LEN];
        loop {
            let mut progressed = false;
            while let Some(e) = self.vehicle.poll_event() {
                if let Event::PersistTimestamp { timestamp } = e {
                    self.vehicle_persisted.push(timestamp);
                }
                self.vehicle_events.push(e);
                progressed = true;
            }
            while let Some(e) = self.gcs.poll_event() {
                if let Event::PersistTimestamp { timestamp } = e {
                    self.gcs_persisted.push(timestamp);
                }
                self.gcs_events.push(e);
                progressed = true;
            }
            while let Some(t) = self.vehicle.poll_transmit(self.now, &mut buf) {
                self.transmit(Origin::Vehicle, &buf[..t.len]);
                progressed = true;
            }
            while let Some(t) = self.gcs.poll_transmit(self.now, &mut buf) {
                self.transmit(Origin::Gcs, &buf[..t.len]);
                progressed = true;
            }
            if let Some(radio) = self.radio.as_mut() {
                let mut out = Vec::new();
                while let Some(t) = radio.poll_transmit(self.now, &mut buf) {
                    out.push((t.to, buf[..t.len].to_vec()));
                }
                while let Some(e) = radio.poll_event() {
                    self.radio_events.push(e);
                }
                for (side, bytes) in out {
                    self.transmit_side(Origin::Radio, Some(side), &bytes);
                    progressed = true;
                }
            }
            if !progressed {
                return sent;
            }
            sent = true;
        }
    }

    /// One round at the current time: deliver what is due, fire due timers, drain
    /// everything. Returns whether anything happened.
    pub fn step(&mut self) -> bool {
        let mut progressed = false;
        while let Some((to, bytes)) = self.link.pop_due(self.now) {
            self.deliver(to, &bytes);
            progressed = true;
        }
        if self.vehicle.poll_timeout().is_some_and(|t| t <= self.now) {
            self.vehicle.handle_timeout(self.now);
        }
        if self.gcs.poll_timeout().is_some_and(|t| t <= self.now) {
            self.gcs.handle_timeout(self.now);
        }
        if let Some(radio) = self.radio.as_mut()
            && radio.poll_timeout().is_some_and(|t| t <= self.now)
        {
            radio.handle_timeout(self.now);
        }
        if let Some(interval) = self.heartbeats
            && self.next_heartbeat <= self.now
        {
            self.next_heartbeat = self.now + interval;
            let hb = mavstack_dialects::common::Heartbeat::default();
            self.vehicle_send(&hb);
            self.gcs_send(&hb);
        }
        progressed |= self.flush();
        progressed
    }

    /// The next instant something is scheduled, if any.
    pub fn next_wakeup(&self) -> Option<Instant> {
        let mut next = self.link.next_delivery();
        let mut consider = |t: Option<Instant>| {
            if let Some(t) = t {
                next = Some(next.map_or(t, |n| n.min(t)));
            }
        };
        consider(self.vehicle.poll_timeout());
        consider(self.gcs.poll_timeout());
        consider(self.radio.as_ref().and_then(Radio::poll_timeout));
        if self.heartbeats.is_some() {
            consider(Some(self.next_heartbeat));
        }
        next
    }

    /// Runs until nothing is scheduled; panics after `max_steps` rounds.
    pub fn drive_bounded(&mut self, max_steps: usize) {
        for _ in 0..max_steps {
            while self.step() {}
            match self.next_wakeup() {
                Some(t) => self.now = self.now.max(t),
                None => return,
            }
        }
        panic!("simulation still busy after {max_steps} steps");
    }

    /// Runs until nothing is scheduled (at most 10 000 rounds).
    pub fn drive(&mut self) {
        self.drive_bounded(10_000);
    }

    /// Runs for `duration` of virtual time (periodic traffic never goes idle).
    pub fn drive_for(&mut self, duration: Duration) {
        let end = self.now + duration;
        loop {
            while self.step() {}
            match self.next_wakeup() {
                Some(t) if t <= end => self.now = self.now.max(t),
                _ => {
                    self.now = end;
                    while self.step() {}
                    return;
                }
            }
        }
    }

    /// Runs until `done` holds or `limit` of virtual time has passed; returns whether it
    /// holds.
    pub fn drive_until(&mut self, limit: Duration, done: impl Fn(&Self) -> bool) -> bool {
        let end = self.now + limit;
        loop {
            while self.step() {}
            if done(self) {
                return true;
            }
            match self.next_wakeup() {
                Some(t) if t <= end => self.now = self.now.max(t),
                _ => return done(self),
            }
        }
    }

    // ----- reading the logs ----------------------------------------------------------

    pub fn handshake_outcomes(&self) -> Vec<HandshakeOutcome> {
        self.gcs_events
            .iter()
            .filter_map(|e| match e {
                Event::Handshake(o) => Some(*o),
                _ => None,
            })
            .collect()
    }

    pub fn frames(events: &[Event]) -> Vec<&ReceivedFrame> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Frame(f) => Some(f),
                _ => None,
            })
            .collect()
    }

    pub fn rejections(events: &[Event]) -> Vec<Rejected> {
        events
            .iter()
            .filter_map(|e| match e {
                Event::Rejected(r) => Some(*r),
                _ => None,
            })
            .collect()
    }

    pub fn sent_by(&self, from: Origin) -> Vec<&Sent> {
        self.sent.iter().filter(|s| s.from == from).collect()
    }
}

// ----- crafting frames by hand ---------------------------------------------------------

use mavstack_core::signing::{SecretKey, append_signature};
use mavstack_core::wire::{FrameHeader, Version, emit_message};

/// An unsigned frame of `message`.
pub fn frame<M: Message>(version: Version, seq: u8, sysid: u8, compid: u8, message: &M) -> Vec<u8> {
    let header = FrameHeader {
        version,
        seq,
        sysid,
        compid,
        signed: false,
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = emit_message(&header, message, &mut buf).unwrap();
    buf[..len].to_vec()
}

/// A signed MAVLink 2 frame of `message`.
pub fn signed_frame<M: Message>(
    seq: u8,
    sysid: u8,
    compid: u8,
    message: &M,
    key: &SecretKey,
    link_id: u8,
    timestamp: u64,
) -> Vec<u8> {
    let header = FrameHeader {
        version: Version::V2,
        seq,
        sysid,
        compid,
        signed: true,
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = emit_message(&header, message, &mut buf).unwrap();
    let len = append_signature(&mut buf, len, link_id, timestamp, key).unwrap();
    buf[..len].to_vec()
}

/// The signing timestamp of the virtual clock's `now`.
pub fn timestamp_at(now: Instant) -> u64 {
    mavstack_core::signing::timestamp_from_unix_micros(now.as_micros())
}

/// The test key.
pub fn key() -> SecretKey {
    SecretKey::new(core::array::from_fn(|i| u8::try_from(i).unwrap()))
}

/// Feeds `bytes` to `channel` at `now` and returns every event.
pub fn feed(channel: &mut Channel, now: Instant, bytes: &[u8]) -> Vec<Event> {
    let mut events = Vec::new();
    let mut rest = bytes;
    loop {
        let n = channel.handle_input(now, rest);
        rest = &rest[n..];
        while let Some(e) = channel.poll_event() {
            events.push(e);
        }
        if rest.is_empty() {
            return events;
        }
        assert!(n > 0 || !events.is_empty(), "channel stalled");
    }
}

/// Every frame `channel` wants to send now.
pub fn transmits(channel: &mut Channel, now: Instant) -> Vec<Vec<u8>> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut out = Vec::new();
    while let Some(t) = channel.poll_transmit(now, &mut buf) {
        out.push(buf[..t.len].to_vec());
    }
    out
}
