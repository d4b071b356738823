//! The client role: [`LogClient`] lists, downloads and erases one vehicle's logs.

use alloc::collections::{BTreeMap, VecDeque};
use alloc::vec;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    LogData, LogEntry, LogErase, LogRequestData, LogRequestEnd, LogRequestList, MavMessage,
};

use super::{CHUNK, LogInfo};
use crate::ranges::{subtract, total};
use crate::rtt::Rtt;
use crate::{Address, Outgoing, Service};

/// [`LogClient`] settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClientConfig {
    /// The longest wait for an answer: the adaptive timeout's ceiling, and its value until a
    /// round trip is measured.
    pub timeout: Duration,
    /// An operation that brings nothing new for `timeout × attempts` fails: that many sends
    /// of a request before a round trip is measured, more once the timeout has adapted to a
    /// faster link. Also the rounds of LOG_ERASE before [`LogError::NotErased`].
    pub attempts: u8,
    /// The largest log [`LogClient::download`] takes: a larger announced size is refused
    /// before anything is allocated.
    pub max_size: u32,
    /// Bytes asked for per LOG_REQUEST_DATA when a download moves on to new data (gaps are
    /// asked for as they are). 0: the whole rest of the log at once, as MAVProxy asks.
    pub window: u32,
    /// Log entries kept at most (a server listing without end is cut there).
    pub max_entries: usize,
    /// How long after LOG_ERASE the list is asked for again, to check that it is empty.
    pub erase_settle: Duration,
}

impl Default for ClientConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(1),
            attempts: 5,
            max_size: 512 << 20,
            window: 0,
            max_entries: 65_536,
            erase_settle: Duration::from_secs(1),
        }
    }
}

/// What a finished operation produced.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LogOutput {
    /// The vehicle's logs ([`LogClient::list`]), by id.
    Entries(Vec<LogInfo>),
    /// A log's bytes ([`LogClient::download`]): the announced size, or less when the vehicle
    /// ended the log earlier.
    Data(Vec<u8>),
    /// The logs are erased: the list asked for afterwards is empty ([`LogClient::erase`]).
    Erased,
}

/// How an operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LogError {
    /// Nothing new for [`ClientConfig::timeout`] × [`ClientConfig::attempts`].
    #[error("no answer after {attempts} attempts")]
    TimedOut {
        /// Sends of the last request.
        attempts: u8,
    },
    /// Logs were still listed after every LOG_ERASE.
    #[error("{left} logs still listed after erasing")]
    NotErased {
        /// How many.
        left: usize,
    },
    /// [`LogClient::cancel`].
    #[error("cancelled")]
    Cancelled,
}

/// Why an operation could not start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum StartError {
    /// Another operation is under way.
    #[error("another log operation is under way")]
    Busy,
    /// The log is larger than [`ClientConfig::max_size`].
    #[error("log of {size} bytes is larger than allowed")]
    TooLarge {
        /// Its announced size.
        size: u32,
    },
}

/// What [`LogClient::poll_event`] reports.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LogEvent {
    /// Bytes of a download, or entries of a list, received so far, and in all.
    Progress {
        /// So far.
        done: u64,
        /// In all.
        total: u64,
    },
    /// The operation ended.
    Finished(Result<LogOutput, LogError>),
}

#[derive(Debug)]
struct Pending {
    sent: Instant,
    attempt: u8,
    deadline: Instant,
    /// Something of what was asked for came.
    answered: bool,
    /// When the last message of this operation came, and the longest pause between two.
    last: Option<Instant>,
    pause: Duration,
    /// When the last message answering this request came.
    last_answer: Option<Instant>,
}

/// Gaps a received run at most this many chunks long apart are asked for in one request.
const MAX_MERGE_CHUNKS: u64 = 64;

