//! The receive path of a [`Channel`]: frames out of the deframer, their signature and replay
//! checks, the version rules on receipt, a vehicle's answers to the handshake, the
//! ground station's handshake steps and SETUP_SIGNING.

use mavstack_core::message::Message;
use mavstack_core::parse::Item;
use mavstack_core::signing::{MAX_TIMESTAMP, SecretKey};
use mavstack_core::time::Instant;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, MavCmd, MavProtocolCapability, MavResult, SetupSigning,
};

use super::transmit::{Control, Framing};
use super::{Channel, EVENTS_PER_FRAME};
use crate::config::{GroundPolicy, Role, VehicleVersion};
use crate::dialect::{CommandRequest, crc_extra_with_builtins};
use crate::event::{
    Event, ProtocolVersionAnswer, RejectReason, Rejected, SigningSetup, SwitchCause,
};
use crate::frame::{Authentication, OwnedFrame, ReceivedFrame};
use crate::handshake::{HandshakeOutcome, HandshakeResult, Step};
use crate::signing::{LinkSigning, SigningConfig};

impl Channel {
    /// Processes buffered frames while the event queue has room. Returns whether every
    /// complete frame has been processed.
    pub(super) fn process_buffered(&mut self) -> bool {
        loop {
            if self.events.free() < EVENTS_PER_FRAME {
                return false;
            }
            let table = self.table;
            let lookup = |id: u32| crc_extra_with_builtins(&table, id);
            let item = if self.datagram_end {
                self.deframer.finish(&lookup)
            } else {
                self.deframer.next_item(&lookup)
            };
            let Some(item) = item else {
                self.input_pending = false;
                self.datagram_end = false;
                return true;
            };
            let (view, known) = match item {
                Item::Frame(f) => (f, true),
                Item::Unknown(f) => (f, false),
            };
            // The parser only yields complete frames, which always copy.
            if let Ok(frame) = OwnedFrame::new(view.as_bytes()) {
                self.process(&frame, known);
            }
        }
    }

    fn process(&mut self, frame: &OwnedFrame, known: bool) {
        let now = self.last_input_at;
        let auth = match self.authenticate(now, frame) {
            Ok(auth) => auth,
            Err(reason) => return self.reject(now, frame, reason),
        };
        if known && frame.msg_id() == SetupSigning::ID && !matches!(self.role, Role::Relay(_)) {
            return self.handle_setup_signing(now, frame);
        }
        self.stats.accepted += 1;
        // A frame whose checksum or signature was checked can drive the link's state; an
        // unknown id whose checksum could not be checked is only delivered.
        let trusted = known || auth.is_authenticated();
        let mut after: [Option<Event>; EVENTS_PER_FRAME - 1] = [None, None, None, None];
        let mut request = None;
        if trusted {
            self.seqs.record(frame.sysid(), frame.compid(), frame.seq());
            after[0] = self.switch_on_receive(frame);
        }
        if known {
            if let Some((answer, event)) = self.answer_protocol_version_request(frame) {
                request = Some(answer);
                after[1] = Some(event);
            }
            if let Some(state) = self.handshake.take() {
                let step = state.handle_frame(now, &self.handshake_config, frame, self.sysid);
                (after[2], after[3]) = self.apply_step(step);
            }
        }
        let answered = request.is_some_and(|a| a != ProtocolVersionAnswer::Ignored);
        // Written in place: where a frame lent by `poll_event_ref` was, over its bytes.
        let _ = self.events.push_with(|slot| match slot {
            Some(Event::Frame(r)) => {
                r.frame.clone_from(frame);
                r.received_at = now;
                r.auth = auth;
                r.crc_checked = known;
                r.answered = answered;
                r.protocol_version_request = request;
            }
            _ => {
                *slot = Some(Event::Frame(ReceivedFrame {
                    frame: frame.clone(),
                    received_at: now,
                    auth,
                    crc_checked: known,
                    answered,
                    protocol_version_request: request,
                }));
            }
        });
        // Taken one by one (moving the whole array would copy four events' room).
        for event in &mut after {
            if let Some(event) = event.take() {
                self.push_event(event);
            }
        }
    }

    pub(super) fn push_event(&mut self, event: Event) {
        // Room was reserved (EVENTS_PER_FRAME) before the frame or timeout was processed.
        let _ = self.events.push(event);
    }

    fn reject(&mut self, now: Instant, frame: &OwnedFrame, reason: RejectReason) {
        self.stats.rejected.count(reason);
        self.push_event(Event::Rejected(Rejected {
            reason,
            version: frame.version(),
            sysid: frame.sysid(),
            compid: frame.compid(),
            msg_id: frame.msg_id(),
            received_at: now,
        }));
    }

