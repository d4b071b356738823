//! The extended parameter protocol (PARAM_EXT_*), which cameras use for their settings: a
//! client ([`ParamExtClient`]: list, read, set) and a server ([`ParamExtServer`]: a table
//! of settings checked against a camera definition).
//!
//! ```text
//!  client                                      camera
//!  PARAM_EXT_REQUEST_LIST ───────────────────► PARAM_EXT_VALUE (index 0..count) × count
//!  PARAM_EXT_REQUEST_READ (name, or index) ──► PARAM_EXT_VALUE
//!  PARAM_EXT_SET (name, type, value) ────────► PARAM_EXT_ACK (ACCEPTED with the new value,
//!                                              IN_PROGRESS, VALUE_UNSUPPORTED or FAILED
//!                                              with the current one)
//! ```
//!
//! PARAM_EXT_VALUE and PARAM_EXT_ACK carry no target: answers are taken from the camera's
//! address only.

use alloc::collections::VecDeque;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavMessage, ParamAck, ParamExtAck, ParamExtRequestList, ParamExtRequestRead, ParamExtSet,
    ParamExtValue,
};

use super::definition::{CameraDefinition, SettingError};
use super::value::{ExtValue, name_field, name_of};
use crate::{Address, Outgoing, Service};

/// Timings of a [`ParamExtClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamExtConfig {
    /// How long to wait for an answer before asking again (default 500 ms).
    pub timeout: Duration,
    /// How many times to ask again (default 5).
    pub retries: u8,
    /// How long a set answered IN_PROGRESS may take (default 5 s).
    pub in_progress_timeout: Duration,
}

impl Default for ParamExtConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            retries: 5,
            in_progress_timeout: Duration::from_secs(5),
        }
    }
}

/// Why a PARAM_EXT_* operation failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ParamExtError {
    /// The camera did not answer, after the retries.
    #[error("no answer from the camera after {attempts} requests")]
    NoAnswer {
        /// How many requests went out.
        attempts: u32,
    },
    /// A list that stayed incomplete after asking for the missing values.
    #[error("{missing} of {count} settings never came")]
    Incomplete {
        /// How many are missing.
        missing: usize,
        /// How many the camera has.
        count: usize,
    },
    /// The camera refused the value.
    #[error("the camera refused {name} = {value}: {result} (it is still {current})")]
    Refused {
        /// The setting.
        name: String,
        /// The value asked for.
        value: String,
        /// PARAM_ACK's name.
        result: &'static str,
        /// The value it kept.
        current: String,
    },
    /// A name that cannot be sent (empty, over 16 bytes).
    #[error("{0:?} is not a setting name (1 to 16 bytes)")]
    BadName(String),
    /// Another operation is running.
    #[error("another PARAM_EXT operation is running")]
    Busy,
}

/// A finished operation of a [`ParamExtClient`].
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum ParamExtEvent {
    /// The whole table, in index order.
    Listed(Result<Vec<(String, ExtValue)>, ParamExtError>),
    /// One setting read.
    Read(Result<(String, ExtValue), ParamExtError>),
    /// A set answered ACCEPTED (with the value the camera took).
    Set(Result<(String, ExtValue), ParamExtError>),
}

#[derive(Clone, Debug)]
enum Op {
    Idle,
    Listing {
        values: Vec<Option<(String, ExtValue)>>,
        count: Option<usize>,
        /// Requests of missing indices left.
        rounds: u8,
    },
    Reading {
        name: String,
    },
    Setting {
        name: String,
        value: ExtValue,
        in_progress: bool,
    },
}

/// The client side of PARAM_EXT_* for one camera: one operation at a time, each ending in
/// a [`ParamExtEvent`]. A [`Service`].
#[derive(Clone, Debug)]
pub struct ParamExtClient {
    target: Address,
    config: ParamExtConfig,
    op: Op,
    /// When to ask again (or give up).
    deadline: Option<Instant>,
    attempts: u32,
    out: VecDeque<Outgoing>,
    events: VecDeque<ParamExtEvent>,
}

