//! Duplicate suppression: a fixed table of recent frames (no heap after creation).
//!
//! A frame whose exact bytes were seen within the window is a duplicate (the same frame over
//! two radios, or a loop). Each sighting renews the entry, so a frame repeated faster than
//! the window stays suppressed. The table has a fixed number of slots; when the probed slots
//! are all live, the oldest is replaced, so memory never grows.
//!
//! A slot keeps the frame's hash and its bytes: equal hashes are only a hint, the bytes
//! decide, so two different frames whose hashes collide (by chance or crafted) are never
//! taken for each other. The bytes live in one buffer of `MAX_FRAME_LEN` bytes per slot,
//! allocated zeroed when the table is made (the pages the slots never use stay untouched).

use alloc::vec;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;

/// Slots probed per lookup.
const PROBES: usize = 8;

#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    hash: u64,
    expires: Instant,
    /// How many of the slot's bytes in [`Dedup::bytes`] are its frame.
    len: u16,
}

/// The table.
#[derive(Clone)]
pub(crate) struct Dedup {
    slots: Vec<Slot>,
    /// `MAX_FRAME_LEN` bytes per slot: the frame each slot stands for.
    bytes: Vec<u8>,
    window: Duration,
    hash: fn(&[u8]) -> u64,
}

impl core::fmt::Debug for Dedup {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        // Not the frames: up to 280 bytes per slot.
        f.debug_struct("Dedup")
            .field("slots", &self.slots.len())
            .field("window", &self.window)
            .finish_non_exhaustive()
    }
}

impl Dedup {
    /// A table of about `capacity` entries (rounded up to a power of two) for `window`,
    /// hashing frames with `hash` (the built-in [`hash`] when `None`).
    #[must_use]
    pub(crate) fn new(capacity: usize, window: Duration, hash: Option<fn(&[u8]) -> u64>) -> Self {
        let slots = capacity.max(PROBES).next_power_of_two();
        Self {
            slots: vec![Slot::default(); slots],
            bytes: vec![0; slots * MAX_FRAME_LEN],
            window,
            hash: hash.unwrap_or(self::hash),
        }
    }

    /// The frame slot `at` stands for.
    fn frame(&self, at: usize) -> &[u8] {
        let start = at * MAX_FRAME_LEN;
        &self.bytes[start..start + usize::from(self.slots[at].len)]
    }

    /// Whether `bytes` were seen within the window; records them either way (a frame
    /// longer than any MAVLink frame is never a duplicate, nor recorded).
    pub(crate) fn seen(&mut self, now: Instant, bytes: &[u8]) -> bool {
        let Ok(len) = u16::try_from(bytes.len()) else {
            return false;
        };
        if bytes.len() > MAX_FRAME_LEN {
            return false;
        }
        let hash = (self.hash)(bytes) | 1; // 0 marks an empty slot
        let mask = self.slots.len() - 1;
        // The low bits pick the slot; `hash` is 64 bits, the table far smaller.
        let start = hash as usize & mask;
        let expires = now + self.window;
        let mut victim = start;
        for i in 0..PROBES {
            let at = (start + i) & mask;
            let slot = self.slots[at];
            if slot.hash == hash && slot.expires > now && self.frame(at) == bytes {
                self.slots[at].expires = expires;
                return true;
            }
            if slot.expires <= now {
                victim = at;
                break;
            }
            if slot.expires < self.slots[victim].expires {
                victim = at;
            }
        }
        self.slots[victim] = Slot { hash, expires, len };
        let start = victim * MAX_FRAME_LEN;
        self.bytes[start..start + bytes.len()].copy_from_slice(bytes);
        false
    }
}

/// A fast 64-bit hash of a frame's bytes (not keyed: a collision costs a byte comparison,
/// never a frame).
fn hash(bytes: &[u8]) -> u64 {
    const K: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut h: u64 = (bytes.len() as u64).wrapping_mul(K);
    let mut chunks = bytes.chunks_exact(8);
    for c in &mut chunks {
        let mut w = [0u8; 8];
        w.copy_from_slice(c);
        h = (h ^ u64::from_le_bytes(w)).wrapping_mul(K).rotate_left(29);
    }
    let mut w = [0u8; 8];
    w[..chunks.remainder().len()].copy_from_slice(chunks.remainder());
    h = (h ^ u64::from_le_bytes(w)).wrapping_mul(K);
    h ^ (h >> 32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_refreshes_on_each_hit() {
        let mut d = Dedup::new(64, Duration::from_millis(100), None);
        let t = Instant::from_secs(1);
        assert!(!d.seen(t, b"frame one"));
        assert!(d.seen(t + Duration::from_millis(90), b"frame one"));
        // Renewed at 90 ms: still a duplicate at 180 ms.
        assert!(d.seen(t + Duration::from_millis(180), b"frame one"));
        assert!(!d.seen(t + Duration::from_millis(180), b"frame two"));
        assert!(!d.seen(t + Duration::from_millis(400), b"frame one"));
    }

    #[test]
    fn full_table_evicts_without_growing() {
        let mut d = Dedup::new(8, Duration::from_secs(10), None);
        let t = Instant::from_secs(1);
        for i in 0u32..1000 {
            assert!(!d.seen(t, &i.to_le_bytes()));
        }
        assert_eq!(d.slots.len(), 8);
        assert_eq!(d.bytes.len(), 8 * MAX_FRAME_LEN);
    }

    #[test]
    fn equal_hashes_of_different_frames_are_not_duplicates() {
        let mut d = Dedup::new(8, Duration::from_secs(10), Some(|_| 42));
        let t = Instant::from_secs(1);
        assert!(!d.seen(t, b"frame one"));
        assert!(!d.seen(t, b"frame two"));
        assert!(d.seen(t, b"frame one"));
        assert!(d.seen(t, b"frame two"));
        assert!(!d.seen(t, &[0u8; MAX_FRAME_LEN + 1]));
        assert!(!d.seen(t, &[0u8; MAX_FRAME_LEN + 1]));
    }

    #[test]
    fn a_crafted_collision_of_the_built_in_hash_is_not_a_duplicate() {
        const K: u64 = 0x9E37_79B9_7F4A_7C15;
        // The state after the first `n` whole chunks of `b`, as `hash` computes it.
        let state = |b: &[u8], n: usize| {
            let mut h = (b.len() as u64).wrapping_mul(K);
            for c in b.chunks_exact(8).take(n) {
                let w = u64::from_le_bytes(c.try_into().unwrap());
                h = (h ^ w).wrapping_mul(K).rotate_left(29);
            }
            h
        };
        // A signed HEARTBEAT's length; its last 13 bytes (the signature) are anyone's to pick
        // on a link that does not check them.
        let a: Vec<u8> = (0u8..34).collect();
        let mut b = a.clone();
        b[12] ^= 0xFF;
        // The fourth chunk undoes the difference the second one made in the state.
        let diff = state(&a, 3) ^ state(&b, 3);
        let w = u64::from_le_bytes(b[24..32].try_into().unwrap()) ^ diff;
        b[24..32].copy_from_slice(&w.to_le_bytes());
        assert_ne!(a, b);
        assert_eq!(hash(&a), hash(&b), "the construction no longer collides");
        let mut d = Dedup::new(64, Duration::from_secs(10), None);
        let t = Instant::from_secs(1);
        assert!(!d.seen(t, &a));
        assert!(!d.seen(t, &b));
        assert!(d.seen(t, &a) && d.seen(t, &b));
    }
}
