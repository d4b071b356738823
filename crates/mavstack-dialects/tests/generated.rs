//! The generated code agrees with the run-time model on every message of every dialect, and
//! with the protocol's golden vectors.
#![cfg(feature = "all")]

use mavstack_core::{MAX_PAYLOAD_LEN, Message, MessageSet};
use mavstack_dialects::{all, ardupilotmega, common, matrixpilot, minimal, paparazzi};
use mavstack_xml::codec;
use proptest::prelude::*;

/// Every dialect module's message table, by built-in dialect name.
fn tables() -> Vec<(&'static str, &'static [mavstack_core::MessageInfo])> {
    vec![
        ("all", all::MavMessage::all()),
        ("ardupilotmega", ardupilotmega::MavMessage::all()),
        ("common", common::MavMessage::all()),
        ("minimal", minimal::MavMessage::all()),
        ("matrixpilot", matrixpilot::MavMessage::all()),
        ("paparazzi", paparazzi::MavMessage::all()),
        ("standard", mavstack_dialects::standard::MavMessage::all()),
        (
            "development",
            mavstack_dialects::development::MavMessage::all(),
        ),
        ("storm32", mavstack_dialects::storm32::MavMessage::all()),
        ("ASLUAV", mavstack_dialects::asluav::MavMessage::all()),
        ("AVSSUAS", mavstack_dialects::avssuas::MavMessage::all()),
        ("csAirLink", mavstack_dialects::csairlink::MavMessage::all()),
        ("cubepilot", mavstack_dialects::cubepilot::MavMessage::all()),
        ("icarous", mavstack_dialects::icarous::MavMessage::all()),
        (
            "loweheiser",
            mavstack_dialects::loweheiser::MavMessage::all(),
        ),
        (
            "python_array_test",
            mavstack_dialects::python_array_test::MavMessage::all(),
        ),
        ("test", mavstack_dialects::test::MavMessage::all()),
        ("uAvionix", mavstack_dialects::uavionix::MavMessage::all()),
        ("ualberta", mavstack_dialects::ualberta::MavMessage::all()),
    ]
}

#[test]
fn message_tables_match_the_model() {
    assert_eq!(tables().len(), mavstack_xml::builtin::dialect_names().len());
    for (name, table) in tables() {
        let model = mavstack_xml::load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(table.len(), model.messages.len(), "{name}");
        for (info, m) in table.iter().zip(&model.messages) {
            assert_eq!(
                (
                    info.id,
                    info.name,
                    info.crc_extra,
                    usize::from(info.min_len),
                    usize::from(info.max_len)
                ),
                (m.id, m.name.as_str(), m.crc_extra, m.min_len, m.max_len),
                "{name}"
            );
            assert_eq!(
                info.target_system_offset.map(usize::from),
                m.target_system_offset,
                "{name} {}",
                m.name
            );
            assert_eq!(
                info.target_component_offset.map(usize::from),
                m.target_component_offset,
                "{name} {}",
                m.name
            );
        }
    }
}

/// The `all` model, loaded once.
fn all_model() -> &'static mavstack_xml::Dialect {
    static MODEL: std::sync::OnceLock<mavstack_xml::Dialect> = std::sync::OnceLock::new();
    MODEL.get_or_init(|| mavstack_xml::load("all").expect("all loads"))
}

/// The full payload bytes of a typed message (floats compared bit for bit, NaN included).
fn bytes_of(m: &all::MavMessage) -> Vec<u8> {
    let mut out = [0u8; MAX_PAYLOAD_LEN];
    let len = m.encode(&mut out);
    out[..len].to_vec()
}

fn payload_strategy() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), MAX_PAYLOAD_LEN)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// For every message of `all`: typed decode then encode gives back the bytes, and each
    /// field the typed code reads is the field the model (and so pymavlink) places there.
    #[test]
    fn typed_code_round_trips_every_message_like_the_model(bytes in payload_strategy()) {
        for m in &all_model().messages {
            let payload = &bytes[..m.max_len];
            let typed = all::MavMessage::decode(m.id, payload).expect("id known");
            prop_assert_eq!(typed.id(), m.id);
            let mut out = [0u8; MAX_PAYLOAD_LEN];
            let len = typed.encode(&mut out);
            prop_assert_eq!(len, m.max_len);
            prop_assert_eq!(&out[..len], payload, "{}", m.name);
            // The dynamic codec reads the same fields: re-encoding its values (text cut at
            // the first NUL and zero-filled) equals typed code re-encoding those bytes.
            let values = codec::decode(m, payload);
            let mut dynamic = [0u8; MAX_PAYLOAD_LEN];
            let dlen = codec::encode(m, &values, &mut dynamic).expect("same shape");
            let typed_again = all::MavMessage::decode(m.id, &dynamic[..dlen]).expect("id known");
            prop_assert_eq!(bytes_of(&typed_again), &dynamic[..dlen], "{}", m.name);
        }
    }

    /// A truncated payload decodes like the zero-extended one; a longer one like the cut one.
    #[test]
    fn short_and_long_payloads(bytes in payload_strategy(), cut in 0usize..MAX_PAYLOAD_LEN) {
        for info in all::MavMessage::all() {
            let max = usize::from(info.max_len);
            let n = cut.min(max);
            let mut extended = [0u8; MAX_PAYLOAD_LEN];
            extended[..n].copy_from_slice(&bytes[..n]);
            let short = all::MavMessage::decode(info.id, &bytes[..n]).expect("known");
            let full = all::MavMessage::decode(info.id, &extended[..max]).expect("known");
            prop_assert_eq!(bytes_of(&short), bytes_of(&full));
            let long = all::MavMessage::decode(info.id, &bytes).expect("known");
            let cut_one = all::MavMessage::decode(info.id, &bytes[..max]).expect("known");
            prop_assert_eq!(bytes_of(&long), bytes_of(&cut_one));
        }
    }
}

