//! Where the channel gets each message's CRC_EXTRA, and the few messages it reads itself.
//!
//! The parser can only check a frame's checksum when it knows the message's CRC_EXTRA. A
//! [`Channel`](crate::Channel) or [`Radio`](crate::Radio) takes any
//! [`CrcExtra`] lookup: [`DialectCrc`] for a compiled-in dialect (the default is `common`), a
//! closure `Fn(u32) -> Option<u8>`, or a table built at run time from XML. Whatever the lookup,
//! the messages the channel handles itself (COMMAND_LONG, COMMAND_INT, COMMAND_ACK,
//! AUTOPILOT_VERSION, RADIO_STATUS, SETUP_SIGNING, PROTOCOL_VERSION) are always known.

use core::marker::PhantomData;

use mavstack_core::message::{Message, MessageSet};
use mavstack_core::parse::CrcExtra;
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandInt, CommandLong, MavCmd, MavMessage, ProtocolVersion,
    RadioStatus, SetupSigning,
};

use crate::frame::OwnedFrame;

/// CRC_EXTRA from a generated dialect's [`MessageSet`].
///
/// ```
/// use mavstack_channel::DialectCrc;
/// use mavstack_core::parse::CrcExtra;
/// let common = DialectCrc::<mavstack_dialects::common::MavMessage>::new();
/// assert_eq!(common.crc_extra(0), Some(50)); // HEARTBEAT
/// assert_eq!(common.crc_extra(0xFF_FFFF), None);
/// ```
pub struct DialectCrc<M>(PhantomData<fn() -> M>);

/// The default lookup: the `common` dialect.
pub type CommonCrc = DialectCrc<MavMessage>;

impl<M> DialectCrc<M> {
    /// The lookup for dialect `M`.
    #[must_use]
    pub const fn new() -> Self {
        Self(PhantomData)
    }
}

impl<M> Default for DialectCrc<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M> Clone for DialectCrc<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for DialectCrc<M> {}

impl<M> core::fmt::Debug for DialectCrc<M> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("DialectCrc")
    }
}

impl<M: MessageSet> CrcExtra for DialectCrc<M> {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        M::info(id).map(|info| info.crc_extra)
    }
}

/// The CRC_EXTRA of the messages the channel reads itself.
pub(crate) const fn builtin_crc_extra(id: u32) -> Option<u8> {
    match id {
        CommandLong::ID => Some(CommandLong::CRC_EXTRA),
        CommandInt::ID => Some(CommandInt::CRC_EXTRA),
        CommandAck::ID => Some(CommandAck::CRC_EXTRA),
        AutopilotVersion::ID => Some(AutopilotVersion::CRC_EXTRA),
        RadioStatus::ID => Some(RadioStatus::CRC_EXTRA),
        SetupSigning::ID => Some(SetupSigning::CRC_EXTRA),
        ProtocolVersion::ID => Some(ProtocolVersion::CRC_EXTRA),
        _ => None,
    }
}

/// A caller's lookup, completed with the built-in messages.
pub(crate) struct WithBuiltins<'a, L>(pub(crate) &'a L);

impl<L: CrcExtra> CrcExtra for WithBuiltins<'_, L> {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        self.0.crc_extra(id).or_else(|| builtin_crc_extra(id))
    }
}

/// How a command was encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CommandEncoding {
    /// COMMAND_LONG (76): seven float parameters and a confirmation counter.
    Long,
    /// COMMAND_INT (75): parameters 5 and 6 as integers, a frame, no confirmation counter.
    Int,
}

/// The fields of a COMMAND_LONG or COMMAND_INT that the channel looks at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CommandRequest {
    pub(crate) encoding: CommandEncoding,
    pub(crate) command: MavCmd,
    pub(crate) target_system: u8,
    pub(crate) target_component: u8,
    pub(crate) param1: f32,
}

impl CommandRequest {
    /// The command in `frame`, if it carries COMMAND_LONG or COMMAND_INT.
    pub(crate) fn from_frame(frame: &OwnedFrame) -> Option<Self> {
        if let Some(c) = frame.decode_as::<CommandLong>() {
            return Some(Self {
                encoding: CommandEncoding::Long,
                command: c.command,
                target_system: c.target_system,
                target_component: c.target_component,
                param1: c.param1,
            });
        }
        frame.decode_as::<CommandInt>().map(|c| Self {
            encoding: CommandEncoding::Int,
            command: c.command,
            target_system: c.target_system,
            target_component: c.target_component,
            param1: c.param1,
        })
    }

    /// Whether the command is addressed to `(sysid, compid)`: target system 0 or ours, and
    /// target component 0 or ours.
    pub(crate) const fn is_for(&self, sysid: u8, compid: u8) -> bool {
        (self.target_system == 0 || self.target_system == sysid)
            && (self.target_component == 0 || self.target_component == compid)
    }

    /// Whether it asks for PROTOCOL_VERSION: MAV_CMD_REQUEST_PROTOCOL_VERSION (519), or
    /// MAV_CMD_REQUEST_MESSAGE (512) with param1 = 300.
    pub(crate) fn requests_protocol_version(&self) -> bool {
        #[allow(clippy::float_cmp)] // an integer message id carried in a float, exactly
        let asks_300 = self.param1 == ProtocolVersion::ID as f32;
        self.command == MavCmd::REQUEST_PROTOCOL_VERSION
            || (self.command == MavCmd::REQUEST_MESSAGE && asks_300)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtins_complete_any_lookup() {
        let nothing = |_: u32| None;
        let with = WithBuiltins(&nothing);
        assert_eq!(with.crc_extra(76), Some(152));
        assert_eq!(with.crc_extra(75), Some(158));
        assert_eq!(with.crc_extra(77), Some(143));
        assert_eq!(with.crc_extra(109), Some(185));
        assert_eq!(with.crc_extra(148), Some(178));
        assert_eq!(with.crc_extra(256), Some(71));
        assert_eq!(with.crc_extra(300), Some(217));
        assert_eq!(with.crc_extra(0), None);
        let common = CommonCrc::new();
        assert_eq!(WithBuiltins(&common).crc_extra(0), Some(50));
    }
}
