//! The frames a [`Channel`] writes: the caller's (`send*`) and its own control frames
//! (COMMAND_ACK, PROTOCOL_VERSION, handshake requests), queued until `poll_transmit`.

use mavstack_core::message::{MAX_PAYLOAD_LEN, Message, MessageInfo};
use mavstack_core::signing::append_signature;
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, FrameHeader, Version};
use mavstack_dialects::common::{CommandAck, MavCmd, MavResult, ProtocolVersion};

use super::{Channel, SendError, Transmit};
use crate::handshake::{HandshakeRequest, RequestMessage};

/// A frame the channel sends on its own.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Control {
    Ack {
        command: MavCmd,
        result: MavResult,
        to: (u8, u8),
    },
    ProtocolVersion(ProtocolVersion),
    Request {
        request: HandshakeRequest,
        attempt: u8,
    },
}

/// Which version a frame goes out in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Framing {
    /// The link's current version.
    Link,
    /// MAVLink 2 whatever the link's version (signed when the link signs): the handshake
    /// request and its answer.
    Mavlink2,
}

impl Channel {
    pub(super) fn queue_control(&mut self, control: Control, framing: Framing) {
        if self.transmits.push((control, framing)).is_err() {
            self.stats.control_dropped += 1;
        }
    }

    pub(super) fn write_control(
        &mut self,
        now: Instant,
        control: &Control,
        framing: Framing,
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        match *control {
            Control::Ack {
                command,
                result,
                to,
            } => {
                let ack = CommandAck {
                    command,
                    result,
                    progress: 0,
                    result_param2: 0,
                    target_system: to.0,
                    target_component: to.1,
                };
                self.write_message(now, &ack, framing, out)
            }
            Control::ProtocolVersion(version) => self.write_message(now, &version, framing, out),
            Control::Request { request, attempt } => match request.message(attempt) {
                RequestMessage::Long(m) => self.write_message(now, &m, framing, out),
                RequestMessage::Int(m) => self.write_message(now, &m, framing, out),
            },
        }
    }

    fn write_message<M: Message>(
        &mut self,
        now: Instant,
        message: &M,
        framing: Framing,
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.write(now, &M::INFO, &payload[..len], framing, out)
    }

    /// Writes one frame: version per `framing`, our ids, the next sequence number, the
    /// signature when the link signs.
    pub(super) fn write(
        &mut self,
        now: Instant,
        info: &MessageInfo,
        payload: &[u8],
        framing: Framing,
        out: &mut [u8],
    ) -> Result<Transmit, SendError> {
        let version = match framing {
            Framing::Link => self.out_version,
            Framing::Mavlink2 => Version::V2,
        };
        if version == Version::V1 && info.id > 255 {
            return Err(SendError::NeedsMavlink2 { msg_id: info.id });
        }
        let signed = self.signing.is_some() && version == Version::V2;
        let header = FrameHeader {
            version,
            seq: self.seq,
            sysid: self.sysid,
            compid: self.compid,
            signed,
        };
        let mut len = wire::emit(&header, info, payload, out)?;
        if let Some(s) = self.signing.as_mut().filter(|_| signed) {
            let timestamp = s.next_timestamp(now);
            len = append_signature(
                out,
                len,
                s.config.link_id,
                timestamp,
                s.config.primary_key(),
            )?;
        }
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.stats.sent += 1;
        Ok(Transmit {
            len,
            version,
            signed,
            seq,
            msg_id: info.id,
        })
    }
}
