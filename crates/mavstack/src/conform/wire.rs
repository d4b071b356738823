//! What came off the wire, frame by frame, for grading: framing, sequence, truncation,
//! checksum, signature. Fed the node's tapped input, so nothing the link layer would drop
//! or repair is hidden.

use std::collections::HashMap;

use mavstack_core::parse::{Deframer, Item};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::time::Instant;
use mavstack_core::wire::{Frame, Version};
use mavstack_core::{Message as _, MessageTable};
use mavstack_dialects::common::{MissionCount, ProtocolVersion};

use crate::router::LinkId;

/// The message id the C library writes for PROTOCOL_VERSION in a MAVLink 1 frame: its id
/// (300) cut to MAVLink 1's 8 bits, which is MISSION_COUNT's id (44). The checksum of that
/// bogus frame is seeded with PROTOCOL_VERSION's CRC_EXTRA.
const V1_PROTOCOL_VERSION_ID: u32 = ProtocolVersion::ID % 256;

/// One frame received.
#[derive(Clone, Debug)]
pub(crate) struct Seen {
    /// Seconds since conform started.
    pub t: f64,
    pub version: Version,
    pub signed: bool,
    /// With a key: whether the signature verified (`None` without a key or unsigned).
    pub verified: Option<bool>,
    pub sysid: u8,
    pub compid: u8,
    pub msg_id: u32,
    pub seq: u8,
    pub payload: Vec<u8>,
    /// A MAVLink 1 frame of id 44 whose checksum verifies with PROTOCOL_VERSION's seed: the C
    /// library's PROTOCOL_VERSION forced into MAVLink 1.
    pub v1_protocol_version: bool,
    /// The checksum could not be checked (an id the dialect does not define).
    pub unchecked: bool,
}

impl Seen {
    pub(crate) fn from(&self, who: (u8, u8)) -> bool {
        (self.sysid, self.compid) == who
    }

    pub(crate) fn is<M: mavstack_core::Message>(&self) -> bool {
        self.msg_id == M::ID && !self.v1_protocol_version
    }

    /// The message, decoded (a short MAVLink 2 payload is zero-extended).
    pub(crate) fn decode<M: mavstack_core::Message>(&self) -> M {
        M::decode(&self.payload)
    }
}

/// Every frame received on the graded links, and what could not be a frame.
pub(crate) struct Wire {
    started: Instant,
    table: MessageTable,
    key: Option<SecretKey>,
    deframers: HashMap<LinkId, Box<Deframer>>,
    pub frames: Vec<Seen>,
    /// Frames whose checksum failed, with when the first one came.
    pub bad_crc: u64,
    pub first_bad_crc: Option<f64>,
}

impl Wire {
    pub(crate) fn new(started: Instant, table: MessageTable, key: Option<SecretKey>) -> Self {
        Self {
            started,
            table,
            key,
            deframers: HashMap::new(),
            frames: Vec::new(),
            bad_crc: 0,
            first_bad_crc: None,
        }
    }

    /// Seconds since the start at `now`.
    pub(crate) fn secs(&self, now: Instant) -> f64 {
        now.saturating_duration_since(self.started).as_secs_f64()
    }

    /// Ends every link's input at `at`: a frame held back (the parser waits to see whether
    /// a checked frame starts inside one it cannot check) is taken now.
    pub(crate) fn finish(&mut self, at: Instant) {
        let links: Vec<LinkId> = self.deframers.keys().copied().collect();
        for link in links {
            self.feed(link, at, &[], true);
        }
    }

