//! The version rules of the protocol digest (§5, with the framing rules of §1–2 that a link
//! depends on), one named test per rule, over the simulation harness.

mod util;

use core::time::Duration;

use mavstack_channel::{
    Channel, CommandEncoding, Config, Event, GroundPolicy, HandshakeError, HandshakeMethod,
    HandshakeResult, LinkVersion, ProtocolVersionAnswer, Role, SendError, SwitchCause, Target,
    VehicleVersion,
};
use mavstack_core::message::Message;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandLong, FlightInformation, Heartbeat, MavCmd,
    MavProtocolCapability, MavResult, ProtocolVersion,
};
use util::{Origin, Pair, T0, feed, frame, transmits};

fn vehicle(version: VehicleVersion) -> Config {
    let mut c = Config::vehicle(1, 1);
    c.vehicle_policy_mut().unwrap().version = version;
    c
}

fn silent_vehicle(version: VehicleVersion) -> Config {
    let mut c = vehicle(version);
    c.vehicle_policy_mut().unwrap().protocol_version = None;
    c
}

fn gcs(policy: GroundPolicy) -> Config {
    let mut c = Config::ground_station(255, 190);
    c.role = Role::GroundStation(policy);
    c
}

/// A ground station that takes a refusal or silence as the outcome (no fallback request for
/// AUTOPILOT_VERSION): what the first phase does on its own.
fn gcs_without_fallback(policy: GroundPolicy) -> Config {
    let mut c = gcs(policy);
    c.handshake.fallback = None;
    c
}

fn start(p: &mut Pair, method: HandshakeMethod, encoding: CommandEncoding) {
    p.gcs
        .start_handshake(p.now, Target::new(1, 1), method, encoding)
        .unwrap();
}

fn version_changes(events: &[Event]) -> Vec<(LinkVersion, LinkVersion, SwitchCause)> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::VersionChanged { from, to, cause } => Some((*from, *to, *cause)),
            _ => None,
        })
        .collect()
}

fn only_outcome(p: &Pair) -> HandshakeResult {
    let outcomes = p.handshake_outcomes();
    assert_eq!(outcomes.len(), 1, "{outcomes:?}");
    outcomes[0].result
}

// ----- vehicle -------------------------------------------------------------------------

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

// ----- ground station ------------------------------------------------------------------

#[test]
fn gcs_switches_on_first_mavlink2_frame() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink2),
        gcs(GroundPolicy::Automatic),
    );
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink1);
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    assert_eq!(
        version_changes(&p.gcs_events),
        [(
            LinkVersion::Mavlink1,
            LinkVersion::Mavlink2,
            SwitchCause::Mavlink2Received
        )]
    );
}

#[test]
fn gcs_switches_on_autopilot_version_capability_flag() {
    let mut p = Pair::default_pair();
    let caps = p.vehicle.capabilities() | MavProtocolCapability::MISSION_INT;
    p.vehicle_send(&AutopilotVersion {
        capabilities: caps,
        ..AutopilotVersion::default()
    });
    p.drive();
    assert!(!p.sent_by(Origin::Vehicle)[0].is_v2(), "sent in MAVLink 1");
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    assert_eq!(
        version_changes(&p.gcs_events),
        [(
            LinkVersion::Mavlink1,
            LinkVersion::Mavlink2,
            SwitchCause::CapabilityFlag
        )]
    );
}

#[test]
fn gcs_ignores_autopilot_version_without_capability_flag() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink1Only),
        gcs(GroundPolicy::Automatic),
    );
    p.vehicle_send(&AutopilotVersion {
        capabilities: p.vehicle.capabilities() | MavProtocolCapability(32768),
        ..AutopilotVersion::default()
    });
    p.drive();
    assert_eq!(
        p.gcs.version(),
        LinkVersion::Mavlink1,
        "32768 is MISSION_RALLY, not MAVLINK2"
    );
}

#[test]
fn heartbeat_mavlink_version_field_does_not_decide_the_version() {
    // HEARTBEAT.mavlink_version is the XML minor version (3), not "1 or 2".
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let hb = Heartbeat {
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let _ = feed(&mut g, T0, &frame(Version::V1, 0, 1, 1, &hb));
    assert_eq!(g.version(), LinkVersion::Mavlink1);
}

#[test]
fn gcs_configured_mavlink2_sends_mavlink2_from_the_start() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::StartMavlink1),
        gcs(GroundPolicy::Mavlink2),
    );
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    p.gcs_send(&Heartbeat::default());
    assert!(p.sent_by(Origin::Gcs)[0].is_v2());
}

