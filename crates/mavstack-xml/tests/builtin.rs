//! Every vendored dialect loads, and the CRC_EXTRA / length anchors of `docs/protocol-notes.md` hold.

use mavstack_xml::{builtin, load};

#[test]
fn every_builtin_dialect_loads() {
    let names = builtin::dialect_names();
    assert!(names.len() >= 19, "{names:?}");
    for name in names {
        let d = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(
            !d.messages.is_empty() || name == "minimal",
            "{name} has no messages"
        );
        assert_eq!(d.root().stem(), name);
    }
}

/// Golden CRC_EXTRA and lengths: `docs/protocol-notes.md` §2, checked against the headers
/// the C generator writes. The anchors are from a 2026 common.xml; the vendored one (pymavlink
/// 2.4.50) predates some extension fields (MISSION_CURRENT, MISSION_COUNT, MISSION_ACK,
/// TIMESYNC are shorter here), so only id, CRC_EXTRA and the base length are anchored:
/// extensions never change those. Full lengths are compared with pymavlink 2.4.50 itself in
/// `tests/pymavlink_definitions.rs`.
#[test]
fn crc_extra_anchors_for_common() {
    let common = load("common").expect("common loads");
    let anchors: &[(&str, u32, u8, usize)] = &[
        ("HEARTBEAT", 0, 50, 9),
        ("SYS_STATUS", 1, 124, 31),
        ("SYSTEM_TIME", 2, 137, 12),
        ("PING", 4, 237, 14),
        ("PARAM_REQUEST_READ", 20, 214, 20),
        ("PARAM_REQUEST_LIST", 21, 159, 2),
        ("PARAM_VALUE", 22, 220, 25),
        ("PARAM_SET", 23, 168, 23),
        ("GPS_RAW_INT", 24, 24, 30),
        ("ATTITUDE", 30, 39, 28),
        ("GLOBAL_POSITION_INT", 33, 104, 28),
        ("MISSION_ITEM", 39, 254, 37),
        ("MISSION_REQUEST", 40, 230, 4),
        ("MISSION_CURRENT", 42, 28, 2),
        ("MISSION_REQUEST_LIST", 43, 132, 2),
        ("MISSION_COUNT", 44, 221, 4),
        ("MISSION_CLEAR_ALL", 45, 232, 2),
        ("MISSION_ITEM_REACHED", 46, 11, 2),
        ("MISSION_ACK", 47, 153, 3),
        ("MISSION_REQUEST_INT", 51, 196, 4),
        ("MISSION_ITEM_INT", 73, 38, 37),
        ("COMMAND_INT", 75, 158, 35),
        ("COMMAND_LONG", 76, 152, 33),
        ("COMMAND_ACK", 77, 143, 3),
        ("RADIO_STATUS", 109, 185, 9),
        ("TIMESYNC", 111, 34, 16),
        ("AUTOPILOT_VERSION", 148, 178, 60),
        ("HOME_POSITION", 242, 104, 52),
        ("MESSAGE_INTERVAL", 244, 95, 6),
        ("EXTENDED_SYS_STATE", 245, 130, 2),
        ("STATUSTEXT", 253, 83, 51),
        ("SETUP_SIGNING", 256, 71, 42),
        ("PROTOCOL_VERSION", 300, 217, 22),
        // extras/events.xml: CRC_EXTRA and lengths as the MAVLink C library generated from
        // the official definitions has them (mavlink_msg_event.h and its neighbours).
        ("COMPONENT_METADATA", 397, 182, 108),
        ("EVENT", 410, 160, 53),
        ("CURRENT_EVENT_SEQUENCE", 411, 106, 3),
        ("REQUEST_EVENT", 412, 33, 6),
        ("RESPONSE_EVENT_ERROR", 413, 77, 7),
        // extras/standard_modes.xml: as pymavlink 2.4.50 generates them from the official
        // development.xml (MAVLink_available_modes_message.crc_extra and its neighbours).
        ("AVAILABLE_MODES", 435, 134, 46),
        ("CURRENT_MODE", 436, 193, 9),
        ("AVAILABLE_MODES_MONITOR", 437, 30, 1),
    ];
    for &(name, id, crc, min) in anchors {
        let m = common
            .message_by_name(name)
            .unwrap_or_else(|| panic!("{name} missing"));
        assert_eq!((m.id, m.crc_extra, m.min_len), (id, crc, min), "{name}");
    }
}

