//! GPS_RTCM_DATA: one correction message in up to four fragments, and put back together.

use alloc::vec::Vec;

use mavstack_dialects::common::GpsRtcmData;

/// The bytes one GPS_RTCM_DATA carries.
pub const FRAGMENT_LEN: usize = 180;

/// Fragments one message may have: the fragment id has two bits.
pub const MAX_FRAGMENTS: usize = 4;

/// The longest message GPS_RTCM_DATA can carry: four full fragments.
pub const MAX_MESSAGE_LEN: usize = FRAGMENT_LEN * MAX_FRAGMENTS;

/// The flag bit that says a message is in fragments.
const FRAGMENTED: u8 = 0x01;

/// Sequence ids have five bits.
const SEQUENCE_IDS: u8 = 32;

/// Why a message cannot be sent in GPS_RTCM_DATA; nothing was sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RtcmError {
    /// An empty message.
    #[error("an RTCM message cannot be empty")]
    Empty,
    /// A message longer than four fragments.
    #[error(
        "an RTCM message of {len} bytes is longer than GPS_RTCM_DATA can carry \
         ({MAX_MESSAGE_LEN} bytes: {MAX_FRAGMENTS} fragments of {FRAGMENT_LEN})"
    )]
    TooLong {
        /// Its length.
        len: usize,
    },
}

/// The sending side: each message gets the next 5-bit sequence id, so that a receiver never
/// mixes the fragments of two messages.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RtcmSender {
    sequence: u8,
}

impl RtcmSender {
    /// A sender whose first message has sequence id `sequence` (modulo 32).
    #[must_use]
    pub const fn starting_at(sequence: u8) -> Self {
        Self {
            sequence: sequence % SEQUENCE_IDS,
        }
    }

    /// The sequence id the next message gets.
    #[must_use]
    pub const fn next_sequence(&self) -> u8 {
        self.sequence
    }

    /// `message` as the GPS_RTCM_DATA messages to send, in order (see [`fragments`]); the
    /// sequence id moves on only when it can be sent.
    ///
    /// # Errors
    /// [`RtcmError::Empty`], [`RtcmError::TooLong`] (over [`MAX_MESSAGE_LEN`] bytes).
    pub fn fragments(&mut self, message: &[u8]) -> Result<Vec<GpsRtcmData>, RtcmError> {
        let parts = fragments(message, self.sequence)?;
        self.sequence = (self.sequence + 1) % SEQUENCE_IDS;
        Ok(parts)
    }
}

/// `message` as GPS_RTCM_DATA messages with sequence id `sequence` (its low five bits):
///
/// - up to [`FRAGMENT_LEN`] bytes: one message, not fragmented (`flags` bit 0 clear, the
///   sequence id in bits 3-7 all the same);
/// - longer: fragments of 180 bytes with ids 0, 1, ... (`flags` = 1 | id << 1 | sequence <<
///   3), the last one shorter; when the length is a multiple of 180 under 720, an empty
///   fragment ends it, since a receiver knows the message is whole only from a fragment
///   shorter than 180 (or from four full ones).
///
/// # Errors
/// [`RtcmError::Empty`], [`RtcmError::TooLong`] (over [`MAX_MESSAGE_LEN`] bytes).
pub fn fragments(message: &[u8], sequence: u8) -> Result<Vec<GpsRtcmData>, RtcmError> {
    let len = message.len();
    if len == 0 {
        return Err(RtcmError::Empty);
    }
    if len > MAX_MESSAGE_LEN {
        return Err(RtcmError::TooLong { len });
    }
    let seq_bits = (sequence % SEQUENCE_IDS) << 3;
    let one = |flags: u8, bytes: &[u8]| {
        let mut m = GpsRtcmData {
            flags,
            len: bytes.len() as u8,
            data: [0; FRAGMENT_LEN],
        };
        m.data[..bytes.len()].copy_from_slice(bytes);
        m
    };
    if len <= FRAGMENT_LEN {
        return Ok(alloc::vec![one(seq_bits, message)]);
    }
    let mut out: Vec<GpsRtcmData> = message
        .chunks(FRAGMENT_LEN)
        .enumerate()
        .map(|(id, bytes)| one(FRAGMENTED | ((id as u8) << 1) | seq_bits, bytes))
        .collect();
    if len.is_multiple_of(FRAGMENT_LEN) && out.len() < MAX_FRAGMENTS {
        out.push(one(FRAGMENTED | ((out.len() as u8) << 1) | seq_bits, &[]));
    }
    Ok(out)
}

