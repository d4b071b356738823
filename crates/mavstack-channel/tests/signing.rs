//! Signing on a link (digest §4): every acceptance rule and every attack as a named test,
//! each checking that the attack is rejected and counted and that no genuine frame is.

mod util;

use core::time::Duration;

use mavstack_channel::{
    Authentication, Channel, Config, Event, LinkVersion, RejectReason, Role, SigningConfig,
    SigningSetup, SwitchCause, VehicleVersion, WallClock, signing::MAX_STREAMS,
};
use mavstack_core::signing::{EPOCH_UNIX_SECS, MAX_TIMESTAMP, SecretKey};
use mavstack_core::time::Instant;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{Heartbeat, RadioStatus, SetupSigning};
use util::{Node, Origin, Pair, T0, feed, frame, key, signed_frame, timestamp_at};

fn signed_config(mut config: Config, link_id: u8) -> Config {
    config.signing = Some(SigningConfig::new(key(), link_id));
    config
}

fn signed_pair() -> Pair {
    Pair::new(
        signed_config(Config::vehicle(1, 1), 1),
        signed_config(Config::ground_station(255, 190), 0),
    )
}

/// A signing ground station on its own.
fn signed_gcs() -> Channel {
    Channel::new(signed_config(Config::ground_station(255, 190), 0)).unwrap()
}

fn rejected(events: &[Event]) -> Vec<RejectReason> {
    Pair::rejections(events).iter().map(|r| r.reason).collect()
}

fn accepted(events: &[Event]) -> usize {
    Pair::frames(events).len()
}

fn wrong_key() -> SecretKey {
    SecretKey::new([0xEE; 32])
}

#[test]
fn signed_link_accepts_the_genuine_stream_both_ways() {
    let mut p = signed_pair().seed(7);
    p.link.knobs.loss = 0.1;
    p.heartbeats = Some(Duration::from_millis(200));
    p.drive_for(Duration::from_secs(30));
    for events in [&p.gcs_events, &p.vehicle_events] {
        assert!(rejected(events).is_empty(), "{:?}", rejected(events));
        let frames = Pair::frames(events);
        assert!(frames.len() > 100);
        assert!(
            frames
                .iter()
                .all(|f| f.auth.is_authenticated() && f.is_signed())
        );
    }
    assert!(p.sent.iter().all(|s| s.is_signed()));
    assert_eq!(p.gcs.stats().rejected.total(), 0);
    assert_eq!(Pair::frames(&p.gcs_events)[0].link_id(), Some(1));
}

#[test]
fn replayed_frame_is_rejected_and_counted() {
    let mut p = signed_pair();
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    let capture = p.sent_by(Origin::Vehicle)[0].bytes.clone();
    p.inject(Origin::Vehicle, &capture);
    p.drive();
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    assert!(matches!(
        rejected(&p.gcs_events)[..],
        [RejectReason::Replayed { .. }]
    ));
    assert_eq!(p.gcs.stats().rejected.replayed, 1);
    assert_eq!(
        accepted(&p.gcs_events),
        2,
        "the genuine frames before and after"
    );
}

#[test]
fn equal_timestamp_counts_as_a_replay() {
    let mut g = signed_gcs();
    let ts = timestamp_at(T0);
    let a = signed_frame(0, 1, 1, &Heartbeat::default(), &key(), 1, ts);
    let b = signed_frame(1, 1, 1, &Heartbeat::default(), &key(), 1, ts);
    let events = feed(&mut g, T0, &[a, b].concat());
    assert_eq!(accepted(&events), 1);
    assert_eq!(
        rejected(&events),
        [RejectReason::Replayed {
            timestamp: ts,
            last: ts
        }]
    );
}

