//! Commands as request/reply, sans-IO: a COMMAND_LONG or COMMAND_INT frame comes in from
//! the broker with a reply address (`T`: an MQTT response topic and correlation data); the
//! tracker lets it into the vehicle's network, resends it until the target answers (as a
//! ground station does: COMMAND_LONG's `confirmation` counted up), and gives back one
//! final reply per request: the target's COMMAND_ACK frame, or a timeout. IN_PROGRESS acks
//! are passed on as intermediate replies and extend the wait. A request whose checksum is
//! wrong is refused ([`RequestError::BadCrc`]) before anything else, so a resend (built anew,
//! with a valid checksum) is only ever made of a frame that was valid; an ACK whose checksum
//! is wrong answers nothing. An ACK that was delivered
//! is what the target said; nothing here turns "sent" into "done".
//!
//! ```
//! use mavstack_bridge::command::{Commands, Reply};
//! use mavstack_core::time::Instant;
//! use mavstack_core::wire::{FrameHeader, Version, emit_message};
//! use mavstack_dialects::common::{CommandAck, CommandLong, MavCmd, MavResult};
//!
//! let frame = |sysid, compid, m: &dyn Fn(&mut [u8]) -> usize| {
//!     let mut out = [0u8; 280];
//!     let n = m(&mut out);
//!     out[..n].to_vec()
//! };
//! let header = |sysid, compid| FrameHeader { version: Version::V2, seq: 0, sysid, compid, signed: false };
//! let arm = CommandLong { target_system: 1, target_component: 1, command: MavCmd::COMPONENT_ARM_DISARM, param1: 1.0, ..Default::default() };
//! let request = frame(255, 190, &|o| emit_message(&header(255, 190), &arm, o).unwrap());
//!
//! let mut cmds = Commands::new(Default::default());
//! let t0 = Instant::from_micros(1_000_000);
//! let into_network = cmds.handle_request(t0, (1, 1), &request, "reply-to-me").unwrap();
//! assert_eq!(into_network, request);
//!
//! let ack = CommandAck { command: MavCmd::COMPONENT_ARM_DISARM, result: MavResult::ACCEPTED, target_system: 255, target_component: 190, ..Default::default() };
//! let ack_frame = frame(1, 1, &|o| emit_message(&header(1, 1), &ack, o).unwrap());
//! let mut replies = Vec::new();
//! cmds.handle_frame(t0, &ack_frame, &mut replies);
//! assert_eq!(replies, [Reply::Ack { to: "reply-to-me", frame: ack_frame, last: true }]);
//! assert!(cmds.is_empty());
//! ```

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_core::wire::{Frame, FrameHeader, emit_message};
use mavstack_dialects::common::{CommandAck, CommandInt, CommandLong, MavResult};

/// How the tracker waits and resends (the services' command client's defaults).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandTiming {
    /// Wait for an ACK before resending (0.5 s).
    pub timeout: Duration,
    /// Resends after the first send (3).
    pub retries: u8,
    /// Wait after an IN_PROGRESS ACK for the next one (3 s).
    pub in_progress_timeout: Duration,
}

impl Default for CommandTiming {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(500),
            retries: 3,
            in_progress_timeout: Duration::from_secs(3),
        }
    }
}

/// Why a request was refused at once.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum RequestError {
    /// Not a whole MAVLink frame.
    #[error("not a MAVLink frame")]
    NotAFrame,
    /// A COMMAND_LONG or COMMAND_INT frame whose checksum is wrong (corrupt on the way).
    #[error("the frame's checksum is wrong")]
    BadCrc,
    /// A frame of another message.
    #[error("message {msg_id} is not COMMAND_LONG or COMMAND_INT")]
    NotACommand {
        /// Its id.
        msg_id: u32,
    },
    /// The frame's target is not the key's.
    #[error("the command targets {target:?}, the key names {key:?}")]
    TargetMismatch {
        /// `(target_system, target_component)` of the frame.
        target: (u8, u8),
        /// The key's `(sysid, compid)`.
        key: (u8, u8),
    },
    /// The same command from the same sender to the same target is already running.
    #[error("the same command to the same target is already waiting for its ACK")]
    Busy,
}