#[test]
fn unknown_ids_are_reported() {
    assert_eq!(
        minimal::MavMessage::decode(1, &[0; 4]),
        Err(mavstack_core::UnknownMessage { id: 1 })
    );
    assert!(
        common::MavMessage::info(300).is_some(),
        "PROTOCOL_VERSION in common"
    );
    assert!(minimal::MavMessage::info(300).is_none());
}

/// `docs/protocol-notes.md` §5: COMMAND_LONG REQUEST_MESSAGE(300) payload, and (§4) the
/// HEARTBEAT payload of the golden frames.
#[test]
fn golden_payloads() {
    let cmd = common::CommandLong {
        target_system: 1,
        target_component: 1,
        command: common::MavCmd::REQUEST_MESSAGE,
        param1: 300.0,
        ..Default::default()
    };
    let mut out = [0u8; MAX_PAYLOAD_LEN];
    let len = cmd.encode(&mut out);
    let mut expected = vec![0x00, 0x00, 0x96, 0x43];
    expected.extend([0u8; 24]);
    expected.extend([0x00, 0x02, 0x01, 0x01, 0x00]);
    assert_eq!(&out[..len], &expected[..]);
    assert_eq!(mavstack_core::payload::truncated_len(&out[..len]), 32);

    let hb = minimal::Heartbeat::decode(&[0, 0, 0, 0, 2, 12, 0x51, 4, 3]);
    assert_eq!(hb.r#type, minimal::MavType::QUADROTOR);
    assert_eq!(hb.autopilot, minimal::MavAutopilot::PX4);
    assert_eq!(hb.system_status, minimal::MavState::ACTIVE);
    assert!(
        hb.base_mode
            .contains(minimal::MavModeFlag::CUSTOM_MODE_ENABLED)
    );
    assert_eq!(hb.mavlink_version, 3);
    assert_eq!(
        minimal::Heartbeat::default().mavlink_version,
        3,
        "the dialect's <version>"
    );
}

#[test]
fn open_enums_keep_unknown_values() {
    let hb = minimal::Heartbeat::decode(&[0, 0, 0, 0, 250, 200, 0xFF, 99, 3]);
    assert_eq!(hb.r#type, minimal::MavType(250));
    assert_eq!(hb.r#type.name(), None);
    assert_eq!(format!("{:?}", hb.r#type), "MavType(250)");
    assert_eq!(
        format!("{:?}", minimal::MavType::QUADROTOR),
        "MAV_TYPE_QUADROTOR"
    );
    let mut out = [0u8; MAX_PAYLOAD_LEN];
    let len = hb.encode(&mut out);
    assert_eq!(&out[..len], &[0, 0, 0, 0, 250, 200, 0xFF, 99, 3]);
    // A bitmask keeps bits it has no name for and prints the rest as hex.
    let flags = minimal::MavModeFlag(0xFF);
    assert_eq!(flags.bits(), 0xFF);
    let shown = format!("{flags:?}");
    assert!(shown.starts_with("MAV_MODE_FLAG_"), "{shown}");
    assert_eq!(
        minimal::MavType::from_name("MAV_TYPE_QUADROTOR"),
        Some(minimal::MavType::QUADROTOR)
    );
}

#[test]
fn dialects_share_types_and_extend_enums() {
    // One type, seen from every dialect that includes the file defining it.
    let hb: ardupilotmega::Heartbeat = minimal::Heartbeat::default();
    let _: common::Heartbeat = hb;
    let set: ardupilotmega::MavMessage = hb.into();
    assert_eq!(set.id(), 0);
    // ardupilotmega.xml adds MAV_CMD entries to common's MavCmd.
    assert_eq!(common::MavCmd::DO_MOTOR_TEST.0, 209);
    let apm_only =
        common::MavCmd::from_name("MAV_CMD_DO_START_MAG_CAL").expect("ardupilotmega entry");
    assert_eq!(apm_only.name(), Some("MAV_CMD_DO_START_MAG_CAL"));
    // loweheiser.xml extends MAV_CMD without including common.xml: it has a type of its own,
    // and ardupilotmega (which includes both) uses common's, which carries loweheiser's entries.
    let _: ardupilotmega::MavCmd = common::MavCmd::NAV_WAYPOINT;
    assert!(
        mavstack_dialects::loweheiser::MavCmd::from_name("MAV_CMD_LOWEHEISER_SET_STATE").is_some()
    );
    assert!(common::MavCmd::from_name("MAV_CMD_LOWEHEISER_SET_STATE").is_some());
}

#[test]
fn serde_is_available() {
    let hb = minimal::Heartbeat {
        custom_mode: 7,
        ..Default::default()
    };
    let json = serde_json::to_value(hb).expect("serializes");
    assert_eq!(json["custom_mode"], 7);
    let back: minimal::Heartbeat = serde_json::from_value(json).expect("deserializes");
    assert_eq!(back, hb);
    let long = common::Statustext {
        text: [b'x'; 50],
        ..Default::default()
    };
    let back: common::Statustext =
        serde_json::from_str(&serde_json::to_string(&long).expect("ser")).expect("de");
    assert_eq!(back, long);
}
