//! The command protocol: COMMAND_LONG / COMMAND_INT → COMMAND_ACK, in both roles.
//!
//! **Client** ([`CommandClient`]): [`CommandClient::send`] sends a command and starts a
//! timer. Without an ACK it resends the same command ([`CommandConfig::retries`] times,
//! every [`CommandConfig::timeout`]; defaults 3 × 0.5 s as MAVSDK), counting COMMAND_LONG's
//! `confirmation` up from 0. An ACK matches by command id and by its *source* being the
//! command's target (a 0 in the target matches any source); an ACK whose
//! `target_system`/`target_component` extension names someone else is ignored.
//! MAV_RESULT_IN_PROGRESS reports [`CommandEvent::Progress`] and switches to the much longer
//! [`CommandConfig::in_progress_timeout`] (3 s), extended by every further IN_PROGRESS;
//! the final ACK ends the command with [`CommandEvent::Finished`]. Several commands can be
//! in flight at once as long as they differ in target or command id. A final ACK is
//! followed by an *echo* window of half the round trip it ended (from the last send; at most
//! half of [`CommandConfig::timeout`], none after IN_PROGRESS): within it, an ACK from the
//! same source for the same command id answers nothing. A vehicle
//! may acknowledge one command twice (PX4 1.16 sends a second, identical ACK for
//! DO_SET_MODE 4–8 ms after the first; our own server acknowledges each copy that got
//! through), and a command sent again at once gets its own answer a round trip later at the
//! earliest: without the window, on a 200 ms link, the echo of the last DO_SET_MODE answered
//! the next one within 10 ms, whatever the vehicle made of it.
//!
//! **Server** ([`CommandServer`]): answers every command addressed to it (or broadcast) by
//! calling the caller's [`CommandHandler`], and ACKs with the result. Retries and
//! duplicates are recognised and answered with the last ACK instead of running the
//! command again: a retry (the same command — kind, id and parameters — with COMMAND_LONG's
//! `confirmation` above 0, or any COMMAND_INT, which has no counter) from the same source
//! within [`CommandServerConfig::dedup_window`] (3 s, longer than a client's whole retry
//! span); a copy of a first send (`confirmation` 0) only right after it (nothing else from
//! that source in between) and within [`CommandServerConfig::duplicate_window`] (a link
//! duplicating the frame; otherwise it is the request repeated on purpose, and runs
//! again); and any instance of a command still in progress from that source. A handler that answers [`Response::in_progress`] finishes later through
//! [`CommandServer::progress`] and [`CommandServer::finish`].

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::MAX_PAYLOAD_LEN;
use mavstack_core::message::Message;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CommandAck, CommandInt, CommandLong, MavCmd, MavMessage, MavResult,
};

use crate::{Address, Outgoing, Service};

/// A command in either encoding. Its `target_*` fields are filled in by the sender.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// COMMAND_LONG: seven float parameters.
    Long(CommandLong),
    /// COMMAND_INT: positional commands (x/y as integers, with a frame).
    Int(CommandInt),
}

impl Command {
    /// COMMAND_LONG `command` with params 1–7 (its target fields are filled in when sent).
    #[must_use]
    pub fn long(command: MavCmd, p: [f32; 7]) -> Self {
        Self::Long(CommandLong {
            command,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            ..CommandLong::default()
        })
    }

    /// The MAV_CMD.
    #[must_use]
    pub const fn id(&self) -> MavCmd {
        match self {
            Self::Long(c) => c.command,
            Self::Int(c) => c.command,
        }
    }

    /// Whom it is addressed to.
    #[must_use]
    pub const fn target(&self) -> Address {
        match self {
            Self::Long(c) => Address::new(c.target_system, c.target_component),
            Self::Int(c) => Address::new(c.target_system, c.target_component),
        }
    }

    fn set_target(&mut self, target: Address) {
        match self {
            Self::Long(c) => {
                (c.target_system, c.target_component) = (target.system, target.component)
            }
            Self::Int(c) => {
                (c.target_system, c.target_component) = (target.system, target.component)
            }
        }
    }

    /// The command as a message, with COMMAND_LONG's `confirmation` set.
    fn to_message(&self, confirmation: u8) -> MavMessage {
        match self {
            Self::Long(c) => MavMessage::CommandLong(CommandLong { confirmation, ..*c }),
            Self::Int(c) => MavMessage::CommandInt(*c),
        }
    }

