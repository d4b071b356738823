//! The vehicle's side of the version rules: MAVLink 1 until a MAVLink 2 frame, its handshake
//! answers (or a NACK, or silence), its capability bit, signing.

use mavstack_channel::{
    Channel, CommandEncoding, Config, Event, GroundPolicy, HandshakeMethod, HandshakeResult,
    LinkVersion, ProtocolVersionAnswer, Role, SwitchCause, VehicleVersion,
};
use mavstack_core::message::Message;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandLong, Heartbeat, MavCmd, MavProtocolCapability, MavResult,
};

use super::util::{self, Origin, Pair, T0, feed, frame, transmits};
use super::{
    gcs, gcs_without_fallback, only_outcome, silent_vehicle, start, vehicle, version_changes,
};

#[test]
fn vehicle_starts_mavlink1_and_switches_on_first_mavlink2_frame() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::StartMavlink1),
        gcs(GroundPolicy::Mavlink2),
    );
    p.vehicle_send(&Heartbeat::default());
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink1);
    // A MAVLink 1 frame does not switch it.
    let v1 = frame(Version::V1, 0, 255, 190, &Heartbeat::default());
    p.deliver_now(util::Node::Vehicle, &v1);
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink1);
    p.gcs_send(&Heartbeat::default()); // the configured GCS sends MAVLink 2
    p.drive();
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink2);
    assert_eq!(
        version_changes(&p.vehicle_events),
        [(
            LinkVersion::Mavlink1,
            LinkVersion::Mavlink2,
            SwitchCause::Mavlink2Received
        )]
    );
    p.vehicle_send(&Heartbeat::default());
    let sent: Vec<bool> = p
        .sent_by(Origin::Vehicle)
        .iter()
        .map(|s| s.is_v2())
        .collect();
    assert_eq!(sent, [false, true]);
}

#[test]
fn vehicle_with_mavlink2_disabled_nacks_in_mavlink1_and_never_switches() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink1Only),
        gcs(GroundPolicy::Automatic),
    );
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    assert_eq!(
        only_outcome(&p),
        HandshakeResult::Nack {
            result: MavResult::UNSUPPORTED
        }
    );
    // MAVLink 2 frames arrive and are parsed, but the link never switches.
    p.gcs_send(&Heartbeat::default());
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink1);
    assert!(version_changes(&p.vehicle_events).is_empty());
    let vehicle_sent = p.sent_by(Origin::Vehicle);
    assert!(vehicle_sent.iter().all(|s| !s.is_v2()));
    // The NACK is a MAVLink 1 COMMAND_ACK: base fields only (3 bytes), no extensions.
    let nack = vehicle_sent
        .iter()
        .find(|s| s.msg_id() == CommandAck::ID)
        .unwrap();
    assert_eq!(nack.payload().len(), 3);
    let ack = CommandAck::decode(nack.payload());
    assert_eq!(
        (ack.command, ack.result),
        (MavCmd::REQUEST_MESSAGE, MavResult::UNSUPPORTED)
    );
    assert!(p.vehicle_events.iter().any(|e| matches!(
        e,
        Event::ProtocolVersionRequested {
            answer: ProtocolVersionAnswer::Nacked(MavResult::UNSUPPORTED),
            ..
        }
    )));
}

#[test]
fn vehicle_nack_result_is_configurable() {
    let mut config = vehicle(VehicleVersion::Mavlink1Only);
    if let Role::Vehicle(policy) = &mut config.role {
        policy.nack_result = MavResult::DENIED;
    }
    let mut p = Pair::new(config, gcs(GroundPolicy::Automatic));
    start(
        &mut p,
        HandshakeMethod::RequestProtocolVersion,
        CommandEncoding::Long,
    );
    p.drive();
    assert_eq!(
        only_outcome(&p),
        HandshakeResult::Nack {
            result: MavResult::DENIED
        }
    );
}

#[test]
fn vehicle_with_signing_sends_signed_mavlink2_from_the_first_frame() {
    let mut config = vehicle(VehicleVersion::StartMavlink1);
    config.signing = Some(mavstack_channel::SigningConfig::new(util::key(), 1));
    let mut p = Pair::new(config, gcs(GroundPolicy::Automatic));
    assert_eq!(p.vehicle.version(), LinkVersion::SignedMavlink2);
    p.vehicle_send(&Heartbeat::default());
    let first = &p.sent_by(Origin::Vehicle)[0];
    assert!(first.is_v2() && first.is_signed());
}