/// `avg` moved an eighth of the way to `sample` (the first sample taken as it is).
fn smooth(avg: Option<Duration>, sample: Duration) -> Duration {
    avg.map_or(sample, |a| (a.saturating_mul(7) + sample) / 8)
}

#[derive(Debug, Default)]
struct List {
    entries: BTreeMap<u16, LogInfo>,
    /// As the last LOG_ENTRY said (0: none yet).
    num_logs: u16,
    /// The highest `last_log_num` heard.
    high: u16,
    /// The range asked for, and the entries held when it was asked.
    asked: (u16, u16),
    held_at_ask: usize,
}

#[derive(Debug)]
struct Download {
    id: u16,
    data: Vec<u8>,
    /// Ranges still wanted, `[start, end)`, sorted and disjoint.
    missing: Vec<(u32, u32)>,
    /// Where the vehicle said the log ends, if before its announced size.
    eof: Option<u32>,
    /// The range asked for last.
    asked: (u32, u32),
    /// The end of the furthest range asked for.
    frontier: u32,
}

#[derive(Debug)]
struct Erase {
    round: u8,
    /// Until when to wait before listing.
    settle: Option<Instant>,
    list: Option<List>,
}

#[derive(Debug)]
enum Op {
    List(List),
    Download(Download),
    Erase(Erase),
}

/// A MAVLink log client for one vehicle, sans-IO like every [`Service`].
///
/// Start one operation ([`list`](Self::list), [`download`](Self::download),
/// [`erase`](Self::erase)), drive it with the [`Service`] calls, and take [`LogEvent`]s from
/// [`poll_event`](Self::poll_event) until [`LogEvent::Finished`]. Every operation ends with
/// LOG_REQUEST_END (the vehicle resumes logging), and so does [`cancel`](Self::cancel).
///
/// - **List**: LOG_REQUEST_LIST(0, 0xFFFF); entries are kept by id until `num_logs` are
///   held. When the stream goes quiet with entries missing, the missing ids (the
///   `num_logs` ids up to `last_log_num`, so both 0- and 1-based numbering) are asked for
///   again, one range at a time.
/// - **Download** of a log whose id and size LOG_ENTRY gave: one LOG_REQUEST_DATA at a
///   time, for the rest of the log (or [`ClientConfig::window`] bytes), chunks kept by
///   offset; when the range asked for has come to its end, or the stream has gone quiet,
///   the first range still missing is asked for, together with the gaps after it that lie
///   closer than the chunks the vehicle sends in a round trip (measured: the first answer's
///   delay over the pause between chunks, at most 64 chunks). A stream that ends early (a
///   short chunk, or count 0, inside the range asked) ends the log there. Only bytes inside
///   the announced size are ever kept, and nothing is allocated beyond it.
/// - **Erase**: LOG_ERASE, then, after [`ClientConfig::erase_settle`], the list: erased when
///   it is empty, LOG_ERASE again otherwise (up to `attempts` rounds).
///
/// "Quiet" is the adaptive retransmission timeout (RFC 6298 estimate from the first answer
/// to each request sent once, doubled for the first two resends, within
/// [`ClientConfig::timeout`]), or twice the longest pause seen between two messages of the
/// stream if that is longer.
#[derive(Debug)]
pub struct LogClient {
    server: Address,
    config: ClientConfig,
    rtt: Rtt,
    op: Option<Op>,
    pending: Option<Pending>,
    /// The operation fails when nothing new has come by then.
    give_up: Option<Instant>,
    /// Smoothed: from a request (sent once) to its first answer, and between two chunks of
    /// a stream. Their ratio is how many chunks a round trip costs.
    first_answer: Option<Duration>,
    chunk_interval: Option<Duration>,
    queue: VecDeque<Outgoing>,
    events: VecDeque<LogEvent>,
}

