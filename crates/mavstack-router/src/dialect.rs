//! What the router reads about a message without decoding it, through the dialect's
//! [`MessageTable`](mavstack_core::MessageTable): CRC_EXTRA (to check and rewrite
//! checksums), the base length (for MAVLink 1) and the target offsets.
//!
//! ```
//! use mavstack_router::MessageTable;
//! let common = MessageTable::of::<mavstack_dialects::common::MavMessage>();
//! let ack = common.info(77).unwrap(); // COMMAND_ACK: its target is an extension field
//! assert_eq!((ack.min_len, ack.target_system_offset), (3, Some(8)));
//! ```

use mavstack_core::message::MessageInfo;

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
/// missions, signing setup, the handshake, file transfer, log requests, HEARTBEAT): it goes through a
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
        | 117..=119 // LOG_REQUEST_LIST, LOG_ENTRY, LOG_REQUEST_DATA (not LOG_DATA: bulk)
        | 121..=122 // LOG_ERASE, LOG_REQUEST_END
        | 256 // SETUP_SIGNING
        | 300 // PROTOCOL_VERSION
        | 320..=324 // PARAM_EXT_*
        | 345 // PARAM_ERROR
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_core::MessageTable;
    use mavstack_dialects::common::MavMessage;

    #[test]
    fn targets_are_bounds_checked() {
        let d = MessageTable::of::<MavMessage>();
        let long = d.info(76).unwrap(); // COMMAND_LONG: target at 30, 31
        let mut payload = [0u8; 33];
        payload[30] = 7;
        payload[31] = 9;
        assert_eq!(target_of(Some(long), &payload), (7, 9));
        // Truncated at the target component: it reads as 0.
        assert_eq!(target_of(Some(long), &payload[..31]), (7, 0));
        assert_eq!(target_of(Some(long), &[]), (0, 0));
        let hb = d.info(0).unwrap();
        assert_eq!(target_of(Some(hb), &[1; 9]), (0, 0));
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