impl RequestError {
    /// The `error` user property of the reply: `not_a_frame`, `bad_crc`, `not_a_command`,
    /// `target_mismatch`, `busy`.
    #[must_use]
    pub const fn code(&self) -> &'static str {
        match self {
            Self::NotAFrame => "not_a_frame",
            Self::BadCrc => "bad_crc",
            Self::NotACommand { .. } => "not_a_command",
            Self::TargetMismatch { .. } => "target_mismatch",
            Self::Busy => "busy",
        }
    }
}

/// A reply to send back to a requester.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Reply<T> {
    /// The target's COMMAND_ACK frame, byte for byte; `last` unless it says IN_PROGRESS.
    Ack {
        /// Where the reply goes.
        to: T,
        /// The frame.
        frame: Vec<u8>,
        /// The final reply.
        last: bool,
    },
    /// No answer after every resend.
    Timeout {
        /// Where the reply goes.
        to: T,
    },
}

/// MAV_RESULT_IN_PROGRESS.
const IN_PROGRESS: MavResult = MavResult(5);

#[derive(Debug)]
struct Pending<T> {
    to: T,
    sender: (u8, u8),
    target: (u8, u8),
    command: u16,
    /// The request as it came; resends of a COMMAND_LONG are this with `confirmation`
    /// counted up (a signed frame is resent as it came: it cannot be changed).
    frame: Vec<u8>,
    long: Option<(FrameHeader, CommandLong)>,
    sends: u8,
    deadline: Instant,
}

/// The requests waiting for their ACK.
#[derive(Debug)]
pub struct Commands<T> {
    timing: CommandTiming,
    pending: Vec<Pending<T>>,
}

impl<T: Clone> Commands<T> {
    /// No requests yet.
    #[must_use]
    pub const fn new(timing: CommandTiming) -> Self {
        Self {
            timing,
            pending: Vec::new(),
        }
    }

    /// A request for `key` (the `(sysid, compid)` of its `@cmd` key): the frame to let into
    /// the network.
    ///
    /// # Errors
    /// [`RequestError`]: not a command frame, a wrong checksum, a target other than the
    /// key's, or the same command already waiting.
    pub fn handle_request(
        &mut self,
        now: Instant,
        key: (u8, u8),
        frame: &[u8],
        to: T,
    ) -> Result<Vec<u8>, RequestError> {
        let view = Frame::new_checked(frame).map_err(|_| RequestError::NotAFrame)?;
        let frame = &frame[..view.frame_len()];
        let crc_extra = match view.msg_id() {
            CommandLong::ID => CommandLong::INFO.crc_extra,
            CommandInt::ID => CommandInt::INFO.crc_extra,
            msg_id => return Err(RequestError::NotACommand { msg_id }),
        };
        if !view.check_crc(crc_extra) {
            return Err(RequestError::BadCrc);
        }
        let (target, command, long) = match view.msg_id() {
            CommandLong::ID => {
                let c = CommandLong::decode(view.payload());
                let header = FrameHeader {
                    version: view.version(),
                    seq: view.seq(),
                    sysid: view.sysid(),
                    compid: view.compid(),
                    signed: false,
                };
                let long = (!view.is_signed()).then_some((header, c));
                ((c.target_system, c.target_component), c.command.0, long)
            }
            CommandInt::ID => {
                let c = CommandInt::decode(view.payload());
                ((c.target_system, c.target_component), c.command.0, None)
            }
            msg_id => return Err(RequestError::NotACommand { msg_id }),
        };
        if target != key {
            return Err(RequestError::TargetMismatch { target, key });
        }
        let sender = (view.sysid(), view.compid());
        if self
            .pending
            .iter()
            .any(|p| p.sender == sender && p.target == target && p.command == command)
        {
            return Err(RequestError::Busy);
        }
        self.pending.push(Pending {
            to,
            sender,
            target,
            command,
            frame: frame.to_vec(),
            long,
            sends: 1,
            deadline: now + self.timing.timeout,
        });
        Ok(frame.to_vec())
    }