#[test]
fn version_is_per_link_not_global() {
    let mut a = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let b = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let _ = feed(
        &mut a,
        T0,
        &frame(Version::V2, 0, 1, 1, &Heartbeat::default()),
    );
    assert_eq!(
        (a.version(), b.version()),
        (LinkVersion::Mavlink2, LinkVersion::Mavlink1)
    );
}

// ----- the handshake -------------------------------------------------------------------

fn assert_handshake_success(p: &Pair) {
    let HandshakeResult::ProtocolVersion(v) = only_outcome(p) else {
        panic!("{:?}", p.handshake_outcomes())
    };
    assert_eq!((v.version, v.min_version, v.max_version), (200, 100, 200));
    assert_eq!(p.gcs.peer_protocol_version(), Some(&v));
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink2);
    // The requests went out in MAVLink 2 framing.
    assert!(p.sent_by(Origin::Gcs).iter().all(|s| s.is_v2()));
}

#[test]
fn handshake_via_request_protocol_version_519() {
    let mut p = Pair::default_pair();
    start(
        &mut p,
        HandshakeMethod::RequestProtocolVersion,
        CommandEncoding::Long,
    );
    p.drive();
    assert_handshake_success(&p);
    let req = CommandLong::decode(p.sent_by(Origin::Gcs)[0].payload());
    assert_eq!(
        (req.command, req.param1),
        (MavCmd::REQUEST_PROTOCOL_VERSION, 1.0)
    );
}

#[test]
fn handshake_via_request_message_300() {
    let mut p = Pair::default_pair();
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    assert_handshake_success(&p);
    let req = CommandLong::decode(p.sent_by(Origin::Gcs)[0].payload());
    assert_eq!((req.command, req.param1), (MavCmd::REQUEST_MESSAGE, 300.0));
}

#[test]
fn handshake_via_command_int() {
    for method in [
        HandshakeMethod::RequestMessage300,
        HandshakeMethod::RequestProtocolVersion,
    ] {
        let mut p = Pair::default_pair();
        start(&mut p, method, CommandEncoding::Int);
        p.drive();
        assert_handshake_success(&p);
        let sent = p.sent_by(Origin::Gcs);
        assert_eq!(sent[0].msg_id(), 75, "COMMAND_INT");
        assert!(p.vehicle_events.iter().any(|e| matches!(
            e,
            Event::ProtocolVersionRequested {
                encoding: CommandEncoding::Int,
                answer: ProtocolVersionAnswer::Accepted,
                ..
            }
        )));
    }
}

#[test]
fn handshake_via_other_message_from_id_256() {
    let mut p = Pair::default_pair();
    let method = HandshakeMethod::RequestMessageOther {
        msg_id: FlightInformation::ID,
    };
    start(&mut p, method, CommandEncoding::Long);
    // The vehicle application answers REQUEST_MESSAGE(264) itself: ACK, then the message in
    // MAVLink 2 framing.
    p.drive_until(Duration::from_millis(100), |p| {
        Pair::frames(&p.vehicle_events)
            .iter()
            .any(|f| f.msg_id() == CommandLong::ID)
    });
    let request = Pair::frames(&p.vehicle_events)[0]
        .decode_as::<CommandLong>()
        .unwrap();
    assert_eq!(
        (request.command, request.param1),
        (MavCmd::REQUEST_MESSAGE, 264.0)
    );
    p.vehicle_send(&CommandAck {
        command: MavCmd::REQUEST_MESSAGE,
        result: MavResult::ACCEPTED,
        ..CommandAck::default()
    });
    let mut buf = [0u8; MAX_FRAME_LEN];
    let t = p
        .vehicle
        .send_mavlink2(p.now, &FlightInformation::default(), &mut buf)
        .unwrap();
    assert_eq!(t.version, Version::V2);
    p.inject(Origin::Vehicle, &buf[..t.len]);
    p.drive();
    assert_eq!(only_outcome(&p), HandshakeResult::Message { msg_id: 264 });
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
}

