//! `mavstack demo`, the README's first command: it must run the whole story on loopback and
//! end by itself with exit 0, and its timeline must show each step, the parameter and mission
//! exchange included, and the MAVLink 1-only peripheral on a link of its own with frames
//! converted both ways. How fast it runs is not asserted (a loaded machine would make that
//! flake); that it ends without being stopped is.

use crate::ends;

use std::process::Command;

#[test]
fn demo_runs_the_handshake_signing_and_attacks_and_ends_by_itself() {
    let out =
        ends::output_ending_by_itself(Command::new(env!("CARGO_BIN_EXE_mavstack")).arg("demo"));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "demo failed ({}):\n{text}{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    for step in [
        "HEARTBEAT from vehicle 1/1 (MAVLink 1)",
        "RADIO_STATUS from the radio (MAVLink 1)",
        "vehicle: link MAVLink 1 → MAVLink 2 (a MAVLink 2 frame arrived)",
        "PROTOCOL_VERSION 200 (min 100, max 200) in MAVLink 2",
        "RADIO_STATUS from the radio (MAVLink 2)",
        "MAV_PROTOCOL_CAPABILITY_MAVLINK2 set",
        "SETUP_SIGNING accepted",
        "signed, signature verified",
        "vehicle ✗ rejected COMMAND_LONG: replayed: timestamp",
        "vehicle ✗ rejected COMMAND_LONG: signature matches none of the link's keys",
        "the genuine stream is still accepted",
        "ground station ← 35 PARAM_VALUEs",
        "PARAM_SET WPNAV_SPEED 500 → 750; vehicle confirms 750",
        "vehicle: param WPNAV_SPEED = 750",
        "vehicle: mission plan stored: 6 items",
        "mission read back: 6 items, identical",
        "1 replay and 1 forgery rejected",
        "HEARTBEAT from the rangefinder 1/158 (MAVLink 1)",
        "HEARTBEAT from the rangefinder 1/158 (MAVLink 2, signed): it speaks MAVLink 1",
        "rangefinder ← COMMAND_LONG SET_MESSAGE_INTERVAL from 255/190 in MAVLink 1",
        "COMMAND_ACK ACCEPTED from the rangefinder",
        "every one signed MAVLink 2",
        "vehicle's radio link (signed MAVLink 2)",
        "vehicle's peripheral link (MAVLink 1)",
        "every one MAVLink 1 (0 refused)",
    ] {
        assert!(text.contains(step), "the timeline lacks {step:?}:\n{text}");
    }
    // Reasons and states read as words, not as Rust's Debug output.
    for debug in [
        "Mavlink2Received",
        "Replayed {",
        "BadSignature",
        "SigningEnabled",
        "MAV_MISSION_TYPE_",
    ] {
        assert!(
            !text.contains(debug),
            "the timeline prints {debug:?}:\n{text}"
        );
    }
}