    /// A frame going to the broker: a COMMAND_ACK that answers a waiting request becomes
    /// its reply (pushed onto `replies`).
    pub fn handle_frame(&mut self, now: Instant, frame: &[u8], replies: &mut Vec<Reply<T>>) {
        if self.pending.is_empty() {
            return;
        }
        let Ok(view) = Frame::new_checked(frame) else {
            return;
        };
        if view.msg_id() != CommandAck::ID || !view.check_crc(CommandAck::INFO.crc_extra) {
            return;
        }
        let ack = CommandAck::decode(view.payload());
        let from = (view.sysid(), view.compid());
        let Some(i) = self.pending.iter().position(|p| {
            p.command == ack.command.0
                && from.0 == p.target.0
                && (p.target.1 == 0 || from.1 == p.target.1)
                && (ack.target_system == 0 || ack.target_system == p.sender.0)
        }) else {
            return;
        };
        let frame = frame[..view.frame_len()].to_vec();
        if ack.result == IN_PROGRESS {
            let p = &mut self.pending[i];
            p.deadline = now + self.timing.in_progress_timeout;
            // No more resends: the target has it.
            p.sends = self.timing.retries.saturating_add(1);
            replies.push(Reply::Ack {
                to: p.to.clone(),
                frame,
                last: false,
            });
        } else {
            let p = self.pending.swap_remove(i);
            replies.push(Reply::Ack {
                to: p.to,
                frame,
                last: true,
            });
        }
    }

    /// Time has passed: resends (frames to let into the network) and timeouts.
    pub fn handle_timeout(
        &mut self,
        now: Instant,
        resend: &mut Vec<Vec<u8>>,
        replies: &mut Vec<Reply<T>>,
    ) {
        let timing = self.timing;
        self.pending.retain_mut(|p| {
            if now < p.deadline {
                return true;
            }
            if p.sends > timing.retries {
                replies.push(Reply::Timeout { to: p.to.clone() });
                return false;
            }
            let confirmation = p.sends;
            p.sends += 1;
            p.deadline = now + timing.timeout;
            match &p.long {
                Some((header, c)) => {
                    let c = CommandLong { confirmation, ..*c };
                    let mut out = [0u8; 280];
                    match emit_message(header, &c, &mut out) {
                        Ok(n) => resend.push(out[..n].to_vec()),
                        Err(_) => resend.push(p.frame.clone()),
                    }
                }
                None => resend.push(p.frame.clone()),
            }
            true
        });
    }

