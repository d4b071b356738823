//! RTK corrections: RTCM3 frames found in a byte stream, and carried to a vehicle in
//! GPS_RTCM_DATA.
//!
//! A base station or an NTRIP caster sends RTCM 3 as a stream of frames: the preamble `0xD3`,
//! six reserved bits (zero), a 10-bit payload length, the payload, and a CRC-24Q of all that.
//! [`Deframer`] finds the frames in a stream that may hold anything else as well (a serial
//! line's noise, another protocol, a frame cut short): a frame is taken only when its CRC
//! holds, and what is not part of a good frame is counted ([`DeframeStats`]), never sent.
//!
//! A vehicle takes corrections in GPS_RTCM_DATA ([`fragments`]): a message of up to 180 bytes
//! in one, a longer one (up to [`MAX_MESSAGE_LEN`] = 4 × 180 bytes) in fragments that share
//! a 5-bit sequence id. The receiver knows it has them all when every fragment before the
//! first one shorter than 180 bytes is there, or when four full ones are: a message whose
//! length is a multiple of 180 (and under 720) therefore ends with an empty fragment
//! (common.xml's rule; ArduPilot's `AP_GPS::handle_gps_rtcm_fragment` waits for it, so a
//! sender that leaves it out loses those messages). [`Reassembler`] is the receiving side
//! (the simulator's; tests').
//!
//! ```
//! use mavstack_services::rtcm::{Deframer, RtcmSender, Reassembler, frame};
//!
//! let good = frame(&[0x3e, 0xd0, 0x00, 0x03]); // an RTCM 1005 header's first bytes
//! let mut stream = b"noise".to_vec();
//! stream.extend_from_slice(&good);
//! let mut deframer = Deframer::new();
//! deframer.push(&stream);
//! assert_eq!(deframer.poll_frame().as_deref(), Some(&good[..]));
//! assert_eq!(deframer.stats().skipped, 5);
//!
//! let mut sender = RtcmSender::default();
//! let mut receiver = Reassembler::default();
//! let message = vec![7u8; 360];
//! let parts = sender.fragments(&message).unwrap();
//! assert_eq!(parts.len(), 3); // 180 + 180 + the empty last fragment
//! let got: Vec<_> = parts.iter().filter_map(|p| receiver.handle(p)).collect();
//! assert_eq!(got, vec![message]);
//! ```

mod inject;

pub use inject::{
    FRAGMENT_LEN, MAX_FRAGMENTS, MAX_MESSAGE_LEN, Reassembler, ReassemblyStats, RtcmError,
    RtcmSender, fragments,
};

use alloc::vec::Vec;

/// The first byte of every RTCM3 frame.
pub const PREAMBLE: u8 = 0xD3;

/// The header: preamble, 6 reserved bits and the 10-bit length.
pub const HEADER_LEN: usize = 3;

/// The CRC-24Q after the payload.
pub const CRC_LEN: usize = 3;

/// The longest payload a 10-bit length can give.
pub const MAX_PAYLOAD: usize = 1023;

/// The longest frame: header, 1,023 payload bytes, CRC.
pub const MAX_FRAME_LEN: usize = HEADER_LEN + MAX_PAYLOAD + CRC_LEN;

/// CRC-24Q's polynomial with its x²⁴ term (Qualcomm's, as RTCM 10403 names it).
const POLY: u32 = 0x0186_4CFB;

const fn crc_table() -> [u32; 256] {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u32) << 16;
        let mut bit = 0;
        while bit < 8 {
            c <<= 1;
            if c & 0x0100_0000 != 0 {
                c ^= POLY;
            }
            bit += 1;
        }
        table[i] = c & 0x00FF_FFFF;
        i += 1;
    }
    table
}

static CRC_TABLE: [u32; 256] = crc_table();

/// The CRC-24Q of `data` (initial value 0, most significant bit first, no final XOR): what
/// the last three bytes of an RTCM3 frame hold, big-endian, computed over the rest.
///
/// ```
/// assert_eq!(mavstack_services::rtcm::crc24q(b"123456789"), 0xCD_E703);
/// ```
#[must_use]
pub fn crc24q(data: &[u8]) -> u32 {
    data.iter().fold(0u32, |crc, &b| {
        let index = usize::from(((crc >> 16) as u8) ^ b);
        ((crc << 8) & 0x00FF_FFFF) ^ CRC_TABLE[index]
    })
}

