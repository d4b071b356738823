//! The ground-station side of the MAVLink 2 handshake, as states consumed by value.
//!
//! The ground station asks the target for a message that exists only in MAVLink 2 and sends
//! the request in MAVLink 2 framing. A target that speaks MAVLink 2, over a path that carries
//! it, acknowledges and answers in MAVLink 2; a target without MAVLink 2 refuses with a
//! failure COMMAND_ACK; a path that mangles MAVLink 2 (a non-transparent radio or router)
//! loses the request or the answer, and the ground station times out.
//!
//! ```text
//!            start_handshake
//!                  │  request (v2)                     retry: same request, confirmation+1
//!                  ▼                                   ┌─────────────┐
//!          ┌───────────────┐  deadline, tries left ────┘             │
//!          │ AwaitingAnswer │◄────────────────────────────────────────┘
//!          └───────────────┘
//!       ACK ok │   │ ACK failure ──────────────► Nack        (link stays MAVLink 1)
//!              │   │ answer in v2 ─────────────► ProtocolVersion / Message (link → MAVLink 2)
//!              ▼   │ deadline, no tries left ──► Timeout { acked: false } (→ MAVLink 1)
//!          ┌────────────────┐
//!          │ AwaitingMessage │  deadline, tries left: retry
//!          └────────────────┘
//!              │ answer in v2 ─────────────────► ProtocolVersion / Message (link → MAVLink 2)
//!              │ deadline, no tries left ──────► Timeout { acked: true } (→ MAVLink 1)
//! ```
//!
//! Each state is consumed by the transition that leaves it ([`Handshake`] wraps whichever is
//! current), so an answer that arrives when nothing awaits it has nowhere to go. The channel
//! drives the transitions; callers only start a handshake
//! ([`Channel::start_handshake`](crate::Channel::start_handshake)), read its state
//! ([`Channel::handshake`](crate::Channel::handshake)) and receive its
//! [`HandshakeOutcome`] as an [`Event::Handshake`](crate::Event::Handshake).
//!
//! **The documents' fallback.** A request for PROTOCOL_VERSION (300 or 519) that is refused
//! (a failure COMMAND_ACK) or unanswered is not the end when [`HandshakeConfig::fallback`]
//! names a message (AUTOPILOT_VERSION by default): "if the target system does not support
//! PROTOCOL_VERSION you can request any other message that it is able to emit". The ground
//! station then asks for that message with REQUEST_MESSAGE in a MAVLink 2 frame, and that
//! message arriving in MAVLink 2 framing proves the link both ways
//! ([`HandshakeResult::Message`], with [`HandshakeOutcome::fallback`] saying why it ran).
//! ArduPilot never implemented PROTOCOL_VERSION, the MAVLink guide deprecated it in 2025-12
//! and PX4 removed command 519 in 2026: the handshake must not depend on it. The fallback
//! ends in a NACK when the system refuses it too, or answers in MAVLink 1; a failure ACK in
//! that phase ends it only at the attempt's deadline, since it may be the late answer to an
//! earlier request for 300 (COMMAND_ACK does not say which message was asked for).
//!
//! Matching follows the command protocol: an ACK counts when its `command` is the request's
//! and its source is the target (a target id of 0 matches any source), and when its
//! `target_system` extension, if set, names this system. ACCEPTED and IN_PROGRESS move on to
//! [`AwaitingMessage`]; any other result (including TEMPORARILY_REJECTED) is a NACK. Once
//! accepted, later ACKs (answers to retries) are ignored. The awaited message counts from the
//! target in MAVLink 2 framing, whether or not an ACK came first.

use core::time::Duration;

use mavstack_core::message::Message;
use mavstack_core::time::Instant;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandInt, CommandLong, MavCmd, MavFrame, MavResult,
    ProtocolVersion,
};

use crate::dialect::CommandEncoding;
use crate::frame::OwnedFrame;

/// Which message the ground station asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum HandshakeMethod {
    /// MAV_CMD_REQUEST_MESSAGE (512) with param1 = 300, PROTOCOL_VERSION (the 2025 devguide).
    RequestMessage300,
    /// MAV_CMD_REQUEST_PROTOCOL_VERSION (519) with param1 = 1 (the original scheme,
    /// deprecated in common.xml since 2025-11).
    RequestProtocolVersion,
    /// MAV_CMD_REQUEST_MESSAGE (512) for any message with an id of 256 or more that the
    /// target supports (the current devguide); success is that message arriving.
    RequestMessageOther {
        /// The message id, at least 256.
        msg_id: u32,
    },
}

