//! Duplicate suppression: a fixed table of recent frame hashes (no heap after creation).
//!
//! A frame whose exact bytes were seen within the window is a duplicate (the same frame over
//! two radios, or a loop). Each sighting renews the entry, so a frame repeated faster than
//! the window stays suppressed. The table has a fixed number of slots; when the probed slots
//! are all live, the oldest is replaced, so memory never grows.

use alloc::vec;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;

/// Slots probed per lookup.
const PROBES: usize = 8;

#[derive(Clone, Copy, Debug, Default)]
struct Slot {
    hash: u64,
    expires: Instant,
}

/// The table.
#[derive(Clone, Debug)]
pub(crate) struct Dedup {
    slots: Vec<Slot>,
    window: Duration,
}

impl Dedup {
    /// A table of about `capacity` entries (rounded up to a power of two) for `window`.
    #[must_use]
    pub(crate) fn new(capacity: usize, window: Duration) -> Self {
        Self {
            slots: vec![Slot::default(); capacity.max(PROBES).next_power_of_two()],
            window,
        }
    }

    /// Whether `bytes` were seen within the window; records them either way.
    pub(crate) fn seen(&mut self, now: Instant, bytes: &[u8]) -> bool {
        let hash = hash(bytes) | 1; // 0 marks an empty slot
        let mask = self.slots.len() - 1;
        // The low bits pick the slot; `hash` is 64 bits, the table far smaller.
        #[allow(clippy::cast_possible_truncation)]
        let start = hash as usize & mask;
        let expires = now + self.window;
        let mut victim = start;
        for i in 0..PROBES {
            let at = (start + i) & mask;
            let slot = self.slots[at];
            if slot.hash == hash && slot.expires > now {
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
        self.slots[victim] = Slot { hash, expires };
        false
    }
}

/// A fast 64-bit hash of a frame's bytes (not keyed: duplicates are not a security boundary;
/// whoever could force a collision could as well send the same bytes).
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
        let mut d = Dedup::new(64, Duration::from_millis(100));
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
        let mut d = Dedup::new(8, Duration::from_secs(10));
        let t = Instant::from_secs(1);
        for i in 0u32..1000 {
            assert!(!d.seen(t, &i.to_le_bytes()));
        }
        assert_eq!(d.slots.len(), 8);
    }
}
