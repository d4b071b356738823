//! The parameter protocol, in both roles.
//!
//! **Client** ([`ParamClient`]):
//! - [`ParamClient::fetch_all`] sends PARAM_REQUEST_LIST and collects the PARAM_VALUE
//!   stream. An inactivity timer restarts with every value; when it expires the missing
//!   indices are re-requested with PARAM_REQUEST_READ by index, a batch at a time, until the
//!   set is complete ([`ParamEvent::List`]). When a fast stream that went to the end of the
//!   table lost many values, the whole list is asked for again instead, as long as another
//!   pass (the table's streaming time, measured) should bring its share of the gaps sooner
//!   than the requests by index would (their round trip and the loss the pass showed). The
//!   phases are types: [`list::AwaitingCount`] → [`list::Collecting`] → [`list::Done`].
//! - [`ParamClient::read`] asks for one value by name or index, [`ParamClient::set`] sends
//!   PARAM_SET and waits for the PARAM_VALUE echo; both resend on timeout, and a set also
//!   resends when the echo carries another value (the target keeps the old value when it
//!   refuses), ending in [`ParamError::Rejected`] if it never changes.
//! - Values travel in a float field in one of two [`Encoding`]s, chosen per target
//!   ([`Encoding::for_autopilot`], [`Encoding::from_capabilities`]).
//!
//! **Server** ([`ParamServer`]): a typed table (name → [`Value`]) with a fixed order, which
//! answers PARAM_REQUEST_LIST with the whole table, PARAM_REQUEST_READ by name or index,
//! and PARAM_SET by storing the value converted to the parameter's own type and
//! broadcasting the value now in force. Unknown names get no answer (the protocol has no
//! NACK); they are reported as [`ParamServerEvent::Unknown`].
//!
//! Timeouts follow MAVSDK (0.5 s, 5 retries, ×4 for the list).

use alloc::collections::{BTreeMap, VecDeque};
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavAutopilot, MavMessage, MavParamType, ParamRequestRead, ParamSet,
};

use crate::{Address, Outgoing, Service, earliest};

pub mod list;
mod value;

use list::{ListFetch, Received};
pub use value::{Encoding, Name, NameError, Value};

/// Retry and timeout settings of a [`ParamClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamConfig {
    /// Time to wait for a PARAM_VALUE after a read, a set or a PARAM_REQUEST_LIST, and the
    /// longest wait between gap re-request rounds (default 0.5 s; a list fetch waits less once it has measured
    /// the round trip: `srtt + 4 × rttvar`, at least 20 ms).
    pub timeout: Duration,
    /// Resends of a read or set, PARAM_REQUEST_LIST resends, and re-request rounds in a
    /// row without a new value before a list fetch gives up (default 5).
    pub retries: u8,
    /// The longest pause of the list stream before its gaps are re-requested (default
    /// 2 s). The fetch waits less on a fast link: 32 of the stream's smoothed gaps between
    /// values or 4 round-trip timeouts, whichever is longer.
    pub list_timeout: Duration,
    /// How many re-requests of missing indices are out at once (default 64; see
    /// [`ParamConfig::for_autopilot`]).
    pub rerequest_batch: usize,
}

impl ParamConfig {
    /// This configuration as a vehicle of `autopilot` takes it: ArduPilot queues
    /// PARAM_REQUEST_READs in a ring of 20 shared by all its links (`GCS_Param.cpp`) and
    /// drops what does not fit, so at most 16 are kept out; every other autopilot, as given.
    #[must_use]
    pub fn for_autopilot(self, autopilot: MavAutopilot) -> Self {
        match autopilot {
            MavAutopilot::ARDUPILOTMEGA => Self {
                rerequest_batch: self.rerequest_batch.min(16),
                ..self
            },
            _ => self,
        }
    }
}

impl Default for ParamConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            retries: 5,
            list_timeout: Duration::from_secs(2),
            rerequest_batch: 64,
        }
    }
}