/// An RTCM3 frame around `payload` (its header and CRC added); a payload longer than
/// [`MAX_PAYLOAD`] is cut to it. For tests and tools that make streams.
#[must_use]
pub fn frame(payload: &[u8]) -> Vec<u8> {
    let payload = &payload[..payload.len().min(MAX_PAYLOAD)];
    let len = payload.len();
    let mut out = Vec::with_capacity(HEADER_LEN + len + CRC_LEN);
    out.push(PREAMBLE);
    out.push((len >> 8) as u8 & 0x03);
    out.push(len as u8);
    out.extend_from_slice(payload);
    let crc = crc24q(&out);
    out.extend_from_slice(&crc.to_be_bytes()[1..]);
    out
}

/// The message number of an RTCM3 frame (the payload's first 12 bits: 1005 for the base
/// station's position, 1074-1127 for MSM observations), if it has a payload of two bytes or
/// more.
#[must_use]
pub fn message_number(frame: &[u8]) -> Option<u16> {
    match frame {
        [PREAMBLE, _, _, a, b, ..] if frame.len() >= HEADER_LEN + 2 + CRC_LEN => {
            Some((u16::from(*a) << 4) | u16::from(*b >> 4))
        }
        _ => None,
    }
}

/// What a [`Deframer`] has seen so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DeframeStats {
    /// Good frames found (their CRC holds).
    pub frames: u64,
    /// The bytes of those frames.
    pub frame_bytes: u64,
    /// Frames dropped: a header that looked right, then a CRC that did not hold, or the
    /// stream ended before its last byte.
    pub damaged: u64,
    /// Bytes that are in no good frame (noise, other protocols, damaged frames).
    pub skipped: u64,
}

/// Finds RTCM3 frames in a byte stream, sans-IO: bytes in with [`push`](Self::push), frames
/// out with [`poll_frame`](Self::poll_frame) (checked by their CRC-24Q), and at the end of
/// the stream [`end`](Self::end). Memory is bounded: what it keeps between calls is less
/// than one frame ([`MAX_FRAME_LEN`]) plus what the last `push` gave.
///
/// After a damaged frame it looks for the next preamble from the byte after the damaged
/// one's, so a good frame that follows a cut one is found.
#[derive(Clone, Debug, Default)]
pub struct Deframer {
    buf: Vec<u8>,
    /// Where the unread part of `buf` starts.
    start: usize,
    ended: bool,
    stats: DeframeStats,
}

impl Deframer {
    /// A deframer at the start of a stream.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the next bytes of the stream. Call [`poll_frame`](Self::poll_frame) until
    /// `None` after each.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0 {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Says that the stream has ended: a frame still incomplete is damaged, and
    /// [`poll_frame`](Self::poll_frame) then finds whatever good frames follow its start.
    pub fn end(&mut self) {
        self.ended = true;
    }

    /// What it has counted so far.
    #[must_use]
    pub const fn stats(&self) -> DeframeStats {
        self.stats
    }

    /// Bytes held that are not yet known to be in a frame or not.
    #[must_use]
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// The next good frame (header, payload and CRC), if the bytes so far hold one.
    #[must_use]
    pub fn poll_frame(&mut self) -> Option<Vec<u8>> {
        loop {
            let rest = &self.buf[self.start..];
            let Some(at) = rest.iter().position(|&b| b == PREAMBLE) else {
                self.skip(rest.len());
                return None;
            };
            self.skip(at);
            let rest = &self.buf[self.start..];
            if rest.len() < HEADER_LEN {
                if self.ended {
                    self.drop_candidate(rest.len() > 1 && rest[1] & 0xFC == 0);
                    continue;
                }
                return None;
            }
            if rest[1] & 0xFC != 0 {
                // Reserved bits set: not a frame's start.
                self.skip(1);
                continue;
            }
            let len = (usize::from(rest[1] & 0x03) << 8) | usize::from(rest[2]);
            let total = HEADER_LEN + len + CRC_LEN;
            if rest.len() < total {
                if self.ended {
                    self.drop_candidate(true);
                    continue;
                }
                return None;
            }
            let body = HEADER_LEN + len;
            let sent = u32::from_be_bytes([0, rest[body], rest[body + 1], rest[body + 2]]);
            if crc24q(&rest[..body]) != sent {
                self.drop_candidate(true);
                continue;
            }
            let frame = rest[..total].to_vec();
            self.start += total;
            self.stats.frames += 1;
            self.stats.frame_bytes += total as u64;
            return Some(frame);
        }
    }