/// What a [`Reassembler`] has seen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReassemblyStats {
    /// Whole messages given out.
    pub messages: u64,
    /// Their bytes.
    pub bytes: u64,
    /// Fragments that went into them.
    pub fragments_used: u64,
    /// Fragments thrown away: a message left incomplete when another sequence id began, or
    /// a fragment id seen twice with other bytes.
    pub fragments_discarded: u64,
    /// Fragments seen again with the same bytes, ignored.
    pub duplicates: u64,
    /// Messages whose `len` is over 180, ignored.
    pub invalid: u64,
}

/// The receiving side of GPS_RTCM_DATA, as common.xml describes it: fragments of one
/// sequence id collected in any order, the message whole when every fragment before the
/// first short one is there (or four full ones); a fragment of another sequence id, or one
/// already held with other bytes, starts over.
#[derive(Clone, Debug)]
pub struct Reassembler {
    buf: [u8; MAX_MESSAGE_LEN],
    /// Fragment ids held (bit n = fragment n).
    held: u8,
    sequence: u8,
    /// How many fragments the message has, once known.
    count: Option<u8>,
    /// Its length, once known.
    total: usize,
    stats: ReassemblyStats,
}

impl Default for Reassembler {
    fn default() -> Self {
        Self {
            buf: [0; MAX_MESSAGE_LEN],
            held: 0,
            sequence: 0,
            count: None,
            total: 0,
            stats: ReassemblyStats::default(),
        }
    }
}

impl Reassembler {
    /// What it has counted.
    #[must_use]
    pub const fn stats(&self) -> ReassemblyStats {
        self.stats
    }

    /// Takes one GPS_RTCM_DATA; a whole message when this completes one.
    pub fn handle(&mut self, m: &GpsRtcmData) -> Option<Vec<u8>> {
        let len = usize::from(m.len);
        if len > FRAGMENT_LEN {
            self.stats.invalid += 1;
            return None;
        }
        let bytes = &m.data[..len];
        if m.flags & FRAGMENTED == 0 {
            return Some(self.give(bytes.to_vec(), 1));
        }
        let id = usize::from((m.flags >> 1) & 0x03);
        let sequence = m.flags >> 3;
        let bit = 1u8 << id;
        let at = id * FRAGMENT_LEN;
        if self.held != 0 {
            let same_message = sequence == self.sequence;
            if same_message && self.held & bit != 0 {
                if self.buf[at..at + len] == *bytes && self.fragment_len(id) == Some(len) {
                    self.stats.duplicates += 1;
                    return None;
                }
                self.discard();
            } else if !same_message {
                self.discard();
            }
        }
        self.sequence = sequence;
        self.held |= bit;
        self.buf[at..at + len].copy_from_slice(bytes);
        if len < FRAGMENT_LEN {
            self.count = Some(id as u8 + 1);
            self.total = at + len;
        } else if self.held == 0x0F && self.count.is_none() {
            self.count = Some(MAX_FRAGMENTS as u8);
            self.total = MAX_MESSAGE_LEN;
        }
        let count = self.count?;
        if u32::from(self.held) != (1u32 << count) - 1 {
            return None;
        }
        let message = self.buf[..self.total].to_vec();
        self.held = 0;
        self.count = None;
        Some(self.give(message, u64::from(count)))
    }

    /// The length fragment `id` was held with, as far as it is known (full before the
    /// short one, the short one's own).
    fn fragment_len(&self, id: usize) -> Option<usize> {
        match self.count {
            Some(count) if id + 1 == usize::from(count) => Some(self.total - id * FRAGMENT_LEN),
            _ => Some(FRAGMENT_LEN),
        }
    }

    fn discard(&mut self) {
        self.stats.fragments_discarded += u64::from(self.held.count_ones());
        self.held = 0;
        self.count = None;
    }

