//! The in-memory test network the sans-IO layers' tests share (feature `testing`, for
//! dev-dependencies only): a seeded RNG and a one-way [`Link`] in virtual time that loses,
//! duplicates, delays and, with jitter, reorders what it carries.
//!
//! The channel's tests carry bytes over it and the services' tests decoded messages; each
//! wraps it in its own `Pair` of endpoints (`crates/mavstack-channel/tests/util/`,
//! `crates/mavstack-services/tests/util/`). The same seed and knobs give the same run.
//!
//! ```
//! use core::time::Duration;
//! use mavstack_core::testing::{Knobs, Link};
//! use mavstack_core::time::Instant;
//!
//! let mut link = Link::new(Knobs::clean(), 1);
//! let t0 = Instant::from_secs(1);
//! link.send(t0, "hello");
//! assert_eq!(link.pop_due(t0), None); // 5 ms latency
//! assert_eq!(link.next_delivery(), Some(t0 + Duration::from_millis(5)));
//! assert_eq!(link.pop_due(t0 + Duration::from_millis(5)), Some("hello"));
//! ```

use core::time::Duration;
use std::vec::Vec;

use crate::time::Instant;

/// SplitMix64: small, seeded, good enough for fault injection.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator from `seed`.
    #[must_use]
    pub const fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// True with probability `p` (no draw when `p` is 0).
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }

    /// Uniform in `0..n` (0, and no draw, when `n` is 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next_u64() % n }
    }
}

/// Fault injection on everything a [`Link`] carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Knobs {
    /// Probability that an item is lost.
    pub loss: f64,
    /// Probability that an item is delivered twice (each copy with its own delay).
    pub duplicate: f64,
    /// Fixed delay of every delivery.
    pub latency: Duration,
    /// Extra random delay in `0..jitter`, so items overtake each other.
    pub jitter: Duration,
}

impl Knobs {
    /// A perfect link with 5 ms latency.
    #[must_use]
    pub const fn clean() -> Self {
        Self {
            loss: 0.0,
            duplicate: 0.0,
            latency: Duration::from_millis(5),
            jitter: Duration::ZERO,
        }
    }

    /// 20 % loss, 20 % duplication, 5–25 ms latency (reordering).
    #[must_use]
    pub const fn hostile() -> Self {
        Self {
            loss: 0.2,
            duplicate: 0.2,
            latency: Duration::from_millis(5),
            jitter: Duration::from_millis(20),
        }
    }
}

impl Default for Knobs {
    /// [`Knobs::clean`].
    fn default() -> Self {
        Self::clean()
    }
}

/// What a [`Link`] did to what it carried, to compare with what the endpoints measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Faults {
    /// Items lost.
    pub lost: u64,
    /// Items delivered twice.
    pub duplicated: u64,
}

#[derive(Debug)]
struct InFlight<T> {
    at: Instant,
    order: u64,
    item: T,
}

/// A link in virtual time: what is sent at `now` arrives at `now + latency (+ jitter)`,
/// unless lost, and maybe twice. The draws per item, in order: loss; if not lost,
/// duplication; then the jitter of each copy (none without jitter).
#[derive(Debug)]
pub struct Link<T> {
    /// The faults applied to every item sent from now on.
    pub knobs: Knobs,
    /// The generator the faults are drawn from.
    pub rng: Rng,
    /// What the link has done so far.
    pub faults: Faults,
    in_flight: Vec<InFlight<T>>,
    order: u64,
}

impl<T: Clone> Link<T> {
    /// An empty link with `knobs`, its faults drawn from `seed`.
    #[must_use]
    pub const fn new(knobs: Knobs, seed: u64) -> Self {
        Self {
            knobs,
            rng: Rng::new(seed),
            faults: Faults {
                lost: 0,
                duplicated: 0,
            },
            in_flight: Vec::new(),
            order: 0,
        }
    }

    /// Sends `item` at `now`; returns how many copies will arrive (0, 1 or 2).
    pub fn send(&mut self, now: Instant, item: T) -> usize {
        if self.rng.chance(self.knobs.loss) {
            self.faults.lost += 1;
            return 0;
        }
        let copies = if self.rng.chance(self.knobs.duplicate) {
            self.faults.duplicated += 1;
            2
        } else {
            1
        };
        for _ in 0..copies {
            let jitter_us = u64::try_from(self.knobs.jitter.as_micros()).unwrap_or(u64::MAX);
            let jitter = Duration::from_micros(self.rng.below(jitter_us));
            self.order += 1;
            self.in_flight.push(InFlight {
                at: now + self.knobs.latency + jitter,
                order: self.order,
                item: item.clone(),
            });
        }
        copies
    }

    /// The earliest item due at `now` (by arrival time, then by sending order), taken off
    /// the link.
    pub fn pop_due(&mut self, now: Instant) -> Option<T> {
        let i = self
            .in_flight
            .iter()
            .enumerate()
            .filter(|(_, f)| f.at <= now)
            .min_by_key(|(_, f)| (f.at, f.order))
            .map(|(i, _)| i)?;
        Some(self.in_flight.remove(i).item)
    }

    /// When the next item arrives, if any is on the way.
    #[must_use]
    pub fn next_delivery(&self) -> Option<Instant> {
        self.in_flight.iter().map(|f| f.at).min()
    }

    /// Items on the way.
    #[must_use]
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }
}
