//! The mavlink2rest JSON mapping against mavlink2rest 1.0.2's own answers, recorded by
//! `tests-interop/mavlink2rest_compare.py` (see `tests/fixtures/mavlink2rest/README.md`):
//! every message type the simulated vehicle sends (both flavours), as 1.0.2 wrote each frame,
//! and the template of every ardupilotmega message.
#![cfg(feature = "http")]

use mavstack::web::default_mapping;
use mavstack::web::json::Header;
use mavstack_core::wire::Frame;
use serde_json::{Map, Value as Json};

const MESSAGES: [&str; 2] = [
    include_str!("fixtures/mavlink2rest/messages-ardupilot.json"),
    include_str!("fixtures/mavlink2rest/messages-px4.json"),
];
const TEMPLATES: &str = include_str!("fixtures/mavlink2rest/templates.jsonl");

/// Fields our definitions (`definitions/`) and rust-mavlink 0.16.2's (which 1.0.2 is built
/// with) define differently: present in only one, or with another enum or bitmask. With
/// rust-mavlink's XML the mapping writes them as 1.0.2 does (`web_json.rs`,
/// `templates_equal_mavlink2rest_on_its_own_definitions`).
const DEFINITION_DIFFERENCES: &[(&str, &[&str])] = &[
    (
        "MISSION_CURRENT",
        &["fence_id", "mission_id", "rally_points_id"],
    ),
    ("MISSION_COUNT", &["opaque_id"]),
    ("MISSION_ACK", &["opaque_id"]),
    ("SET_ATTITUDE_TARGET", &["thrust_body"]),
    ("TIMESYNC", &["target_component", "target_system"]),
    ("SERIAL_CONTROL", &["target_component", "target_system"]),
    ("GIMBAL_DEVICE_INFORMATION", &["cap_flags2"]),
    ("WIFI_CONFIG_AP", &["mode", "response"]),
    ("ONBOARD_COMPUTER_STATUS", &["status_flags"]),
    ("REQUEST_DATA_STREAM", &["req_stream_id"]),
    ("DATA_STREAM", &["stream_id"]),
    ("LANDING_TARGET", &["position_valid"]),
    ("CAMERA_IMAGE_CAPTURED", &["capture_result"]),
    ("CAMERA_TRACKING_IMAGE_STATUS", &["tracking_status"]),
    ("CAMERA_TRACKING_GEO_STATUS", &["tracking_status"]),
    ("AIS_VESSEL", &["navigational_status"]),
];

/// Messages only our definitions have (1.0.2 answers "Invalid message name.").
const ONLY_OURS: &[&str] = &[
    "AIRSPEED",
    "GLOBAL_POSITION_SENSOR",
    "PARAM_ERROR",
    "RELAY_STATUS",
    "NAMED_VALUE_STRING",
];

fn without_differences(name: &str, value: &Json) -> Json {
    let skip = DEFINITION_DIFFERENCES
        .iter()
        .find(|(n, _)| *n == name)
        .map_or(&[][..], |(_, fields)| *fields);
    match value {
        Json::Object(map) => Json::Object(
            map.iter()
                .filter(|(k, _)| !skip.contains(&k.as_str()))
                .map(|(k, v)| (k.clone(), v.clone()))
                .collect::<Map<_, _>>(),
        ),
        other => other.clone(),
    }
}

fn hex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).expect("hex"))
        .collect()
}

#[test]
fn frames_are_written_and_read_as_mavlink2rest_does() {
    let mapping = default_mapping();
    let mut types = std::collections::BTreeSet::new();
    for file in MESSAGES {
        let entries: Vec<Json> = serde_json::from_str(file).expect("fixture");
        for entry in entries {
            let bytes = hex(entry["frame"].as_str().expect("frame"));
            let frame = Frame::new_checked(&bytes[..]).expect("a whole frame");
            let theirs = &entry["mavlink2rest"];
            let name = theirs["message"]["type"].as_str().expect("type");
            types.insert(name.to_owned());
            // Written: the header and the message, as 1.0.2 wrote this frame.
            let header = Header {
                system_id: frame.sysid(),
                component_id: frame.compid(),
                sequence: frame.seq(),
            };
            assert_eq!(header.to_json(), theirs["header"], "{name}");
            let ours = mapping
                .message_json(frame.msg_id(), frame.payload())
                .expect("a known message");
            assert_eq!(
                without_differences(name, &ours),
                without_differences(name, &theirs["message"]),
                "{name}"
            );
            // Key order too: 1.0.2's objects are sorted by key.
            let keys: Vec<&String> = ours.as_object().expect("object").keys().collect();
            let mut sorted = keys.clone();
            sorted.sort();
            assert_eq!(keys, sorted, "{name}");
            // Read: 1.0.2's object is the same payload (fields it lacks left zero).
            if DEFINITION_DIFFERENCES.iter().all(|(n, _)| *n != name) {
                let (id, payload) = mapping
                    .parse_message(&theirs["message"])
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
                assert_eq!(id, frame.msg_id());
                let mut sent = frame.payload().to_vec();
                sent.resize(payload.len(), 0);
                assert_eq!(payload, sent, "{name}");
            }
        }
    }
    // Every message type the simulator sent in the recording, both flavours together.
    assert!(types.len() >= 22, "{types:?}");
    for name in [
        "HEARTBEAT",
        "STATUSTEXT",
        "COMMAND_ACK",
        "AUTOPILOT_VERSION",
        "PARAM_VALUE",
    ] {
        assert!(types.contains(name), "{name} missing from the fixtures");
    }
}

#[test]
fn templates_are_mavlink2rest_s() {
    let mapping = default_mapping();
    let mut compared = 0;
    for line in TEMPLATES.lines() {
        let t: Json = serde_json::from_str(line).expect("a JSON line");
        let name = t["name"].as_str().expect("name");
        let ours = mapping.template(name);
        if t["status"] == 404 {
            assert!(
                ONLY_OURS.contains(&name) == ours.is_some(),
                "{name}: 1.0.2 does not know it"
            );
            continue;
        }
        let ours = ours.unwrap_or_else(|| panic!("{name}: no template"));
        assert_eq!(ours["header"], t["body"]["header"], "{name}");
        assert_eq!(
            without_differences(name, &ours["message"]),
            without_differences(name, &t["body"]["message"]),
            "{name}"
        );
        compared += 1;
    }
    assert!(compared > 290, "{compared}");
}
