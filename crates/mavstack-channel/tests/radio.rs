//! The semi-transparent radio (digest §5): forwarding, RADIO_STATUS injection in MAVLink 1
//! and then MAVLink 2, and a ground station accepting it on a signed link.

mod util;

use core::time::Duration;

use mavstack_channel::radio::{Injection, RADIO_QUEUE};
use mavstack_channel::{
    Authentication, CommandEncoding, Config, HandshakeMethod, LinkVersion, Radio, RadioConfig,
    RadioEvent, RejectReason, Side, SigningConfig, Target,
};
use mavstack_core::message::Message;
use mavstack_core::time::Instant;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{Heartbeat, RadioStatus};
use util::{Origin, Pair, T0, frame, key, signed_frame, timestamp_at};

fn statuses(p: &Pair) -> Vec<&util::Sent> {
    p.sent_by(Origin::Radio)
        .into_iter()
        .filter(|s| s.msg_id() == RadioStatus::ID && s.bytes[if s.is_v2() { 5 } else { 3 }] == 51)
        .collect()
}

fn drain(radio: &mut Radio) -> Vec<(Side, bool, Vec<u8>)> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut out = Vec::new();
    while let Some(t) = radio.poll_transmit(T0, &mut buf) {
        out.push((t.to, t.injected, buf[..t.len].to_vec()));
    }
    out
}

#[test]
fn radio_forwards_frames_unchanged_at_frame_boundaries() {
    let mut radio = Radio::new(RadioConfig::default());
    // An untrimmed MAVLink 2 frame (trailing zero kept: a re-serialising forwarder would
    // trim it and break its checksum), a signed frame, a MAVLink 1 frame, noise in between.
    let mut untrimmed = frame(Version::V1, 3, 1, 1, &Heartbeat::default());
    untrimmed = {
        let mut f = vec![0xfd, 9, 0, 0, 3, 1, 1, 0, 0, 0];
        f.extend_from_slice(&untrimmed[6..15]);
        let mut crc = mavstack_core::Crc16::new();
        crc.update(&f[1..]);
        crc.update_byte(Heartbeat::CRC_EXTRA);
        f.extend_from_slice(&crc.value().to_le_bytes());
        f
    };
    let signed = signed_frame(4, 1, 1, &Heartbeat::default(), &key(), 1, 77);
    let v1 = frame(Version::V1, 5, 1, 1, &Heartbeat::default());
    let stream = [&untrimmed[..], &[0x11, 0x22], &signed, &[0x33], &v1].concat();
    let mut got = Vec::new();
    for piece in stream.chunks(5) {
        assert_eq!(radio.handle_input(T0, Side::B, piece), piece.len());
        got.extend(drain(&mut radio));
    }
    let forwarded: Vec<_> = got
        .into_iter()
        .map(|(side, injected, bytes)| {
            assert!(side == Side::A && !injected);
            bytes
        })
        .collect();
    assert_eq!(forwarded, [untrimmed, signed, v1]);
    let stats = radio.stats();
    assert_eq!(
        (stats.forwarded, stats.parser[1].skipped_bytes),
        ([3, 0], 3)
    );
}

#[test]
fn radio_injects_radio_status_in_mavlink1_until_the_first_mavlink2_frame_then_in_mavlink2() {
    let mut p = Pair::default_pair().with_radio(RadioConfig::default());
    p.heartbeats = Some(Duration::from_secs(1));
    p.drive_for(Duration::from_millis(3_500));
    let before = statuses(&p).len();
    assert_eq!(before, 4, "one at start, then every second");
    assert!(statuses(&p).iter().all(|s| !s.is_v2()));
    assert!(p.radio_events.is_empty());
    // The handshake brings the first MAVLink 2 frame through the radio.
    p.gcs
        .start_handshake(
            p.now,
            Target::new(1, 1),
            HandshakeMethod::RequestMessage300,
            CommandEncoding::Long,
        )
        .unwrap();
    p.drive_for(Duration::from_secs(3));
    assert_eq!(
        p.radio_events,
        [RadioEvent::FirstMavlink2 { from: Side::A }]
    );
    assert!(p.handshake_outcomes()[0].result.is_success());
    let after: Vec<_> = statuses(&p).into_iter().skip(before).collect();
    assert!(
        after.len() >= 3 && after.iter().all(|s| s.is_v2()),
        "{after:?}"
    );
    // RADIO_STATUS went towards the ground station only, with plausible figures.
    let frames = Pair::frames(&p.gcs_events);
    let from_radio: Vec<_> = frames
        .iter()
        .filter(|f| (f.sysid(), f.compid()) == (51, 68))
        .collect();
    assert_eq!(from_radio.len(), statuses(&p).len());
    assert!(
        Pair::frames(&p.vehicle_events)
            .iter()
            .all(|f| f.sysid() != 51)
    );
    let status = from_radio[0].decode_as::<RadioStatus>().unwrap();
    assert!(status.rssi > status.noise && status.remrssi > status.remnoise);
    assert_eq!(status.txbuf, 100);
}