    /// The signing checks, in order: unsigned frames against the allow-list; the signature
    /// against every key; only then the replay table.
    fn authenticate(
        &mut self,
        now: Instant,
        frame: &OwnedFrame,
    ) -> Result<Authentication, RejectReason> {
        let signature = frame.signature();
        let Some(signing) = self.signing.as_mut() else {
            return Ok(signature.map_or(Authentication::Unsigned, |s| {
                Authentication::NotChecked {
                    link_id: s.link_id,
                    timestamp: s.timestamp,
                }
            }));
        };
        let Some(signature) = signature else {
            if signing.config.is_allowed_unsigned(frame.msg_id()) {
                return Ok(Authentication::AllowedUnsigned);
            }
            return Err(match frame.version() {
                Version::V1 => RejectReason::Mavlink1OnSignedLink,
                Version::V2 => RejectReason::UnsignedNotAllowed,
            });
        };
        let key_index = signing
            .verify(&frame.view())
            .ok_or(RejectReason::BadSignature)?;
        let local = signing.current(now);
        signing.replay.check_and_record(
            (frame.sysid(), frame.compid(), signature.link_id),
            signature.timestamp,
            local,
        )?;
        signing.raise(signature.timestamp);
        Ok(Authentication::Verified {
            link_id: signature.link_id,
            timestamp: signature.timestamp,
            key_index,
        })
    }

    /// The version rules on receipt: the first MAVLink 2 frame, and AUTOPILOT_VERSION's
    /// capability flag for an automatic ground station.
    fn switch_on_receive(&mut self, frame: &OwnedFrame) -> Option<Event> {
        if frame.version() == Version::V2 {
            self.mavlink2_received = true;
            let switches = match self.role {
                Role::Vehicle(p) => p.version == VehicleVersion::StartMavlink1,
                Role::Relay(v) => v == VehicleVersion::StartMavlink1,
                Role::GroundStation(p) => p == GroundPolicy::Automatic,
            };
            if switches {
                return self.set_out_version(Version::V2, SwitchCause::Mavlink2Received);
            }
        }
        if self.role == Role::GroundStation(GroundPolicy::Automatic)
            && let Some(av) = frame.decode_as::<AutopilotVersion>()
            && av.capabilities.contains(MavProtocolCapability::MAVLINK2)
        {
            return self.set_out_version(Version::V2, SwitchCause::CapabilityFlag);
        }
        None
    }

    fn set_out_version(&mut self, version: Version, cause: SwitchCause) -> Option<Event> {
        if self.signing.is_some() || self.out_version == version {
            return None;
        }
        let from = self.version();
        self.out_version = version;
        Some(Event::VersionChanged {
            from,
            to: self.version(),
            cause,
        })
    }

    /// A vehicle's side of the handshake: what it did with a request for PROTOCOL_VERSION
    /// addressed to it, and the event reporting it.
    fn answer_protocol_version_request(
        &mut self,
        frame: &OwnedFrame,
    ) -> Option<(ProtocolVersionAnswer, Event)> {
        let Role::Vehicle(policy) = self.role else {
            return None;
        };
        let cmd = CommandRequest::from_frame(frame)?;
        if !cmd.requests_protocol_version() || !cmd.is_for(self.sysid, self.compid) {
            return None;
        }
        let to = (frame.sysid(), frame.compid());
        // A refusal: ArduPilot's (REQUEST_MESSAGE for a message it cannot send fails, a
        // command it does not know is unsupported), or a link with MAVLink 2 disabled.
        let refusal = match (policy.protocol_version, policy.version) {
            (None, _) if policy.refuse_unsupported => {
                Some(if cmd.command == MavCmd::REQUEST_PROTOCOL_VERSION {
                    MavResult::UNSUPPORTED
                } else {
                    MavResult::FAILED
                })
            }
            (Some(_), VehicleVersion::Mavlink1Only) => Some(policy.nack_result),
            _ => None,
        };
        let answer = match (policy.protocol_version, refusal) {
            (_, Some(result)) => {
                self.queue_control(
                    Control::Ack {
                        command: cmd.command,
                        result,
                        to,
                    },
                    Framing::Link,
                );
                ProtocolVersionAnswer::Nacked(result)
            }
            (None, None) => ProtocolVersionAnswer::Ignored,
            (Some(version), None) => {
                if self.transmits.free() < 2 {
                    self.stats.control_dropped += 2;
                } else {
                    self.queue_control(
                        Control::Ack {
                            command: cmd.command,
                            result: MavResult::ACCEPTED,
                            to,
                        },
                        Framing::Link,
                    );
                    self.queue_control(Control::ProtocolVersion(version), Framing::Mavlink2);
                }
                ProtocolVersionAnswer::Accepted
            }
        };
        let event = Event::ProtocolVersionRequested {
            sysid: to.0,
            compid: to.1,
            command: cmd.command,
            encoding: cmd.encoding,
            answer,
        };
        Some((answer, event))
    }

