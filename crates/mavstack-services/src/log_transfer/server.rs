//! The server role: [`LogServer`] lists and streams the logs of a [`LogStore`].

use alloc::collections::VecDeque;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{LogData, LogEntry, MavMessage};

use super::{CHUNK, LogInfo, LogStore};
use crate::{Address, Outgoing, Service};

/// [`LogServer`] settings: how fast it may send.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServerConfig {
    /// Messages (LOG_DATA or LOG_ENTRY) sent per tick at most (0 counts as 1).
    pub per_tick: u16,
    /// How long a tick lasts: at most `per_tick` messages go out in any tick, so a stream
    /// runs at up to `per_tick × 90` bytes per `tick`.
    pub tick: Duration,
}

impl Default for ServerConfig {
    /// 20 messages every 10 ms: up to 2,000 LOG_DATA (180 kB) a second, a few MAVProxy
    /// (a Python program) keeps up with on a loopback link; ArduPilot SITL sends 40 per
    /// loop, a flight controller on a radio 1.
    fn default() -> Self {
        Self {
            per_tick: 20,
            tick: Duration::from_millis(10),
        }
    }
}

/// What a [`LogServer`] did, for a log or a user interface.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LogServerEvent {
    /// A LOG_REQUEST_LIST is being answered with `entries` LOG_ENTRY.
    Listing {
        /// Who asked.
        to: Address,
        /// Entries to send.
        entries: u16,
    },
    /// A LOG_REQUEST_DATA is being answered.
    Sending {
        /// Who asked.
        to: Address,
        /// The log.
        id: u16,
        /// From this offset.
        ofs: u32,
        /// Bytes to send (to the end of the range asked or of the log).
        bytes: u32,
    },
    /// A LOG_REQUEST_DATA for a log there is not: ignored (as ArduPilot does), and what was
    /// being sent stopped.
    NoSuchLog {
        /// Who asked.
        from: Address,
        /// The id asked for.
        id: u16,
    },
    /// LOG_REQUEST_END: sending stopped.
    Ended {
        /// Who asked.
        by: Address,
    },
    /// LOG_ERASE: every log erased.
    Erased {
        /// Who asked.
        by: Address,
    },
}

/// Events kept for [`LogServer::poll_event`] at most (the oldest go first).
const MAX_EVENTS: usize = 64;

#[derive(Debug)]
enum Activity {
    Idle,
    Listing {
        to: Address,
        pending: VecDeque<LogInfo>,
        num_logs: u16,
        last_log_num: u16,
    },
    Sending {
        to: Address,
        id: u16,
        next: u32,
        end: u32,
        /// Nothing to send from `next` (at or beyond the log's end, or count 0): one chunk of
        /// count 0.
        empty: bool,
    },
}

/// A MAVLink log server over a [`LogStore`], sans-IO like every [`Service`].
///
/// - LOG_REQUEST_LIST(start, end) is answered with one LOG_ENTRY per log whose id is in
///   `start..=end` (`num_logs` every log, `last_log_num` the highest id); with no logs at
///   all, one LOG_ENTRY with id and `num_logs` 0.
/// - LOG_REQUEST_DATA(id, ofs, count) is answered with LOG_DATA chunks of 90 bytes (the last
///   one shorter) covering `ofs..ofs + count` cut at the log's end, never a byte outside the
///   log; a request at or beyond the end (or for 0 bytes) gets one chunk of count 0; a log
///   id there is not gets nothing.
/// - Only one thing is done at a time: a new request (from anyone) replaces the one being
///   answered, LOG_REQUEST_END stops it, LOG_ERASE erases the store and stops it.
/// - Messages go out lazily from [`Service::poll_transmit`], at most
///   [`ServerConfig::per_tick`] per [`ServerConfig::tick`]: after that `poll_transmit` says
///   `None` until [`Service::handle_timeout`] at [`Service::poll_timeout`] opens the next
///   tick. Memory stays bounded whatever the log's size.
/// - Requests whose target is not this server (its system and component, or 0) are
///   ignored. Answers are addressed to the requester ([`Outgoing::target`]).
#[derive(Debug)]
pub struct LogServer<S: LogStore> {
    me: Address,
    config: ServerConfig,
    store: S,
    activity: Activity,
    /// Messages still allowed in the current tick, and when it ends.
    budget: u16,
    tick_end: Option<Instant>,
    events: VecDeque<LogServerEvent>,
}

fn u16_of(n: usize) -> u16 {
    u16::try_from(n).unwrap_or(u16::MAX)
}

impl<S: LogStore> LogServer<S> {
    /// A server answering as `me` with the logs of `store`.
    #[must_use]
    pub const fn new(me: Address, config: ServerConfig, store: S) -> Self {
        Self {
            me,
            config,
            store,
            activity: Activity::Idle,
            budget: 0,
            tick_end: None,
            events: VecDeque::new(),
        }
    }

    /// The store.
    #[must_use]
    pub const fn store(&self) -> &S {
        &self.store
    }

    /// The store, mutably (logs added or removed take effect at the next request).
    pub const fn store_mut(&mut self) -> &mut S {
        &mut self.store
    }

