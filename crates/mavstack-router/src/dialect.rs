//! Where the router learns what it needs about a message without decoding it: CRC_EXTRA (to
//! check and rewrite checksums), the base length (for MAVLink 1) and the target offsets.

use core::marker::PhantomData;

use mavstack_core::message::{MessageInfo, MessageSet};
use mavstack_core::parse::CrcExtra;

/// The message facts a router reads: a [`CrcExtra`] lookup for the links' parsers, plus the
/// whole [`MessageInfo`] for routing and conversion. Cloned once per link.
pub trait Dialect: CrcExtra + Clone {
    /// The facts of message `id`, or `None` for an id the dialect does not define (such a
    /// frame is forwarded byte for byte as a broadcast, and never converted).
    fn info(&self, id: u32) -> Option<MessageInfo>;
}

/// The facts of a generated dialect `M` (e.g. `mavstack_dialects::ardupilotmega::MavMessage`).
///
/// ```
/// use mavstack_router::{Dialect, DialectInfo};
/// let common = DialectInfo::<mavstack_dialects::common::MavMessage>::new();
/// let ack = common.info(77).unwrap(); // COMMAND_ACK: its target is an extension field
/// assert_eq!((ack.min_len, ack.target_system_offset), (3, Some(8)));
/// ```
pub struct DialectInfo<M>(PhantomData<fn() -> M>);

impl<M> DialectInfo<M> {
    /// The facts of dialect `M`.
    #[must_use]
    pub const fn new() -> Self {
        Self(PhantomData)
    }
}

impl<M> Default for DialectInfo<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M> Clone for DialectInfo<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for DialectInfo<M> {}

impl<M> core::fmt::Debug for DialectInfo<M> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("DialectInfo")
    }
}

impl<M: MessageSet> CrcExtra for DialectInfo<M> {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        M::info(id).map(|info| info.crc_extra)
    }
}

impl<M: MessageSet> Dialect for DialectInfo<M> {
    #[inline]
    fn info(&self, id: u32) -> Option<MessageInfo> {
        M::info(id).copied()
    }
}

/// The facts of whatever dialect a function knows: a plain `fn` pointer, so that the
/// dialect can be chosen at run time (e.g. by name on a command line).
///
/// ```
/// use mavstack_core::MessageSet as _;
/// use mavstack_router::{Dialect, InfoFn};
/// let apm = InfoFn(|id| mavstack_dialects::common::MavMessage::info(id).copied());
/// assert_eq!(apm.info(0).map(|i| i.crc_extra), Some(50));
/// ```
#[derive(Clone, Copy, Debug)]
pub struct InfoFn(pub fn(u32) -> Option<MessageInfo>);

impl CrcExtra for InfoFn {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        (self.0)(id).map(|info| info.crc_extra)
    }
}

impl Dialect for InfoFn {
    #[inline]
    fn info(&self, id: u32) -> Option<MessageInfo> {
        (self.0)(id)
    }
}

/// The target `(system, component)` of a frame's payload as transmitted: read through the
/// message's target offsets, 0 (broadcast) for a message without target fields, an unknown
/// message, or a field that MAVLink 2 truncation or a MAVLink 1 frame left out.
#[must_use]
pub fn target_of(info: Option<&MessageInfo>, payload: &[u8]) -> (u8, u8) {
    let Some(info) = info else {
        return (0, 0);
    };
    let read = |offset: Option<u8>| {
        offset
            .and_then(|o| payload.get(usize::from(o)))
            .copied()
            .unwrap_or(0)
    };
    (
        read(info.target_system_offset),
        read(info.target_component_offset),
    )
}

/// Whether message `id` is configuration or control traffic (commands, parameters,
/// missions, signing setup, the handshake, file transfer, HEARTBEAT): it goes through a
/// link's priority queue and is never rate limited, so telemetry cannot starve it.
#[must_use]
pub const fn is_control(id: u32) -> bool {
    matches!(
        id,
        0 // HEARTBEAT
        | 11 // SET_MODE
        | 20..=23 // PARAM_REQUEST_READ, PARAM_REQUEST_LIST, PARAM_VALUE, PARAM_SET
        | 37..=41 // MISSION_{REQUEST_PARTIAL,WRITE_PARTIAL}_LIST, MISSION_ITEM, MISSION_REQUEST, MISSION_SET_CURRENT
        | 43..=47 // MISSION_REQUEST_LIST, COUNT, CLEAR_ALL, ITEM_REACHED, ACK
        | 51 // MISSION_REQUEST_INT
        | 66 // REQUEST_DATA_STREAM
        | 73 // MISSION_ITEM_INT
        | 75..=77 // COMMAND_INT, COMMAND_LONG, COMMAND_ACK
        | 80 // COMMAND_CANCEL
        | 110 // FILE_TRANSFER_PROTOCOL
        | 256 // SETUP_SIGNING
        | 300 // PROTOCOL_VERSION
        | 320..=324 // PARAM_EXT_*
        | 345 // PARAM_ERROR
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::common::MavMessage;

    #[test]
    fn targets_are_bounds_checked() {
        let d = DialectInfo::<MavMessage>::new();
        let long = d.info(76).unwrap(); // COMMAND_LONG: target at 30, 31
        let mut payload = [0u8; 33];
        payload[30] = 7;
        payload[31] = 9;
        assert_eq!(target_of(Some(&long), &payload), (7, 9));
        // Truncated at the target component: it reads as 0.
        assert_eq!(target_of(Some(&long), &payload[..31]), (7, 0));
        assert_eq!(target_of(Some(&long), &[]), (0, 0));
        let hb = d.info(0).unwrap();
        assert_eq!(target_of(Some(&hb), &[1; 9]), (0, 0));
        assert_eq!(target_of(None, &payload), (0, 0));
    }

    #[test]
    fn control_traffic_is_classified() {
        for id in [
            0, 20, 21, 22, 23, 39, 40, 43, 44, 45, 47, 51, 73, 75, 76, 77, 256, 300,
        ] {
            assert!(is_control(id), "{id}");
        }
        for id in [1, 24, 30, 33, 74, 109, 242, 253] {
            assert!(!is_control(id), "{id}");
        }
    }
}
