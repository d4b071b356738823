//! The list fetch as typestate: [`AwaitingCount`] → [`Collecting`] → [`Done`].
//!
//! Each state is consumed by value by `on_value` / `on_timeout`, which return the next
//! state wrapped in [`ListFetch`], so a value that arrives in a state that cannot use it
//! has nowhere to go.

use alloc::collections::{BTreeMap, BTreeSet, VecDeque};
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{MavMessage, ParamRequestList, ParamRequestRead};

use super::{Name, ParamConfig, ParamError, Value};
use crate::rtt::Rtt;
use crate::{Address, Outgoing};

/// The phase of a list fetch.
#[derive(Debug)]
pub enum ListFetch {
    /// PARAM_REQUEST_LIST sent; no PARAM_VALUE yet.
    AwaitingCount(AwaitingCount),
    /// The count is known; values are arriving, gaps are re-requested by index.
    Collecting(Collecting),
    /// Every index has a value.
    Done(Done),
}

/// PARAM_REQUEST_LIST sent; waiting for the first PARAM_VALUE to learn the count.
#[derive(Debug)]
pub struct AwaitingCount {
    target: Address,
    attempts: u8,
    deadline: Instant,
    /// When PARAM_REQUEST_LIST was last sent.
    sent: Instant,
}

/// Values arriving; `missing` holds the indices not seen yet.
#[derive(Debug)]
pub struct Collecting {
    target: Address,
    values: Vec<Option<(Name, Value)>>,
    missing: BTreeSet<u16>,
    deadline: Instant,
    /// Rounds in a row that brought no new value: a round is a timer expiry at least a
    /// re-request's wait, and at least [`ParamConfig::timeout`], after the round before
    /// (re-requests expire one by one).
    fruitless: u8,
    /// Whether anything new arrived since the round began.
    progressed: bool,
    /// When the next round may begin.
    round_end: Instant,
    /// Indices re-requested and not answered yet (at most `rerequest_batch`), with when,
    /// and whether the answer is no round-trip sample: a resent request's (Karn's rule), or
    /// one of an index past the highest received (the stream, in index order, may bring it
    /// at once, and did: such samples brought the wait to its floor on a 200 ms link).
    outstanding: BTreeMap<u16, (Instant, bool)>,
    /// Whether the stream has ended and gaps are being re-requested.
    rerequesting: bool,
    /// The round trip of requests to this target.
    rtt: Rtt,
    /// The last value's arrival (none before the first), and the smoothed gap between
    /// values of the stream (µs; none before the second value: the first has nothing to be
    /// compared to).
    last_value: Option<Instant>,
    gap_us: Option<u64>,
    /// Indices whose re-request was lost once already: their next one counts as resent.
    retried: BTreeSet<u16>,
    /// The highest index received.
    highest: Option<u16>,
    /// The list stream under way: the first or a later one (see [`Pass`]).
    pass: Pass,
    /// PARAM_REQUEST_LISTs sent again after the first stream.
    relists: u8,
}

/// One pass of the list stream: what it brought, to tell the loss of the link.
#[derive(Clone, Copy, Debug, Default)]
struct Pass {
    /// Values missing when it began (the whole table for the first).
    expected: usize,
    /// Of those, how many it brought.
    brought: usize,
    /// The highest index it brought (any value of it, new or not).
    highest: Option<u16>,
}

impl Pass {
    /// A value of the stream at `index`; `new` when it was missing.
    fn saw(&mut self, index: u16, new: bool) {
        self.highest = self.highest.max(Some(index));
        if new {
            self.brought += 1;
        }
    }
}

/// How many times a fetch asks for the whole list again at most (see
/// [`Collecting::relist_pays`]).
const MAX_RELISTS: u8 = 4;