#[test]
fn signing_with_mavlink2_disabled_is_a_config_error() {
    let mut config = vehicle(VehicleVersion::Mavlink1Only);
    config.signing = Some(mavstack_channel::SigningConfig::new(util::key(), 1));
    assert_eq!(
        Channel::new(config).unwrap_err(),
        mavstack_channel::ConfigError::SigningNeedsMavlink2
    );
    assert_eq!(
        Channel::new(Config::vehicle(0, 1)).unwrap_err(),
        mavstack_channel::ConfigError::ZeroSystemId
    );
    assert_eq!(
        Channel::new(Config::vehicle(1, 0)).unwrap_err(),
        mavstack_channel::ConfigError::ZeroComponentId
    );
}

#[test]
fn capability_flag_is_set_iff_mavlink2_would_be_accepted() {
    let cap = |v| Channel::new(vehicle(v)).unwrap().capabilities();
    // Set even while the link still sends MAVLink 1.
    let starting_v1 = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    assert_eq!(starting_v1.version(), LinkVersion::Mavlink1);
    assert_eq!(starting_v1.capabilities(), MavProtocolCapability::MAVLINK2);
    assert_eq!(
        cap(VehicleVersion::Mavlink2),
        MavProtocolCapability::MAVLINK2
    );
    assert_eq!(cap(VehicleVersion::Mavlink1Only), MavProtocolCapability(0));
    assert_eq!(MavProtocolCapability::MAVLINK2.0, 8192);
}

#[test]
fn vehicle_configured_mavlink2_sends_mavlink2_from_the_start() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink2),
        gcs(GroundPolicy::Automatic),
    );
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink2);
    p.vehicle_send(&Heartbeat::default());
    assert!(p.sent_by(Origin::Vehicle)[0].is_v2());
}

#[test]
fn vehicle_without_protocol_version_support_stays_silent() {
    let mut p = Pair::new(
        silent_vehicle(VehicleVersion::StartMavlink1),
        gcs_without_fallback(GroundPolicy::Automatic),
    );
    start(
        &mut p,
        HandshakeMethod::RequestProtocolVersion,
        CommandEncoding::Long,
    );
    p.drive();
    assert!(
        p.sent_by(Origin::Vehicle).is_empty(),
        "neither ACK nor answer"
    );
    // The requests reach the application, unanswered, for its own command handling.
    let frames = Pair::frames(&p.vehicle_events);
    assert!(!frames.is_empty());
    assert!(frames.iter().all(|f| f.msg_id() == CommandLong::ID
        && !f.answered
        && f.protocol_version_request == Some(ProtocolVersionAnswer::Ignored)));
    assert!(p.vehicle_events.iter().any(|e| matches!(
        e,
        Event::ProtocolVersionRequested {
            answer: ProtocolVersionAnswer::Ignored,
            ..
        }
    )));
}

#[test]
fn vehicle_answers_requests_for_itself_or_broadcast_only() {
    let now = T0;
    let mut v = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let request = |ts: u8, tc: u8| CommandLong {
        target_system: ts,
        target_component: tc,
        command: MavCmd::REQUEST_PROTOCOL_VERSION,
        param1: 1.0,
        ..CommandLong::default()
    };
    for (ts, tc, answered) in [
        (2, 1, false),
        (1, 2, false),
        (1, 1, true),
        (0, 0, true),
        (1, 0, true),
    ] {
        let events = feed(
            &mut v,
            now,
            &frame(Version::V1, 0, 255, 190, &request(ts, tc)),
        );
        let Event::Frame(f) = &events[0] else {
            panic!("{events:?}")
        };
        assert_eq!(f.answered, answered, "target {ts}/{tc}");
        let expected = answered.then_some(ProtocolVersionAnswer::Accepted);
        assert_eq!(f.protocol_version_request, expected);
        assert_eq!(transmits(&mut v, now).len(), if answered { 2 } else { 0 });
    }
}

#[test]
fn request_message_for_another_message_is_left_to_the_application() {
    let mut v = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let other = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::REQUEST_MESSAGE,
        param1: AutopilotVersion::ID as f32,
        ..CommandLong::default()
    };
    let events = feed(&mut v, T0, &frame(Version::V1, 0, 255, 190, &other));
    assert!(matches!(&events[..], [Event::Frame(f)] if !f.answered));
    assert!(transmits(&mut v, T0).is_empty());
}