#[test]
fn handshake_start_errors() {
    let mut v = Channel::new(Config::vehicle(1, 1)).unwrap();
    let m = HandshakeMethod::RequestMessage300;
    assert_eq!(
        v.start_handshake(T0, Target::new(1, 1), m, CommandEncoding::Long),
        Err(HandshakeError::NotGroundStation)
    );
    let mut g = Channel::new(Config::ground_station(255, 190)).unwrap();
    assert_eq!(
        g.start_handshake(
            T0,
            Target::new(1, 1),
            HandshakeMethod::RequestMessageOther { msg_id: 148 },
            CommandEncoding::Long
        ),
        Err(HandshakeError::NotMavlink2Message { msg_id: 148 })
    );
    g.start_handshake(T0, Target::new(1, 1), m, CommandEncoding::Long)
        .unwrap();
    assert_eq!(
        g.start_handshake(T0, Target::new(1, 1), m, CommandEncoding::Long),
        Err(HandshakeError::InProgress)
    );
    assert_eq!(g.handshake().map(|h| h.name()), Some("awaiting_answer"));
    assert!(g.cancel_handshake().is_some());
    assert_eq!(g.poll_timeout(), None);
}

#[test]
fn handshake_nack_keeps_link_on_mavlink1() {
    let mut p = Pair::new(
        vehicle(VehicleVersion::Mavlink1Only),
        gcs_without_fallback(GroundPolicy::Automatic),
    );
    p.heartbeats = Some(Duration::from_secs(1));
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive_for(Duration::from_secs(5));
    assert!(matches!(only_outcome(&p), HandshakeResult::Nack { .. }));
    assert_eq!(p.handshake_outcomes()[0].attempts, 1);
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink1);
    assert_eq!(p.vehicle.version(), LinkVersion::Mavlink1);
    // After the handshake, the ground station's heartbeats are MAVLink 1.
    let late: Vec<_> = p
        .sent_by(Origin::Gcs)
        .into_iter()
        .filter(|s| s.msg_id() == 0)
        .collect();
    assert!(late.len() >= 4 && late.iter().all(|s| !s.is_v2()));
}

#[test]
fn handshake_timeout_with_retries_falls_back_to_mavlink1() {
    let mut p = Pair::new(
        silent_vehicle(VehicleVersion::Mavlink1Only),
        gcs_without_fallback(GroundPolicy::Automatic),
    );
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    let outcome = p.handshake_outcomes()[0];
    assert_eq!(outcome.result, HandshakeResult::Timeout { acked: false });
    assert_eq!(outcome.attempts, 4, "one request and three retries");
    assert_eq!(
        outcome.finished_at - outcome.started_at,
        Duration::from_millis(2_000)
    );
    // COMMAND_LONG counts its retries in `confirmation`.
    let confirmations: Vec<u8> = p
        .sent_by(Origin::Gcs)
        .iter()
        .map(|s| CommandLong::decode(s.payload()).confirmation)
        .collect();
    assert_eq!(confirmations, [0, 1, 2, 3]);
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink1);
    assert!(p.gcs.handshake().is_none());
}

#[test]
fn handshake_retry_count_and_interval_are_configurable() {
    let mut config = gcs_without_fallback(GroundPolicy::Automatic);
    config.handshake.retries = 1;
    config.handshake.interval = Duration::from_secs(2);
    let mut p = Pair::new(silent_vehicle(VehicleVersion::Mavlink1Only), config);
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    let outcome = p.handshake_outcomes()[0];
    assert_eq!(
        (outcome.attempts, outcome.finished_at - outcome.started_at),
        (2, Duration::from_secs(4))
    );
}

#[test]
fn handshake_timeout_when_the_path_drops_mavlink2_falls_back_to_mavlink1() {
    // A non-transparent radio that mangles MAVLink 2: the vehicle would answer, but neither
    // the request nor the answer gets through.
    let mut p = Pair::default_pair();
    p.drop_v2 = true;
    p.heartbeats = Some(Duration::from_secs(1));
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive_for(Duration::from_secs(5));
    assert_eq!(only_outcome(&p), HandshakeResult::Timeout { acked: false });
    assert_eq!(
        (p.gcs.version(), p.vehicle.version()),
        (LinkVersion::Mavlink1, LinkVersion::Mavlink1)
    );
    // MAVLink 1 traffic still flows both ways.
    assert!(Pair::frames(&p.gcs_events).len() >= 4);
}