    /// Takes one input of `link` and every frame found in it: a whole datagram (`end`:
    /// nothing of it waits for the next one, so what the parser holds back is taken too) or a
    /// stream read.
    pub(crate) fn feed(&mut self, link: LinkId, at: Instant, mut data: &[u8], end: bool) {
        let t = self.secs(at);
        let table = self.table;
        // Id 44 is looked at in `take`: it is both MISSION_COUNT and the bogus MAVLink 1
        // PROTOCOL_VERSION.
        let parser_lookup = move |id: u32| {
            if id == V1_PROTOCOL_VERSION_ID {
                None
            } else {
                table.crc_extra(id)
            }
        };
        let owned = |item: Item<'_>| match item {
            Item::Frame(f) => (f.as_bytes().to_vec(), false),
            Item::Unknown(f) => (f.as_bytes().to_vec(), true),
        };
        let deframer = self.deframers.entry(link).or_default();
        let bad_before = deframer.stats().bad_crc;
        let mut found = Vec::new();
        loop {
            let n = deframer.push(data);
            data = &data[n..];
            while let Some(item) = deframer.next_item(&parser_lookup) {
                found.push(owned(item));
            }
            if n == 0 || data.is_empty() {
                break;
            }
        }
        if end {
            while let Some(item) = deframer.finish(&parser_lookup) {
                found.push(owned(item));
            }
        }
        let bad = deframer.stats().bad_crc - bad_before;
        self.count_bad(bad, t);
        for (bytes, unknown) in found {
            self.take(t, &bytes, unknown);
        }
    }

    fn count_bad(&mut self, n: u64, t: f64) {
        if n > 0 {
            self.bad_crc += n;
            self.first_bad_crc.get_or_insert(t);
        }
    }

    fn take(&mut self, t: f64, bytes: &[u8], unknown: bool) {
        // The deframer hands over whole frames only: this check never fails.
        let Ok(frame) = Frame::new_checked(bytes) else {
            return;
        };
        let mut v1_protocol_version = false;
        let mut unchecked = unknown;
        if unknown && frame.msg_id() == V1_PROTOCOL_VERSION_ID {
            unchecked = false;
            if frame.check_crc(MissionCount::CRC_EXTRA) {
                // A genuine MISSION_COUNT.
            } else if frame.version() == Version::V1 && frame.check_crc(ProtocolVersion::CRC_EXTRA)
            {
                v1_protocol_version = true;
            } else {
                self.count_bad(1, t);
                return;
            }
        }
        let verified = match (&self.key, frame.is_signed()) {
            (Some(key), true) => Some(signing::verify(&frame, key).is_ok()),
            _ => None,
        };
        self.frames.push(Seen {
            t,
            version: frame.version(),
            signed: frame.is_signed(),
            verified,
            sysid: frame.sysid(),
            compid: frame.compid(),
            msg_id: frame.msg_id(),
            seq: frame.seq(),
            payload: frame.payload().to_vec(),
            v1_protocol_version,
            unchecked,
        });
    }
}

/// PROTOCOL_VERSION's values from a frame (a genuine one, or the bogus MAVLink 1 one, whose
/// payload has the same layout).
pub(crate) fn protocol_version(seen: &Seen) -> ProtocolVersion {
    ProtocolVersion::decode(&seen.payload)
}

#[cfg(test)]
mod tests {
    use mavstack_dialects::common::MavMessage;

    use super::*;

    /// MISSION_COUNT (count 5, to 255/190) as pymavlink 2.4.50 packs it, from 1/1, seq 0:
    /// MAVLink 1, and MAVLink 2 (mission_type 0 truncated).
    const MISSION_COUNT_V1: [u8; 12] = [
        0xfe, 0x04, 0x00, 0x01, 0x01, 0x2c, 0x05, 0x00, 0xff, 0xbe, 0x54, 0xcb,
    ];
    const MISSION_COUNT_V2: [u8; 16] = [
        0xfd, 0x04, 0x00, 0x00, 0x00, 0x01, 0x01, 0x2c, 0x00, 0x00, 0x05, 0x00, 0xff, 0xbe, 0xd5,
        0x04,
    ];

    /// The C library's PROTOCOL_VERSION forced into MAVLink 1 (id 44, checksum seeded with
    /// PROTOCOL_VERSION's CRC_EXTRA), after a HEARTBEAT: the `fake_protocol_version` seed of
    /// the `conform_wire` fuzz target, written with pymavlink's x25crc, without the target's
    /// first byte (how it cuts the input).
    fn fake_protocol_version() -> Vec<u8> {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../fuzz/corpus/conform_wire/fake_protocol_version"
        );
        let seed = std::fs::read(path).expect("the seed is checked in");
        seed[1..].to_vec()
    }

    fn read(bytes: &[u8]) -> Wire {
        let mut wire = Wire::new(Instant::ZERO, MessageTable::of::<MavMessage>(), None);
        wire.feed(LinkId::new(0), Instant::ZERO, bytes, true);
        wire
    }

    /// Id 44 is MISSION_COUNT, or in MAVLink 1 the bogus PROTOCOL_VERSION: each frame's
    /// checksum says which, and one that fits neither is counted as bad.
    #[test]
    fn id_44_is_told_apart_by_its_checksum() {
        let wire = read(&fake_protocol_version());
        assert_eq!(wire.bad_crc, 0);
        let ids: Vec<(u32, bool, bool)> = wire
            .frames
            .iter()
            .map(|f| (f.msg_id, f.v1_protocol_version, f.unchecked))
            .collect();
        assert_eq!(ids, [(0, false, false), (44, true, false)]);
        assert_eq!(protocol_version(&wire.frames[1]).version, 200);

        for genuine in [&MISSION_COUNT_V1[..], &MISSION_COUNT_V2[..]] {
            let wire = read(genuine);
            assert_eq!(wire.bad_crc, 0);
            assert_eq!(wire.frames.len(), 1);
            let seen = &wire.frames[0];
            assert!(seen.is::<MissionCount>() && !seen.unchecked, "{seen:?}");
            assert_eq!(seen.decode::<MissionCount>().count, 5);
        }

        // A payload byte changed: neither checksum holds.
        let mut damaged = fake_protocol_version();
        let last = damaged.len() - 3;
        damaged[last] ^= 1;
        let wire = read(&damaged);
        assert_eq!((wire.frames.len(), wire.bad_crc), (1, 1));
    }
}