#[test]
fn forged_signature_is_rejected_and_counted() {
    let mut g = signed_gcs();
    let forged = signed_frame(
        0,
        1,
        1,
        &Heartbeat::default(),
        &wrong_key(),
        1,
        timestamp_at(T0),
    );
    let events = feed(&mut g, T0, &forged);
    assert_eq!(rejected(&events), [RejectReason::BadSignature]);
    let stats = g.stats();
    assert_eq!((stats.rejected.bad_signature, stats.accepted), (1, 0));
    assert!(
        g.signing_streams().is_empty(),
        "the replay table was not touched"
    );
}

#[test]
fn huge_timestamp_forgery_does_not_lock_out_the_genuine_stream() {
    // pymavlink 2.4.50 recorded the stream timestamp before checking the signature: one
    // forged frame with a huge timestamp then locked out the genuine stream.
    let mut p = signed_pair();
    p.vehicle_send(&Heartbeat::default());
    p.drive();
    let genuine = p.sent_by(Origin::Vehicle)[0].bytes.clone();
    // Same stream (sysid 1, compid 1, link 1), maximal timestamp, wrong key...
    let forged = signed_frame(
        9,
        1,
        1,
        &Heartbeat::default(),
        &wrong_key(),
        1,
        MAX_TIMESTAMP,
    );
    // ...and a genuine frame with its timestamp rewritten (the signature no longer fits).
    let mut tampered = genuine.clone();
    let at = tampered.len() - 12;
    tampered[at..at + 6].copy_from_slice(&MAX_TIMESTAMP.to_le_bytes()[..6]);
    let before = p.gcs.signing_timestamp();
    p.inject(Origin::Vehicle, &forged);
    p.inject(Origin::Vehicle, &tampered);
    p.drive();
    assert_eq!(
        p.gcs.signing_timestamp(),
        before,
        "forgeries never raise our timestamp"
    );
    for _ in 0..3 {
        p.now += Duration::from_millis(100);
        p.vehicle_send(&Heartbeat::default());
        p.drive();
    }
    assert_eq!(
        rejected(&p.gcs_events),
        [RejectReason::BadSignature, RejectReason::BadSignature]
    );
    assert_eq!(
        accepted(&p.gcs_events),
        4,
        "every genuine frame, before and after"
    );
}

#[test]
fn mavlink1_frame_on_a_signed_link_is_rejected() {
    let mut g = signed_gcs();
    let events = feed(
        &mut g,
        T0,
        &frame(Version::V1, 0, 1, 1, &Heartbeat::default()),
    );
    assert_eq!(rejected(&events), [RejectReason::Mavlink1OnSignedLink]);
    assert_eq!(g.stats().rejected.mavlink1_on_signed_link, 1);
}