#[test]
fn handshake_timeout_with_an_ack_reports_that_the_target_answered() {
    // The target's MAVLink 1 ACK ACCEPTED gets through, its MAVLink 2 answer never does (a
    // path that carries MAVLink 1 only, as far as the answer is concerned).
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    g.start_handshake(
        T0,
        Target::new(1, 1),
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    )
    .unwrap();
    let _ = transmits(&mut g, T0);
    let ack = CommandAck {
        command: MavCmd::REQUEST_MESSAGE,
        result: MavResult::ACCEPTED,
        target_system: 255,
        target_component: 190,
        ..CommandAck::default()
    };
    let _ = feed(&mut g, T0, &frame(Version::V1, 0, 1, 1, &ack));
    assert_eq!(g.handshake().map(|h| h.name()), Some("awaiting_message"));
    let mut now = T0;
    let mut result = None;
    for _ in 0..10 {
        now += Duration::from_millis(500);
        g.handle_timeout(now);
        let _ = transmits(&mut g, now);
        while let Some(e) = g.poll_event() {
            if let Event::Handshake(o) = e {
                result = Some(o.result);
            }
        }
    }
    assert_eq!(result, Some(HandshakeResult::Timeout { acked: true }));
}

#[test]
fn handshake_ack_for_another_requester_or_command_is_ignored() {
    let mut g = Channel::new(gcs_without_fallback(GroundPolicy::Automatic)).unwrap();
    g.start_handshake(
        T0,
        Target::new(1, 1),
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    )
    .unwrap();
    let nack = |command, target_system, sysid| {
        frame(
            Version::V2,
            0,
            sysid,
            1,
            &CommandAck {
                command,
                result: MavResult::DENIED,
                target_system,
                ..CommandAck::default()
            },
        )
    };
    let _ = feed(&mut g, T0, &nack(MavCmd::REQUEST_MESSAGE, 254, 1)); // another GCS's
    let _ = feed(&mut g, T0, &nack(MavCmd::REQUEST_PROTOCOL_VERSION, 255, 1)); // other command
    let _ = feed(&mut g, T0, &nack(MavCmd::REQUEST_MESSAGE, 255, 2)); // another vehicle
    assert_eq!(g.handshake().map(|h| h.name()), Some("awaiting_answer"));
    let events = feed(&mut g, T0, &nack(MavCmd::REQUEST_MESSAGE, 255, 1));
    assert!(events.iter().any(|e| matches!(
        e,
        Event::Handshake(o) if o.result == HandshakeResult::Nack { result: MavResult::DENIED }
    )));
}

#[test]
fn handshake_succeeds_under_20_percent_loss_thanks_to_retries() {
    let mut successes = 0;
    let mut needed_retries = 0;
    for seed in 0..50 {
        let mut p = Pair::default_pair().seed(seed);
        p.link.knobs.loss = 0.2;
        start(
            &mut p,
            HandshakeMethod::RequestMessage300,
            CommandEncoding::Long,
        );
        p.drive();
        let outcome = p.handshake_outcomes()[0];
        if outcome.result.is_success() {
            successes += 1;
            assert_eq!(p.gcs.version(), LinkVersion::Mavlink2);
        }
        if outcome.attempts > 1 {
            needed_retries += 1;
        }
    }
    // One attempt succeeds with probability 0.8 × 0.8; four fail together with ≈ 1.7 %.
    assert!(successes >= 47, "{successes} of 50");
    assert!(
        needed_retries >= 5,
        "retries were exercised: {needed_retries}"
    );
}

#[test]
fn handshake_answer_comes_in_mavlink2_framing_even_on_a_mavlink1_link() {
    // A requester that sends its request in MAVLink 1 (as QGC does on a fresh link): the
    // vehicle's link stays MAVLink 1, the ACK is MAVLink 1, PROTOCOL_VERSION is MAVLink 2.
    let mut v = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let request = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::REQUEST_PROTOCOL_VERSION,
        param1: 1.0,
        ..CommandLong::default()
    };
    let _ = feed(&mut v, T0, &frame(Version::V1, 0, 255, 190, &request));
    let out = transmits(&mut v, T0);
    assert_eq!(out.len(), 2);
    assert_eq!(
        (out[0][0], out[0][5]),
        (0xfe, 77),
        "COMMAND_ACK in MAVLink 1"
    );
    assert_eq!(out[1][0], 0xfd, "PROTOCOL_VERSION in MAVLink 2");
    assert_eq!(v.version(), LinkVersion::Mavlink1);
    let pv = mavstack_channel::OwnedFrame::new(&out[1])
        .unwrap()
        .decode_as::<ProtocolVersion>()
        .unwrap();
    assert_eq!(
        (pv.version, pv.min_version, pv.max_version),
        (200, 100, 200)
    );
    // The ACK's extensions would name the requester; MAVLink 1 drops them.
    assert_eq!(out[0][1], 3);
}