    /// Whether it is listing or sending.
    #[must_use]
    pub const fn is_busy(&self) -> bool {
        !matches!(self.activity, Activity::Idle)
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<LogServerEvent> {
        self.events.pop_front()
    }

    fn event(&mut self, event: LogServerEvent) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events.push_back(event);
    }

    /// Opens a new tick if the last one is over.
    fn refill(&mut self, now: Instant) {
        if self.tick_end.is_none_or(|end| now >= end) {
            self.budget = self.config.per_tick.max(1);
            self.tick_end = Some(now + self.config.tick);
        }
    }

    fn list(&mut self, from: Address, start: u16, end: u16) {
        let logs = self.store.logs();
        let (pending, num_logs, last_log_num) = if logs.is_empty() {
            // "No logs": one entry with id 0 and num_logs 0.
            (VecDeque::from([LogInfo::default()]), 0, 0)
        } else {
            let last = logs.iter().map(|l| l.id).max().unwrap_or(0);
            let wanted: VecDeque<LogInfo> = logs
                .iter()
                .filter(|l| (start..=end).contains(&l.id))
                .copied()
                .collect();
            (wanted, u16_of(logs.len()), last)
        };
        self.event(LogServerEvent::Listing {
            to: from,
            entries: u16_of(pending.len()),
        });
        self.activity = if pending.is_empty() {
            Activity::Idle
        } else {
            Activity::Listing {
                to: from,
                pending,
                num_logs,
                last_log_num,
            }
        };
    }

    fn data(&mut self, from: Address, id: u16, ofs: u32, count: u32) {
        let Some(log) = self.store.logs().into_iter().find(|l| l.id == id) else {
            self.activity = Activity::Idle;
            self.event(LogServerEvent::NoSuchLog { from, id });
            return;
        };
        let end = ofs.saturating_add(count).min(log.size);
        // At or beyond the end (or nothing asked for): one chunk of count 0, as ArduPilot.
        let empty = ofs >= end;
        self.event(LogServerEvent::Sending {
            to: from,
            id,
            ofs,
            bytes: end.saturating_sub(ofs),
        });
        self.activity = Activity::Sending {
            to: from,
            id,
            next: ofs,
            end,
            empty,
        };
    }

    /// The next message of the activity under way (no budget check).
    fn next_message(&mut self) -> Option<Outgoing> {
        match &mut self.activity {
            Activity::Idle => None,
            Activity::Listing {
                to,
                pending,
                num_logs,
                last_log_num,
            } => {
                let to = *to;
                let info = pending.pop_front()?;
                let entry = LogEntry {
                    id: info.id,
                    num_logs: *num_logs,
                    last_log_num: *last_log_num,
                    time_utc: info.time_utc,
                    size: info.size,
                };
                if pending.is_empty() {
                    self.activity = Activity::Idle;
                }
                Some(Outgoing {
                    target: to,
                    message: MavMessage::LogEntry(entry),
                })
            }
            Activity::Sending {
                to,
                id,
                next,
                end,
                empty,
            } => {
                let (to, id, ofs) = (*to, *id, *next);
                let mut chunk = LogData {
                    id,
                    ofs,
                    ..LogData::default()
                };
                let done = if *empty {
                    true
                } else {
                    let want = usize::try_from(end.saturating_sub(ofs))
                        .unwrap_or(CHUNK)
                        .min(CHUNK);
                    let n = match self.store.read(id, ofs, &mut chunk.data[..want]) {
                        Ok(n) => n.min(want),
                        // An unreadable log ends here, as ArduPilot ends one: count 0.
                        Err(_) => 0,
                    };
                    // What the store did not fill stays zero.
                    chunk.data[n..].fill(0);
                    chunk.count = u8::try_from(n).unwrap_or(0);
                    let n32 = u32::try_from(n).unwrap_or(0);
                    *next = ofs.saturating_add(n32);
                    n < want || *next >= *end
                };
                if done {
                    self.activity = Activity::Idle;
                }
                Some(Outgoing {
                    target: to,
                    message: MavMessage::LogData(chunk),
                })
            }
        }
    }
}

impl<S: LogStore> Service for LogServer<S> {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let target = match message {
            MavMessage::LogRequestList(m) => (m.target_system, m.target_component),
            MavMessage::LogRequestData(m) => (m.target_system, m.target_component),
            MavMessage::LogRequestEnd(m) => (m.target_system, m.target_component),
            MavMessage::LogErase(m) => (m.target_system, m.target_component),
            _ => return false,
        };
        if !self.me.is_reached_by(Address::new(target.0, target.1)) {
            return false;
        }
        self.refill(now);
        match message {
            MavMessage::LogRequestList(m) => self.list(from, m.start, m.end),
            MavMessage::LogRequestData(m) => self.data(from, m.id, m.ofs, m.count),
            MavMessage::LogRequestEnd(_) => {
                self.activity = Activity::Idle;
                self.event(LogServerEvent::Ended { by: from });
            }
            MavMessage::LogErase(_) => {
                self.activity = Activity::Idle;
                self.store.erase();
                self.event(LogServerEvent::Erased { by: from });
            }
            _ => {}
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.refill(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        if self.budget == 0 {
            return None;
        }
        let out = self.next_message()?;
        self.budget -= 1;
        Some(out)
    }

    fn poll_timeout(&self) -> Option<Instant> {
        if self.is_busy() { self.tick_end } else { None }
    }
}