    /// Carries out a handshake transition; returns the events it causes.
    pub(super) fn apply_step(&mut self, step: Step) -> (Option<Event>, Option<Event>) {
        match step {
            Step::Wait(state) => {
                self.handshake = Some(state);
                (None, None)
            }
            Step::Resend(state) => {
                self.queue_control(
                    Control::Request {
                        request: *state.request(),
                        attempt: state.attempts(),
                    },
                    Framing::Mavlink2,
                );
                self.handshake = Some(state);
                (None, None)
            }
            Step::Done(outcome) => {
                let switch = self.finish_handshake(&outcome);
                (Some(Event::Handshake(outcome)), switch)
            }
        }
    }

    fn finish_handshake(&mut self, outcome: &HandshakeOutcome) -> Option<Event> {
        let automatic = self.role == Role::GroundStation(GroundPolicy::Automatic);
        match outcome.result {
            HandshakeResult::ProtocolVersion(version) => {
                self.peer_protocol_version = Some(version);
                self.set_out_version(Version::V2, SwitchCause::Handshake)
            }
            HandshakeResult::Message { .. } => {
                self.set_out_version(Version::V2, SwitchCause::Handshake)
            }
            HandshakeResult::Nack { .. } if automatic => {
                self.set_out_version(Version::V1, SwitchCause::HandshakeFallback)
            }
            // A timeout falls back unless MAVLink 2 frames did arrive: then the link carries
            // MAVLink 2 and the first-frame rule already decided.
            HandshakeResult::Timeout { .. } if automatic && !self.mavlink2_received => {
                self.set_out_version(Version::V1, SwitchCause::HandshakeFallback)
            }
            _ => None,
        }
    }

    fn handle_setup_signing(&mut self, now: Instant, frame: &OwnedFrame) {
        let Some(setup) = frame.decode_as::<SetupSigning>() else {
            return;
        };
        if !self.secure {
            return self.reject(now, frame, RejectReason::SetupSigningInsecure);
        }
        if setup.target_system != self.sysid
            || (setup.target_component != 0 && setup.target_component != self.compid)
        {
            return self.reject(now, frame, RejectReason::SetupSigningMisaddressed);
        }
        if !self.accepts_mavlink2() {
            return self.reject(now, frame, RejectReason::SetupSigningNeedsMavlink2);
        }
        if self.setup_signing_held {
            return self.reject(now, frame, RejectReason::SetupSigningHeld);
        }
        self.stats.accepted += 1;
        let before = self.version();
        let disable = setup.secret_key == [0; 32] && setup.initial_timestamp == 0;
        let (event, cause) = if disable {
            self.signing = None;
            self.out_version = Version::V2;
            (SigningSetup::Disabled, SwitchCause::SigningDisabled)
        } else {
            let key = SecretKey::new(setup.secret_key);
            let previous = self.signing.take();
            let mut config = previous
                .as_ref()
                .map_or_else(|| SigningConfig::new(key.clone(), 0), |p| p.config.clone());
            config.replace_keys(key.clone());
            let carried = previous
                .as_ref()
                .map_or(0, |p| p.last_timestamp().saturating_add(1));
            config.initial_timestamp = carried.max(setup.initial_timestamp).min(MAX_TIMESTAMP);
            let mut signing = LinkSigning::new(config);
            if let Some(p) = previous {
                signing.replay = p.replay;
            }
            self.signing = Some(signing);
            self.out_version = Version::V2;
            (
                SigningSetup::Enabled {
                    key,
                    initial_timestamp: setup.initial_timestamp,
                },
                SwitchCause::SigningEnabled,
            )
        };
        self.push_event(Event::SigningSetup {
            sysid: frame.sysid(),
            compid: frame.compid(),
            setup: event,
        });
        let after = self.version();
        if before != after {
            self.push_event(Event::VersionChanged {
                from: before,
                to: after,
                cause,
            });
        }
    }
}