#[test]
fn protocol_version_answer_is_configurable() {
    let mut config = vehicle(VehicleVersion::Mavlink2);
    if let Role::Vehicle(p) = &mut config.role {
        let pv = p.protocol_version.as_mut().unwrap();
        pv.spec_version_hash = *b"specsha1";
        pv.library_version_hash = *b"libsha01";
    }
    let mut p = Pair::new(config, gcs(GroundPolicy::Automatic));
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    let HandshakeResult::ProtocolVersion(v) = only_outcome(&p) else {
        panic!()
    };
    assert_eq!(
        (&v.spec_version_hash, &v.library_version_hash),
        (b"specsha1", b"libsha01")
    );
}

// ----- golden vectors of the digest (§10) ----------------------------------------------

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

// ----- framing rules the link relies on (§1–2) -----------------------------------------

#[test]
fn mavlink1_link_refuses_mavlink2_only_messages_with_a_typed_error() {
    let mut v = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    assert_eq!(
        v.send(T0, &ProtocolVersion::default(), &mut buf),
        Err(SendError::NeedsMavlink2 { msg_id: 300 })
    );
    assert_eq!(
        v.send_raw(T0, 300, 217, &[0; 22], &mut buf),
        Err(SendError::NeedsMavlink2 { msg_id: 300 })
    );
    // The explicit one-off MAVLink 2 answer works; the link stays MAVLink 1.
    let t = v
        .send_mavlink2(T0, &ProtocolVersion::default(), &mut buf)
        .unwrap();
    assert_eq!(
        (t.version, t.seq, v.version()),
        (Version::V2, 0, LinkVersion::Mavlink1)
    );
    let mut off = Channel::new(vehicle(VehicleVersion::Mavlink1Only)).unwrap();
    assert_eq!(
        off.send_mavlink2(T0, &ProtocolVersion::default(), &mut buf),
        Err(SendError::Mavlink2Disabled)
    );
    assert_eq!(
        v.send_raw(T0, 1 << 24, 0, &[], &mut buf),
        Err(SendError::InvalidMessageId { msg_id: 1 << 24 })
    );
    assert!(matches!(
        v.send(T0, &Heartbeat::default(), &mut buf[..10]),
        Err(SendError::Emit(_))
    ));
}

#[test]
fn send_raw_writes_the_payload_with_the_given_crc_extra() {
    let mut g = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let payload = [0, 0, 0, 0, 2, 12, 0x51, 4, 3];
    let t = g.send_raw(T0, 0, 50, &payload, &mut buf).unwrap();
    let mut v = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let events = feed(&mut v, T0, &buf[..t.len]);
    assert!(matches!(&events[0], Event::Frame(f) if f.crc_checked && f.frame.payload() == payload));
}

#[test]
fn tx_sequence_runs_per_link_and_wraps() {
    let mut a = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let mut b = Channel::new(vehicle(VehicleVersion::StartMavlink1)).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let seqs: Vec<u8> = (0..258)
        .map(|_| a.send(T0, &Heartbeat::default(), &mut buf).unwrap().seq)
        .collect();
    assert_eq!((seqs[0], seqs[255], seqs[256], seqs[257]), (0, 255, 0, 1));
    assert_eq!(b.send(T0, &Heartbeat::default(), &mut buf).unwrap().seq, 0);
    assert_eq!(a.stats().sent, 258);
}

#[test]
fn both_versions_are_accepted_interleaved_on_one_stream() {
    let mut g = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    let mut stream = Vec::new();
    for seq in 0..6u8 {
        let v = if seq % 2 == 0 {
            Version::V1
        } else {
            Version::V2
        };
        stream.extend(frame(v, seq, 1, 1, &Heartbeat::default()));
    }
    let events = feed(&mut g, T0, &stream);
    let versions: Vec<_> = Pair::frames(&events)
        .iter()
        .map(|f| f.version().number())
        .collect();
    assert_eq!(versions, [1, 2, 1, 2, 1, 2]);
}