    /// Whether two commands are the same request (kind, id, target and every parameter
    /// bit for bit, so NaN equals NaN), `confirmation` aside.
    fn same_request(&self, other: &Self) -> bool {
        let mut a = [0u8; MAX_PAYLOAD_LEN];
        let mut b = [0u8; MAX_PAYLOAD_LEN];
        match (self, other) {
            (Self::Long(x), Self::Long(y)) => {
                let n = CommandLong {
                    confirmation: 0,
                    ..*x
                }
                .encode(&mut a);
                let m = CommandLong {
                    confirmation: 0,
                    ..*y
                }
                .encode(&mut b);
                a[..n] == b[..m]
            }
            (Self::Int(x), Self::Int(y)) => {
                let n = x.encode(&mut a);
                let m = y.encode(&mut b);
                a[..n] == b[..m]
            }
            _ => false,
        }
    }

    fn is_int(&self) -> bool {
        matches!(self, Self::Int(_))
    }
}

/// Retry and timeout settings of a [`CommandClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandConfig {
    /// Time to wait for an ACK before resending (default 0.5 s, MAVSDK's value).
    pub timeout: Duration,
    /// Resends after the first send (default 3, as MAVSDK and QGC).
    pub retries: u8,
    /// Time to wait after an IN_PROGRESS ACK for the next ACK (default 3 s, MAVSDK's value).
    pub in_progress_timeout: Duration,
}

impl Default for CommandConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            retries: 3,
            in_progress_timeout: Duration::from_secs(3),
        }
    }
}

/// Names one command sent by a [`CommandClient`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct CommandHandle(u32);

/// Why [`CommandClient::send`] refused a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SendError {
    /// The same command id to the same target is still in flight: its ACKs could not be
    /// told apart.
    #[error("command {command:?} to {target} is already in flight")]
    AlreadyInFlight {
        /// The target.
        target: Address,
        /// The command id.
        command: MavCmd,
    },
}

/// How a command ended without being accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum CommandError {
    /// No ACK at all after every retry.
    #[error("no acknowledgement after {attempts} attempts")]
    TimedOut {
        /// How many times the command was sent.
        attempts: u8,
    },
    /// The target said IN_PROGRESS, then went silent for the in-progress timeout.
    #[error("no final acknowledgement after progress {progress}")]
    InProgressTimedOut {
        /// The last progress reported (0–100, 255 unknown).
        progress: u8,
    },
    /// The target answered with a final result other than ACCEPTED.
    #[error("rejected with result {result:?} (param2 {result_param2})")]
    Rejected {
        /// The MAV_RESULT.
        result: MavResult,
        /// The ACK's `result_param2`.
        result_param2: i32,
    },
    /// Cancelled locally with [`CommandClient::cancel`].
    #[error("cancelled")]
    Cancelled,
}

/// What a [`CommandClient`] reports.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum CommandEvent {
    /// An IN_PROGRESS ACK arrived; the command is still running.
    Progress {
        /// The command.
        handle: CommandHandle,
        /// 0–100, or 255 when unknown.
        progress: u8,
    },
    /// The command ended: accepted (with its final ACK) or not.
    Finished {
        /// The command.
        handle: CommandHandle,
        /// The ACCEPTED ACK, or why not.
        result: Result<CommandAck, CommandError>,
    },
}

#[derive(Debug)]
struct InFlight {
    handle: CommandHandle,
    target: Address,
    command: Command,
    /// Sends so far.
    attempts: u8,
    /// When it was last sent.
    sent_at: Instant,
    deadline: Instant,
    progress: Option<u8>,
}

/// The client side of the command protocol.
#[derive(Debug)]
pub struct CommandClient {
    own: Address,
    config: CommandConfig,
    next_handle: u32,
    in_flight: Vec<InFlight>,
    out: VecDeque<Outgoing>,
    events: VecDeque<CommandEvent>,
    /// The echo windows of the final ACKs received lately (see the module docs).
    echoes: AckEchoes,
}

/// The echo windows of the final ACKs a [`CommandClient`] took (see the module docs), for a
/// caller that runs a client per command to hand from one to the next
/// ([`CommandClient::with_echoes`], [`CommandClient::take_echoes`]): the echo of one
/// command's ACK comes after that client is gone.
#[derive(Clone, Debug, Default)]
pub struct AckEchoes(Vec<Echo>);

/// An ACK from `from` for `command` before `until` is the echo of one already taken.
#[derive(Clone, Copy, Debug)]
struct Echo {
    from: Address,
    command: MavCmd,
    until: Instant,
}

