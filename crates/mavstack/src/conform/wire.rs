//! What came off the wire, frame by frame, for grading: framing, sequence, truncation,
//! checksum, signature. Fed the node's tapped input, so nothing the link layer would drop
//! or repair is hidden.

use std::collections::HashMap;

use mavstack_core::parse::{Deframer, Item};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::time::Instant;
use mavstack_core::wire::{Frame, STX_V1, Version};
use mavstack_core::{Crc16, Message as _, MessageTable};
use mavstack_dialects::common::{MissionCount, ProtocolVersion};

use crate::router::LinkId;

/// The message id the C library writes for PROTOCOL_VERSION in a MAVLink 1 frame (300 mod
/// 256, which is MISSION_COUNT's id).
pub(crate) const V1_PROTOCOL_VERSION_ID: u32 = 300 % 256;

/// PROTOCOL_VERSION's CRC_EXTRA (the checksum seed of that bogus MAVLink 1 frame).
const PROTOCOL_VERSION_CRC_EXTRA: u8 = 217;

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
        let frame = Frame::new_unchecked(bytes);
        let mut v1_protocol_version = false;
        let mut unchecked = unknown;
        if unknown && frame.msg_id() == V1_PROTOCOL_VERSION_ID {
            unchecked = false;
            if crc_with(&frame, MissionCount::CRC_EXTRA) {
                // A genuine MISSION_COUNT.
            } else if frame.version() == Version::V1 && crc_with(&frame, PROTOCOL_VERSION_CRC_EXTRA)
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

/// Whether `frame`'s checksum is right for `crc_extra`.
fn crc_with(frame: &Frame<&[u8]>, crc_extra: u8) -> bool {
    let bytes = frame.as_bytes();
    let header = if bytes[0] == STX_V1 { 6 } else { 10 };
    let end = header + frame.payload_len();
    if bytes.len() < end + 2 {
        return false;
    }
    let mut crc = Crc16::of_prefix(&bytes[1..], end - 1);
    crc.update_byte(crc_extra);
    crc.value().to_le_bytes() == [bytes[end], bytes[end + 1]]
}

/// PROTOCOL_VERSION's values from a frame (a genuine one, or the bogus MAVLink 1 one, whose
/// payload has the same layout).
pub(crate) fn protocol_version(seen: &Seen) -> ProtocolVersion {
    ProtocolVersion::decode(&seen.payload)
}
