//! Where the channel gets each message's CRC_EXTRA, and the few messages it reads itself.
//!
//! The parser can only check a frame's checksum when it knows the message's CRC_EXTRA. A
//! [`Channel`](crate::Channel) or [`Radio`](crate::Radio) takes it from a
//! [`MessageTable`]: a compiled-in dialect's ([`MessageTable::of`]; the default is `common`)
//! or one built at run time from XML. Whatever the table, the messages the channel handles
//! itself (COMMAND_LONG, COMMAND_INT, COMMAND_ACK, AUTOPILOT_VERSION, RADIO_STATUS,
//! SETUP_SIGNING, PROTOCOL_VERSION) are always known.

use mavstack_core::MessageTable;
use mavstack_core::message::{Message, MessageInfo};
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandInt, CommandLong, MavCmd, MavMessage, ProtocolVersion,
    RadioStatus, SetupSigning,
};

use crate::frame::OwnedFrame;

/// The `common` dialect's table, what [`Channel::new`](crate::Channel::new) and
/// [`Radio::new`](crate::Radio::new) use.
pub(crate) fn common_table() -> MessageTable {
    MessageTable::of::<MavMessage>()
}

/// The entries of the messages the channel reads itself, as generated (sorted by id).
static BUILTIN_ENTRIES: [MessageInfo; 7] = [
    CommandInt::INFO,
    CommandLong::INFO,
    CommandAck::INFO,
    RadioStatus::INFO,
    AutopilotVersion::INFO,
    SetupSigning::INFO,
    ProtocolVersion::INFO,
];

/// The messages the channel reads itself, as a table. Out of order entries fail the build.
static BUILTINS: MessageTable = match MessageTable::new(&BUILTIN_ENTRIES) {
    Ok(table) => table,
    Err(_) => panic!("BUILTIN_ENTRIES is not sorted by id"),
};

/// The CRC_EXTRA of `id` in `table`, completed with the messages the channel reads itself.
#[inline]
pub(crate) fn crc_extra_with_builtins(table: &MessageTable, id: u32) -> Option<u8> {
    table.crc_extra(id).or_else(|| BUILTINS.crc_extra(id))
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
        let asks_300 = self.param1 == ProtocolVersion::ID as f32;
        self.command == MavCmd::REQUEST_PROTOCOL_VERSION
            || (self.command == MavCmd::REQUEST_MESSAGE && asks_300)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in entries are the `common` dialect's own, for exactly the messages the
    /// channel decodes.
    #[test]
    fn builtins_are_the_common_entries_of_the_messages_read() {
        let common = common_table();
        for entry in BUILTINS.entries() {
            assert_eq!(common.info(entry.id), Some(entry), "{}", entry.name);
        }
        let names = BUILTINS.entries().iter().map(|m| m.name);
        assert!(
            names.eq([
                "COMMAND_INT",
                "COMMAND_LONG",
                "COMMAND_ACK",
                "RADIO_STATUS",
                "AUTOPILOT_VERSION",
                "SETUP_SIGNING",
                "PROTOCOL_VERSION",
            ]),
            "{:?}",
            BUILTINS.entries()
        );
    }

    /// The CRC_EXTRAs pymavlink's `common` gives these ids.
    #[test]
    fn builtins_complete_any_table() {
        let nothing = MessageTable::empty();
        let with = |id| crc_extra_with_builtins(&nothing, id);
        assert_eq!(with(76), Some(152));
        assert_eq!(with(75), Some(158));
        assert_eq!(with(77), Some(143));
        assert_eq!(with(109), Some(185));
        assert_eq!(with(148), Some(178));
        assert_eq!(with(256), Some(71));
        assert_eq!(with(300), Some(217));
        assert_eq!(with(0), None);
        assert_eq!(crc_extra_with_builtins(&common_table(), 0), Some(50));
    }
}