    fn give(&mut self, message: Vec<u8>, fragments: u64) -> Vec<u8> {
        self.stats.messages += 1;
        self.stats.bytes += message.len() as u64;
        self.stats.fragments_used += fragments;
        message
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::string::ToString as _;

    fn message(len: usize) -> Vec<u8> {
        (0..len).map(|i| (i * 7 + 1) as u8).collect()
    }

    #[test]
    fn lengths_fragments_and_the_empty_last_one() {
        let cases: [(usize, &[u8]); 9] = [
            (1, &[1]),
            (179, &[179]),
            (180, &[180]),
            (181, &[180, 1]),
            (359, &[180, 179]),
            (360, &[180, 180, 0]),
            (540, &[180, 180, 180, 0]),
            (541, &[180, 180, 180, 1]),
            (720, &[180, 180, 180, 180]),
        ];
        for (len, want) in cases {
            let parts = fragments(&message(len), 5).unwrap();
            let lens: Vec<u8> = parts.iter().map(|p| p.len).collect();
            assert_eq!(lens, want, "{len} bytes");
            for (id, p) in parts.iter().enumerate() {
                let want_flags = if len <= FRAGMENT_LEN {
                    5 << 3
                } else {
                    1 | (id as u8) << 1 | 5 << 3
                };
                assert_eq!(p.flags, want_flags, "{len} bytes, fragment {id}");
            }
            let joined: Vec<u8> = parts
                .iter()
                .flat_map(|p| p.data[..usize::from(p.len)].to_vec())
                .collect();
            assert_eq!(joined, message(len));
        }
        assert_eq!(fragments(&[], 0), Err(RtcmError::Empty));
        let err = fragments(&message(721), 0).unwrap_err();
        assert_eq!(err, RtcmError::TooLong { len: 721 });
        assert_eq!(
            err.to_string(),
            "an RTCM message of 721 bytes is longer than GPS_RTCM_DATA can carry (720 bytes: \
             4 fragments of 180)"
        );
    }

    #[test]
    fn sequence_ids_advance_and_wrap() {
        let mut s = RtcmSender::starting_at(30);
        let seq = |s: &mut RtcmSender| s.fragments(&message(200)).unwrap()[0].flags >> 3;
        assert_eq!(seq(&mut s), 30);
        assert_eq!(seq(&mut s), 31);
        assert_eq!(seq(&mut s), 0);
        assert!(s.fragments(&message(900)).is_err());
        assert_eq!(s.next_sequence(), 1);
    }

    #[test]
    fn reassembled_in_any_order_and_without_the_empty_fragment_never() {
        let mut r = Reassembler::default();
        let mut parts = fragments(&message(500), 3).unwrap();
        parts.reverse();
        let got: Vec<_> = parts.iter().filter_map(|p| r.handle(p)).collect();
        assert_eq!(got, [message(500)]);
        // 360 bytes without their empty last fragment (MAVSDK 4.1's sender): never whole,
        // and thrown away when the next message begins.
        let parts = fragments(&message(360), 4).unwrap();
        assert!(parts[..2].iter().all(|p| r.handle(p).is_none()));
        let next = fragments(&message(10), 5).unwrap();
        assert_eq!(r.handle(&next[0]), Some(message(10)));
        let parts = fragments(&message(400), 6).unwrap();
        assert_eq!(r.handle(&parts[0]), None);
        assert_eq!(r.handle(&parts[0]), None); // a duplicate
        assert_eq!(r.handle(&parts[1]), None);
        assert_eq!(r.handle(&parts[2]), Some(message(400)));
        let s = r.stats();
        assert_eq!(s.messages, 3);
        assert_eq!(s.fragments_used, 3 + 1 + 3);
        // The 360-byte message's two fragments were held until sequence 6 began.
        assert_eq!(s.fragments_discarded, 2);
        assert_eq!(s.duplicates, 1);
        let parts = fragments(&message(360), 7).unwrap();
        assert_eq!(r.handle(&parts[0]), None);
        let other = fragments(&message(300), 8).unwrap();
        assert_eq!(r.handle(&other[0]), None);
        assert_eq!(r.stats().fragments_discarded, 3);
    }

    #[test]
    fn four_full_fragments_need_no_end() {
        let mut r = Reassembler::default();
        let parts = fragments(&message(720), 9).unwrap();
        let got: Vec<_> = parts.iter().filter_map(|p| r.handle(p)).collect();
        assert_eq!(got, [message(720)]);
    }
}