/// One parameter as reported by PARAM_VALUE.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Param {
    /// Its name.
    pub name: Name,
    /// Its value, decoded.
    pub value: Value,
    /// Its index in the target's table.
    pub index: u16,
    /// How many parameters the target has.
    pub count: u16,
}

/// Names a read or set of a [`ParamClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ParamHandle(u32);

/// Which parameter to read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamRef {
    /// By name (preferred: indices can change on ArduPilot).
    Name(Name),
    /// By index.
    Index(u16),
}

/// Why a parameter request failed.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamError {
    /// No answer after every retry.
    #[error("no answer after {attempts} attempts")]
    TimedOut {
        /// How many times the request was sent.
        attempts: u8,
    },
    /// The target kept echoing another value than the one set.
    #[error("the target keeps the value {value:?}")]
    Rejected {
        /// The value in force.
        value: Value,
    },
    /// The list fetch stopped making progress with values still missing.
    #[error("{missing} of {count} parameters never arrived")]
    ListIncomplete {
        /// How many are missing.
        missing: usize,
        /// How many the target has.
        count: usize,
    },
    /// The value's type cannot be carried by this protocol (64-bit types).
    #[error("a {param_type:?} value cannot be carried by PARAM_SET")]
    UnsupportedType {
        /// The type.
        param_type: MavParamType,
    },
    /// Cancelled with [`ParamClient::cancel`].
    #[error("cancelled")]
    Cancelled,
}

/// Why a request was not started.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamRequestError {
    /// A list fetch from this target is already running.
    #[error("a parameter list fetch from {target} is already running")]
    ListBusy {
        /// The target.
        target: Address,
    },
    /// A set of this parameter on this target is already waiting for its echo.
    #[error("parameter {name} on {target} is already being set")]
    SetBusy {
        /// The target.
        target: Address,
        /// The name.
        name: Name,
    },
}

/// What a [`ParamClient`] reports.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum ParamEvent {
    /// A list fetch ended.
    List {
        /// Whom it was fetched from.
        target: Address,
        /// Every `(name, value)` by index, or why not.
        result: Result<Vec<(Name, Value)>, ParamError>,
    },
    /// A read or set ended.
    Finished {
        /// The request.
        handle: ParamHandle,
        /// The value now in force, or why not.
        result: Result<Param, ParamError>,
    },
    /// A PARAM_VALUE that answered nothing of ours (another client's set, a broadcast).
    Value {
        /// Who sent it.
        from: Address,
        /// The parameter.
        param: Param,
    },
}

#[derive(Debug)]
enum Op {
    Read(ParamRef),
    Set(Name, Value),
}

#[derive(Debug)]
struct Pending {
    handle: ParamHandle,
    target: Address,
    op: Op,
    attempts: u8,
    deadline: Instant,
    /// The last value a set's echo carried, when it differed.
    last_echo: Option<Value>,
}

/// The client side of the parameter protocol.
#[derive(Debug)]
pub struct ParamClient {
    config: ParamConfig,
    default_encoding: Encoding,
    encodings: BTreeMap<Address, Encoding>,
    next_handle: u32,
    lists: Vec<ListFetch>,
    pending: Vec<Pending>,
    out: VecDeque<Outgoing>,
    events: VecDeque<ParamEvent>,
}

