//! The digest's golden vectors (§10): the handshake request, the vehicle's ACK, a MAVLink 1
//! request, byte for byte.

use mavstack_channel::{
    Channel, CommandEncoding, GroundPolicy, HandshakeMethod, Target, VehicleVersion,
};
use mavstack_core::wire::Version;
use mavstack_dialects::common::{CommandLong, MavCmd};

use super::util::{T0, feed, frame, transmits};
use super::{gcs, vehicle};

#[test]
fn handshake_request_matches_the_digest_golden_vector() {
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    g.start_handshake(
        T0,
        Target::new(1, 1),
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    )
    .unwrap();
    let out = transmits(&mut g, T0);
    let expected =
        "fd20000000ffbe4c000000009643000000000000000000000000000000000000000000000000000201016b39";
    assert_eq!(hex(&out[0]), expected);
}

#[test]
fn vehicle_ack_matches_the_digest_golden_vector() {
    let mut v = Channel::new(vehicle(VehicleVersion::Mavlink2)).unwrap();
    let request =
        "fd20000000ffbe4c000000009643000000000000000000000000000000000000000000000000000201016b39";
    let _ = feed(&mut v, T0, &unhex(request));
    let out = transmits(&mut v, T0);
    assert_eq!(hex(&out[0]), "fd0a00000001014d00000002000000000000ffbe5dc4");
}

#[test]
fn v1_request_matches_the_digest_golden_vector() {
    let request = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::REQUEST_MESSAGE,
        param1: 300.0,
        ..CommandLong::default()
    };
    assert_eq!(
        hex(&frame(Version::V1, 0, 255, 190, &request)),
        "fe2100ffbe4c0000964300000000000000000000000000000000000000000000000000020101006caa"
    );
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(text: &str) -> Vec<u8> {
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
        .collect()
}