/// The most echo windows kept at once (one per source and command id; the oldest go first).
const MAX_ECHOES: usize = 32;

impl AckEchoes {
    /// Whether an ACK from `from` for `command` at `now` is the echo of one already taken
    /// (windows that have closed are forgotten).
    fn covers(&mut self, now: Instant, from: Address, command: MavCmd) -> bool {
        self.0.retain(|e| now < e.until);
        self.0
            .iter()
            .any(|e| e.from == from && e.command == command)
    }

    /// Opens the window of a final ACK from `from` for `command`, until `until`.
    fn open(&mut self, from: Address, command: MavCmd, until: Instant) {
        if self.0.len() >= MAX_ECHOES {
            self.0.remove(0);
        }
        self.0.push(Echo {
            from,
            command,
            until,
        });
    }
}

impl CommandClient {
    /// A client sending as `own` (its ids recognise ACKs addressed to us).
    #[must_use]
    pub fn new(own: Address, config: CommandConfig) -> Self {
        Self {
            own,
            config,
            next_handle: 0,
            in_flight: Vec::new(),
            out: VecDeque::new(),
            events: VecDeque::new(),
            echoes: AckEchoes::default(),
        }
    }

    /// This client, knowing the echo windows an earlier client took.
    #[must_use]
    pub fn with_echoes(mut self, echoes: AckEchoes) -> Self {
        self.echoes = echoes;
        self
    }

    /// The echo windows of the final ACKs taken so far (this client forgets them).
    pub fn take_echoes(&mut self) -> AckEchoes {
        core::mem::take(&mut self.echoes)
    }

    /// Sends `command` to `target` (its `target_*` fields are overwritten) and starts its
    /// timer. The result comes as a [`CommandEvent::Finished`] with the returned handle.
    ///
    /// # Errors
    ///
    /// [`SendError::AlreadyInFlight`] if the same command id to the same target is still
    /// waiting for its ACK.
    pub fn send(
        &mut self,
        now: Instant,
        target: Address,
        mut command: Command,
    ) -> Result<CommandHandle, SendError> {
        let id = command.id();
        if self
            .in_flight
            .iter()
            .any(|f| f.target == target && f.command.id() == id)
        {
            return Err(SendError::AlreadyInFlight {
                target,
                command: id,
            });
        }
        command.set_target(target);
        let handle = CommandHandle(self.next_handle);
        self.next_handle = self.next_handle.wrapping_add(1);
        self.out.push_back(Outgoing {
            target,
            message: command.to_message(0),
        });
        self.in_flight.push(InFlight {
            handle,
            target,
            command,
            attempts: 1,
            sent_at: now,
            deadline: now + self.config.timeout,
            progress: None,
        });
        Ok(handle)
    }

    /// Stops waiting for a command (it finishes with [`CommandError::Cancelled`]). Returns
    /// whether it was in flight. The target is not told.
    pub fn cancel(&mut self, handle: CommandHandle) -> bool {
        let Some(i) = self.in_flight.iter().position(|f| f.handle == handle) else {
            return false;
        };
        self.in_flight.remove(i);
        self.events.push_back(CommandEvent::Finished {
            handle,
            result: Err(CommandError::Cancelled),
        });
        true
    }

    /// How many commands are waiting for an ACK.
    #[must_use]
    pub fn in_flight(&self) -> usize {
        self.in_flight.len()
    }

    /// Feeds one COMMAND_ACK from `from`. Returns whether it matched a command in flight.
    pub fn handle_ack(&mut self, now: Instant, from: Address, ack: &CommandAck) -> bool {
        if (ack.target_system != 0 && ack.target_system != self.own.system)
            || (ack.target_component != 0 && ack.target_component != self.own.component)
        {
            return false;
        }
        if self.echoes.covers(now, from, ack.command) {
            return false;
        }
        let Some(i) = self
            .in_flight
            .iter()
            .position(|f| f.command.id() == ack.command && from.is_reached_by(f.target))
        else {
            return false;
        };
        if ack.result == MavResult::IN_PROGRESS {
            let f = &mut self.in_flight[i];
            f.progress = Some(ack.progress);
            f.deadline = now + self.config.in_progress_timeout;
            self.events.push_back(CommandEvent::Progress {
                handle: f.handle,
                progress: ack.progress,
            });
            return true;
        }
        let f = self.in_flight.remove(i);
        // After IN_PROGRESS the wait was the command's run, not the link's round trip. The
        // window never outlasts half a resend wait: a command it keeps from its answer is
        // answered again after its resend, past the window.
        if f.progress.is_none() {
            let half_round_trip = now.saturating_duration_since(f.sent_at) / 2;
            let until = now + half_round_trip.min(self.config.timeout / 2);
            self.echoes.open(from, ack.command, until);
        }
        let result = if ack.result == MavResult::ACCEPTED {
            Ok(*ack)
        } else {
            Err(CommandError::Rejected {
                result: ack.result,
                result_param2: ack.result_param2,
            })
        };
        self.events.push_back(CommandEvent::Finished {
            handle: f.handle,
            result,
        });
        true
    }