    /// When [`Commands::handle_timeout`] is next due.
    #[must_use]
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.pending.iter().map(|p| p.deadline).min()
    }

    /// Nothing waits.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_core::wire::Version;
    use mavstack_dialects::common::MavCmd;

    fn header(sysid: u8, compid: u8) -> FrameHeader {
        FrameHeader {
            version: Version::V2,
            seq: 7,
            sysid,
            compid,
            signed: false,
        }
    }

    fn frame<M: mavstack_core::Message>(sysid: u8, compid: u8, m: &M) -> Vec<u8> {
        let mut out = [0u8; 280];
        let n = emit_message(&header(sysid, compid), m, &mut out).unwrap();
        out[..n].to_vec()
    }

    fn arm() -> CommandLong {
        CommandLong {
            target_system: 1,
            target_component: 1,
            command: MavCmd::COMPONENT_ARM_DISARM,
            param1: 1.0,
            ..Default::default()
        }
    }

    fn ack(result: MavResult, to: u8) -> Vec<u8> {
        frame(
            1,
            1,
            &CommandAck {
                command: MavCmd::COMPONENT_ARM_DISARM,
                result,
                target_system: to,
                ..Default::default()
            },
        )
    }

    fn t(ms: u64) -> Instant {
        Instant::from_micros(1_000_000_000 + ms * 1000)
    }

    #[test]
    fn resends_count_confirmation_up_then_time_out() {
        let mut c = Commands::new(CommandTiming::default());
        c.handle_request(t(0), (1, 1), &frame(255, 190, &arm()), 1)
            .unwrap();
        let (mut resend, mut replies) = (Vec::new(), Vec::new());
        for (i, ms) in [500, 1000, 1500].into_iter().enumerate() {
            assert_eq!(c.poll_timeout(), Some(t(ms)));
            c.handle_timeout(t(ms), &mut resend, &mut replies);
            let f = Frame::new_checked(&resend[i][..]).unwrap();
            assert_eq!(CommandLong::decode(f.payload()).confirmation, i as u8 + 1);
            assert!(f.check_crc(CommandLong::INFO.crc_extra));
        }
        assert!(replies.is_empty());
        c.handle_timeout(t(2000), &mut resend, &mut replies);
        assert_eq!(replies, [Reply::Timeout { to: 1 }]);
        assert!(c.is_empty());
    }

    #[test]
    fn in_progress_is_passed_on_and_waits_longer() {
        let mut c = Commands::new(CommandTiming::default());
        c.handle_request(t(0), (1, 1), &frame(255, 190, &arm()), "r")
            .unwrap();
        let mut replies = Vec::new();
        c.handle_frame(t(100), &ack(IN_PROGRESS, 255), &mut replies);
        assert!(matches!(&replies[..], [Reply::Ack { last: false, .. }]));
        assert_eq!(c.poll_timeout(), Some(t(3100)));
        let mut resend = Vec::new();
        c.handle_timeout(t(3100), &mut resend, &mut replies);
        assert!(resend.is_empty(), "no resend after IN_PROGRESS");
        assert!(matches!(replies.last(), Some(Reply::Timeout { to: "r" })));
    }

    #[test]
    fn acks_for_others_do_not_answer() {
        let mut c = Commands::new(CommandTiming::default());
        c.handle_request(t(0), (1, 1), &frame(255, 190, &arm()), 0)
            .unwrap();
        let mut replies = Vec::new();
        c.handle_frame(t(1), &ack(MavResult::ACCEPTED, 254), &mut replies);
        let other = CommandAck {
            command: MavCmd::COMPONENT_ARM_DISARM,
            ..Default::default()
        };
        c.handle_frame(t(1), &frame(2, 1, &other), &mut replies);
        assert!(replies.is_empty());
        c.handle_frame(t(2), &ack(MavResult::DENIED, 0), &mut replies);
        assert_eq!(replies.len(), 1);
    }

    #[test]
    fn bad_requests_are_refused() {
        let mut c = Commands::new(CommandTiming::default());
        let req = frame(255, 190, &arm());
        assert_eq!(
            c.handle_request(t(0), (1, 2), &req, 0),
            Err(RequestError::TargetMismatch {
                target: (1, 1),
                key: (1, 2)
            })
        );
        assert_eq!(
            c.handle_request(t(0), (1, 1), &req[..5], 0),
            Err(RequestError::NotAFrame)
        );
        let hb = frame(255, 190, &mavstack_dialects::common::Heartbeat::default());
        assert_eq!(
            c.handle_request(t(0), (1, 1), &hb, 0),
            Err(RequestError::NotACommand { msg_id: 0 })
        );
        c.handle_request(t(0), (1, 1), &req, 0).unwrap();
        assert_eq!(
            c.handle_request(t(0), (1, 1), &req, 0),
            Err(RequestError::Busy)
        );
    }

    #[test]
    fn corrupt_requests_are_refused_and_corrupt_acks_answer_nothing() {
        let mut c = Commands::new(CommandTiming::default());
        let mut corrupt = frame(255, 190, &arm());
        corrupt[14] ^= 0x01; // param1: the checksum no longer matches
        assert_eq!(
            c.handle_request(t(0), (1, 1), &corrupt, 0),
            Err(RequestError::BadCrc)
        );
        assert_eq!(RequestError::BadCrc.code(), "bad_crc");
        let int = CommandInt {
            target_system: 1,
            target_component: 1,
            ..Default::default()
        };
        let mut corrupt_int = frame(255, 190, &int);
        corrupt_int[11] ^= 0x80;
        assert_eq!(
            c.handle_request(t(0), (1, 1), &corrupt_int, 0),
            Err(RequestError::BadCrc)
        );
        // Nothing waits, so nothing is ever resent with a fresh checksum.
        assert!(c.is_empty());
        let (mut resend, mut replies) = (Vec::new(), Vec::new());
        c.handle_timeout(t(5000), &mut resend, &mut replies);
        assert!(resend.is_empty() && replies.is_empty());
        c.handle_request(t(0), (1, 1), &frame(255, 190, &arm()), 1)
            .unwrap();
        let mut bad_ack = ack(MavResult::ACCEPTED, 255);
        bad_ack[10] ^= 0x01;
        c.handle_frame(t(1), &bad_ack, &mut replies);
        assert!(replies.is_empty(), "a corrupt ACK answered");
        assert!(!c.is_empty());
    }
}