    /// Counts `n` bytes as in no frame and moves past them.
    fn skip(&mut self, n: usize) {
        self.stats.skipped += n as u64;
        self.start += n;
    }

    /// A frame's start that is not one after all (`damaged`: its header looked right):
    /// moves past its preamble only, to look for the next one inside it.
    fn drop_candidate(&mut self, damaged: bool) {
        if damaged {
            self.stats.damaged += 1;
        }
        self.skip(1);
    }
}

/// The fuzz target `rtcm`: the deframer, the fragmenter and the reassembler on arbitrary
/// input, with their properties checked (a bug panics):
///
/// - fed in pieces the data chooses, the deframer finds the same frames as fed at once;
///   every frame it gives has a good CRC-24Q and the length its header says; the bytes of
///   the frames plus those skipped plus those pending are all the bytes fed;
/// - each good frame of up to [`MAX_MESSAGE_LEN`] bytes comes out of [`fragments`] in at
///   most four messages of at most 180 bytes each, the last one shorter than 180 unless
///   there are four, and [`Reassembler`] gives it back byte for byte; a longer one is
///   refused;
/// - the data read as GPS_RTCM_DATA messages (`flags`, `len`, bytes) never makes the
///   reassembler give more than [`MAX_MESSAGE_LEN`] bytes.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_rtcm(data: &[u8]) {
    use mavstack_dialects::common::GpsRtcmData;

    let mut whole = Deframer::new();
    whole.push(data);
    whole.end();
    let frames: Vec<Vec<u8>> = core::iter::from_fn(|| whole.poll_frame()).collect();
    let stats = whole.stats();
    let framed: usize = frames.iter().map(Vec::len).sum();
    assert_eq!(framed as u64, stats.frame_bytes);
    assert_eq!(stats.frame_bytes + stats.skipped, data.len() as u64);
    assert_eq!(whole.pending(), 0);

    let mut pieces = Deframer::new();
    let mut rest = data;
    let mut again = Vec::new();
    let mut step = 1usize;
    while !rest.is_empty() {
        let n = (usize::from(rest[0]) % 97 + step).min(rest.len());
        step = step % 13 + 1;
        pieces.push(&rest[..n]);
        rest = &rest[n..];
        again.extend(core::iter::from_fn(|| pieces.poll_frame()));
        let s = pieces.stats();
        assert_eq!(
            s.frame_bytes + s.skipped + pieces.pending() as u64,
            (data.len() - rest.len()) as u64
        );
    }
    pieces.end();
    again.extend(core::iter::from_fn(|| pieces.poll_frame()));
    assert_eq!(again, frames);

    let mut sender = RtcmSender::default();
    let mut receiver = Reassembler::default();
    for f in &frames {
        let len = (usize::from(f[1] & 0x03) << 8) | usize::from(f[2]);
        assert_eq!(f.len(), HEADER_LEN + len + CRC_LEN);
        let sent = u32::from_be_bytes([0, f[f.len() - 3], f[f.len() - 2], f[f.len() - 1]]);
        assert_eq!(crc24q(&f[..f.len() - CRC_LEN]), sent);
        match sender.fragments(f) {
            Ok(parts) => {
                assert!(f.len() <= MAX_MESSAGE_LEN && parts.len() <= MAX_FRAGMENTS);
                let last = parts.last().map_or(0, |p| usize::from(p.len));
                assert!(last < FRAGMENT_LEN || parts.len() == MAX_FRAGMENTS || parts.len() == 1);
                let got: Vec<Vec<u8>> = parts.iter().filter_map(|p| receiver.handle(p)).collect();
                assert_eq!(got, core::slice::from_ref(f));
            }
            Err(RtcmError::TooLong { len }) => assert!(len > MAX_MESSAGE_LEN),
            Err(e) => panic!("{e}"),
        }
    }

    let mut any = Reassembler::default();
    let mut rest = data;
    while let [flags, len, tail @ ..] = rest {
        let n = usize::from(*len).min(FRAGMENT_LEN).min(tail.len());
        let mut m = GpsRtcmData {
            flags: *flags,
            len: *len,
            data: [0; FRAGMENT_LEN],
        };
        m.data[..n].copy_from_slice(&tail[..n]);
        rest = &tail[n..];
        if let Some(out) = any.handle(&m) {
            assert!(out.len() <= MAX_MESSAGE_LEN);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    #[test]
    fn crc24q_matches_an_independent_implementation() {
        let oracle = crc::Crc::<u32>::new(&crc::CRC_24_LTE_A);
        assert_eq!(crc24q(b"123456789"), 0xCD_E703);
        for len in [0usize, 1, 2, 3, 100, 1026] {
            let data: Vec<u8> = (0..len).map(|i| (i * 31 + 7) as u8).collect();
            assert_eq!(crc24q(&data), oracle.checksum(&data), "{len} bytes");
        }
    }

    #[test]
    fn garbage_damaged_and_good_frames_are_counted() {
        let a = frame(&[0x3e, 0xd0, 1, 2, 3]);
        let mut long = vec![0x43, 0x20];
        long.extend([7u8; 150]);
        let b = frame(&long);
        let mut damaged = frame(&[0x44, 0x60, 9, 9]);
        damaged[5] ^= 0x40;
        let mut stream = b"\x00\xffgarbage".to_vec();
        stream.extend_from_slice(&a);
        stream.extend_from_slice(&damaged);
        stream.extend_from_slice(&[PREAMBLE, 0xFC, 0x00]); // reserved bits set
        stream.extend_from_slice(&b);
        let cut = &frame(&[1; 40])[..20];
        stream.extend_from_slice(cut);
        let mut d = Deframer::new();
        let mut got = Vec::new();
        for chunk in stream.chunks(7) {
            d.push(chunk);
            got.extend(core::iter::from_fn(|| d.poll_frame()));
        }
        assert_eq!(got, [a.clone(), b.clone()]);
        assert_eq!(d.stats().damaged, 1);
        assert_eq!(d.pending(), cut.len());
        d.end();
        assert_eq!(d.poll_frame(), None);
        let s = d.stats();
        assert_eq!(s.frames, 2);
        assert_eq!(s.damaged, 2); // the CRC and the cut one
        assert_eq!(s.frame_bytes, (a.len() + b.len()) as u64);
        assert_eq!(s.frame_bytes + s.skipped, stream.len() as u64);
    }

    #[test]
    fn a_good_frame_inside_a_false_start_is_found() {
        // A false preamble whose length reaches past the good frame that follows it.
        let good = frame(&[0x3e, 0xd0, 5]);
        let mut stream = vec![PREAMBLE, 0x03, 0xff];
        stream.extend_from_slice(&good);
        let mut d = Deframer::new();
        d.push(&stream);
        assert_eq!(d.poll_frame(), None);
        d.end();
        assert_eq!(d.poll_frame(), Some(good));
        assert_eq!(d.stats().damaged, 1);
        assert_eq!(d.stats().skipped, 3);
    }

    #[test]
    fn garbage_alone_gives_no_frame() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let noise: Vec<u8> = (0..50_000)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state as u8
            })
            .collect();
        let mut d = Deframer::new();
        d.push(&noise);
        d.end();
        assert_eq!(d.poll_frame(), None);
        assert_eq!(d.stats().frames, 0);
        assert_eq!(d.stats().skipped, noise.len() as u64);
        assert!(d.stats().damaged > 0);
    }

    #[test]
    fn message_numbers() {
        assert_eq!(message_number(&frame(&[0x3e, 0xd0, 0])), Some(1005));
        assert_eq!(message_number(&frame(&[0x43, 0x20])), Some(1074));
        assert_eq!(message_number(&frame(&[0x43])), None);
    }
}