    /// The next result, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<CommandEvent> {
        self.events.pop_front()
    }
}

impl Service for CommandClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::CommandAck(ack) => self.handle_ack(now, from, ack),
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        let mut i = 0;
        while i < self.in_flight.len() {
            let f = &mut self.in_flight[i];
            if now < f.deadline {
                i += 1;
                continue;
            }
            let error = if let Some(progress) = f.progress {
                CommandError::InProgressTimedOut { progress }
            } else if f.attempts <= self.config.retries {
                // confirmation: 0 on the first send, 1.. on resends.
                self.out.push_back(Outgoing {
                    target: f.target,
                    message: f.command.to_message(f.attempts),
                });
                f.attempts = f.attempts.saturating_add(1);
                f.sent_at = now;
                f.deadline = now + self.config.timeout;
                i += 1;
                continue;
            } else {
                CommandError::TimedOut {
                    attempts: f.attempts,
                }
            };
            let f = self.in_flight.remove(i);
            self.events.push_back(CommandEvent::Finished {
                handle: f.handle,
                result: Err(error),
            });
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.in_flight.iter().map(|f| f.deadline).min()
    }
}

/// One command received by a [`CommandServer`], as its handler sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct Request {
    /// Who sent it.
    pub from: Address,
    /// The command (COMMAND_LONG's `confirmation` as received).
    pub command: Command,
}

/// What a [`CommandHandler`] answers: the ACK's result, progress and `result_param2`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Response {
    /// The MAV_RESULT.
    pub result: MavResult,
    /// Progress 0–100 (255 unknown) for IN_PROGRESS.
    pub progress: u8,
    /// Command-specific extra result.
    pub result_param2: i32,
}

impl Response {
    /// A final result.
    #[must_use]
    pub const fn done(result: MavResult) -> Self {
        Self {
            result,
            progress: 0,
            result_param2: 0,
        }
    }

    /// IN_PROGRESS with `progress` (0–100, 255 unknown): the command keeps running and ends
    /// with [`CommandServer::finish`].
    #[must_use]
    pub const fn in_progress(progress: u8) -> Self {
        Self {
            result: MavResult::IN_PROGRESS,
            progress,
            result_param2: 0,
        }
    }
}

/// Runs commands for a [`CommandServer`].
pub trait CommandHandler {
    /// Runs (or starts) one command and says how it went. Unknown commands should answer
    /// `Response::done(MavResult::UNSUPPORTED)`. Called once per request: retries and
    /// duplicates never reach it.
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response;
}

/// Settings of a [`CommandServer`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandServerConfig {
    /// How long a finished command's ACK is remembered to answer retries of it (default
    /// 3 s, longer than a client's 4 × 0.5 s retry span).
    pub dedup_window: Duration,
    /// How long a COMMAND_LONG sent with `confirmation` 0 counts as a copy of the previous
    /// identical one (default 50 ms): a frame duplicated by the link. Sent again later, it
    /// is a new request and runs again (REQUEST_MESSAGE asked twice gets two answers).
    pub duplicate_window: Duration,
}

impl Default for CommandServerConfig {
    fn default() -> Self {
        Self {
            dedup_window: Duration::from_secs(3),
            duplicate_window: Duration::from_millis(50),
        }
    }
}

/// What a [`CommandServer`] reports.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum CommandServerEvent {
    /// A command was handed to the handler, which answered `response`.
    Executed {
        /// The request.
        request: Request,
        /// The handler's answer.
        response: Response,
    },
    /// A retry or duplicate was answered with the last ACK instead of running again.
    Duplicate {
        /// Who sent it.
        from: Address,
        /// The command id.
        command: MavCmd,
    },
}

#[derive(Debug)]
struct Recent {
    from: Address,
    command: Command,
    ack: CommandAck,
    at: Instant,
}

/// The server side of the command protocol, dispatching to a [`CommandHandler`].
#[derive(Debug)]
pub struct CommandServer<H> {
    own: Address,
    config: CommandServerConfig,
    handler: H,
    recent: Vec<Recent>,
    out: VecDeque<Outgoing>,
    events: VecDeque<CommandServerEvent>,
}