impl ParamClient {
    /// A client using `encoding` for targets without one of their own
    /// ([`ParamClient::set_encoding`]).
    #[must_use]
    pub fn new(config: ParamConfig, encoding: Encoding) -> Self {
        Self {
            config,
            default_encoding: encoding,
            encodings: BTreeMap::new(),
            next_handle: 0,
            lists: Vec::new(),
            pending: Vec::new(),
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// Uses `encoding` for values from and to `target` (from its HEARTBEAT's autopilot or
    /// its AUTOPILOT_VERSION capabilities).
    pub fn set_encoding(&mut self, target: Address, encoding: Encoding) {
        self.encodings.insert(target, encoding);
    }

    fn encoding(&self, target: Address) -> Encoding {
        self.encodings
            .iter()
            .find(|(a, _)| a.is_reached_by(target) || target.is_reached_by(**a))
            .map_or(self.default_encoding, |(_, e)| *e)
    }

    /// The state of the list fetch from `target`, if one is running.
    #[must_use]
    pub fn list_state(&self, target: Address) -> Option<&ListFetch> {
        self.lists.iter().find(|l| l.target() == target)
    }

    /// Fetches the whole parameter set of `target`; ends with [`ParamEvent::List`].
    ///
    /// # Errors
    ///
    /// [`ParamRequestError::ListBusy`] if a fetch from `target` is already running.
    pub fn fetch_all(&mut self, now: Instant, target: Address) -> Result<(), ParamRequestError> {
        if self.list_state(target).is_some() {
            return Err(ParamRequestError::ListBusy { target });
        }
        let state = list::AwaitingCount::start(now, target, &self.config, &mut self.out);
        self.lists.push(ListFetch::AwaitingCount(state));
        Ok(())
    }

    /// Reads one parameter of `target`; ends with [`ParamEvent::Finished`].
    pub fn read(&mut self, now: Instant, target: Address, param: ParamRef) -> ParamHandle {
        self.start(now, target, Op::Read(param))
    }

    /// Sets one parameter of `target` and waits for the target to confirm the value; ends
    /// with [`ParamEvent::Finished`].
    ///
    /// # Errors
    ///
    /// [`ParamRequestError::SetBusy`] if a set of `name` on `target` is still waiting.
    pub fn set(
        &mut self,
        now: Instant,
        target: Address,
        name: Name,
        value: Value,
    ) -> Result<ParamHandle, ParamRequestError> {
        if self
            .pending
            .iter()
            .any(|p| p.target == target && matches!(p.op, Op::Set(n, _) if n == name))
        {
            return Err(ParamRequestError::SetBusy { target, name });
        }
        Ok(self.start(now, target, Op::Set(name, value)))
    }

    /// Stops waiting for a read or set (it finishes with [`ParamError::Cancelled`]).
    /// Returns whether it was pending.
    pub fn cancel(&mut self, handle: ParamHandle) -> bool {
        let Some(i) = self.pending.iter().position(|p| p.handle == handle) else {
            return false;
        };
        self.pending.remove(i);
        self.events.push_back(ParamEvent::Finished {
            handle,
            result: Err(ParamError::Cancelled),
        });
        true
    }

    fn start(&mut self, now: Instant, target: Address, op: Op) -> ParamHandle {
        let handle = ParamHandle(self.next_handle);
        self.next_handle = self.next_handle.wrapping_add(1);
        let p = Pending {
            handle,
            target,
            op,
            attempts: 1,
            deadline: now + self.config.timeout,
            last_echo: None,
        };
        self.out.push_back(self.request(&p));
        self.pending.push(p);
        handle
    }

    fn request(&self, p: &Pending) -> Outgoing {
        let (ts, tc) = (p.target.system, p.target.component);
        let message = match p.op {
            Op::Read(ParamRef::Name(name)) => MavMessage::ParamRequestRead(ParamRequestRead {
                target_system: ts,
                target_component: tc,
                param_id: name.to_field(),
                param_index: -1,
            }),
            Op::Read(ParamRef::Index(index)) => MavMessage::ParamRequestRead(ParamRequestRead {
                target_system: ts,
                target_component: tc,
                param_id: [0; 16],
                param_index: i16::try_from(index).unwrap_or(i16::MAX),
            }),
            Op::Set(name, value) => MavMessage::ParamSet(ParamSet {
                target_system: ts,
                target_component: tc,
                param_id: name.to_field(),
                param_value: self.encoding(p.target).encode(value),
                param_type: value.param_type(),
            }),
        };
        Outgoing {
            target: p.target,
            message,
        }
    }

    /// Feeds one PARAM_VALUE from `from`. Returns whether it was decodable.
    pub fn handle_value(
        &mut self,
        now: Instant,
        from: Address,
        msg: &mavstack_dialects::common::ParamValue,
    ) -> bool {
        let Some(value) = self.encoding(from).decode(msg.param_value, msg.param_type) else {
            return false;
        };
        let param = Param {
            name: Name::from_field(&msg.param_id),
            value,
            index: msg.param_index,
            count: msg.param_count,
        };
        let mut used = false;
        // List fetches (PX4's hash entry, index 32767, is past the count and ignored).
        if param.index < param.count {
            for slot in &mut self.lists {
                if !from.is_reached_by(slot.target()) {
                    continue;
                }
                used = true;
                let state = core::mem::replace(
                    slot,
                    ListFetch::Done(list::Done {
                        target: from,
                        params: Vec::new(),
                    }),
                );
                *slot = state.on_value(
                    now,
                    Received {
                        name: param.name,
                        value,
                        count: param.count,
                        index: param.index,
                    },
                    &self.config,
                    &mut self.out,
                );
            }
            self.finish_lists();
        }
        // Reads and sets.
        let mut i = 0;
        while i < self.pending.len() {
            let p = &mut self.pending[i];
            let matches = from.is_reached_by(p.target)
                && match p.op {
                    Op::Read(ParamRef::Name(n)) | Op::Set(n, _) => n == param.name,
                    Op::Read(ParamRef::Index(ix)) => ix == param.index,
                };
            if !matches {
                i += 1;
                continue;
            }
            used = true;
            if let Op::Set(_, wanted) = p.op {
                let confirmed = wanted
                    .converted_to(value.param_type())
                    .is_some_and(|w| w.same_as(value));
                if !confirmed {
                    // Resend at once: the target refused, or this was an older value.
                    p.last_echo = Some(value);
                    if p.attempts <= self.config.retries {
                        p.attempts += 1;
                        p.deadline = now + self.config.timeout;
                        let request = self.request(&self.pending[i]);
                        self.out.push_back(request);
                        i += 1;
                    } else {
                        let p = self.pending.remove(i);
                        self.events.push_back(ParamEvent::Finished {
                            handle: p.handle,
                            result: Err(ParamError::Rejected { value }),
                        });
                    }
                    continue;
                }
            }
            let p = self.pending.remove(i);
            self.events.push_back(ParamEvent::Finished {
                handle: p.handle,
                result: Ok(param),
            });
        }
        if !used {
            self.events.push_back(ParamEvent::Value { from, param });
        }
        true
    }

    fn finish_lists(&mut self) {
        let mut i = 0;
        while i < self.lists.len() {
            if matches!(self.lists[i], ListFetch::Done(_)) {
                if let ListFetch::Done(done) = self.lists.remove(i) {
                    self.events.push_back(ParamEvent::List {
                        target: done.target,
                        result: Ok(done.params),
                    });
                }
            } else {
                i += 1;
            }
        }
    }

    /// The next result, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<ParamEvent> {
        self.events.pop_front()
    }
}

impl Service for ParamClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::ParamValue(v) => self.handle_value(now, from, v),
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        let mut lists = core::mem::take(&mut self.lists);
        lists.retain_mut(|slot| {
            let target = slot.target();
            let state = core::mem::replace(
                slot,
                ListFetch::Done(list::Done {
                    target,
                    params: Vec::new(),
                }),
            );
            match state.on_timeout(now, &self.config, &mut self.out) {
                Ok(next) => {
                    *slot = next;
                    true
                }
                Err(e) => {
                    self.events.push_back(ParamEvent::List {
                        target,
                        result: Err(e),
                    });
                    false
                }
            }
        });
        self.lists = lists;
        let mut i = 0;
        while i < self.pending.len() {
            let p = &self.pending[i];
            if now < p.deadline {
                i += 1;
            } else if p.attempts <= self.config.retries {
                let request = self.request(p);
                self.out.push_back(request);
                let p = &mut self.pending[i];
                p.attempts += 1;
                p.deadline = now + self.config.timeout;
                i += 1;
            } else {
                let p = self.pending.remove(i);
                let error = match (p.op, p.last_echo) {
                    (Op::Set(..), Some(value)) => ParamError::Rejected { value },
                    _ => ParamError::TimedOut {
                        attempts: p.attempts,
                    },
                };
                self.events.push_back(ParamEvent::Finished {
                    handle: p.handle,
                    result: Err(error),
                });
            }
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let lists = self.lists.iter().filter_map(ListFetch::deadline).min();
        let pending = self.pending.iter().map(|p| p.deadline).min();
        earliest(lists, pending)
    }
}

