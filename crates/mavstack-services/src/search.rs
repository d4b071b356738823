//! [`Search`]: what the discoveries of a system's components (its cameras, its gimbal
//! managers) share: whom they ask, REQUEST_MESSAGE sent to them, asked again every
//! [`DiscoveryConfig::ask_every`], and the end, [`DiscoveryConfig::settle`] after the last
//! find or at [`DiscoveryConfig::limit`] with none. The discoveries decide what a find is
//! and whom to ask again.

use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{CommandLong, MavCmd, MavMessage};

use crate::{Address, Outgoing};

/// Timings of a discovery ([`GimbalDiscovery`](crate::gimbal::GimbalDiscovery),
/// [`CameraDiscovery`](crate::camera::CameraDiscovery)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DiscoveryConfig {
    /// How often the requests go out again while nothing has answered (default 500 ms).
    pub ask_every: Duration,
    /// How long after the last new find the search ends (default 700 ms: a system's
    /// components answer one request within a round trip of each other).
    pub settle: Duration,
    /// How long the search lasts at most, when nothing answers (default 3 s).
    pub limit: Duration,
}

impl Default for DiscoveryConfig {
    fn default() -> Self {
        Self {
            ask_every: Duration::from_millis(500),
            settle: Duration::from_millis(700),
            limit: Duration::from_secs(3),
        }
    }
}

/// A search among the components of one system.
#[derive(Clone, Debug)]
pub(crate) struct Search {
    /// The system searched.
    pub(crate) system: u8,
    /// Its components to ask (besides the whole system), sorted, without 0 or repeats.
    pub(crate) components: Vec<u8>,
    config: DiscoveryConfig,
    started: Instant,
    /// When the requests go out again (`None`: not again).
    pub(crate) next_ask: Option<Instant>,
    last_found: Option<Instant>,
    out: Vec<Outgoing>,
    done: bool,
    taken: bool,
}

impl Search {
    /// A search of `system` starting at `now`, asking `components`.
    pub(crate) fn new(
        now: Instant,
        system: u8,
        components: &[u8],
        config: DiscoveryConfig,
    ) -> Self {
        let mut components: Vec<u8> = components.iter().copied().filter(|&c| c != 0).collect();
        components.sort_unstable();
        components.dedup();
        Self {
            system,
            components,
            config,
            started: now,
            next_ask: Some(now),
            last_found: None,
            out: Vec::new(),
            done: false,
            taken: false,
        }
    }

    /// Whether the search has ended.
    pub(crate) const fn done(&self) -> bool {
        self.done
    }

    /// Something new was found at `now`: the search ends `settle` later unless more is.
    pub(crate) const fn found(&mut self, now: Instant) {
        self.last_found = Some(now);
    }

    /// Queues MAV_CMD_REQUEST_MESSAGE(`msg_id`) to `component` of the system (0: all).
    pub(crate) fn request(&mut self, component: u8, msg_id: u32) {
        self.out.push(Outgoing {
            target: Address::new(self.system, component),
            message: MavMessage::CommandLong(CommandLong {
                target_system: self.system,
                target_component: component,
                command: MavCmd::REQUEST_MESSAGE,
                param1: msg_id as f32,
                ..CommandLong::default()
            }),
        });
    }

    /// Time passes: ends the search when its time is up; whether the requests are to go
    /// out again now (the next time is then set).
    pub(crate) fn tick(&mut self, now: Instant) -> bool {
        if self.done {
            return false;
        }
        if now >= self.deadline() {
            self.done = true;
            self.next_ask = None;
            return false;
        }
        match self.next_ask {
            Some(due) if now >= due => {
                self.next_ask = Some(now + self.config.ask_every);
                true
            }
            _ => false,
        }
    }

    /// Whether the result is to be given now (the search has ended and it was not given).
    pub(crate) const fn take(&mut self) -> bool {
        if !self.done || self.taken {
            return false;
        }
        self.taken = true;
        true
    }

    /// The next request to send.
    pub(crate) fn poll_transmit(&mut self) -> Option<Outgoing> {
        (!self.out.is_empty()).then(|| self.out.remove(0))
    }

    /// When [`Search::tick`] is due next.
    pub(crate) fn poll_timeout(&self) -> Option<Instant> {
        if self.done {
            return None;
        }
        let end = self.deadline();
        Some(self.next_ask.map_or(end, |a| a.min(end)))
    }

    fn deadline(&self) -> Instant {
        match self.last_found {
            Some(t) => t + self.config.settle,
            None => self.started + self.config.limit,
        }
    }
}
