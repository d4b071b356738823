//! The list fetch as typestate: [`AwaitingCount`] → [`Collecting`] → [`Done`].
//!
//! Each state is consumed by value by `on_value` / `on_timeout`, which return the next
//! state wrapped in [`ListFetch`], so a value that arrives in a state that cannot use it
//! has nowhere to go.

use alloc::collections::{BTreeSet, VecDeque};
use alloc::vec::Vec;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{MavMessage, ParamRequestList, ParamRequestRead};

use super::{Name, ParamConfig, ParamError, Value};
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
}

/// Values arriving; `missing` holds the indices not seen yet.
#[derive(Debug)]
pub struct Collecting {
    target: Address,
    values: Vec<Option<(Name, Value)>>,
    missing: BTreeSet<u16>,
    deadline: Instant,
    /// Timer expiries in a row that brought no new value.
    fruitless: u8,
    /// Whether anything new arrived since the last expiry.
    progressed: bool,
    /// Indices re-requested and not answered yet (at most `rerequest_batch`).
    outstanding: BTreeSet<u16>,
    /// Whether the stream has ended and gaps are being re-requested.
    rerequesting: bool,
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
        Self {
            target,
            attempts: 1,
            deadline: now + config.list_timeout,
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
        let c = Collecting {
            target: self.target,
            values: alloc::vec![None; count],
            missing: (0..v.count).collect(),
            deadline: now,
            fruitless: 0,
            progressed: false,
            outstanding: BTreeSet::new(),
            rerequesting: false,
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
        self.deadline = now + config.list_timeout;
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
                attempts: 1,
                deadline: now,
            };
            return again.on_value(now, v, config, out);
        }
        if let Some(slot) = self.values.get_mut(usize::from(v.index))
            && self.missing.remove(&v.index)
        {
            *slot = Some((v.name, v.value));
            self.progressed = true;
        }
        // An answered re-request frees its place for the next gap (a sliding window).
        if self.outstanding.remove(&v.index) {
            self.top_up(config, out);
        }
        // The inactivity timer restarts with every value.
        self.deadline = now
            + if self.rerequesting {
                config.timeout
            } else {
                config.list_timeout
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
        if self.progressed {
            self.fruitless = 0;
        } else {
            self.fruitless += 1;
        }
        self.progressed = false;
        if self.fruitless > config.retries {
            return Err(ParamError::ListIncomplete {
                missing: self.missing.len(),
                count: self.values.len(),
            });
        }
        // Whatever was outstanding is presumed lost: re-request the gaps, a window at a
        // time, by index (as QGC does).
        self.outstanding.clear();
        self.rerequesting = true;
        self.top_up(config, out);
        self.deadline = now + config.timeout;
        Ok(ListFetch::Collecting(self))
    }

    /// Re-requests missing indices until `rerequest_batch` are outstanding.
    fn top_up(&mut self, config: &ParamConfig, out: &mut VecDeque<Outgoing>) {
        let room = config
            .rerequest_batch
            .max(1)
            .saturating_sub(self.outstanding.len());
        let next: Vec<u16> = self
            .missing
            .iter()
            .filter(|i| !self.outstanding.contains(i))
            .take(room)
            .copied()
            .collect();
        for index in next {
            self.outstanding.insert(index);
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