impl HandshakeMethod {
    /// The name used in reports: `request_message_300`, `request_protocol_version` or
    /// `request_message_other`.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::RequestMessage300 => "request_message_300",
            Self::RequestProtocolVersion => "request_protocol_version",
            Self::RequestMessageOther { .. } => "request_message_other",
        }
    }

    /// The command sent.
    #[must_use]
    pub const fn command(self) -> MavCmd {
        match self {
            Self::RequestProtocolVersion => MavCmd::REQUEST_PROTOCOL_VERSION,
            Self::RequestMessage300 | Self::RequestMessageOther { .. } => MavCmd::REQUEST_MESSAGE,
        }
    }

    /// The message that answers it.
    #[must_use]
    pub const fn awaited_message(self) -> u32 {
        match self {
            Self::RequestMessage300 | Self::RequestProtocolVersion => ProtocolVersion::ID,
            Self::RequestMessageOther { msg_id } => msg_id,
        }
    }

    /// The command's param1: 1 for MAV_CMD_REQUEST_PROTOCOL_VERSION, the message id for
    /// MAV_CMD_REQUEST_MESSAGE (message ids are 24 bits: exact in an f32).
    #[must_use]
    pub const fn param1(self) -> f32 {
        match self {
            Self::RequestProtocolVersion => 1.0,
            Self::RequestMessage300 | Self::RequestMessageOther { .. } => {
                self.awaited_message() as f32
            }
        }
    }
}

/// A system and component to talk to; 0 in either is a wildcard (broadcast).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Target {
    /// Target system id (0: any).
    pub system: u8,
    /// Target component id (0: any).
    pub component: u8,
}

impl Target {
    /// The target `(system, component)`.
    #[must_use]
    pub const fn new(system: u8, component: u8) -> Self {
        Self { system, component }
    }

    /// Whether a frame from `(sysid, compid)` comes from this target.
    #[must_use]
    pub const fn matches(self, sysid: u8, compid: u8) -> bool {
        (self.system == 0 || self.system == sysid)
            && (self.component == 0 || self.component == compid)
    }
}

/// What a handshake asks of whom, and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct HandshakeRequest {
    /// Whom to ask.
    pub target: Target,
    /// Which message to ask for.
    pub method: HandshakeMethod,
    /// COMMAND_LONG or COMMAND_INT.
    pub encoding: CommandEncoding,
}

/// The request as a message, for attempt `attempt` (1 = first).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum RequestMessage {
    Long(CommandLong),
    Int(CommandInt),
}

impl HandshakeRequest {
    /// The command for attempt `attempt` (1 = first): COMMAND_LONG counts retries in its
    /// `confirmation` field (0 first, then 1, 2, ...); COMMAND_INT has no such field.
    pub(crate) fn message(&self, attempt: u8) -> RequestMessage {
        let m = self.method;
        match self.encoding {
            CommandEncoding::Long => RequestMessage::Long(CommandLong {
                target_system: self.target.system,
                target_component: self.target.component,
                command: m.command(),
                confirmation: attempt.saturating_sub(1),
                param1: m.param1(),
                ..CommandLong::default()
            }),
            CommandEncoding::Int => RequestMessage::Int(CommandInt {
                target_system: self.target.system,
                target_component: self.target.component,
                frame: MavFrame::GLOBAL,
                command: m.command(),
                param1: m.param1(),
                ..CommandInt::default()
            }),
        }
    }
}

/// Retries of the handshake request.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct HandshakeConfig {
    /// Resends after the first request (default 3, as QGC and MAVSDK).
    pub retries: u8,
    /// How long to wait for an answer before resending, and after the last send before
    /// giving up (default 500 ms, MAVSDK's command timeout).
    pub interval: Duration,
    /// The message requested, in MAVLink 2, when a request for PROTOCOL_VERSION is refused
    /// or unanswered (default AUTOPILOT_VERSION, which every autopilot emits on request;
    /// `None`: no fallback, the refusal or silence is the outcome).
    pub fallback: Option<u32>,
}

impl Default for HandshakeConfig {
    fn default() -> Self {
        Self {
            retries: 3,
            interval: Duration::from_millis(500),
            fallback: Some(AutopilotVersion::ID),
        }
    }
}

