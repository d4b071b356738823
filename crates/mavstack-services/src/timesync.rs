//! TIMESYNC (id 111): answering peers and estimating the offset to one.
//!
//! [`Timesync`] answers every request (`tc1 == 0`) with its own time in `tc1` and `ts1`
//! copied back, and, when [`TimesyncConfig::interval`] is set, sends its own requests
//! (`ts1` = its time) and turns each answer into an offset sample:
//! `rtt = now − ts1`, `offset = tc1 − (ts1 + now) / 2`. Samples with an RTT above
//! [`TimesyncConfig::max_rtt`] (10 ms, as MAVSDK) are discarded; the rest are smoothed.
//! Answers are matched by their `ts1` against the requests we sent, since this dialect's
//! TIMESYNC has no target fields (several components answering a broadcast request each
//! give a sample; the answers from others' requests carry a `ts1` we never sent).
//!
//! Our time is the driver's [`Instant`] in nanoseconds plus
//! [`TimesyncConfig::clock_offset_ns`] (to put it on whatever base the component uses).

use alloc::collections::VecDeque;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{MavMessage, Timesync as TimesyncMsg};

use crate::{Address, Outgoing, Service};

/// Settings of a [`Timesync`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimesyncConfig {
    /// How often to send our own requests (`None`: only answer; default 5 s, as MAVSDK).
    pub interval: Option<Duration>,
    /// Samples with a longer round trip are discarded (default 10 ms).
    pub max_rtt: Duration,
    /// Added to the driver's time (in ns) to give our TIMESYNC time.
    pub clock_offset_ns: i64,
}

impl Default for TimesyncConfig {
    fn default() -> Self {
        Self {
            interval: Some(Duration::from_secs(5)),
            max_rtt: Duration::from_millis(10),
            clock_offset_ns: 0,
        }
    }
}

/// What a [`Timesync`] reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum TimesyncEvent {
    /// A sample was taken.
    Sample {
        /// Who answered.
        from: Address,
        /// The round trip.
        rtt: Duration,
        /// This sample's offset (peer time − our time) in ns.
        offset_ns: i64,
        /// The smoothed offset after it.
        estimate_ns: i64,
    },
    /// An answer came back too slowly to be trusted.
    Discarded {
        /// Who answered.
        from: Address,
        /// Its round trip.
        rtt: Duration,
    },
}

/// How many of our requests are remembered for matching answers.
const REMEMBERED: usize = 8;

/// The TIMESYNC responder and offset estimator.
#[derive(Debug)]
pub struct Timesync {
    config: TimesyncConfig,
    next: Instant,
    sent: VecDeque<i64>,
    estimate: Option<i64>,
    out: VecDeque<Outgoing>,
    events: VecDeque<TimesyncEvent>,
}

impl Timesync {
    /// A new responder (and estimator if the config has an interval); the first request
    /// goes out at the first [`Service::handle_timeout`].
    #[must_use]
    pub fn new(config: TimesyncConfig) -> Self {
        Self {
            config,
            next: Instant::ZERO,
            sent: VecDeque::new(),
            estimate: None,
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    fn time_ns(&self, now: Instant) -> i64 {
        i64::try_from(now.as_micros())
            .unwrap_or(i64::MAX)
            .saturating_mul(1_000)
            .saturating_add(self.config.clock_offset_ns)
    }

    /// The smoothed offset (peer time − our time) in ns, once a sample was taken.
    #[must_use]
    pub fn offset_ns(&self) -> Option<i64> {
        self.estimate
    }

    /// The next event, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<TimesyncEvent> {
        self.events.pop_front()
    }
}

impl Service for Timesync {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let MavMessage::Timesync(m) = message else {
            return false;
        };
        let ours = self.time_ns(now);
        if m.tc1 == 0 {
            self.out.push_back(Outgoing {
                target: from,
                message: MavMessage::Timesync(TimesyncMsg {
                    tc1: ours,
                    ts1: m.ts1,
                }),
            });
            return true;
        }
        // Only answers to our own requests (several components may answer one
        // broadcast request; each answer is a sample).
        if !self.sent.contains(&m.ts1) {
            return false;
        }
        let rtt_ns = ours.saturating_sub(m.ts1).max(0);
        let rtt = Duration::from_nanos(u64::try_from(rtt_ns).unwrap_or(0));
        if rtt > self.config.max_rtt {
            self.events
                .push_back(TimesyncEvent::Discarded { from, rtt });
            return true;
        }
        let offset_ns = m.tc1.saturating_sub(m.ts1 / 2 + ours / 2);
        let estimate = self.estimate.map_or(offset_ns, |e| {
            e.saturating_add((offset_ns.saturating_sub(e)) / 4)
        });
        self.estimate = Some(estimate);
        self.events.push_back(TimesyncEvent::Sample {
            from,
            rtt,
            offset_ns,
            estimate_ns: estimate,
        });
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        let Some(every) = self.config.interval else {
            return;
        };
        if now < self.next {
            return;
        }
        let ts1 = self.time_ns(now);
        if self.sent.len() == REMEMBERED {
            self.sent.pop_front();
        }
        self.sent.push_back(ts1);
        self.out.push_back(Outgoing {
            target: Address::BROADCAST,
            message: MavMessage::Timesync(TimesyncMsg { tc1: 0, ts1 }),
        });
        self.next = now + every;
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.config.interval.map(|_| self.next)
    }
}