impl LogClient {
    /// A client of the log server at `server`.
    #[must_use]
    pub fn new(server: Address, config: ClientConfig) -> Self {
        Self {
            server,
            config,
            rtt: Rtt::default(),
            op: None,
            pending: None,
            give_up: None,
            first_answer: None,
            chunk_interval: None,
            queue: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// Whether an operation is under way.
    #[must_use]
    pub const fn is_busy(&self) -> bool {
        self.op.is_some()
    }

    /// The next event, if any.
    pub fn poll_event(&mut self) -> Option<LogEvent> {
        self.events.pop_front()
    }

    /// Lists the vehicle's logs.
    ///
    /// # Errors
    ///
    /// [`StartError::Busy`].
    pub fn list(&mut self, now: Instant) -> Result<(), StartError> {
        if self.op.is_some() {
            return Err(StartError::Busy);
        }
        self.op = Some(Op::List(List::default()));
        self.progressed(now);
        self.send_list(now, (0, u16::MAX), 1);
        Ok(())
    }

    /// Downloads log `id` of `size` bytes (as its LOG_ENTRY said).
    ///
    /// # Errors
    ///
    /// [`StartError::Busy`], [`StartError::TooLarge`] (nothing allocated, nothing sent).
    pub fn download(&mut self, now: Instant, id: u16, size: u32) -> Result<(), StartError> {
        if self.op.is_some() {
            return Err(StartError::Busy);
        }
        if size > self.config.max_size {
            return Err(StartError::TooLarge { size });
        }
        let len = usize::try_from(size).map_err(|_| StartError::TooLarge { size })?;
        self.op = Some(Op::Download(Download {
            id,
            data: vec![0; len],
            missing: if size > 0 {
                vec![(0, size)]
            } else {
                Vec::new()
            },
            eof: None,
            asked: (0, 0),
            frontier: 0,
        }));
        self.progressed(now);
        self.next_data(now, 1);
        Ok(())
    }

    /// Erases every log, and checks that the list is empty afterwards.
    ///
    /// # Errors
    ///
    /// [`StartError::Busy`].
    pub fn erase(&mut self, now: Instant) -> Result<(), StartError> {
        if self.op.is_some() {
            return Err(StartError::Busy);
        }
        self.transmit(MavMessage::LogErase(LogErase {
            target_system: self.server.system,
            target_component: self.server.component,
        }));
        let settle = now + self.config.erase_settle;
        self.op = Some(Op::Erase(Erase {
            round: 1,
            settle: Some(settle),
            list: None,
        }));
        self.give_up = Some(settle + self.stall_limit());
        Ok(())
    }

    /// Abandons the operation under way ([`LogError::Cancelled`]) and sends LOG_REQUEST_END.
    pub fn cancel(&mut self) {
        if self.op.is_some() {
            self.finish(Err(LogError::Cancelled));
        }
    }

    fn stall_limit(&self) -> Duration {
        self.config
            .timeout
            .saturating_mul(u32::from(self.config.attempts.max(1)))
    }

    /// Something new came at `now`: the operation lives on.
    fn progressed(&mut self, now: Instant) {
        self.give_up = Some(now + self.stall_limit());
    }

    fn transmit(&mut self, message: MavMessage) {
        self.queue.push_back(Outgoing {
            target: self.server,
            message,
        });
    }

    /// The wait for an answer to send number `attempt` of a request: the adaptive timeout,
    /// doubled for each resend but at most twice. The losses of a radio link are random,
    /// not congestion: waiting ever longer would only slow the gaps' refill, and the
    /// operation fails on time anyway (`timeout × attempts` without anything new).
    fn wait(&self, attempt: u8) -> Duration {
        self.rtt.backoff(self.config.timeout, attempt.min(3))
    }

    fn arm(&mut self, now: Instant, attempt: u8) {
        self.pending = Some(Pending {
            sent: now,
            attempt,
            deadline: now + self.wait(attempt),
            answered: false,
            last: None,
            pause: Duration::ZERO,
            last_answer: None,
        });
    }

    fn finish(&mut self, result: Result<LogOutput, LogError>) {
        self.op = None;
        self.pending = None;
        self.give_up = None;
        self.transmit(MavMessage::LogRequestEnd(LogRequestEnd {
            target_system: self.server.system,
            target_component: self.server.component,
        }));
        self.events.push_back(LogEvent::Finished(result));
    }

    /// A message of the operation came at `now`: the pending request's deadline moves; the
    /// first answer to a request sent once is a round-trip sample.
    fn heard(&mut self, now: Instant, answers: bool) {
        let wait = self.wait(self.pending.as_ref().map_or(1, |p| p.attempt));
        let Some(p) = self.pending.as_mut() else {
            return;
        };
        if let Some(last) = p.last {
            p.pause = p.pause.max(now.saturating_duration_since(last));
        }
        p.last = Some(now);
        if answers {
            if let Some(prev) = p.last_answer {
                let gap = now.saturating_duration_since(prev);
                self.chunk_interval = Some(smooth(self.chunk_interval, gap));
            }
            p.last_answer = Some(now);
        }
        if answers && !p.answered {
            p.answered = true;
            if p.attempt == 1 {
                self.rtt.sample(p.sent, now);
                let latency = now.saturating_duration_since(p.sent);
                self.first_answer = Some(smooth(self.first_answer, latency));
            }
        }
        let quiet = wait
            .max(p.pause.saturating_mul(2))
            .min(self.config.timeout.saturating_mul(2));
        p.deadline = now + quiet;
    }

    // ----- list ------------------------------------------------------------------------

    fn list_mut(&mut self) -> Option<&mut List> {
        match self.op.as_mut()? {
            Op::List(l) => Some(l),
            Op::Erase(e) => e.list.as_mut(),
            Op::Download(_) => None,
        }
    }

    fn send_list(&mut self, now: Instant, (start, end): (u16, u16), attempt: u8) {
        let Some(list) = self.list_mut() else {
            return;
        };
        list.asked = (start, end);
        list.held_at_ask = list.entries.len();
        let server = self.server;
        self.transmit(MavMessage::LogRequestList(LogRequestList {
            target_system: server.system,
            target_component: server.component,
            start,
            end,
        }));
        self.arm(now, attempt);
    }

    fn on_entry(&mut self, now: Instant, e: &LogEntry) -> bool {
        let max_entries = self.config.max_entries;
        let Some(list) = self.list_mut() else {
            return false;
        };
        let (start, end) = list.asked;
        let answers = (start..=end).contains(&e.id) || e.num_logs == 0;
        if e.num_logs == 0 {
            list.entries.clear();
            list.num_logs = 0;
            self.heard(now, answers);
            self.list_done(now);
            return true;
        }
        list.num_logs = e.num_logs;
        list.high = list.high.max(e.last_log_num);
        let fresh = !list.entries.contains_key(&e.id) && list.entries.len() < max_entries;
        if fresh {
            list.entries.insert(
                e.id,
                LogInfo {
                    id: e.id,
                    time_utc: e.time_utc,
                    size: e.size,
                },
            );
        }
        let (held, total) = (list.entries.len(), usize::from(list.num_logs));
        let complete = held >= total || held >= max_entries;
        // The last one of the range asked for: what is missing can be asked for now.
        let last_asked = e.id >= end.min(list.high);
        self.heard(now, answers);
        if fresh {
            self.progressed(now);
            self.events.push_back(LogEvent::Progress {
                done: held as u64,
                total: total as u64,
            });
        }
        if complete {
            self.list_done(now);
        } else if last_asked && answers {
            self.next_list(now);
        }
        true
    }

    /// The list is complete (or the vehicle has none).
    fn list_done(&mut self, now: Instant) {
        let entries: Vec<LogInfo> = self
            .list_mut()
            .map(|l| l.entries.values().copied().collect())
            .unwrap_or_default();
        match self.op.as_mut() {
            Some(Op::Erase(e)) => {
                if entries.is_empty() {
                    self.finish(Ok(LogOutput::Erased));
                } else if e.round >= self.config.attempts.max(1) {
                    self.finish(Err(LogError::NotErased {
                        left: entries.len(),
                    }));
                } else {
                    e.round += 1;
                    e.list = None;
                    let settle = now + self.config.erase_settle;
                    e.settle = Some(settle);
                    self.pending = None;
                    self.give_up = Some(settle + self.stall_limit());
                    self.transmit(MavMessage::LogErase(LogErase {
                        target_system: self.server.system,
                        target_component: self.server.component,
                    }));
                }
            }
            _ => self.finish(Ok(LogOutput::Entries(entries))),
        }
    }

    /// Asks again for what the list still lacks (after a quiet spell, or its last entry).
    fn next_list(&mut self, now: Instant) {
        let (pending_attempt, answered) = self
            .pending
            .as_ref()
            .map_or((0, false), |p| (p.attempt, p.answered));
        let Some(list) = self.list_mut() else {
            return;
        };
        let whole = (0, u16::MAX);
        // A range that got no answer may hold no log (ids that are not consecutive): the
        // whole list again then.
        let range = if list.asked != whole && !answered {
            whole
        } else {
            missing_ids(list).unwrap_or(whole)
        };
        let attempt = if list.entries.len() > list.held_at_ask {
            1
        } else {
            pending_attempt.saturating_add(1)
        };
        self.send_list(now, range, attempt);
    }

    // ----- download --------------------------------------------------------------------

    /// Asks for the first range still missing, or ends the download when none is.
    fn next_data(&mut self, now: Instant, attempt: u8) {
        let window = match self.config.window {
            0 => u32::MAX,
            w => w.max(CHUNK as u32),
        };
        let merge = self.merge_bytes();
        let Some(Op::Download(d)) = self.op.as_mut() else {
            return;
        };
        let size = u32::try_from(d.data.len()).unwrap_or(u32::MAX);
        let end = d.eof.map_or(size, |e| e.min(size));
        subtract(&mut d.missing, end, u32::MAX);
        let Some(&(a, b)) = d.missing.first() else {
            let mut data = core::mem::take(&mut d.data);
            data.truncate(end as usize);
            self.finish(Ok(LogOutput::Data(data)));
            return;
        };
        let (a, b) = if a < d.frontier {
            // A gap, with the gaps after it that are closer than a round trip's worth of
            // chunks: sending those again costs less than asking for each.
            let mut b = b.min(d.frontier);
            for &(c, e) in &d.missing[1..] {
                if c >= d.frontier || c - b > merge {
                    break;
                }
                b = e.min(d.frontier);
            }
            (a, b)
        } else {
            let b = b.min(a.saturating_add(window));
            d.frontier = b;
            (a, b)
        };
        d.asked = (a, b);
        let id = d.id;
        let server = self.server;
        self.transmit(MavMessage::LogRequestData(LogRequestData {
            target_system: server.system,
            target_component: server.component,
            id,
            ofs: a,
            count: b - a,
        }));
        self.arm(now, attempt);
    }

    /// How many bytes a received run between two gaps may span for both to be asked for in
    /// one request: the chunks the vehicle sends in the time a request takes to be
    /// answered (0 until both are measured; at most [`MAX_MERGE_CHUNKS`]).
    fn merge_bytes(&self) -> u32 {
        let (Some(latency), Some(interval)) = (self.first_answer, self.chunk_interval) else {
            return 0;
        };
        let chunks = if interval.is_zero() {
            MAX_MERGE_CHUNKS
        } else {
            u64::try_from(latency.as_nanos() / interval.as_nanos())
                .unwrap_or(MAX_MERGE_CHUNKS)
                .min(MAX_MERGE_CHUNKS)
        };
        u32::try_from(chunks * CHUNK as u64).unwrap_or(u32::MAX)
    }

    fn on_data(&mut self, now: Instant, m: &LogData) -> bool {
        let Some(Op::Download(d)) = self.op.as_mut() else {
            return false;
        };
        let n = usize::from(m.count);
        if m.id != d.id || n > CHUNK {
            return false;
        }
        let size = d.data.len() as u64;
        let ofs = u64::from(m.ofs);
        let end = ofs + n as u64;
        // Only what lies inside the announced size is kept.
        let (s, e) = (ofs.min(size), end.min(size));
        let before = total(&d.missing);
        if s < e {
            let (su, eu) = (s as usize, e as usize);
            d.data[su..eu].copy_from_slice(&m.data[..eu - su]);
            subtract(&mut d.missing, s as u32, e as u32);
        }
        let now_left = total(&d.missing);
        let (a, b) = (u64::from(d.asked.0), u64::from(d.asked.1));
        let answers = (a <= ofs && ofs < b) || (n == 0 && ofs == a);
        // A short chunk (or none) before the end of what was asked: the log ends there.
        let ends_early = answers && n < CHUNK && end < b;
        let range_done = answers && end >= b;
        if ends_early {
            let at = u32::try_from(end).unwrap_or(u32::MAX);
            d.eof = Some(d.eof.map_or(at, |e| e.min(at)));
        }
        let all_here = d.missing.is_empty();
        self.heard(now, answers);
        if now_left < before {
            self.progressed(now);
            self.events.push_back(LogEvent::Progress {
                done: size - now_left,
                total: size,
            });
        }
        if ends_early || range_done || all_here {
            self.next_data(now, 1);
        }
        true
    }
}

/// The first run of ids the list still lacks, if the ids can be told: the `num_logs` ids
/// up to the highest (`last_log_num`).
fn missing_ids(list: &List) -> Option<(u16, u16)> {
    let count = list.num_logs;
    if count == 0 || list.high.checked_add(1)? < count {
        return None;
    }
    let low = list.high + 1 - count;
    let start = (low..=list.high).find(|id| !list.entries.contains_key(id))?;
    let end = (start..=list.high)
        .take_while(|id| !list.entries.contains_key(id))
        .last()
        .unwrap_or(start);
    Some((start, end))
}

impl Service for LogClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if !from.is_reached_by(self.server) {
            return false;
        }
        match message {
            MavMessage::LogEntry(e) => self.on_entry(now, e),
            MavMessage::LogData(m) => self.on_data(now, m),
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        if self.op.is_none() {
            return;
        }
        if self.give_up.is_some_and(|t| now >= t) {
            let attempts = self.pending.as_ref().map_or(0, |p| p.attempt);
            self.finish(Err(LogError::TimedOut { attempts }));
            return;
        }
        if let Some(Op::Erase(e)) = self.op.as_mut()
            && e.settle.is_some_and(|t| now >= t)
        {
            e.settle = None;
            e.list = Some(List::default());
            self.progressed(now);
            self.send_list(now, (0, u16::MAX), 1);
            return;
        }
        let Some(p) = self.pending.as_ref() else {
            return;
        };
        if now < p.deadline {
            return;
        }
        let (answered, attempt) = (p.answered, p.attempt);
        match self.op {
            Some(Op::Download(_)) => {
                if answered {
                    // The stream went quiet: ask for what is still missing.
                    self.next_data(now, 1);
                } else {
                    self.next_data(now, attempt.saturating_add(1));
                }
            }
            Some(Op::List(_) | Op::Erase(_)) => self.next_list(now),
            None => {}
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.queue.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let settle = match &self.op {
            Some(Op::Erase(e)) => e.settle,
            _ => None,
        };
        [
            self.pending.as_ref().map(|p| p.deadline),
            self.give_up,
            settle,
        ]
        .into_iter()
        .flatten()
        .min()
    }
}