impl ParamExtClient {
    /// A client of the camera at `target`.
    #[must_use]
    pub const fn new(target: Address, config: ParamExtConfig) -> Self {
        Self {
            target,
            config,
            op: Op::Idle,
            deadline: None,
            attempts: 0,
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// The next finished operation.
    pub fn poll_event(&mut self) -> Option<ParamExtEvent> {
        self.events.pop_front()
    }

    fn start(&mut self, now: Instant, op: Op) -> Result<(), ParamExtError> {
        if !matches!(self.op, Op::Idle) {
            return Err(ParamExtError::Busy);
        }
        self.op = op;
        self.attempts = 0;
        self.ask(now);
        Ok(())
    }

    /// Asks for every setting (PARAM_EXT_REQUEST_LIST); missing ones are asked for by
    /// index afterwards.
    ///
    /// # Errors
    /// [`ParamExtError::Busy`].
    pub fn list(&mut self, now: Instant) -> Result<(), ParamExtError> {
        self.start(
            now,
            Op::Listing {
                values: Vec::new(),
                count: None,
                rounds: self.config.retries,
            },
        )
    }

    /// Reads setting `name`.
    ///
    /// # Errors
    /// [`ParamExtError::BadName`], [`ParamExtError::Busy`].
    pub fn read(&mut self, now: Instant, name: &str) -> Result<(), ParamExtError> {
        name_field(name).ok_or_else(|| ParamExtError::BadName(name.to_string()))?;
        self.start(
            now,
            Op::Reading {
                name: name.to_string(),
            },
        )
    }

    /// Sets `name` to `value`.
    ///
    /// # Errors
    /// [`ParamExtError::BadName`], [`ParamExtError::Busy`].
    pub fn set(&mut self, now: Instant, name: &str, value: ExtValue) -> Result<(), ParamExtError> {
        name_field(name).ok_or_else(|| ParamExtError::BadName(name.to_string()))?;
        self.start(
            now,
            Op::Setting {
                name: name.to_string(),
                value,
                in_progress: false,
            },
        )
    }

    fn send(&mut self, message: MavMessage) {
        self.out.push_back(Outgoing {
            target: self.target,
            message,
        });
    }

    fn read_request(&self, name: Option<&str>, index: i16) -> MavMessage {
        MavMessage::ParamExtRequestRead(ParamExtRequestRead {
            target_system: self.target.system,
            target_component: self.target.component,
            param_id: name.and_then(name_field).unwrap_or([0; 16]),
            param_index: index,
        })
    }

    /// Sends the current operation's request (again).
    fn ask(&mut self, now: Instant) {
        self.attempts += 1;
        self.deadline = Some(now + self.config.timeout);
        match &self.op {
            Op::Idle => self.deadline = None,
            Op::Listing { values, count, .. } => match count {
                None => {
                    let m = MavMessage::ParamExtRequestList(ParamExtRequestList {
                        target_system: self.target.system,
                        target_component: self.target.component,
                    });
                    self.send(m);
                }
                Some(_) => {
                    let missing: Vec<i16> = values
                        .iter()
                        .enumerate()
                        .filter(|(_, v)| v.is_none())
                        .filter_map(|(i, _)| i16::try_from(i).ok())
                        .collect();
                    for i in missing {
                        let m = self.read_request(None, i);
                        self.send(m);
                    }
                }
            },
            Op::Reading { name } => {
                let m = self.read_request(Some(name), -1);
                self.send(m);
            }
            Op::Setting { name, value, .. } => {
                let m = MavMessage::ParamExtSet(ParamExtSet {
                    target_system: self.target.system,
                    target_component: self.target.component,
                    param_id: name_field(name).unwrap_or([0; 16]),
                    param_value: value.encode(),
                    param_type: value.ty().wire(),
                });
                self.send(m);
            }
        }
    }

    fn finish(&mut self, event: ParamExtEvent) {
        self.op = Op::Idle;
        self.deadline = None;
        self.events.push_back(event);
    }

    fn take_value(&mut self, now: Instant, v: &ParamExtValue) {
        let name = name_of(&v.param_id);
        let Some(value) = ExtValue::decode(v.param_type, &v.param_value) else {
            return;
        };
        match &mut self.op {
            Op::Listing { values, count, .. } => {
                let n = usize::from(v.param_count);
                if count.is_none() || values.len() != n {
                    *count = Some(n);
                    values.resize(n, None);
                }
                if let Some(slot) = values.get_mut(usize::from(v.param_index)) {
                    *slot = Some((name, value));
                }
                if values.iter().all(Option::is_some) {
                    let all = core::mem::take(values).into_iter().flatten().collect();
                    self.finish(ParamExtEvent::Listed(Ok(all)));
                } else {
                    // The stream is still coming: wait for its end before asking.
                    self.deadline = Some(now + self.config.timeout);
                }
            }
            Op::Reading { name: wanted } if *wanted == name => {
                self.finish(ParamExtEvent::Read(Ok((name, value))));
            }
            _ => {}
        }
    }

    fn take_ack(&mut self, now: Instant, ack: &ParamExtAck) {
        let Op::Setting {
            name,
            value,
            in_progress,
        } = &mut self.op
        else {
            return;
        };
        if name_of(&ack.param_id) != *name {
            return;
        }
        let current = ExtValue::decode(ack.param_type, &ack.param_value);
        match ack.param_result {
            ParamAck::ACCEPTED => {
                let taken = current.unwrap_or_else(|| value.clone());
                let name = name.clone();
                self.finish(ParamExtEvent::Set(Ok((name, taken))));
            }
            ParamAck::IN_PROGRESS => {
                *in_progress = true;
                self.deadline = Some(now + self.config.in_progress_timeout);
            }
            result => {
                let error = ParamExtError::Refused {
                    name: name.clone(),
                    value: value.to_string(),
                    result: match result {
                        ParamAck::VALUE_UNSUPPORTED => "VALUE_UNSUPPORTED",
                        ParamAck::FAILED => "FAILED",
                        _ => "UNKNOWN",
                    },
                    current: current.map_or_else(|| "unknown".to_string(), |c| c.to_string()),
                };
                self.finish(ParamExtEvent::Set(Err(error)));
            }
        }
    }
}

impl Service for ParamExtClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if from.system != self.target.system
            || (self.target.component != 0 && from.component != self.target.component)
        {
            return false;
        }
        match message {
            MavMessage::ParamExtValue(v) => self.take_value(now, v),
            MavMessage::ParamExtAck(a) => self.take_ack(now, a),
            _ => return false,
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        let Some(deadline) = self.deadline else {
            return;
        };
        if now < deadline {
            return;
        }
        let attempts = self.attempts;
        let out_of_tries = attempts > u32::from(self.config.retries);
        match &mut self.op {
            Op::Idle => self.deadline = None,
            Op::Listing {
                values,
                count,
                rounds,
            } => {
                if count.is_some() {
                    if *rounds == 0 {
                        let missing = values.iter().filter(|v| v.is_none()).count();
                        let count = values.len();
                        self.finish(ParamExtEvent::Listed(Err(ParamExtError::Incomplete {
                            missing,
                            count,
                        })));
                    } else {
                        *rounds -= 1;
                        self.ask(now);
                    }
                } else if out_of_tries {
                    self.finish(ParamExtEvent::Listed(Err(ParamExtError::NoAnswer {
                        attempts,
                    })));
                } else {
                    self.ask(now);
                }
            }
            Op::Reading { .. } if out_of_tries => {
                self.finish(ParamExtEvent::Read(Err(ParamExtError::NoAnswer {
                    attempts,
                })));
            }
            Op::Setting { .. } if out_of_tries => {
                self.finish(ParamExtEvent::Set(Err(ParamExtError::NoAnswer {
                    attempts,
                })));
            }
            Op::Setting { in_progress, .. } => {
                // After IN_PROGRESS, asking again gets the current state.
                *in_progress = false;
                self.ask(now);
            }
            Op::Reading { .. } => self.ask(now),
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.deadline
    }
}

/// The server side of PARAM_EXT_* for a camera: its settings, as its definition has them
/// (defaults first), each set checked against the definition (its type, its options as the
/// other settings narrow them, its limits, exclusions, read-only). Answers go to the
/// requester. [`poll_changed`](Self::poll_changed) tells the camera's owner what was set.
#[derive(Clone, Debug)]
pub struct ParamExtServer {
    own: Address,
    definition: CameraDefinition,
    values: Vec<(String, ExtValue)>,
    out: VecDeque<Outgoing>,
    changed: VecDeque<(Address, String, ExtValue)>,
}

impl ParamExtServer {
    /// The settings of `definition`, at their defaults, served at `own`.
    #[must_use]
    pub fn new(own: Address, definition: CameraDefinition) -> Self {
        let values = definition
            .settings
            .iter()
            .map(|s| (s.name.clone(), s.default.clone()))
            .collect();
        Self {
            own,
            definition,
            values,
            out: VecDeque::new(),
            changed: VecDeque::new(),
        }
    }

    /// The definition it serves.
    #[must_use]
    pub const fn definition(&self) -> &CameraDefinition {
        &self.definition
    }

    /// A setting's value.
    #[must_use]
    pub fn get(&self, name: &str) -> Option<&ExtValue> {
        self.values.iter().find(|(n, _)| n == name).map(|(_, v)| v)
    }

    /// Every setting, in the definition's order.
    #[must_use]
    pub fn values(&self) -> &[(String, ExtValue)] {
        &self.values
    }

    /// Sets a value as a client would, checked the same way (without telling anyone).
    ///
    /// # Errors
    /// The [`SettingError`] that says why not.
    pub fn set(&mut self, name: &str, value: ExtValue) -> Result<(), SettingError> {
        let values = &self.values;
        let current = |n: &str| values.iter().find(|(k, _)| k == n).map(|(_, v)| v.clone());
        self.definition.check(name, &value, &current)?;
        if let Some(slot) = self.values.iter_mut().find(|(n, _)| n == name) {
            slot.1 = value;
        }
        Ok(())
    }

    /// Every setting back to its default (MAV_CMD_RESET_CAMERA_SETTINGS).
    pub fn reset(&mut self) {
        for (slot, s) in self.values.iter_mut().zip(&self.definition.settings) {
            slot.1 = s.default.clone();
        }
    }

    /// The next setting a client changed: who, which, the new value.
    pub fn poll_changed(&mut self) -> Option<(Address, String, ExtValue)> {
        self.changed.pop_front()
    }

    fn value_message(&self, index: usize) -> Option<MavMessage> {
        let (name, value) = self.values.get(index)?;
        Some(MavMessage::ParamExtValue(ParamExtValue {
            param_id: name_field(name)?,
            param_value: value.encode(),
            param_type: value.ty().wire(),
            param_count: u16::try_from(self.values.len()).unwrap_or(u16::MAX),
            param_index: u16::try_from(index).unwrap_or(u16::MAX),
        }))
    }

    fn answer(&mut self, to: Address, message: MavMessage) {
        self.out.push_back(Outgoing {
            target: to,
            message,
        });
    }

    fn handle_set(&mut self, from: Address, m: &ParamExtSet) {
        let name = name_of(&m.param_id);
        let Some(index) = self.values.iter().position(|(n, _)| *n == name) else {
            let ack = ParamExtAck {
                param_id: m.param_id,
                param_value: m.param_value,
                param_type: m.param_type,
                param_result: ParamAck::FAILED,
            };
            self.answer(from, MavMessage::ParamExtAck(ack));
            return;
        };
        let result = match ExtValue::decode(m.param_type, &m.param_value) {
            Some(value) => match self.set(&name, value.clone()) {
                Ok(()) => {
                    self.changed.push_back((from, name, value));
                    ParamAck::ACCEPTED
                }
                Err(_) => ParamAck::VALUE_UNSUPPORTED,
            },
            None => ParamAck::VALUE_UNSUPPORTED,
        };
        let current = &self.values[index].1;
        let ack = ParamExtAck {
            param_id: m.param_id,
            param_value: current.encode(),
            param_type: current.ty().wire(),
            param_result: result,
        };
        self.answer(from, MavMessage::ParamExtAck(ack));
    }
}

impl Service for ParamExtServer {
    fn handle_message(&mut self, _now: Instant, from: Address, message: &MavMessage) -> bool {
        let target = match message {
            MavMessage::ParamExtRequestList(m) => (m.target_system, m.target_component),
            MavMessage::ParamExtRequestRead(m) => (m.target_system, m.target_component),
            MavMessage::ParamExtSet(m) => (m.target_system, m.target_component),
            _ => return false,
        };
        // Sets and reads name a camera: broadcasts are not for one.
        if target.0 != self.own.system || target.1 != self.own.component {
            return false;
        }
        match message {
            MavMessage::ParamExtRequestList(_) => {
                for i in 0..self.values.len() {
                    if let Some(m) = self.value_message(i) {
                        self.answer(from, m);
                    }
                }
            }
            MavMessage::ParamExtRequestRead(m) => {
                let index = if m.param_index >= 0 {
                    Some(m.param_index as usize)
                } else {
                    let name = name_of(&m.param_id);
                    self.values.iter().position(|(n, _)| *n == name)
                };
                if let Some(msg) = index.and_then(|i| self.value_message(i)) {
                    self.answer(from, msg);
                }
            }
            MavMessage::ParamExtSet(m) => self.handle_set(from, m),
            _ => {}
        }
        true
    }

    fn handle_timeout(&mut self, _now: Instant) {}

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        None
    }
}
