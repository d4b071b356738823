//! A deterministic simulation harness for service tests, after quinn-proto's `Pair`: two
//! services (say a ground-station client and a vehicle server) over an in-memory link of
//! decoded messages with a virtual clock, loss, duplication and latency jitter (which
//! reorders), and a seeded RNG.
//!
//! ```text
//!   a (address A) ──► [loss, dup, latency + jitter] ──► b (address B)
//!   a             ◄── [loss, dup, latency + jitter] ◄── b
//! ```
#![allow(
    dead_code,
    unreachable_pub,
    reason = "each test binary uses a part of the harness"
)]

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_services::{Address, Service};

/// The virtual clock starts here.
pub const T0: Instant = Instant::from_secs(1_000);

/// SplitMix64: small, seeded, good enough for fault injection.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }

    /// Uniform in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: u64) -> u64 {
        if n == 0 { 0 } else { self.next_u64() % n }
    }
}

/// Fault injection on every message.
#[derive(Clone, Copy, Debug)]
pub struct Knobs {
    /// Probability that a message is lost.
    pub loss: f64,
    /// Probability that a message is delivered twice (the copy with its own latency).
    pub duplicate: f64,
    /// Fixed delay of every delivery.
    pub latency: Duration,
    /// Extra random delay in `0..jitter`, so messages overtake each other.
    pub jitter: Duration,
}

impl Knobs {
    /// A perfect link with 5 ms latency.
    pub fn clean() -> Self {
        Self {
            loss: 0.0,
            duplicate: 0.0,
            latency: Duration::from_millis(5),
            jitter: Duration::ZERO,
        }
    }

    /// 20 % loss, 20 % duplication, 5–25 ms latency (reordering).
    pub fn hostile() -> Self {
        Self {
            loss: 0.2,
            duplicate: 0.2,
            latency: Duration::from_millis(5),
            jitter: Duration::from_millis(20),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    A,
    B,
}

struct InFlight {
    at: Instant,
    order: u64,
    to: Side,
    message: MavMessage,
}

/// Counts of one direction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Messages the sender emitted.
    pub sent: u64,
    /// Messages delivered (duplicates included).
    pub delivered: u64,
}

/// Two services over a simulated link.
pub struct Pair<A, B> {
    pub a: A,
    pub b: B,
    pub a_addr: Address,
    pub b_addr: Address,
    pub now: Instant,
    pub knobs: Knobs,
    pub rng: Rng,
    /// a → b
    pub ab: Counts,
    /// b → a
    pub ba: Counts,
    link: Vec<InFlight>,
    order: u64,
}

impl<A: Service, B: Service> Pair<A, B> {
    pub fn new(a: A, a_addr: Address, b: B, b_addr: Address, knobs: Knobs, seed: u64) -> Self {
        Self {
            a,
            b,
            a_addr,
            b_addr,
            now: T0,
            knobs,
            rng: Rng::new(seed),
            ab: Counts::default(),
            ba: Counts::default(),
            link: Vec::new(),
            order: 0,
        }
    }

    fn queue(&mut self, to: Side, message: MavMessage) {
        let copies = if self.rng.chance(self.knobs.loss) {
            0
        } else if self.rng.chance(self.knobs.duplicate) {
            2
        } else {
            1
        };
        for _ in 0..copies {
            let jitter = self.rng.below(self.knobs.jitter.as_micros() as u64);
            let at = self.now + self.knobs.latency + Duration::from_micros(jitter);
            self.order += 1;
            self.link.push(InFlight {
                at,
                order: self.order,
                to,
                message: message.clone(),
            });
        }
    }

    /// Moves everything both sides want to send onto the link.
    pub fn flush(&mut self) {
        while let Some(out) = self.a.poll_transmit() {
            self.ab.sent += 1;
            self.queue(Side::B, out.message);
        }
        while let Some(out) = self.b.poll_transmit() {
            self.ba.sent += 1;
            self.queue(Side::A, out.message);
        }
    }

    /// The next time something happens: a delivery or a service timer.
    fn next_time(&self) -> Option<Instant> {
        let deliveries = self.link.iter().map(|m| m.at).min();
        [deliveries, self.a.poll_timeout(), self.b.poll_timeout()]
            .into_iter()
            .flatten()
            .min()
    }

    /// Advances to the next event and handles it. Returns false when nothing is left to do.
    pub fn step(&mut self) -> bool {
        self.flush();
        let Some(next) = self.next_time() else {
            return false;
        };
        self.now = self.now.max(next);
        let now = self.now;
        // Deliver everything due, in arrival order.
        let mut due: Vec<InFlight> = Vec::new();
        let mut i = 0;
        while i < self.link.len() {
            if self.link[i].at <= now {
                due.push(self.link.swap_remove(i));
            } else {
                i += 1;
            }
        }
        due.sort_by_key(|m| (m.at, m.order));
        for m in due {
            match m.to {
                Side::A => {
                    self.ba.delivered += 1;
                    let _ = self.a.handle_message(now, self.b_addr, &m.message);
                }
                Side::B => {
                    self.ab.delivered += 1;
                    let _ = self.b.handle_message(now, self.a_addr, &m.message);
                }
            }
        }
        if self.a.poll_timeout().is_some_and(|t| t <= now) {
            self.a.handle_timeout(now);
        }
        if self.b.poll_timeout().is_some_and(|t| t <= now) {
            self.b.handle_timeout(now);
        }
        self.flush();
        true
    }

    /// Steps until `done` says so (checked after every step) or `limit` of virtual time has
    /// passed. Returns whether `done` was reached.
    pub fn drive_until(
        &mut self,
        limit: Duration,
        mut done: impl FnMut(&mut A, &mut B, Instant) -> bool,
    ) -> bool {
        let end = self.now + limit;
        loop {
            if done(&mut self.a, &mut self.b, self.now) {
                return true;
            }
            if self.now >= end || !self.step() {
                return done(&mut self.a, &mut self.b, self.now);
            }
        }
    }

    /// Steps until `limit` of virtual time has passed (or nothing is left to do).
    pub fn drive_for(&mut self, limit: Duration) {
        let end = self.now + limit;
        self.flush();
        while self.next_time().is_some_and(|t| t <= end) {
            self.step();
        }
        self.now = self.now.max(end);
    }

    /// Messages in both directions so far.
    pub fn messages(&self) -> u64 {
        self.ab.sent + self.ba.sent
    }
}
