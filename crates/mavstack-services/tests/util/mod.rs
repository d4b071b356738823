//! A deterministic simulation harness for service tests, after quinn-proto's `Pair`: two
//! services (say a ground-station client and a vehicle server) over the shared in-memory
//! test network (`mavstack_core::testing::Link`) carrying decoded messages: a virtual clock,
//! loss, duplication and latency jitter (which reorders), and a seeded RNG.
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

pub use mavstack_core::testing::{Knobs, Link};
use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_services::{Address, Service};

/// The virtual clock starts here.
pub const T0: Instant = Instant::from_secs(1_000);

/// Which end a message goes to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    A,
    B,
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
    /// Both directions, each message with the side it goes to.
    pub link: Link<(Side, MavMessage)>,
    /// a → b
    pub ab: Counts,
    /// b → a
    pub ba: Counts,
}

impl<A: Service, B: Service> Pair<A, B> {
    pub fn new(a: A, a_addr: Address, b: B, b_addr: Address, knobs: Knobs, seed: u64) -> Self {
        Self {
            a,
            b,
            a_addr,
            b_addr,
            now: T0,
            link: Link::new(knobs, seed),
            ab: Counts::default(),
            ba: Counts::default(),
        }
    }

    fn queue(&mut self, to: Side, message: MavMessage) {
        self.link.send(self.now, (to, message));
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
        [
            self.link.next_delivery(),
            self.a.poll_timeout(),
            self.b.poll_timeout(),
        ]
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
        while let Some((to, message)) = self.link.pop_due(now) {
            match to {
                Side::A => {
                    self.ba.delivered += 1;
                    let _ = self.a.handle_message(now, self.b_addr, &message);
                }
                Side::B => {
                    self.ab.delivered += 1;
                    let _ = self.b.handle_message(now, self.a_addr, &message);
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
