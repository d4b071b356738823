//! The handshake: each request (519, REQUEST_MESSAGE 300, COMMAND_INT, another message),
//! NACKs, retries and timeouts, loss, the answer's framing.

use core::time::Duration;

use mavstack_channel::{
    Channel, CommandEncoding, Config, Event, GroundPolicy, HandshakeError, HandshakeMethod,
    HandshakeResult, LinkVersion, ProtocolVersionAnswer, Role, Target, VehicleVersion,
};
use mavstack_core::message::Message;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{
    CommandAck, CommandLong, FlightInformation, MavCmd, MavResult, ProtocolVersion,
};

use super::util::{Origin, Pair, T0, feed, frame, transmits};
use super::{gcs, gcs_without_fallback, only_outcome, silent_vehicle, start, vehicle};

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