/// Why the handshake fell back to requesting another message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FallbackReason {
    /// The request for PROTOCOL_VERSION was refused with this COMMAND_ACK result (ArduPilot:
    /// FAILED for REQUEST_MESSAGE, UNSUPPORTED for 519).
    Refused(MavResult),
    /// No PROTOCOL_VERSION came after every retry.
    Unanswered {
        /// Whether an ACK ACCEPTED came for it.
        acked: bool,
    },
}

impl FallbackReason {
    /// The result the first phase would have ended with.
    const fn result(self) -> HandshakeResult {
        match self {
            Self::Refused(result) => HandshakeResult::Nack { result },
            Self::Unanswered { acked } => HandshakeResult::Timeout { acked },
        }
    }
}

/// How a handshake ended.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum HandshakeResult {
    /// PROTOCOL_VERSION arrived in MAVLink 2: the link now sends MAVLink 2.
    ProtocolVersion(ProtocolVersion),
    /// The message asked for with [`HandshakeMethod::RequestMessageOther`] (directly, or as
    /// the fallback) arrived in MAVLink 2: the link now sends MAVLink 2.
    Message {
        /// Its id.
        msg_id: u32,
    },
    /// The target refused (COMMAND_ACK with this result): the link stays on MAVLink 1.
    Nack {
        /// The ACK's result, e.g. UNSUPPORTED or DENIED.
        result: MavResult,
    },
    /// No answer after every retry: the link falls back to MAVLink 1.
    Timeout {
        /// Whether an ACK ACCEPTED came (the target speaks MAVLink 2 but its answer never
        /// arrived: the path mangles MAVLink 2).
        acked: bool,
    },
}

impl HandshakeResult {
    /// The name used in reports: `protocol_version`, `message_v2`, `nack` or `timeout`.
    #[must_use]
    pub const fn name(&self) -> &'static str {
        match self {
            Self::ProtocolVersion(_) => "protocol_version",
            Self::Message { .. } => "message_v2",
            Self::Nack { .. } => "nack",
            Self::Timeout { .. } => "timeout",
        }
    }

    /// Whether MAVLink 2 got through.
    #[must_use]
    pub const fn is_success(&self) -> bool {
        matches!(self, Self::ProtocolVersion(_) | Self::Message { .. })
    }
}

/// A finished handshake.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandshakeOutcome {
    /// What was asked last: the fallback's request when it ran.
    pub request: HandshakeRequest,
    /// Why the fallback ran (the request for PROTOCOL_VERSION was refused or unanswered);
    /// `None` when it did not.
    pub fallback: Option<FallbackReason>,
    /// How it ended.
    pub result: HandshakeResult,
    /// Requests sent (1 + retries used), in the last phase.
    pub attempts: u8,
    /// When it started.
    pub started_at: Instant,
    /// When it ended.
    pub finished_at: Instant,
}

/// What every state carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Progress {
    request: HandshakeRequest,
    attempts: u8,
    deadline: Instant,
    started_at: Instant,
    /// Set in the fallback phase: why it runs.
    fallback: Option<FallbackReason>,
    /// In the fallback phase: a failure ACK seen (it ends the phase at the deadline).
    refused: Option<MavResult>,
}

/// Waiting for the first sign of an answer: an ACK or the message itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AwaitingAnswer(Progress);

/// The target accepted the command; waiting for the message in MAVLink 2 framing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AwaitingMessage(Progress);

/// The state of a running handshake.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handshake {
    /// Nothing heard yet.
    AwaitingAnswer(AwaitingAnswer),
    /// Accepted; the message has not arrived yet.
    AwaitingMessage(AwaitingMessage),
}

/// What a transition leads to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Step {
    /// Keep waiting in this state.
    Wait(Handshake),
    /// Send the request again (attempt number inside the state), then wait.
    Resend(Handshake),
    /// Finished.
    Done(HandshakeOutcome),
}