impl Collecting {
    /// How long the stream may pause before its gaps are re-requested: 32 of its usual
    /// gaps (a vehicle sends its table in bursts), only 4 once this pass brought the last
    /// index (the table goes out in index order: nothing more of the stream is on its way;
    /// a value from an earlier pass says nothing of this one), at least
    /// [`Rtt::FLOOR`], at most [`ParamConfig::list_timeout`] (also before a gap is known).
    /// The round trip does not count: the stream's values are spaced by the sender, and a
    /// pause that waited for four round trips cost seconds on a slow link.
    fn stream_wait(&self, config: &ParamConfig) -> Duration {
        let ended = self
            .pass
            .highest
            .is_some_and(|h| usize::from(h) + 1 >= self.values.len());
        let gaps: u64 = if ended { 4 } else { 32 };
        Duration::from_micros(self.gap_us.map_or(u64::MAX, |g| g.saturating_mul(gaps)))
            .max(Rtt::FLOOR)
            .min(config.list_timeout)
    }

    /// Whether asking for the whole list again should bring the missing values sooner than
    /// asking for them one by one, judged when a pass of the stream has ended.
    ///
    /// A pass streams the table in `count × gap` after a round trip and brings the fraction
    /// `p` of the missing values that the last pass brought. One by one, `window` requests
    /// are out at once and each gets through both ways with `p²`, so the values such a pass
    /// would bring take `missing × srtt / (window × p)`. On a fast link that loses a fifth
    /// of its frames (a Wi-Fi or cellular link; 20 % each way and 200 ms in the bench),
    /// ArduPilot's table of 1,354 streams in about a second, while 270 values one by one,
    /// 16 at a time, take four; on a telemetry radio the table takes seconds to stream and
    /// its few gaps go one by one. A stream that stopped well before the end of the table
    /// paused or was cut: it says nothing of the loss, and the gaps go one by one.
    fn relist_pays(&self, config: &ParamConfig) -> bool {
        let count = self.values.len();
        let reached = self.pass.highest.map_or(0, |h| usize::from(h) + 1);
        if self.relists >= MAX_RELISTS || reached + count / 16 < count || self.pass.brought == 0 {
            return false;
        }
        let (Some(gap), Some(srtt)) = (self.gap_us, self.rtt.srtt_us()) else {
            return false;
        };
        let wide = |n: usize| u128::try_from(n).unwrap_or(u128::MAX);
        let pass = u128::from(gap) * wide(count) + u128::from(srtt);
        let one_by_one = wide(self.missing.len()) * u128::from(srtt) * wide(self.pass.expected)
            / (wide(config.rerequest_batch.max(1)) * wide(self.pass.brought));
        pass < one_by_one
    }

    /// Asks for the whole list again: a new pass of the stream begins, whose first value
    /// comes a round trip later (and ArduPilot's second a moment after it, as on the first
    /// pass: the gap is measured anew).
    fn relist(&mut self, now: Instant, config: &ParamConfig, out: &mut VecDeque<Outgoing>) {
        self.relists += 1;
        self.pass = Pass {
            expected: self.missing.len(),
            ..Pass::default()
        };
        self.last_value = None;
        self.gap_us = None;
        request_list(self.target, out);
        self.deadline = now + self.rerequest_wait(config);
    }

    /// How long to wait for the answer to a re-request.
    fn rerequest_wait(&self, config: &ParamConfig) -> Duration {
        self.rtt.timeout(config.timeout)
    }

    /// When the oldest re-request still outstanding is presumed lost: each has its own
    /// wait, so answers to the others (a sliding window) do not hold back the resend of
    /// one the vehicle dropped (ArduPilot drops a request that does not fit its queue).
    fn rerequest_deadline(&self, now: Instant, config: &ParamConfig) -> Instant {
        let oldest = self.outstanding.values().map(|(sent, _)| *sent).min();
        oldest.unwrap_or(now) + self.rerequest_wait(config)
    }
}

/// Every value of the set, by index.
#[derive(Debug)]
pub struct Done {
    /// Whom they came from.
    pub target: Address,
    /// `(name, value)` by index.
    pub params: Vec<(Name, Value)>,
}