impl<H: CommandHandler> CommandServer<H> {
    /// A server answering commands for `own` (and broadcasts).
    #[must_use]
    pub fn new(own: Address, config: CommandServerConfig, handler: H) -> Self {
        Self {
            own,
            config,
            handler,
            recent: Vec::new(),
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// The handler.
    pub fn handler(&self) -> &H {
        &self.handler
    }

    /// The handler, mutably.
    pub fn handler_mut(&mut self) -> &mut H {
        &mut self.handler
    }

    /// Feeds one command from `from`. Returns whether it was addressed to us.
    pub fn handle_command(&mut self, now: Instant, from: Address, command: &Command) -> bool {
        if !self.own.is_reached_by(command.target()) {
            return false;
        }
        let window = self.config.dedup_window;
        self.recent.retain(|r| {
            r.ack.result == MavResult::IN_PROGRESS || now.saturating_duration_since(r.at) < window
        });
        let id = command.id();
        let first_send = matches!(command, Command::Long(c) if c.confirmation == 0);
        let duplicate_window = self.config.duplicate_window;
        // A copy the link made follows its original directly: nothing else from that
        // source came in between.
        let latest_from = self.recent.iter().rposition(|r| r.from == from);
        if let Some((_, r)) = self.recent.iter().enumerate().find(|&(i, r)| {
            r.from == from
                && r.command.id() == id
                && r.command.is_int() == command.is_int()
                && (r.ack.result == MavResult::IN_PROGRESS
                    || (r.command.same_request(command)
                        && (!first_send
                            || (Some(i) == latest_from
                                && now.saturating_duration_since(r.at) < duplicate_window))))
        }) {
            self.out.push_back(Outgoing {
                target: from,
                message: MavMessage::CommandAck(r.ack),
            });
            self.events
                .push_back(CommandServerEvent::Duplicate { from, command: id });
            return true;
        }
        let request = Request {
            from,
            command: command.clone(),
        };
        let response = self.handler.handle_command(now, &request);
        let ack = CommandAck {
            command: id,
            result: response.result,
            progress: response.progress,
            result_param2: response.result_param2,
            target_system: from.system,
            target_component: from.component,
        };
        self.recent
            .retain(|r| !(r.from == from && r.command.id() == id));
        self.recent.push(Recent {
            from,
            command: command.clone(),
            ack,
            at: now,
        });
        self.out.push_back(Outgoing {
            target: from,
            message: MavMessage::CommandAck(ack),
        });
        self.events
            .push_back(CommandServerEvent::Executed { request, response });
        true
    }

    /// Reports progress (0–100, 255 unknown) of a running command `command` from `from`
    /// with another IN_PROGRESS ACK. Returns whether such a command is running.
    pub fn progress(&mut self, now: Instant, from: Address, command: MavCmd, progress: u8) -> bool {
        self.update(now, from, command, Response::in_progress(progress))
    }

    /// Ends a running command `command` from `from` with its final ACK. Returns whether
    /// such a command was running.
    pub fn finish(
        &mut self,
        now: Instant,
        from: Address,
        command: MavCmd,
        response: Response,
    ) -> bool {
        self.update(now, from, command, response)
    }

    fn update(&mut self, now: Instant, from: Address, command: MavCmd, response: Response) -> bool {
        let Some(r) = self.recent.iter_mut().find(|r| {
            r.from == from && r.command.id() == command && r.ack.result == MavResult::IN_PROGRESS
        }) else {
            return false;
        };
        r.ack.result = response.result;
        r.ack.progress = response.progress;
        r.ack.result_param2 = response.result_param2;
        r.at = now;
        self.out.push_back(Outgoing {
            target: from,
            message: MavMessage::CommandAck(r.ack),
        });
        true
    }

    /// The next event, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<CommandServerEvent> {
        self.events.pop_front()
    }
}

impl<H: CommandHandler> Service for CommandServer<H> {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::CommandLong(c) => self.handle_command(now, from, &Command::Long(*c)),
            MavMessage::CommandInt(c) => self.handle_command(now, from, &Command::Int(*c)),
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        let window = self.config.dedup_window;
        self.recent.retain(|r| {
            r.ack.result == MavResult::IN_PROGRESS || now.saturating_duration_since(r.at) < window
        });
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        // Forgetting old ACKs needs no timer: it happens on the next command.
        None
    }
}