impl Progress {
    /// Ends the handshake with `result`, or, when `result` is the first phase's refusal or
    /// silence and a fallback is configured, starts the fallback phase.
    fn finish(mut self, now: Instant, config: &HandshakeConfig, result: HandshakeResult) -> Step {
        let reason = match result {
            HandshakeResult::Nack { result } => Some(FallbackReason::Refused(result)),
            HandshakeResult::Timeout { acked } => Some(FallbackReason::Unanswered { acked }),
            HandshakeResult::ProtocolVersion(_) | HandshakeResult::Message { .. } => None,
        };
        let asked_for_300 = matches!(
            self.request.method,
            HandshakeMethod::RequestMessage300 | HandshakeMethod::RequestProtocolVersion
        );
        if let (Some(reason), Some(msg_id), None, true) =
            (reason, config.fallback, self.fallback, asked_for_300)
        {
            self.request.method = HandshakeMethod::RequestMessageOther { msg_id };
            self.request.encoding = CommandEncoding::Long;
            self.attempts = 1;
            self.deadline = now + config.interval;
            self.fallback = Some(reason);
            return Step::Resend(self.state(false));
        }
        let result = match (self.fallback, result.is_success()) {
            // The fallback failed too: a refusal in either phase is a NACK.
            (Some(FallbackReason::Refused(first)), false) => HandshakeResult::Nack {
                result: self.refused.unwrap_or(first),
            },
            (Some(FallbackReason::Unanswered { .. }), false) if self.refused.is_some() => {
                HandshakeResult::Nack {
                    result: self.refused.unwrap_or(MavResult::FAILED),
                }
            }
            (Some(first @ FallbackReason::Unanswered { acked }), false) => match result {
                HandshakeResult::Timeout { acked: again } => HandshakeResult::Timeout {
                    acked: acked || again,
                },
                _ => first.result(),
            },
            _ => result,
        };
        Step::Done(HandshakeOutcome {
            request: self.request,
            fallback: self.fallback,
            result,
            attempts: self.attempts,
            started_at: self.started_at,
            finished_at: now,
        })
    }

    /// What `frame` says, if it is the awaited message: its result when it came in MAVLink 2;
    /// in the fallback phase, the message in MAVLink 1 shows the link has no MAVLink 2.
    fn answer(&self, frame: &OwnedFrame) -> Option<Answer> {
        let method = self.request.method;
        if !self.request.target.matches(frame.sysid(), frame.compid()) {
            return None;
        }
        if frame.version() != Version::V2 {
            let fallback_answered_in_v1 = self.fallback.is_some()
                && matches!(method, HandshakeMethod::RequestMessageOther { msg_id } if frame.msg_id() == msg_id);
            return fallback_answered_in_v1.then_some(Answer::Mavlink1);
        }
        match method {
            HandshakeMethod::RequestMessage300 | HandshakeMethod::RequestProtocolVersion => frame
                .decode_as::<ProtocolVersion>()
                .map(|v| Answer::Mavlink2(HandshakeResult::ProtocolVersion(v))),
            HandshakeMethod::RequestMessageOther { msg_id } => (frame.msg_id() == msg_id)
                .then_some(Answer::Mavlink2(HandshakeResult::Message { msg_id })),
        }
    }

    /// The ACK in `frame`, if it answers the request of `own_sysid`.
    fn ack(&self, frame: &OwnedFrame, own_sysid: u8) -> Option<CommandAck> {
        let ack = frame.decode_as::<CommandAck>()?;
        let for_us = ack.target_system == 0 || ack.target_system == own_sysid;
        (ack.command == self.request.method.command()
            && for_us
            && self.request.target.matches(frame.sysid(), frame.compid()))
        .then_some(ack)
    }

    /// Feeds the awaited message (or its MAVLink 1 copy in the fallback phase).
    fn answered(self, now: Instant, config: &HandshakeConfig, answer: Answer) -> Step {
        match answer {
            Answer::Mavlink2(result) => self.finish(now, config, result),
            Answer::Mavlink1 => {
                let refused = self.refused.unwrap_or(match self.fallback {
                    Some(FallbackReason::Refused(first)) => first,
                    _ => MavResult::FAILED,
                });
                self.finish(now, config, HandshakeResult::Nack { result: refused })
            }
        }
    }

    fn timeout(mut self, now: Instant, config: &HandshakeConfig, acked: bool) -> Step {
        if now < self.deadline {
            return Step::Wait(self.state(acked));
        }
        if let Some(result) = self.refused {
            return self.finish(now, config, HandshakeResult::Nack { result });
        }
        if self.attempts > config.retries {
            return self.finish(now, config, HandshakeResult::Timeout { acked });
        }
        self.attempts += 1;
        self.deadline = now + config.interval;
        Step::Resend(self.state(acked))
    }