#[test]
fn unsigned_frame_not_on_the_allow_list_is_rejected() {
    let mut g = signed_gcs();
    let events = feed(
        &mut g,
        T0,
        &frame(Version::V2, 0, 1, 1, &Heartbeat::default()),
    );
    assert_eq!(rejected(&events), [RejectReason::UnsignedNotAllowed]);
    assert_eq!(g.stats().rejected.unsigned_not_allowed, 1);
    assert_eq!(g.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn allow_listed_unsigned_frames_are_accepted_but_not_authenticated() {
    let mut g = signed_gcs();
    let status = RadioStatus::default();
    let stream = [
        frame(Version::V1, 0, 51, 68, &status),
        frame(Version::V2, 1, 51, 68, &status),
    ]
    .concat();
    let events = feed(&mut g, T0, &stream);
    let frames = Pair::frames(&events);
    assert_eq!(frames.len(), 2);
    assert!(
        frames
            .iter()
            .all(|f| f.auth == Authentication::AllowedUnsigned)
    );
    assert!(!frames[0].auth.is_authenticated());
}

#[test]
fn unsigned_allow_list_is_configurable() {
    let mut config = signed_config(Config::ground_station(255, 190), 0);
    let signing = config.signing.as_mut().unwrap();
    signing.clear_allowed_unsigned();
    signing.allow_unsigned(0).unwrap(); // HEARTBEAT
    let mut g = Channel::new(config).unwrap();
    let stream = [
        frame(Version::V2, 0, 51, 68, &RadioStatus::default()),
        frame(Version::V2, 0, 1, 1, &Heartbeat::default()),
    ]
    .concat();
    let events = feed(&mut g, T0, &stream);
    assert_eq!(rejected(&events), [RejectReason::UnsignedNotAllowed]);
    assert_eq!(Pair::frames(&events)[0].msg_id(), 0);
}

#[test]
fn badly_signed_frame_is_rejected_even_if_allow_listed() {
    let mut g = signed_gcs();
    let forged = signed_frame(
        0,
        51,
        68,
        &RadioStatus::default(),
        &wrong_key(),
        0,
        timestamp_at(T0),
    );
    assert_eq!(
        rejected(&feed(&mut g, T0, &forged)),
        [RejectReason::BadSignature]
    );
}

#[test]
fn new_stream_more_than_a_minute_behind_is_rejected() {
    let mut g = signed_gcs();
    let now = T0;
    let local = timestamp_at(now);
    let hb = Heartbeat::default();
    let too_old = signed_frame(0, 1, 1, &hb, &key(), 1, local - 6_000_001);
    let events = feed(&mut g, now, &too_old);
    assert!(matches!(
        rejected(&events)[..],
        [RejectReason::TooOld { .. }]
    ));
    assert_eq!(g.stats().rejected.too_old, 1);
    // Just inside the minute: accepted. Far ahead (a sender with a better clock): accepted.
    let inside = signed_frame(0, 1, 1, &hb, &key(), 2, local - 6_000_000 + 1);
    let ahead = signed_frame(0, 2, 1, &hb, &key(), 1, local + 360_000_000);
    let events = feed(&mut g, now, &[inside, ahead].concat());
    assert_eq!(accepted(&events), 2);
    assert!(rejected(&events).is_empty());
}

#[test]
fn signing_streams_are_keyed_by_sysid_compid_and_link_id() {
    let mut g = signed_gcs();
    let ts = timestamp_at(T0);
    let hb = Heartbeat::default();
    let stream = [
        signed_frame(0, 1, 1, &hb, &key(), 0, ts),
        signed_frame(0, 1, 1, &hb, &key(), 1, ts),
        signed_frame(0, 1, 2, &hb, &key(), 0, ts),
        signed_frame(0, 2, 1, &hb, &key(), 0, ts),
    ]
    .concat();
    let events = feed(&mut g, T0, &stream);
    assert_eq!(accepted(&events), 4);
    assert_eq!(g.signing_streams().len(), 4);
}

#[test]
fn full_stream_table_rejects_new_streams_and_counts() {
    let mut g = signed_gcs();
    let ts = timestamp_at(T0);
    let mut stream = Vec::new();
    for i in 0..=MAX_STREAMS {
        let sysid = u8::try_from(i + 1).unwrap();
        stream.extend(signed_frame(
            0,
            sysid,
            1,
            &Heartbeat::default(),
            &key(),
            0,
            ts,
        ));
    }
    let events = feed(&mut g, T0, &stream);
    assert_eq!(accepted(&events), MAX_STREAMS);
    assert_eq!(rejected(&events), [RejectReason::StreamTableFull]);
    // Known streams still pass.
    let events = feed(
        &mut g,
        T0,
        &signed_frame(1, 1, 1, &Heartbeat::default(), &key(), 0, ts + 1),
    );
    assert_eq!(accepted(&events), 1);
}

#[test]
fn link_timestamp_rises_with_verified_incoming_frames() {
    let mut config = signed_config(Config::ground_station(255, 190), 0);
    config.signing.as_mut().unwrap().wall_clock = WallClock::None;
    let mut g = Channel::new(config).unwrap();
    let theirs = timestamp_at(T0) + 12_345;
    let _ = feed(
        &mut g,
        T0,
        &signed_frame(0, 1, 1, &Heartbeat::default(), &key(), 1, theirs),
    );
    assert_eq!(g.signing_timestamp(), Some(theirs));
    let mut buf = [0u8; MAX_FRAME_LEN];
    let t = g.send(T0, &Heartbeat::default(), &mut buf).unwrap();
    let sent = mavstack_channel::OwnedFrame::new(&buf[..t.len]).unwrap();
    assert_eq!(sent.signature().unwrap().timestamp, theirs + 1);
}

#[test]
fn outgoing_timestamps_never_go_backwards_even_if_the_clock_steps_back() {
    let mut v = Channel::new(signed_config(Config::vehicle(1, 1), 1)).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut last = 0;
    for now in [
        T0 + Duration::from_secs(10),
        T0 + Duration::from_secs(10),
        T0,
        T0,
        T0 + Duration::from_secs(1),
    ] {
        for _ in 0..3 {
            let t = v.send(now, &Heartbeat::default(), &mut buf).unwrap();
            let ts = mavstack_channel::OwnedFrame::new(&buf[..t.len])
                .unwrap()
                .signature()
                .unwrap()
                .timestamp;
            assert!(ts > last, "{ts} after {last}");
            last = ts;
        }
    }
}

#[test]
fn signing_timestamps_count_10us_units_since_2015() {
    let mut v = Channel::new(signed_config(Config::vehicle(1, 1), 1)).unwrap();
    let now = Instant::from_micros((EPOCH_UNIX_SECS + 1) * 1_000_000 + 25);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let t = v.send(now, &Heartbeat::default(), &mut buf).unwrap();
    let sig = mavstack_channel::OwnedFrame::new(&buf[..t.len])
        .unwrap()
        .signature()
        .unwrap();
    assert_eq!((sig.timestamp, sig.link_id), (100_002, 1));
    // A caller whose instants are not Unix-anchored gives the offset.
    let mut config = signed_config(Config::vehicle(1, 1), 1);
    config.signing.as_mut().unwrap().wall_clock =
        WallClock::OffsetMicros(i64::try_from(EPOCH_UNIX_SECS * 1_000_000).unwrap());
    let mut booted = Channel::new(config).unwrap();
    let t = booted
        .send(Instant::from_secs(2), &Heartbeat::default(), &mut buf)
        .unwrap();
    let sig = mavstack_channel::OwnedFrame::new(&buf[..t.len])
        .unwrap()
        .signature()
        .unwrap();
    assert_eq!(sig.timestamp, 200_000);
}

#[test]
fn timestamp_persistence_event_and_restart_never_reuses_timestamps() {
    let mut config = signed_config(Config::vehicle(1, 1), 1);
    let signing = config.signing.as_mut().unwrap();
    signing.wall_clock = WallClock::None; // the hard case: no clock at all
    signing.persist_margin = 100;
    let mut v = Channel::new(config.clone()).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut stored = Vec::new();
    let mut used = Vec::new();
    for _ in 0..250 {
        let t = v.send(T0, &Heartbeat::default(), &mut buf).unwrap();
        used.push(
            mavstack_channel::OwnedFrame::new(&buf[..t.len])
                .unwrap()
                .signature()
                .unwrap()
                .timestamp,
        );
        while let Some(e) = v.poll_event() {
            if let Event::PersistTimestamp { timestamp } = e {
                stored.push(timestamp);
            }
        }
    }
    assert_eq!(stored.len(), 3, "once per margin of timestamps: {stored:?}");
    assert!(stored.windows(2).all(|w| w[0] < w[1]));
    // Restart from the last stored value: every new timestamp is above every old one.
    config.signing.as_mut().unwrap().initial_timestamp = *stored.last().unwrap();
    let mut restarted = Channel::new(config).unwrap();
    let t = restarted.send(T0, &Heartbeat::default(), &mut buf).unwrap();
    let first = mavstack_channel::OwnedFrame::new(&buf[..t.len])
        .unwrap()
        .signature()
        .unwrap()
        .timestamp;
    assert!(first > *used.iter().max().unwrap());
    assert_eq!(v.signing_timestamp(), used.last().copied());
}

#[test]
fn timestamp_persistence_through_the_harness() {
    let mut p = signed_pair();
    p.heartbeats = Some(Duration::from_secs(1));
    p.drive_for(Duration::from_secs(130));
    // The default margin is one minute: the first frame and then about once a minute.
    assert!(
        (2..=4).contains(&p.vehicle_persisted.len()),
        "{:?}",
        p.vehicle_persisted
    );
    let last_used = p.vehicle.signing_timestamp().unwrap();
    assert!(*p.vehicle_persisted.last().unwrap() > last_used);
}

fn setup(
    target_system: u8,
    target_component: u8,
    key: [u8; 32],
    initial_timestamp: u64,
) -> SetupSigning {
    SetupSigning {
        target_system,
        target_component,
        secret_key: key,
        initial_timestamp,
    }
}

#[test]
fn setup_signing_on_an_insecure_link_is_rejected_and_counted() {
    let mut v = Channel::new(Config::vehicle(1, 1)).unwrap();
    let f = frame(Version::V2, 0, 255, 190, &setup(1, 1, [7; 32], 1));
    let events = feed(&mut v, T0, &f);
    assert_eq!(rejected(&events), [RejectReason::SetupSigningInsecure]);
    assert_eq!(v.stats().rejected.setup_signing_insecure, 1);
    assert_eq!(
        v.version(),
        LinkVersion::Mavlink1,
        "a rejected frame switches nothing"
    );
    assert!(v.signing().is_none());
}

#[test]
fn setup_signing_on_a_secure_link_enables_signing() {
    let mut config = Config::vehicle(1, 1);
    config.secure = true;
    let mut gcs = Config::ground_station(255, 190);
    gcs.role = Role::GroundStation(mavstack_channel::GroundPolicy::Mavlink2); // id 256 needs v2
    let mut p = Pair::new(config, gcs);
    let new_key = [0x5A; 32];
    let initial = timestamp_at(T0);
    p.gcs_send(&setup(1, 1, new_key, initial));
    p.drive();
    let setups: Vec<_> = p
        .vehicle_events
        .iter()
        .filter_map(|e| match e {
            Event::SigningSetup {
                setup:
                    SigningSetup::Enabled {
                        key,
                        initial_timestamp,
                    },
                sysid,
                ..
            } => Some((*key.as_bytes(), *initial_timestamp, *sysid)),
            _ => None,
        })
        .collect();
    assert_eq!(setups, [(new_key, initial, 255)]);
    assert!(
        Pair::frames(&p.vehicle_events).is_empty(),
        "the key is never delivered as a frame"
    );
    assert_eq!(p.vehicle.version(), LinkVersion::SignedMavlink2);
    assert!(p.vehicle_events.iter().any(|e| matches!(
        e,
        Event::VersionChanged {
            to: LinkVersion::SignedMavlink2,
            cause: SwitchCause::SigningEnabled,
            ..
        }
    )));
    // The ground station takes the key too; from now on the link is signed both ways.
    p.gcs
        .set_signing(Some(SigningConfig::new(SecretKey::new(new_key), 0)))
        .unwrap();
    p.vehicle_send(&Heartbeat::default());
    p.gcs_send(&Heartbeat::default());
    p.drive();
    let last = Pair::frames(&p.gcs_events).last().copied().unwrap().clone();
    assert!(last.auth.is_authenticated());
    assert!(rejected(&p.vehicle_events).is_empty() && rejected(&p.gcs_events).is_empty());
}

#[test]
fn setup_signing_held_by_the_vehicle_is_rejected_until_released() {
    let mut config = Config::vehicle(1, 1);
    config.secure = true;
    let mut v = Channel::new(config).unwrap();
    assert!(!v.is_setup_signing_held());
    v.hold_setup_signing(true);
    let events = feed(
        &mut v,
        T0,
        &frame(Version::V2, 0, 255, 190, &setup(1, 1, [7; 32], 1)),
    );
    assert_eq!(rejected(&events), [RejectReason::SetupSigningHeld]);
    assert_eq!(v.stats().rejected.setup_signing_held, 1);
    assert!(
        v.signing().is_none(),
        "a held SETUP_SIGNING changes nothing"
    );
    v.hold_setup_signing(false);
    let events = feed(
        &mut v,
        T0,
        &frame(Version::V2, 1, 255, 190, &setup(1, 1, [7; 32], 1)),
    );
    assert!(rejected(&events).is_empty());
    assert_eq!(v.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn setup_signing_misaddressed_is_rejected() {
    let mut config = Config::vehicle(1, 1);
    config.secure = true;
    let mut v = Channel::new(config).unwrap();
    for (ts, tc) in [(2, 1), (0, 0), (1, 2)] {
        let events = feed(
            &mut v,
            T0,
            &frame(Version::V2, 0, 255, 190, &setup(ts, tc, [7; 32], 1)),
        );
        assert_eq!(
            rejected(&events),
            [RejectReason::SetupSigningMisaddressed],
            "{ts}/{tc}"
        );
    }
    // Component 0 means every component of this system.
    let events = feed(
        &mut v,
        T0,
        &frame(Version::V2, 1, 255, 190, &setup(1, 0, [7; 32], 1)),
    );
    assert!(rejected(&events).is_empty());
    assert_eq!(v.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn setup_signing_with_an_all_zero_key_disables_signing() {
    let mut config = signed_config(Config::vehicle(1, 1), 1);
    config.secure = true;
    let mut v = Channel::new(config).unwrap();
    let f = signed_frame(
        0,
        255,
        190,
        &setup(1, 1, [0; 32], 0),
        &key(),
        0,
        timestamp_at(T0),
    );
    let events = feed(&mut v, T0, &f);
    assert!(events.iter().any(|e| matches!(
        e,
        Event::SigningSetup {
            setup: SigningSetup::Disabled,
            ..
        }
    )));
    assert_eq!(v.version(), LinkVersion::Mavlink2);
    assert!(v.signing().is_none());
}

#[test]
fn setup_signing_on_a_signed_link_must_itself_be_signed() {
    let mut config = signed_config(Config::vehicle(1, 1), 1);
    config.secure = true;
    let mut v = Channel::new(config).unwrap();
    let events = feed(
        &mut v,
        T0,
        &frame(Version::V2, 0, 255, 190, &setup(1, 1, [0; 32], 0)),
    );
    assert_eq!(rejected(&events), [RejectReason::UnsignedNotAllowed]);
    assert_eq!(v.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn setup_signing_to_a_mavlink1_only_vehicle_is_rejected() {
    let mut config = Config::vehicle(1, 1);
    config.secure = true;
    if let Role::Vehicle(p) = &mut config.role {
        p.version = VehicleVersion::Mavlink1Only;
    }
    let mut v = Channel::new(config).unwrap();
    let events = feed(
        &mut v,
        T0,
        &frame(Version::V2, 0, 255, 190, &setup(1, 1, [7; 32], 1)),
    );
    assert_eq!(rejected(&events), [RejectReason::SetupSigningNeedsMavlink2]);
}

#[test]
fn signed_frames_on_a_link_without_keys_are_delivered_not_checked() {
    let mut g = Channel::new(Config::ground_station(255, 190)).unwrap();
    let f = signed_frame(0, 1, 1, &Heartbeat::default(), &wrong_key(), 3, 42);
    let events = feed(&mut g, T0, &f);
    let frames = Pair::frames(&events);
    assert_eq!(
        frames[0].auth,
        Authentication::NotChecked {
            link_id: 3,
            timestamp: 42
        }
    );
    assert!(!frames[0].auth.is_authenticated() && frames[0].is_signed());
}

#[test]
fn any_of_the_link_keys_verifies_incoming_frames() {
    let mut config = signed_config(Config::ground_station(255, 190), 0);
    config
        .signing
        .as_mut()
        .unwrap()
        .add_key(wrong_key())
        .unwrap();
    let mut g = Channel::new(config).unwrap();
    let f = signed_frame(
        0,
        1,
        1,
        &Heartbeat::default(),
        &wrong_key(),
        1,
        timestamp_at(T0),
    );
    let events = feed(&mut g, T0, &f);
    assert!(matches!(
        Pair::frames(&events)[0].auth,
        Authentication::Verified { key_index: 1, .. }
    ));
    // Outgoing frames use the primary key.
    assert_eq!(
        g.signing().unwrap().primary_key().as_bytes(),
        key().as_bytes()
    );
}

#[test]
fn golden_signed_heartbeat_verifies_through_the_channel() {
    // Digest §10: key 00..1f, link 1, timestamp 0x0102030405.
    let golden = [
        0xfd, 0x09, 0x01, 0x00, 0x00, 0x01, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02,
        0x0c, 0x51, 0x04, 0x03, 0xfc, 0x8c, 0x01, 0x05, 0x04, 0x03, 0x02, 0x01, 0x00, 0xb6, 0x81,
        0xa6, 0xe1, 0x10, 0x5b,
    ];
    let mut config = signed_config(Config::ground_station(255, 190), 0);
    config.signing.as_mut().unwrap().wall_clock = WallClock::None;
    let mut g = Channel::new(config).unwrap();
    let events = feed(&mut g, T0, &golden);
    assert!(matches!(
        Pair::frames(&events)[0].auth,
        Authentication::Verified {
            link_id: 1,
            timestamp: 0x0102030405,
            key_index: 0
        }
    ));
    // The C parser's replay check: the identical frame again is rejected.
    assert!(matches!(
        rejected(&feed(&mut g, T0, &golden))[..],
        [RejectReason::Replayed { .. }]
    ));
}

#[test]
fn frame_with_a_bad_checksum_is_never_accepted_for_its_signature() {
    let mut g = signed_gcs();
    let mut f = signed_frame(0, 1, 1, &Heartbeat::default(), &key(), 1, timestamp_at(T0));
    // Corrupt the payload, then re-sign the corrupted bytes with the right key: the signature
    // is valid, the checksum is not.
    f[14] ^= 0xff;
    let unsigned_len = f.len() - 13;
    let mut buf = [0u8; MAX_FRAME_LEN];
    buf[..unsigned_len].copy_from_slice(&f[..unsigned_len]);
    let len = mavstack_core::signing::append_signature(
        &mut buf,
        unsigned_len,
        1,
        timestamp_at(T0),
        &key(),
    )
    .unwrap();
    let events = feed(&mut g, T0, &buf[..len]);
    assert!(events.is_empty());
    assert_eq!(g.stats().parser.bad_crc, 1);
}

#[test]
fn handshake_on_a_signed_link_is_signed() {
    let mut p = signed_pair();
    p.gcs
        .start_handshake(
            p.now,
            mavstack_channel::Target::new(1, 1),
            mavstack_channel::HandshakeMethod::RequestMessage300,
            mavstack_channel::CommandEncoding::Long,
        )
        .unwrap();
    p.drive();
    assert!(p.handshake_outcomes()[0].result.is_success());
    assert!(p.sent.iter().all(|s| s.is_signed()));
    assert_eq!(p.gcs.version(), LinkVersion::SignedMavlink2);
}

#[test]
fn set_signing_at_run_time_reports_the_version_change() {
    let mut g = Channel::new(Config::ground_station(255, 190)).unwrap();
    g.set_signing(Some(SigningConfig::new(key(), 0))).unwrap();
    assert!(matches!(
        g.poll_event(),
        Some(Event::VersionChanged {
            from: LinkVersion::Mavlink1,
            to: LinkVersion::SignedMavlink2,
            ..
        })
    ));
    g.set_signing(None).unwrap();
    assert_eq!(g.version(), LinkVersion::Mavlink2);
    let mut v1 = Config::vehicle(1, 1);
    if let Role::Vehicle(p) = &mut v1.role {
        p.version = VehicleVersion::Mavlink1Only;
    }
    let mut v1 = Channel::new(v1).unwrap();
    assert!(v1.set_signing(Some(SigningConfig::new(key(), 0))).is_err());
}

#[test]
fn no_genuine_frame_is_rejected_under_loss_duplication_and_attack() {
    for seed in 0..5 {
        let mut p = signed_pair().seed(seed);
        p.link.knobs.loss = 0.1;
        p.link.knobs.duplicate = 0.1;
        let mut injected = 0;
        for i in 0..200u64 {
            p.now += Duration::from_millis(50);
            p.vehicle_send(&Heartbeat::default());
            if i % 7 == 0 {
                // Forgeries of the vehicle's stream, some with huge timestamps.
                let ts = if i % 2 == 0 {
                    MAX_TIMESTAMP
                } else {
                    timestamp_at(p.now) + 1
                };
                let forged = signed_frame(200, 1, 1, &Heartbeat::default(), &wrong_key(), 1, ts);
                p.deliver_now(Node::Gcs, &forged);
                injected += 1;
            }
            if i % 11 == 0 {
                p.deliver_now(
                    Node::Gcs,
                    &frame(Version::V1, 0, 1, 1, &Heartbeat::default()),
                );
                injected += 1;
            }
            p.drive();
        }
        let stats = p.gcs.stats();
        let delivered = 200 - p.link.faults.lost;
        // Every genuine frame that arrived was accepted; each duplicate was a replay.
        assert_eq!(stats.accepted, delivered, "seed {seed}");
        let dups_arrived = stats.rejected.replayed;
        assert!(dups_arrived <= p.link.faults.duplicated);
        assert_eq!(
            stats.rejected.total(),
            injected + dups_arrived,
            "seed {seed}: {stats:?}"
        );
        assert_eq!(
            stats.rejected.bad_signature + stats.rejected.mavlink1_on_signed_link,
            injected
        );
    }
}

#[test]
fn changing_signing_settings_keeps_timestamps_rising_and_replay_state() {
    let mut config = signed_config(Config::vehicle(1, 1), 1);
    config.signing.as_mut().unwrap().wall_clock = WallClock::None;
    let mut v = Channel::new(config.clone()).unwrap();
    let mut buf = [0u8; MAX_FRAME_LEN];
    for _ in 0..5 {
        let _ = v.send(T0, &Heartbeat::default(), &mut buf).unwrap();
    }
    let _ = feed(
        &mut v,
        T0,
        &signed_frame(0, 255, 190, &Heartbeat::default(), &key(), 0, 1_000),
    );
    let last = v.signing_timestamp().unwrap();
    // New settings (a second key) with a stale initial timestamp.
    let mut new = config.signing.clone().unwrap();
    new.add_key(wrong_key()).unwrap();
    new.initial_timestamp = 0;
    v.set_signing(Some(new)).unwrap();
    let t = v.send(T0, &Heartbeat::default(), &mut buf).unwrap();
    let ts = mavstack_channel::OwnedFrame::new(&buf[..t.len])
        .unwrap()
        .signature()
        .unwrap()
        .timestamp;
    assert!(ts > last);
    // The replayed frame of the old settings is still a replay.
    let events = feed(
        &mut v,
        T0,
        &signed_frame(0, 255, 190, &Heartbeat::default(), &key(), 0, 1_000),
    );
    assert!(matches!(
        rejected(&events)[..],
        [RejectReason::Replayed { .. }]
    ));
}