#[test]
fn truncated_and_longer_payloads_are_accepted() {
    let mut g = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    // A truncated MAVLink 2 COMMAND_ACK (trailing zeros dropped) decodes zero-extended.
    let ack = CommandAck {
        command: MavCmd::REQUEST_MESSAGE,
        result: MavResult::ACCEPTED,
        ..CommandAck::default()
    };
    let v2 = frame(Version::V2, 0, 1, 1, &ack);
    assert_eq!(v2[1], 2);
    // A MAVLink 1 COMMAND_ACK with extensions (LEN 10, as pymavlink sends with a v2 dialect).
    let mut payload = [0u8; 10];
    payload[..2].copy_from_slice(&512u16.to_le_bytes());
    payload[8] = 255;
    let mut long_v1 = vec![0xfe, 10, 1, 1, 1, 77];
    long_v1.extend_from_slice(&payload);
    let mut crc = mavstack_core::Crc16::new();
    crc.update(&long_v1[1..]);
    crc.update_byte(CommandAck::CRC_EXTRA);
    long_v1.extend_from_slice(&crc.value().to_le_bytes());
    let events = feed(&mut g, T0, &[v2, long_v1].concat());
    let frames = Pair::frames(&events);
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[0].decode_as::<CommandAck>(), Some(ack));
    assert_eq!(
        frames[1].decode_as::<CommandAck>().unwrap().target_system,
        255
    );
}

#[test]
fn noise_false_starts_and_bad_crc_are_counted_and_the_next_frame_found() {
    let mut g = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    let good = frame(Version::V2, 7, 1, 1, &Heartbeat::default());
    let mut bad = good.clone();
    let n = bad.len();
    bad[n - 1] ^= 0xff;
    // A false start (0xfd claiming 5 bytes) in noise, a frame with a bad checksum, then
    // two good frames: the parser resumes one byte after each failed start.
    let stream = [&[0x00, 0xfd, 0x05][..], &bad, &good, &good].concat();
    let events = feed(&mut g, T0, &stream);
    assert_eq!(Pair::frames(&events).len(), 2);
    let stats = g.stats();
    assert_eq!(
        (stats.parser.frames, stats.accepted, stats.duplicates),
        (2, 2, 1)
    );
    assert!(
        stats.parser.bad_crc >= 1 && stats.parser.skipped_bytes >= 3,
        "{stats:?}"
    );
}

#[test]
fn unknown_incompat_flags_are_dropped() {
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let mut f = frame(Version::V2, 0, 1, 1, &Heartbeat::default());
    f[2] = 0x02;
    let events = feed(&mut g, T0, &f);
    assert!(Pair::frames(&events).is_empty());
    assert_eq!(g.stats().parser.bad_incompat, 1);
    assert_eq!(g.version(), LinkVersion::Mavlink1);
}

#[test]
fn unknown_message_ids_are_delivered_unchecked_and_never_switch_the_link() {
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut other = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    let t = other
        .send_raw(T0, 0xABCDE, 0x11, &[1, 2, 3], &mut buf)
        .unwrap();
    let stream = [&buf[..t.len], &[0xfd][..]].concat(); // a start marker after it: a frame
    let events = feed(&mut g, T0, &stream);
    let frames = Pair::frames(&events);
    assert_eq!(frames.len(), 1);
    assert!(!frames[0].crc_checked);
    assert_eq!(frames[0].msg_id(), 0xABCDE);
    assert_eq!(g.version(), LinkVersion::Mavlink1);
    assert_eq!(g.stats().parser.unknown_id, 1);
    assert!(
        g.sources().is_empty(),
        "unchecked frames are not counted by sequence"
    );
}

