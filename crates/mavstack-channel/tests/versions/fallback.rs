//! The documents' fallback: when PROTOCOL_VERSION is refused or unanswered, another message
//! (AUTOPILOT_VERSION) asked for in MAVLink 2 proves the link.

use core::time::Duration;

use mavstack_channel::{
    Channel, CommandEncoding, Event, GroundPolicy, HandshakeMethod, HandshakeResult, LinkVersion,
    Target, VehicleVersion,
};
use mavstack_core::message::Message;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{AutopilotVersion, CommandAck, CommandLong, MavCmd, MavResult};

use super::util::{Origin, Pair, T0, feed, frame, transmits};
use super::{gcs, gcs_without_fallback, only_outcome, silent_vehicle, start, vehicle};

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