/// Why a table operation of a [`ParamServer`] failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TableError {
    /// No parameter has this name.
    #[error("no parameter named {name}")]
    Unknown {
        /// The name.
        name: Name,
    },
    /// The table already holds 65,535 parameters, all PARAM_VALUE can index.
    #[error("the parameter table is full")]
    Full,
}

/// What a [`ParamServer`] reports.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum ParamServerEvent {
    /// A PARAM_SET changed a value (already converted to the parameter's type).
    Changed {
        /// Who set it.
        from: Address,
        /// The name.
        name: Name,
        /// The value now in force.
        value: Value,
    },
    /// A read or set named a parameter the table does not have; nothing was answered.
    Unknown {
        /// Who asked.
        from: Address,
        /// The name, or `None` for an index out of range.
        name: Option<Name>,
    },
}

/// The server side of the parameter protocol: a typed table, in insertion order.
#[derive(Debug)]
pub struct ParamServer {
    own: Address,
    encoding: Encoding,
    table: Vec<(Name, Value)>,
    index: BTreeMap<Name, u16>,
    out: VecDeque<Outgoing>,
    events: VecDeque<ParamServerEvent>,
}

impl ParamServer {
    /// An empty table served as `own`, sending values in `encoding`.
    #[must_use]
    pub fn new(own: Address, encoding: Encoding) -> Self {
        Self {
            own,
            encoding,
            table: Vec::new(),
            index: BTreeMap::new(),
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// Adds a parameter (or replaces one's value and type), returning its index.
    ///
    /// # Errors
    ///
    /// [`TableError::Full`] past 65,535 parameters.
    pub fn insert(&mut self, name: Name, value: Value) -> Result<u16, TableError> {
        if let Some(&i) = self.index.get(&name) {
            self.table[usize::from(i)].1 = value;
            return Ok(i);
        }
        let i = u16::try_from(self.table.len())
            .ok()
            .filter(|&i| i < u16::MAX)
            .ok_or(TableError::Full)?;
        self.table.push((name, value));
        self.index.insert(name, i);
        Ok(i)
    }

    /// A parameter's value.
    #[must_use]
    pub fn get(&self, name: Name) -> Option<Value> {
        self.index.get(&name).map(|&i| self.table[usize::from(i)].1)
    }

    /// The table in index order.
    pub fn iter(&self) -> impl Iterator<Item = &(Name, Value)> {
        self.table.iter()
    }

    /// How many parameters the table holds.
    #[must_use]
    pub fn len(&self) -> usize {
        self.table.len()
    }

    /// Whether the table is empty (the server then ignores list requests).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }

    /// Sets a value locally (converted to the parameter's type) and broadcasts it, as a
    /// vehicle does when a value changes on board. Returns the value now in force.
    ///
    /// # Errors
    ///
    /// [`TableError::Unknown`] for a name not in the table.
    pub fn set(&mut self, name: Name, value: Value) -> Result<Value, TableError> {
        let (i, v) = self.store(name, value)?;
        self.send_value(Address::BROADCAST, i);
        Ok(v)
    }

    /// Sets a value locally (converted to the parameter's type) without telling anyone, as
    /// ArduPilot does for the parameters of an uploaded `param.pck`. Returns the value now
    /// in force.
    ///
    /// # Errors
    ///
    /// [`TableError::Unknown`] for a name not in the table.
    pub fn set_quietly(&mut self, name: Name, value: Value) -> Result<Value, TableError> {
        self.store(name, value).map(|(_, v)| v)
    }

    fn store(&mut self, name: Name, value: Value) -> Result<(u16, Value), TableError> {
        let &i = self.index.get(&name).ok_or(TableError::Unknown { name })?;
        let slot = &mut self.table[usize::from(i)];
        if let Some(v) = value.converted_to(slot.1.param_type()) {
            slot.1 = v;
        }
        Ok((i, slot.1))
    }

    fn count(&self) -> u16 {
        u16::try_from(self.table.len()).unwrap_or(u16::MAX)
    }

    fn send_value(&mut self, target: Address, i: u16) {
        let Some(&(name, value)) = self.table.get(usize::from(i)) else {
            return;
        };
        self.out.push_back(Outgoing {
            target,
            message: MavMessage::ParamValue(mavstack_dialects::common::ParamValue {
                param_id: name.to_field(),
                param_value: self.encoding.encode(value),
                param_type: value.param_type(),
                param_count: self.count(),
                param_index: i,
            }),
        });
    }

    fn lookup(&mut self, from: Address, field: &[u8; 16]) -> Option<u16> {
        let name = Name::from_field(field);
        let found = self.index.get(&name).copied();
        if found.is_none() {
            self.events.push_back(ParamServerEvent::Unknown {
                from,
                name: Some(name),
            });
        }
        found
    }

    /// The next event, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<ParamServerEvent> {
        self.events.pop_front()
    }
}

impl Service for ParamServer {
    fn handle_message(&mut self, _now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::ParamRequestList(m)
                if self
                    .own
                    .is_reached_by(Address::new(m.target_system, m.target_component)) =>
            {
                // A component without parameters stays silent.
                for i in 0..self.count() {
                    self.send_value(from, i);
                }
                true
            }
            MavMessage::ParamRequestRead(m)
                if self
                    .own
                    .is_reached_by(Address::new(m.target_system, m.target_component)) =>
            {
                let i = if m.param_index >= 0 {
                    let i = m.param_index.unsigned_abs();
                    if usize::from(i) >= self.table.len() {
                        self.events
                            .push_back(ParamServerEvent::Unknown { from, name: None });
                        return true;
                    }
                    Some(i)
                } else {
                    self.lookup(from, &m.param_id)
                };
                if let Some(i) = i {
                    self.send_value(from, i);
                }
                true
            }
            MavMessage::ParamSet(m)
                if self
                    .own
                    .is_reached_by(Address::new(m.target_system, m.target_component)) =>
            {
                let Some(i) = self.lookup(from, &m.param_id) else {
                    return true;
                };
                let (name, old) = self.table[usize::from(i)];
                // Decode with the type the sender says, falling back to ours; then keep
                // our type.
                let value = self
                    .encoding
                    .decode(m.param_value, m.param_type)
                    .or_else(|| self.encoding.decode(m.param_value, old.param_type()))
                    .and_then(|v| v.converted_to(old.param_type()));
                if let Some(value) = value {
                    self.table[usize::from(i)].1 = value;
                    if !value.same_as(old) {
                        self.events
                            .push_back(ParamServerEvent::Changed { from, name, value });
                    }
                }
                // The value in force, changed or not, to everyone.
                self.send_value(Address::BROADCAST, i);
                true
            }
            _ => false,
        }
    }

    fn handle_timeout(&mut self, _now: Instant) {}

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        None
    }
}