    const fn state(self, acked: bool) -> Handshake {
        if acked {
            Handshake::AwaitingMessage(AwaitingMessage(self))
        } else {
            Handshake::AwaitingAnswer(AwaitingAnswer(self))
        }
    }
}

/// The awaited message, seen.
enum Answer {
    /// In MAVLink 2: the handshake's result.
    Mavlink2(HandshakeResult),
    /// The fallback's message in MAVLink 1: the link has no MAVLink 2.
    Mavlink1,
}

impl AwaitingAnswer {
    /// The state after the first request, sent at `now`.
    pub(crate) fn start(now: Instant, request: HandshakeRequest, config: &HandshakeConfig) -> Self {
        Self(Progress {
            request,
            attempts: 1,
            deadline: now + config.interval,
            started_at: now,
            fallback: None,
            refused: None,
        })
    }

    fn handle_frame(
        mut self,
        now: Instant,
        config: &HandshakeConfig,
        frame: &OwnedFrame,
        own_sysid: u8,
    ) -> Step {
        if let Some(answer) = self.0.answer(frame) {
            return self.0.answered(now, config, answer);
        }
        match self.0.ack(frame, own_sysid) {
            Some(ack)
                if ack.result == MavResult::ACCEPTED || ack.result == MavResult::IN_PROGRESS =>
            {
                Step::Wait(Handshake::AwaitingMessage(AwaitingMessage(self.0)))
            }
            // In the fallback phase a refusal may be the late answer to a request for 300:
            // it ends the phase at the deadline unless the message comes first.
            Some(ack) if self.0.fallback.is_some() => {
                self.0.refused = Some(ack.result);
                Step::Wait(Handshake::AwaitingAnswer(self))
            }
            Some(ack) => self
                .0
                .finish(now, config, HandshakeResult::Nack { result: ack.result }),
            None => Step::Wait(Handshake::AwaitingAnswer(self)),
        }
    }
}

impl AwaitingMessage {
    fn handle_frame(self, now: Instant, config: &HandshakeConfig, frame: &OwnedFrame) -> Step {
        match self.0.answer(frame) {
            Some(answer) => self.0.answered(now, config, answer),
            None => Step::Wait(Handshake::AwaitingMessage(self)),
        }
    }
}

impl Handshake {
    const fn progress(&self) -> &Progress {
        match self {
            Self::AwaitingAnswer(s) => &s.0,
            Self::AwaitingMessage(s) => &s.0,
        }
    }

    /// What is being asked.
    #[must_use]
    pub const fn request(&self) -> &HandshakeRequest {
        &self.progress().request
    }

    /// Requests sent so far.
    #[must_use]
    pub const fn attempts(&self) -> u8 {
        self.progress().attempts
    }

    /// When the current attempt times out.
    #[must_use]
    pub const fn deadline(&self) -> Instant {
        self.progress().deadline
    }

    /// When the handshake started.
    #[must_use]
    pub const fn started_at(&self) -> Instant {
        self.progress().started_at
    }

    /// The name of the state: `awaiting_answer` or `awaiting_message`.
    #[must_use]
    pub const fn name(&self) -> &'static str {
        match self {
            Self::AwaitingAnswer(_) => "awaiting_answer",
            Self::AwaitingMessage(_) => "awaiting_message",
        }
    }

    /// Whether the fallback phase is running (the request for PROTOCOL_VERSION was refused or
    /// unanswered; the fallback message is asked for now).
    #[must_use]
    pub const fn fallback(&self) -> Option<FallbackReason> {
        self.progress().fallback
    }

    /// Feeds an accepted frame.
    pub(crate) fn handle_frame(
        self,
        now: Instant,
        config: &HandshakeConfig,
        frame: &OwnedFrame,
        own_sysid: u8,
    ) -> Step {
        match self {
            Self::AwaitingAnswer(s) => s.handle_frame(now, config, frame, own_sysid),
            Self::AwaitingMessage(s) => s.handle_frame(now, config, frame),
        }
    }

    /// Feeds the time.
    pub(crate) fn handle_timeout(self, now: Instant, config: &HandshakeConfig) -> Step {
        match self {
            Self::AwaitingAnswer(s) => s.0.timeout(now, config, false),
            Self::AwaitingMessage(s) => s.0.timeout(now, config, true),
        }
    }
}