#[test]
fn a_full_event_queue_pauses_input_without_losing_frames() {
    let mut g = Channel::new(gcs(GroundPolicy::Mavlink2)).unwrap();
    let stream: Vec<u8> = (0..100u8)
        .flat_map(|seq| frame(Version::V2, seq, 1, 1, &Heartbeat::default()))
        .collect();
    let first = g.handle_input(T0, &stream);
    assert!(first < stream.len(), "the queue filled and input paused");
    let mut frames = 0;
    let mut rest = &stream[first..];
    loop {
        while let Some(e) = g.poll_event() {
            frames += usize::from(matches!(e, Event::Frame(_)));
        }
        if rest.is_empty() {
            break;
        }
        let n = g.handle_input(T0, rest);
        rest = &rest[n..];
    }
    assert_eq!(frames, 100);
    assert_eq!(g.stats().lost, 0);
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

// ----- the documents' fallback: another message in MAVLink 2 ------------------------------

/// A ground station that has sent REQUEST_MESSAGE(300) to 1/1 at T0.
fn gcs_asking_for_300() -> Channel {
    let mut g = Channel::new(gcs(GroundPolicy::Automatic)).unwrap();
    g.start_handshake(
        T0,
        Target::new(1, 1),
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    )
    .unwrap();
    let _ = transmits(&mut g, T0);
    g
}

fn ack_from_vehicle(command: MavCmd, result: MavResult) -> Vec<u8> {
    frame(
        Version::V2,
        0,
        1,
        1,
        &CommandAck {
            command,
            result,
            target_system: 255,
            target_component: 190,
            ..CommandAck::default()
        },
    )
}

/// A ground station whose request for 300 the vehicle refused with `result` at T0: the
/// fallback's request has gone out (and been taken off the link).
fn gcs_in_fallback(result: MavResult) -> Channel {
    let mut g = gcs_asking_for_300();
    let _ = feed(
        &mut g,
        T0,
        &ack_from_vehicle(MavCmd::REQUEST_MESSAGE, result),
    );
    let _ = transmits(&mut g, T0);
    g
}

/// The REQUEST_MESSAGE commands among `sent`, as (magic byte, param1).
fn requests(sent: &[Vec<u8>]) -> Vec<(u8, f32)> {
    sent.iter()
        .filter_map(|b| {
            let (id, payload) = match b[0] {
                0xFD => (
                    u32::from_le_bytes([b[7], b[8], b[9], 0]),
                    &b[10..10 + usize::from(b[1])],
                ),
                _ => (u32::from(b[5]), &b[6..6 + usize::from(b[1])]),
            };
            (id == CommandLong::ID).then(|| (b[0], CommandLong::decode(payload).param1))
        })
        .collect()
}

fn outcome_of(events: &[Event]) -> Option<mavstack_channel::HandshakeOutcome> {
    events.iter().find_map(|e| match e {
        Event::Handshake(o) => Some(*o),
        _ => None,
    })
}

#[test]
fn refused_300_falls_back_to_autopilot_version_in_mavlink2_and_switches() {
    // ArduPilot: REQUEST_MESSAGE(300) → COMMAND_ACK FAILED; REQUEST_MESSAGE(148) →
    // AUTOPILOT_VERSION, all in MAVLink 2.
    let mut g = gcs_asking_for_300();
    let events = feed(
        &mut g,
        T0,
        &ack_from_vehicle(MavCmd::REQUEST_MESSAGE, MavResult::FAILED),
    );
    assert!(outcome_of(&events).is_none(), "the fallback runs first");
    assert_eq!(
        g.handshake().and_then(|h| h.fallback()),
        Some(mavstack_channel::FallbackReason::Refused(MavResult::FAILED))
    );
    let sent = transmits(&mut g, T0);
    assert_eq!(
        requests(&sent),
        [(0xFD, 148.0)],
        "REQUEST_MESSAGE(148) in MAVLink 2"
    );
    let av = AutopilotVersion::default(); // no capability flag: the framing is the proof
    let events = feed(&mut g, T0, &frame(Version::V2, 1, 1, 1, &av));
    let outcome = outcome_of(&events).expect("finished");
    assert_eq!(outcome.result, HandshakeResult::Message { msg_id: 148 });
    assert_eq!(outcome.result.name(), "message_v2");
    assert_eq!(
        outcome.fallback,
        Some(mavstack_channel::FallbackReason::Refused(MavResult::FAILED))
    );
    assert_eq!(outcome.request.method.name(), "request_message_other");
    assert_eq!(g.version(), LinkVersion::Mavlink2);
}

#[test]
fn a_late_refusal_in_the_fallback_phase_does_not_end_it() {
    // The ACK FAILED of an earlier retry of the request for 300 may arrive after the
    // fallback's request went out: COMMAND_ACK does not say which message was asked for.
    let mut g = gcs_in_fallback(MavResult::FAILED);
    let t = T0 + Duration::from_millis(100);
    let events = feed(
        &mut g,
        t,
        &ack_from_vehicle(MavCmd::REQUEST_MESSAGE, MavResult::FAILED),
    );
    assert!(outcome_of(&events).is_none());
    let av = AutopilotVersion::default();
    let events = feed(&mut g, t, &frame(Version::V2, 1, 1, 1, &av));
    assert_eq!(
        outcome_of(&events).map(|o| o.result),
        Some(HandshakeResult::Message { msg_id: 148 })
    );
}

#[test]
fn a_refused_fallback_ends_in_a_nack_at_the_attempts_deadline() {
    let mut g = gcs_in_fallback(MavResult::UNSUPPORTED);
    let _ = feed(
        &mut g,
        T0,
        &ack_from_vehicle(MavCmd::REQUEST_MESSAGE, MavResult::DENIED),
    );
    g.handle_timeout(T0 + Duration::from_millis(499));
    assert!(g.handshake().is_some());
    let at = T0 + Duration::from_millis(500);
    g.handle_timeout(at);
    let mut events = Vec::new();
    while let Some(e) = g.poll_event() {
        events.push(e);
    }
    let outcome = outcome_of(&events).expect("finished");
    assert_eq!(
        outcome.result,
        HandshakeResult::Nack {
            result: MavResult::DENIED
        }
    );
    assert_eq!(outcome.finished_at, at);
    assert!(transmits(&mut g, at).is_empty(), "no further request");
    assert_eq!(g.version(), LinkVersion::Mavlink1);
}

#[test]
fn the_fallback_answered_in_mavlink1_is_a_nack() {
    // A system with MAVLink 2 disabled: it refuses 300 and answers the fallback in MAVLink 1.
    let mut g = gcs_in_fallback(MavResult::UNSUPPORTED);
    let av = AutopilotVersion::default();
    let events = feed(&mut g, T0, &frame(Version::V1, 1, 1, 1, &av));
    let outcome = outcome_of(&events).expect("finished");
    assert_eq!(
        outcome.result,
        HandshakeResult::Nack {
            result: MavResult::UNSUPPORTED
        }
    );
    assert_eq!(g.version(), LinkVersion::Mavlink1);
}

#[test]
fn silence_to_300_then_autopilot_version_in_mavlink2_proves_the_link() {
    let mut g = gcs_asking_for_300();
    let mut now = T0;
    let mut sent = Vec::new();
    // Four requests for 300, 500 ms apart, unanswered.
    for _ in 0..4 {
        now += Duration::from_millis(500);
        g.handle_timeout(now);
        sent.extend(transmits(&mut g, now));
    }
    let asked = requests(&sent);
    assert_eq!(asked.len(), 4, "{asked:?}");
    assert_eq!(asked.last(), Some(&(0xFD, 148.0)), "{asked:?}");
    assert!(asked[..3].iter().all(|r| *r == (0xFD, 300.0)), "{asked:?}");
    let events = feed(
        &mut g,
        now,
        &frame(Version::V2, 1, 1, 1, &AutopilotVersion::default()),
    );
    let outcome = outcome_of(&events).expect("finished");
    assert_eq!(outcome.result, HandshakeResult::Message { msg_id: 148 });
    assert_eq!(
        outcome.fallback,
        Some(mavstack_channel::FallbackReason::Unanswered { acked: false })
    );
}

#[test]
fn silence_to_both_requests_times_out_after_both_phases() {
    let mut p = Pair::new(
        silent_vehicle(VehicleVersion::Mavlink1Only),
        gcs(GroundPolicy::Automatic),
    );
    start(
        &mut p,
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    );
    p.drive();
    let outcome = p.handshake_outcomes()[0];
    assert_eq!(outcome.result, HandshakeResult::Timeout { acked: false });
    assert_eq!(
        outcome.finished_at - outcome.started_at,
        Duration::from_millis(4_000),
        "2 s for each phase"
    );
    let asked: Vec<f32> = p
        .sent_by(Origin::Gcs)
        .iter()
        .map(|s| CommandLong::decode(s.payload()).param1)
        .collect();
    assert_eq!(
        asked,
        [300.0, 300.0, 300.0, 300.0, 148.0, 148.0, 148.0, 148.0]
    );
    assert_eq!(p.gcs.version(), LinkVersion::Mavlink1);
}

#[test]
fn a_vehicle_that_refuses_like_ardupilot_fails_300_and_does_not_know_519() {
    let mut v = vehicle(VehicleVersion::Mavlink2);
    let policy = v.vehicle_policy_mut().unwrap();
    policy.protocol_version = None;
    policy.refuse_unsupported = true;
    for (method, want) in [
        (HandshakeMethod::RequestMessage300, MavResult::FAILED),
        (
            HandshakeMethod::RequestProtocolVersion,
            MavResult::UNSUPPORTED,
        ),
    ] {
        let mut p = Pair::new(v.clone(), gcs_without_fallback(GroundPolicy::Automatic));
        start(&mut p, method, CommandEncoding::Long);
        p.drive();
        assert_eq!(only_outcome(&p), HandshakeResult::Nack { result: want });
        let acks: Vec<(bool, MavResult)> = p
            .sent_by(Origin::Vehicle)
            .iter()
            .filter(|s| s.msg_id() == CommandAck::ID)
            .map(|s| (s.is_v2(), CommandAck::decode(s.payload()).result))
            .collect();
        assert_eq!(acks, [(true, want)], "{method:?}");
    }
}