#[test]
fn ground_station_accepts_radio_status_on_a_signed_link_via_the_allow_list() {
    let mut vehicle = Config::vehicle(1, 1);
    vehicle.signing = Some(SigningConfig::new(key(), 1));
    let mut gcs = Config::ground_station(255, 190);
    gcs.signing = Some(SigningConfig::new(key(), 0));
    let mut p = Pair::new(vehicle, gcs).with_radio(RadioConfig::default());
    p.heartbeats = Some(Duration::from_millis(500));
    p.drive_for(Duration::from_secs(4));
    let frames = Pair::frames(&p.gcs_events);
    let status: Vec<_> = frames
        .iter()
        .filter(|f| f.msg_id() == RadioStatus::ID)
        .collect();
    // The first RADIO_STATUS left before any frame passed: MAVLink 1. Then MAVLink 2.
    assert_eq!(status.first().unwrap().version(), Version::V1);
    assert_eq!(status.last().unwrap().version(), Version::V2);
    assert!(
        status
            .iter()
            .all(|f| f.auth == Authentication::AllowedUnsigned)
    );
    assert!(Pair::rejections(&p.gcs_events).is_empty());
    assert!(
        frames
            .iter()
            .filter(|f| f.msg_id() == 0)
            .all(|f| f.auth.is_authenticated())
    );
    assert_eq!(p.gcs.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn radio_status_is_rejected_on_a_signed_link_without_the_allow_list() {
    let mut vehicle = Config::vehicle(1, 1);
    vehicle.signing = Some(SigningConfig::new(key(), 1));
    let mut gcs = Config::ground_station(255, 190);
    let mut signing = SigningConfig::new(key(), 0);
    signing.clear_allowed_unsigned();
    gcs.signing = Some(signing);
    let mut p = Pair::new(vehicle, gcs).with_radio(RadioConfig::default());
    p.heartbeats = Some(Duration::from_millis(500));
    p.drive_for(Duration::from_secs(3));
    let reasons: Vec<_> = Pair::rejections(&p.gcs_events)
        .iter()
        .map(|r| r.reason)
        .collect();
    assert_eq!(reasons[0], RejectReason::Mavlink1OnSignedLink);
    assert!(
        reasons[1..]
            .iter()
            .all(|r| *r == RejectReason::UnsignedNotAllowed)
    );
    // Count what has arrived by now (the last frames may still be on the way).
    let arrived = |s: &&&util::Sent| s.at + p.link.knobs.latency <= p.now;
    let stats = p.gcs.stats();
    assert_eq!(
        stats.rejected.total(),
        statuses(&p).iter().filter(arrived).count() as u64
    );
    assert!(
        Pair::rejections(&p.gcs_events)
            .iter()
            .all(|r| r.msg_id == RadioStatus::ID)
    );
    // Every genuine frame still got through.
    let vehicle_frames = p.sent_by(Origin::Vehicle).iter().filter(arrived).count() as u64;
    assert_eq!(stats.accepted, vehicle_frames);
}

#[test]
fn handshake_succeeds_through_the_radio_under_loss() {
    let mut ok = 0;
    for seed in 0..20 {
        let mut p = Pair::default_pair()
            .with_radio(RadioConfig::default())
            .seed(seed);
        p.link.knobs.loss = 0.1;
        p.gcs
            .start_handshake(
                p.now,
                Target::new(1, 1),
                HandshakeMethod::RequestProtocolVersion,
                CommandEncoding::Int,
            )
            .unwrap();
        p.drive_until(Duration::from_secs(5), |p| {
            !p.handshake_outcomes().is_empty()
        });
        ok += usize::from(p.handshake_outcomes()[0].result.is_success());
    }
    assert!(ok >= 18, "{ok} of 20");
}

#[test]
fn radio_injects_towards_both_sides_when_configured() {
    let mut config = RadioConfig::default();
    config.injection = Injection::BothSides;
    config.interval = Duration::from_millis(250);
    let mut p = Pair::default_pair().with_radio(config);
    p.drive_for(Duration::from_millis(900));
    let to_vehicle = Pair::frames(&p.vehicle_events)
        .iter()
        .filter(|f| f.sysid() == 51)
        .count();
    let to_gcs = Pair::frames(&p.gcs_events)
        .iter()
        .filter(|f| f.sysid() == 51)
        .count();
    assert_eq!((to_vehicle, to_gcs), (4, 4));
}

#[test]
fn radio_status_goes_between_frames_never_inside_one() {
    let mut radio = Radio::new(RadioConfig::default());
    let hb = frame(Version::V2, 0, 1, 1, &Heartbeat::default());
    let (head, tail) = hb.split_at(7);
    assert_eq!(radio.handle_input(T0, Side::B, head), head.len());
    radio.handle_timeout(T0); // due now, while a frame is half-way through
    let out = drain(&mut radio);
    assert_eq!(out.len(), 1);
    assert!(out[0].1, "only the injected status so far");
    assert_eq!(radio.handle_input(T0, Side::B, tail), tail.len());
    let out = drain(&mut radio);
    assert_eq!(out, [(Side::A, false, hb)]);
    assert_eq!(radio.poll_timeout(), Some(T0 + Duration::from_secs(1)));
}

#[test]
fn radio_pauses_input_when_a_queue_is_full_without_losing_frames() {
    let mut radio = Radio::new(RadioConfig::default());
    let stream: Vec<u8> = (0..200u8)
        .flat_map(|s| frame(Version::V1, s, 1, 1, &Heartbeat::default()))
        .collect();
    let mut rest = &stream[..];
    let mut forwarded = Vec::new();
    let mut paused = false;
    while !rest.is_empty() {
        let n = radio.handle_input(Instant::ZERO, Side::A, rest);
        paused |= n < rest.len();
        rest = &rest[n..];
        forwarded.extend(drain(&mut radio).into_iter().map(|(_, _, b)| b));
    }
    assert!(paused, "the queue of {RADIO_QUEUE} filled");
    assert_eq!(forwarded.concat(), stream);
}

#[test]
fn radio_reports_the_first_mavlink2_frame_once() {
    let mut radio = Radio::new(RadioConfig::default());
    let v2 = frame(Version::V2, 0, 1, 1, &Heartbeat::default());
    for _ in 0..3 {
        let _ = radio.handle_input(T0, Side::B, &v2);
        let _ = drain(&mut radio);
    }
    assert_eq!(
        radio.poll_event(),
        Some(RadioEvent::FirstMavlink2 { from: Side::B })
    );
    assert_eq!(radio.poll_event(), None);
    assert!(radio.mavlink2_seen());
    // A signed vehicle's frames pass the radio untouched and verify at the other end.
    let signed = signed_frame(1, 1, 1, &Heartbeat::default(), &key(), 1, timestamp_at(T0));
    let _ = radio.handle_input(T0, Side::B, &signed);
    assert_eq!(drain(&mut radio), [(Side::A, false, signed)]);
}

#[test]
fn radio_forwards_frames_of_unknown_ids_without_checking_them() {
    let mut radio = Radio::new(RadioConfig::default());
    let mut unknown = vec![
        0xfd, 3, 0, 0, 0, 1, 1, 0xde, 0xbc, 0x0a, 1, 2, 3, 0x12, 0x34,
    ];
    let hb = frame(Version::V1, 1, 1, 1, &Heartbeat::default());
    unknown.extend_from_slice(&hb);
    assert_eq!(radio.handle_input(T0, Side::A, &unknown), unknown.len());
    let out: Vec<_> = drain(&mut radio)
        .into_iter()
        .map(|(to, _, b)| (to, b))
        .collect();
    assert_eq!(out, [(Side::B, unknown[..15].to_vec()), (Side::B, hb)]);
    assert_eq!(radio.stats().parser[0].unknown_id, 1);
}