#[test]
fn wire_order_of_worked_layouts() {
    let common = load("common").expect("common loads");
    let offsets = |name: &str| -> Vec<(String, usize, bool)> {
        let m = common.message_by_name(name).expect("message exists");
        m.fields
            .iter()
            .map(|f| (f.name.clone(), f.offset, f.extension))
            .collect()
    };
    let mission_count = offsets("MISSION_COUNT");
    let expected = [
        ("count", 0, false),
        ("target_system", 2, false),
        ("target_component", 3, false),
        ("mission_type", 4, true),
    ];
    assert_eq!(mission_count.len(), expected.len());
    for (got, want) in mission_count.iter().zip(expected) {
        assert_eq!((got.0.as_str(), got.1, got.2), want);
    }
    let hb = common.message(0).expect("HEARTBEAT");
    assert_eq!(hb.fields[0].name, "custom_mode");
    assert!(hb.fields.iter().any(|f| f.ty.mavlink_version));
    let cmd = common
        .message_by_name("COMMAND_LONG")
        .expect("COMMAND_LONG");
    assert_eq!(
        (cmd.target_system_offset, cmd.target_component_offset),
        (Some(30), Some(31))
    );
}

#[test]
fn protocol_version_reaches_every_dialect_that_includes_common() {
    for name in ["common", "ardupilotmega", "all", "development", "storm32"] {
        let d = load(name).expect("loads");
        let pv = d
            .message(300)
            .unwrap_or_else(|| panic!("{name} lacks PROTOCOL_VERSION"));
        assert_eq!((pv.name.as_str(), pv.crc_extra), ("PROTOCOL_VERSION", 217));
        assert!(
            pv.file.ends_with("common.xml"),
            "{name}: belongs to {:?}",
            pv.file
        );
        assert!(pv.location.file.ends_with("protocol_version.xml"));
    }
    assert!(load("minimal").expect("loads").message(300).is_none());
}

#[test]
fn the_events_protocol_reaches_every_dialect_that_includes_common() {
    for name in ["common", "ardupilotmega", "all", "development"] {
        let d = load(name).expect("loads");
        for id in [397, 410, 411, 412, 413] {
            let m = d
                .message(id)
                .unwrap_or_else(|| panic!("{name} lacks message {id}"));
            assert!(m.file.ends_with("common.xml"), "{name}: {:?}", m.file);
            assert!(m.location.file.ends_with("events.xml"));
        }
        assert!(d.enum_by_name("MAV_EVENT_ERROR_REASON").is_some());
    }
    assert!(load("minimal").expect("loads").message(410).is_none());
}

#[test]
fn enums_merge_across_files() {
    let apm = load("ardupilotmega").expect("loads");
    let cmd = apm.enum_by_name("MAV_CMD").expect("MAV_CMD");
    let from_common = cmd
        .entries
        .iter()
        .filter(|e| e.file.ends_with("common.xml"))
        .count();
    let from_apm = cmd
        .entries
        .iter()
        .filter(|e| e.file.ends_with("ardupilotmega.xml"))
        .count();
    assert!(
        from_common > 100 && from_apm > 10,
        "{from_common} {from_apm}"
    );
    assert!(cmd.file.ends_with("common.xml"));
}

#[test]
fn every_field_enum_is_defined() {
    let mut undefined = Vec::new();
    for name in builtin::dialect_names() {
        let d = load(name).expect("loads");
        for m in &d.messages {
            for f in &m.fields {
                if let Some(e) = &f.enum_name
                    && d.enum_by_name(e).is_none()
                {
                    undefined.push(format!("{name}: {}.{} -> {e}", m.name, f.name));
                }
            }
        }
    }
    assert!(undefined.is_empty(), "{undefined:#?}");
}