fn request_list(target: Address, out: &mut VecDeque<Outgoing>) {
    out.push_back(Outgoing {
        target,
        message: MavMessage::ParamRequestList(ParamRequestList {
            target_system: target.system,
            target_component: target.component,
        }),
    });
}

impl AwaitingCount {
    /// Sends PARAM_REQUEST_LIST to `target`.
    pub(super) fn start(
        now: Instant,
        target: Address,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> Self {
        request_list(target, out);
        // The first value comes a round trip later; a lost request costs this much.
        Self {
            target,
            attempts: 1,
            deadline: now + config.timeout,
            sent: now,
        }
    }

    /// The first value: the count is known, collecting starts.
    fn on_value(
        self,
        now: Instant,
        v: Received,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> ListFetch {
        let count = usize::from(v.count);
        let mut rtt = Rtt::default();
        if self.attempts == 1 {
            rtt.sample(self.sent, now);
        }
        let c = Collecting {
            target: self.target,
            values: alloc::vec![None; count],
            missing: (0..v.count).collect(),
            deadline: now,
            fruitless: 0,
            progressed: false,
            round_end: now,
            outstanding: BTreeMap::new(),
            rerequesting: false,
            rtt,
            last_value: None,
            gap_us: None,
            retried: BTreeSet::new(),
            highest: None,
            pass: Pass {
                expected: count,
                ..Pass::default()
            },
            relists: 0,
        };
        c.on_value(now, v, config, out)
    }

    fn on_timeout(
        mut self,
        now: Instant,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> Result<ListFetch, ParamError> {
        if self.attempts > config.retries {
            return Err(ParamError::TimedOut {
                attempts: self.attempts,
            });
        }
        request_list(self.target, out);
        self.attempts += 1;
        self.deadline = now + config.timeout;
        self.sent = now;
        Ok(ListFetch::AwaitingCount(self))
    }
}

impl Collecting {
    /// How many values are still missing.
    #[must_use]
    pub fn missing(&self) -> usize {
        self.missing.len()
    }

    /// How many values the target has.
    #[must_use]
    pub fn count(&self) -> usize {
        self.values.len()
    }

    fn on_value(
        mut self,
        now: Instant,
        v: Received,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> ListFetch {
        if usize::from(v.count) != self.values.len() {
            // The set changed under us (ArduPilot can add parameters): start over with
            // the new count.
            let again = AwaitingCount {
                target: self.target,
                attempts: 2,
                deadline: now,
                sent: now,
            };
            return again.on_value(now, v, config, out);
        }
        let new = if let Some(slot) = self.values.get_mut(usize::from(v.index))
            && self.missing.remove(&v.index)
        {
            *slot = Some((v.name, v.value));
            self.progressed = true;
            self.highest = self.highest.max(Some(v.index));
            true
        } else {
            false
        };
        if !self.rerequesting {
            self.pass.saw(v.index, new);
        }
        // An answered re-request frees its place for the next gap (a sliding window).
        if let Some((sent, no_sample)) = self.outstanding.remove(&v.index) {
            if !no_sample {
                self.rtt.sample(sent, now);
            }
            self.top_up(now, config, out);
        } else if !self.rerequesting
            && let Some(last) = self.last_value
        {
            let gap =
                u64::try_from(now.saturating_duration_since(last).as_micros()).unwrap_or(u64::MAX);
            self.gap_us = Some(self.gap_us.map_or(gap, |g| (7 * g + gap) / 8));
        }
        self.last_value = Some(now);
        // The stream's inactivity timer restarts with every value; a re-request's runs from
        // when it was sent.
        self.deadline = if self.rerequesting {
            self.rerequest_deadline(now, config)
        } else {
            now + self.stream_wait(config)
        };
        if self.missing.is_empty() {
            let params = self.values.into_iter().flatten().collect();
            return ListFetch::Done(Done {
                target: self.target,
                params,
            });
        }
        ListFetch::Collecting(self)
    }

    fn on_timeout(
        mut self,
        now: Instant,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> Result<ListFetch, ParamError> {
        let wait = self.rerequest_wait(config);
        // A round lasts at least `config.timeout`, whatever the round trip measured: a gap
        // re-requested while the list still streams may be answered by the stream at once,
        // and such samples can bring the wait down to its floor, where a pause of the stream
        // (a relay or radio that delivers in bursts) would use up every round in a moment.
        let round = wait.max(config.timeout);
        if self.progressed {
            self.fruitless = 0;
            self.progressed = false;
            self.round_end = now + round;
        } else if now >= self.round_end {
            self.fruitless += 1;
            self.round_end = now + round;
        }
        if self.fruitless > config.retries {
            return Err(ParamError::ListIncomplete {
                missing: self.missing.len(),
                count: self.values.len(),
            });
        }
        // The stream has ended: the whole list again, or the gaps one by one.
        if !self.rerequesting && self.relist_pays(config) {
            self.relist(now, config, out);
            return Ok(ListFetch::Collecting(self));
        }
        // The re-requests whose wait is over are presumed lost: re-request the gaps, a window
        // at a time, by index (as QGC does).
        let retried = &mut self.retried;
        self.outstanding.retain(|&index, (sent, _)| {
            let lost = *sent + wait <= now;
            if lost {
                retried.insert(index);
            }
            !lost
        });
        self.rerequesting = true;
        self.top_up(now, config, out);
        self.deadline = self.rerequest_deadline(now, config);
        Ok(ListFetch::Collecting(self))
    }

    /// Re-requests missing indices until `rerequest_batch` are outstanding.
    fn top_up(&mut self, now: Instant, config: &ParamConfig, out: &mut VecDeque<Outgoing>) {
        let room = config
            .rerequest_batch
            .max(1)
            .saturating_sub(self.outstanding.len());
        let next: Vec<u16> = self
            .missing
            .iter()
            .filter(|i| !self.outstanding.contains_key(i))
            .take(room)
            .copied()
            .collect();
        for index in next {
            let resent = self.retried.contains(&index);
            let ahead = self.highest.is_none_or(|h| index > h);
            self.outstanding.insert(index, (now, resent || ahead));
            out.push_back(Outgoing {
                target: self.target,
                message: MavMessage::ParamRequestRead(ParamRequestRead {
                    target_system: self.target.system,
                    target_component: self.target.component,
                    param_id: [0; 16],
                    param_index: i16::try_from(index).unwrap_or(i16::MAX),
                }),
            });
        }
    }
}

/// One decoded PARAM_VALUE.
#[derive(Clone, Copy, Debug)]
pub(super) struct Received {
    pub(super) name: Name,
    pub(super) value: Value,
    pub(super) count: u16,
    pub(super) index: u16,
}

impl ListFetch {
    /// Whom the list is fetched from.
    #[must_use]
    pub fn target(&self) -> Address {
        match self {
            Self::AwaitingCount(s) => s.target,
            Self::Collecting(s) => s.target,
            Self::Done(s) => s.target,
        }
    }

    pub(super) fn deadline(&self) -> Option<Instant> {
        match self {
            Self::AwaitingCount(s) => Some(s.deadline),
            Self::Collecting(s) => Some(s.deadline),
            Self::Done(_) => None,
        }
    }

    pub(super) fn on_value(
        self,
        now: Instant,
        v: Received,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> Self {
        match self {
            Self::AwaitingCount(s) => s.on_value(now, v, config, out),
            Self::Collecting(s) => s.on_value(now, v, config, out),
            Self::Done(s) => Self::Done(s),
        }
    }

    pub(super) fn on_timeout(
        self,
        now: Instant,
        config: &ParamConfig,
        out: &mut VecDeque<Outgoing>,
    ) -> Result<Self, ParamError> {
        match self {
            Self::AwaitingCount(s) if now >= s.deadline => s.on_timeout(now, config, out),
            Self::Collecting(s) if now >= s.deadline => s.on_timeout(now, config, out),
            other => Ok(other),
        }
    }
}
