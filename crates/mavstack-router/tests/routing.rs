//! The router core, deterministic: every routing, framing and signing rule as a named test
//! over links fed by hand, with a virtual clock.

use core::time::Duration;

use mavstack_channel::SigningConfig;
use mavstack_core::message::{Message, MessageSet};
use mavstack_core::signing::{SecretKey, append_signature, verify};
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{
    Attitude, CommandAck, CommandLong, Heartbeat, LogData, LogRequestData, LogRequestEnd, MavCmd,
    MavMessage, MavSysStatusSensorExtended, ProtocolVersion, SysStatus,
};
use mavstack_router::{
    LinkConfig, LinkId, LocalFrames, MessageTable, Router, RouterConfig, SendTo, VersionMode,
};

type R = Router;

const T0: Instant = Instant::from_secs(1_767_225_600);

fn router() -> R {
    Router::new(RouterConfig::default(), MessageTable::of::<MavMessage>())
}

fn key(b: u8) -> SecretKey {
    SecretKey::new([b; 32])
}

/// A frame of `msg` from `(sysid, compid)`, in `version`, signed with `sign` if given.
fn frame<M: Message>(
    msg: &M,
    version: Version,
    src: (u8, u8),
    seq: u8,
    sign: Option<(&SecretKey, u64)>,
) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version,
        seq,
        sysid: src.0,
        compid: src.1,
        signed: sign.is_some(),
    };
    let mut len = wire::emit_message(&header, msg, &mut buf).unwrap();
    if let Some((k, ts)) = sign {
        len = append_signature(&mut buf, len, 7, ts, k).unwrap();
    }
    buf[..len].to_vec()
}

fn hb() -> Heartbeat {
    Heartbeat {
        custom_mode: 5,
        mavlink_version: 3,
        ..Heartbeat::default()
    }
}

fn command(target: (u8, u8)) -> CommandLong {
    CommandLong {
        command: MavCmd::REQUEST_MESSAGE,
        param1: 300.0,
        target_system: target.0,
        target_component: target.1,
        ..CommandLong::default()
    }
}

/// Every frame the router sends, by link.
fn drain(r: &mut R) -> Vec<(LinkId, Vec<u8>)> {
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    while let Some(t) = r.poll_transmit(&mut buf) {
        out.push((t.link, buf[..t.len].to_vec()));
    }
    while r.poll_event().is_some() {}
    out
}

fn on(out: &[(LinkId, Vec<u8>)], link: LinkId) -> Vec<Vec<u8>> {
    out.iter()
        .filter(|(l, _)| *l == link)
        .map(|(_, b)| b.clone())
        .collect()
}

fn link(r: &mut R, name: &str, f: impl FnOnce(&mut LinkConfig)) -> LinkId {
    let mut c = LinkConfig::new(name);
    f(&mut c);
    r.add_link(c).unwrap()
}

#[test]
fn broadcasts_go_everywhere_but_back_and_targeted_frames_only_where_the_target_is() {
    let mut r = router();
    let (a, b, c) = (
        link(&mut r, "a", |_| {}),
        link(&mut r, "b", |_| {}),
        link(&mut r, "c", |_| {}),
    );
    let vehicle = frame(&hb(), Version::V2, (1, 1), 0, None);
    r.handle_datagram(T0, a, &vehicle);
    let out = drain(&mut r);
    assert_eq!(
        (on(&out, a).len(), on(&out, b), on(&out, c)),
        (0, vec![vehicle.clone()], vec![vehicle.clone()])
    );
    // b is the ground station; its command to 1/1 goes to a only.
    r.handle_datagram(T0, b, &frame(&hb(), Version::V2, (255, 190), 0, None));
    drain(&mut r);
    let cmd = frame(&command((1, 1)), Version::V2, (255, 190), 1, None);
    r.handle_datagram(T0, b, &cmd);
    let out = drain(&mut r);
    assert_eq!(out, vec![(a, cmd)]);
    // To a system nobody has heard: dropped and counted on the link it came from.
    r.handle_datagram(
        T0,
        b,
        &frame(&command((77, 1)), Version::V2, (255, 190), 2, None),
    );
    assert!(drain(&mut r).is_empty());
    assert_eq!(r.link_status(b).unwrap().counters.dropped.unknown_target, 1);
    // The answer (COMMAND_ACK, target in its extension fields) goes back to b only.
    let ack = CommandAck {
        command: MavCmd::REQUEST_MESSAGE,
        target_system: 255,
        target_component: 190,
        ..CommandAck::default()
    };
    let ack = frame(&ack, Version::V2, (1, 1), 1, None);
    r.handle_datagram(T0, a, &ack);
    assert_eq!(drain(&mut r), vec![(b, ack)]);
}

#[test]
fn log_data_goes_to_the_link_that_asked_for_the_log_not_everywhere() {
    let mut r = router();
    let (vehicle, gcs, radio) = (
        link(&mut r, "vehicle", |_| {}),
        link(&mut r, "gcs", |_| {}),
        link(&mut r, "radio", |_| {}),
    );
    r.handle_datagram(T0, vehicle, &frame(&hb(), Version::V2, (1, 1), 0, None));
    r.handle_datagram(T0, gcs, &frame(&hb(), Version::V2, (255, 190), 0, None));
    r.handle_datagram(T0, radio, &frame(&hb(), Version::V2, (254, 190), 0, None));
    drain(&mut r);
    let chunk = |seq: u8| {
        let data = LogData {
            id: 3,
            ofs: u32::from(seq) * 90,
            count: 90,
            data: [seq; 90],
        };
        frame(&data, Version::V2, (1, 1), seq, None)
    };
    // Nobody asked: LOG_DATA is a broadcast, as its lack of target fields says.
    r.handle_datagram(T0, vehicle, &chunk(1));
    let out = drain(&mut r);
    assert_eq!((on(&out, gcs).len(), on(&out, radio).len()), (1, 1));
    // The ground station asks for log 3: its data goes to it alone, for as long as it flows.
    let ask = LogRequestData {
        target_system: 1,
        target_component: 1,
        id: 3,
        ofs: 0,
        count: u32::MAX,
    };
    let ask = frame(&ask, Version::V2, (255, 190), 1, None);
    r.handle_datagram(T0, gcs, &ask);
    assert_eq!(drain(&mut r), vec![(vehicle, ask)]);
    for (i, seq) in (2..40u8).enumerate() {
        let at = T0 + Duration::from_millis(500 * i as u64);
        r.handle_datagram(at, vehicle, &chunk(seq));
        assert_eq!(drain(&mut r), vec![(gcs, chunk(seq))], "chunk {seq}");
    }
    // Its LOG_REQUEST_END ends that (the radio's cannot).
    let end = |src: (u8, u8)| {
        let end = LogRequestEnd {
            target_system: 1,
            target_component: 1,
        };
        frame(&end, Version::V2, src, 2, None)
    };
    let later = T0 + Duration::from_secs(20);
    r.handle_datagram(later, radio, &end((254, 190)));
    drain(&mut r);
    r.handle_datagram(later, vehicle, &chunk(41));
    assert_eq!(drain(&mut r), vec![(gcs, chunk(41))]);
    r.handle_datagram(later, gcs, &end((255, 190)));
    drain(&mut r);
    r.handle_datagram(later, vehicle, &chunk(42));
    let out = drain(&mut r);
    assert_eq!((on(&out, gcs).len(), on(&out, radio).len()), (1, 1));
}

#[test]
fn an_echo_on_another_link_does_not_cut_the_vehicle_off() {
    // mavlink-router #452: one frame with the vehicle's sysid coming back from another link
    // stops the vehicle's traffic to that link for good. Here both keep working.
    let mut r = router();
    let (veh, gcs, echo) = (
        link(&mut r, "veh", |_| {}),
        link(&mut r, "gcs", |_| {}),
        link(&mut r, "echo", |_| {}),
    );
    let hb1 = frame(&hb(), Version::V2, (1, 1), 0, None);
    r.handle_datagram(T0, veh, &hb1);
    r.handle_datagram(T0, gcs, &frame(&hb(), Version::V2, (255, 190), 0, None));
    drain(&mut r);
    r.handle_datagram(T0 + Duration::from_millis(5), echo, &hb1); // the echo
    let out = drain(&mut r);
    assert_eq!(
        on(&out, veh),
        vec![hb1.clone()],
        "the echo is a broadcast: it reaches the vehicle's link too"
    );
    let cmd = frame(&command((1, 1)), Version::V2, (255, 190), 1, None);
    r.handle_datagram(T0 + Duration::from_millis(10), gcs, &cmd);
    assert!(
        on(&drain(&mut r), veh).contains(&cmd),
        "the command still reaches the vehicle"
    );
    // The vehicle's own telemetry still reaches the echoing link.
    let hb2 = frame(&hb(), Version::V2, (1, 1), 1, None);
    r.handle_datagram(T0 + Duration::from_millis(20), veh, &hb2);
    assert!(on(&drain(&mut r), echo).contains(&hb2));
}

#[test]
fn a_mavlink1_link_gets_base_fields_and_never_an_id_above_255() {
    let mut r = router();
    let veh = link(&mut r, "veh", |_| {});
    let legacy = link(&mut r, "legacy", |c| c.version = VersionMode::Mavlink1);
    let status = SysStatus {
        voltage_battery: 12_000,
        current_battery: -1,
        battery_remaining: 77,
        onboard_control_sensors_present_extended: MavSysStatusSensorExtended(1),
        ..SysStatus::default()
    };
    let v2 = frame(&status, Version::V2, (1, 1), 42, None);
    r.handle_datagram(T0, veh, &v2);
    let pv = ProtocolVersion {
        version: 200,
        min_version: 100,
        max_version: 200,
        ..ProtocolVersion::default()
    };
    r.handle_datagram(T0, veh, &frame(&pv, Version::V2, (1, 1), 43, None));
    let out = on(&drain(&mut r), legacy);
    assert_eq!(out.len(), 1);
    let f = Frame::new_checked(&out[0][..]).unwrap();
    assert_eq!(
        (f.version(), f.seq(), f.sysid(), f.compid(), f.msg_id()),
        (Version::V1, 42, 1, 1, SysStatus::ID)
    );
    assert!(f.check_crc(SysStatus::CRC_EXTRA));
    assert_eq!(f.payload().len(), SysStatus::MIN_LEN, "base fields only");
    let mut expect = status;
    expect.onboard_control_sensors_present_extended = MavSysStatusSensorExtended(0); // an extension: not in MAVLink 1
    assert_eq!(
        MavMessage::decode(f.msg_id(), f.payload()),
        Ok(MavMessage::SysStatus(expect))
    );
    let s = r.link_status(legacy).unwrap();
    assert_eq!(
        (
            s.counters.conversions.to_mavlink1,
            s.counters.dropped.cannot_convert
        ),
        (1, 1)
    );
}

#[test]
fn a_mavlink2_link_gets_mavlink1_frames_converted_and_truncated() {
    let mut r = router();
    let old = link(&mut r, "old", |_| {});
    let v2 = link(&mut r, "v2", |c| c.version = VersionMode::Mavlink2);
    let auto = link(&mut r, "auto", |_| {});
    let att = Attitude {
        time_boot_ms: 7,
        roll: 0.5,
        ..Attitude::default()
    };
    let v1 = frame(&att, Version::V1, (1, 1), 3, None);
    r.handle_datagram(T0, old, &v1);
    let out = drain(&mut r);
    let got = on(&out, v2);
    let f = Frame::new_checked(&got[0][..]).unwrap();
    assert_eq!((f.version(), f.seq()), (Version::V2, 3));
    assert_ne!(f.payload().last(), Some(&0), "truncated");
    assert_eq!(Attitude::decode(f.payload()), att);
    // An auto link whose peer has not spoken MAVLink 2 gets it as it arrived.
    assert_eq!(on(&out, auto), vec![v1.clone()]);
    // Once its peer sends MAVLink 2, it is a MAVLink 2 link.
    r.handle_datagram(T0, auto, &frame(&hb(), Version::V2, (255, 190), 0, None));
    drain(&mut r);
    r.handle_datagram(T0, old, &v1);
    let got = on(&drain(&mut r), auto);
    assert_eq!(got[0][0], 0xfd);
    assert_eq!(r.link_status(auto).unwrap().mode.as_str(), "2");
}

#[test]
fn signed_links_carry_only_frames_that_verify_with_their_key() {
    let (k1, k2) = (key(1), key(2));
    let mut r = router();
    let plain = link(&mut r, "plain", |_| {});
    let trusted = link(&mut r, "trusted", |c| c.trusted = true);
    let s1 = link(&mut r, "s1", |c| {
        c.signing = Some(SigningConfig::new(k1.clone(), 1))
    });
    let s2 = link(&mut r, "s2", |c| {
        c.signing = Some(SigningConfig::new(k2.clone(), 2))
    });
    let s1b = link(&mut r, "s1b", |c| {
        c.signing = Some(SigningConfig::new(k1.clone(), 3))
    });
    let ts = mavstack_core::signing::timestamp_from_unix_micros(T0.as_micros());
    // Untrusted plain frames never go onto signed links.
    r.handle_datagram(T0, plain, &frame(&hb(), Version::V2, (9, 1), 0, None));
    let out = drain(&mut r);
    assert!(on(&out, s1).is_empty() && on(&out, s2).is_empty());
    assert_eq!(
        r.link_status(s1)
            .unwrap()
            .counters
            .dropped
            .untrusted_to_signed,
        1
    );
    // Trusted ones are signed with each link's own key.
    r.handle_datagram(T0, trusted, &frame(&hb(), Version::V1, (8, 1), 0, None));
    let out = drain(&mut r);
    for (l, k) in [(s1, &k1), (s2, &k2)] {
        let got = on(&out, l);
        let f = Frame::new_checked(&got[0][..]).unwrap();
        assert!(verify(&f, k).is_ok());
        assert_eq!((f.sysid(), f.version()), (8, Version::V2));
    }
    // A frame signed with k1 arriving on s1: byte for byte to s1b (same key), re-signed for
    // s2 (verified on a signed link), signature removed for the plain links.
    let signed = frame(&hb(), Version::V2, (1, 1), 5, Some((&k1, ts + 100)));
    r.handle_datagram(T0, s1, &signed);
    let out = drain(&mut r);
    assert_eq!(on(&out, s1b), vec![signed.clone()]);
    assert!(verify(&Frame::new_checked(&on(&out, s2)[0][..]).unwrap(), &k2).is_ok());
    for l in [plain, trusted] {
        let f = on(&out, l);
        let f = Frame::new_checked(&f[0][..]).unwrap();
        assert!(!f.is_signed());
        assert!(f.check_crc(Heartbeat::CRC_EXTRA));
        assert_eq!(Heartbeat::decode(f.payload()), hb());
    }
    assert!(on(&out, s1).is_empty());
    // The same bytes again: a replay, dropped on arrival.
    r.handle_datagram(T0, s1, &signed);
    assert!(drain(&mut r).is_empty());
    assert_eq!(r.link_status(s1).unwrap().channel.rejected.replayed, 1);
    // Unsigned on a signed link: dropped there.
    r.handle_datagram(T0, s1, &frame(&hb(), Version::V2, (1, 1), 6, None));
    assert!(drain(&mut r).is_empty());
    // A wrong key: dropped.
    r.handle_datagram(
        T0,
        s1,
        &frame(&hb(), Version::V2, (1, 1), 7, Some((&k2, ts + 200))),
    );
    assert!(drain(&mut r).is_empty());
    assert_eq!(r.link_status(s1).unwrap().channel.rejected.bad_signature, 1);
}

#[test]
fn dedup_lets_a_frame_reach_each_link_once() {
    let mut config = RouterConfig::default();
    config.dedup = Some(Duration::from_millis(200));
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let (radio1, radio2, gcs) = (
        link(&mut r, "r1", |_| {}),
        link(&mut r, "r2", |_| {}),
        link(&mut r, "gcs", |_| {}),
    );
    let f = frame(&hb(), Version::V2, (1, 1), 0, None);
    r.handle_datagram(T0, radio1, &f);
    r.handle_datagram(T0 + Duration::from_millis(3), radio2, &f);
    let out = drain(&mut r);
    assert_eq!(on(&out, gcs), vec![f.clone()]);
    assert_eq!(r.link_status(gcs).unwrap().counters.dropped.duplicate, 1);
    // The window renews on each sighting.
    r.handle_datagram(T0 + Duration::from_millis(150), radio2, &f);
    r.handle_datagram(T0 + Duration::from_millis(300), radio1, &f);
    assert!(on(&drain(&mut r), gcs).is_empty());
    r.handle_datagram(T0 + Duration::from_millis(600), radio1, &f);
    assert_eq!(on(&drain(&mut r), gcs).len(), 1);
}

#[test]
fn filters_and_rate_limits_apply_per_link_and_spare_control_traffic() {
    let mut r = router();
    let veh = link(&mut r, "veh", |_| {});
    let radio = link(&mut r, "radio", |c| {
        c.limits.per_message.push((Attitude::ID, 10));
        c.filters_out.msg.block.push(SysStatus::ID);
        c.queue_frames = 8;
    });
    let gcs = link(&mut r, "gcs", |_| {});
    r.handle_datagram(T0, gcs, &frame(&hb(), Version::V2, (255, 190), 0, None));
    drain(&mut r);
    let mut now = T0;
    let mut attitude_out = 0;
    for i in 0..100u8 {
        r.handle_datagram(
            now,
            veh,
            &frame(&Attitude::default(), Version::V2, (1, 1), i, None),
        );
        r.handle_datagram(
            now,
            veh,
            &frame(&SysStatus::default(), Version::V2, (1, 1), i, None),
        );
        attitude_out += on(&drain(&mut r), radio).len();
        now += Duration::from_millis(20);
    }
    assert_eq!(attitude_out, 20, "50 Hz limited to 10 Hz for 2 s");
    let c = r.link_status(radio).unwrap().counters;
    assert_eq!((c.dropped.rate_limited, c.dropped.filtered), (80, 100));
}

#[test]
fn a_flood_that_fills_a_link_never_keeps_a_command_out() {
    let mut r = router();
    let veh = link(&mut r, "veh", |c| c.queue_frames = 8);
    let (gcs, flood) = (link(&mut r, "gcs", |_| {}), link(&mut r, "flood", |_| {}));
    r.handle_datagram(T0, veh, &frame(&hb(), Version::V2, (1, 1), 0, None));
    drain(&mut r);
    for i in 0..50u8 {
        r.handle_datagram(
            T0,
            flood,
            &frame(&Attitude::default(), Version::V2, (2, 1), i, None),
        );
    }
    r.handle_datagram(
        T0,
        gcs,
        &frame(&command((1, 1)), Version::V2, (255, 190), 0, None),
    );
    let to_veh = on(&drain(&mut r), veh);
    assert_eq!(to_veh.len(), 9);
    assert_eq!(
        Frame::new_checked(&to_veh[0][..]).unwrap().msg_id(),
        CommandLong::ID,
        "control first"
    );
    assert_eq!(r.link_status(veh).unwrap().counters.dropped.queue_full, 42);
    assert_eq!(
        r.link_status(gcs).unwrap().counters.dropped.queue_full,
        0,
        "other links unaffected"
    );
}

#[test]
fn routes_expire_and_removed_links_take_their_routes() {
    let mut r = router();
    let (a, b) = (link(&mut r, "a", |_| {}), link(&mut r, "b", |_| {}));
    r.handle_datagram(T0, a, &frame(&hb(), Version::V2, (1, 1), 0, None));
    drain(&mut r);
    assert_eq!(r.routes().count(), 1);
    r.handle_timeout(T0 + Duration::from_secs(31));
    assert_eq!(r.routes().count(), 0);
    r.handle_datagram(
        T0 + Duration::from_secs(32),
        a,
        &frame(&hb(), Version::V2, (1, 1), 1, None),
    );
    drain(&mut r);
    r.remove_link(a);
    assert_eq!(r.routes().count(), 0);
    r.handle_datagram(
        T0 + Duration::from_secs(33),
        b,
        &frame(&command((1, 1)), Version::V2, (255, 190), 0, None),
    );
    assert!(drain(&mut r).is_empty());
    assert_eq!(r.link_status(b).unwrap().counters.dropped.unknown_target, 1);
}

#[test]
fn unknown_ids_go_byte_for_byte_but_are_never_converted() {
    let mut r = router();
    let (a, b, legacy) = (
        link(&mut r, "a", |_| {}),
        link(&mut r, "b", |_| {}),
        link(&mut r, "l", |c| c.version = VersionMode::Mavlink1),
    );
    // A message id no dialect defines, a valid-looking frame (its CRC cannot be checked).
    let info = mavstack_core::MessageInfo {
        id: 42_042,
        name: "",
        crc_extra: 1,
        min_len: 4,
        max_len: 4,
        target_system_offset: None,
        target_component_offset: None,
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: false,
    };
    let len = wire::emit(&header, &info, &[1, 2, 3, 4], &mut buf).unwrap();
    r.handle_datagram(T0, a, &buf[..len]);
    let out = drain(&mut r);
    assert_eq!(on(&out, b), vec![buf[..len].to_vec()]);
    assert!(on(&out, legacy).is_empty());
    assert_eq!(
        r.link_status(legacy)
            .unwrap()
            .counters
            .dropped
            .cannot_convert,
        1
    );
}

#[test]
fn a_truncated_datagram_costs_only_itself() {
    let mut r = router();
    let (a, b) = (link(&mut r, "a", |_| {}), link(&mut r, "b", |_| {}));
    let good = frame(&hb(), Version::V2, (1, 1), 0, None);
    r.handle_datagram(T0, a, &good[..good.len() - 3]);
    let mut corrupt = good.clone();
    corrupt[12] ^= 0xff;
    r.handle_datagram(T0, a, &corrupt);
    let next = frame(&hb(), Version::V2, (1, 1), 1, None);
    r.handle_datagram(T0, a, &next);
    assert_eq!(
        on(&drain(&mut r), b),
        vec![next],
        "the frame after the bad ones, at once"
    );
    assert_eq!(r.link_status(a).unwrap().channel.parser.bad_crc, 1);
}

/// The router's own messages ([`Router::send`]): each link frames them its own way.
#[test]
fn own_messages_take_each_links_version_and_signing() {
    let mut r = router();
    let k = key(9);
    let v1 = link(&mut r, "v1", |c| c.version = VersionMode::Mavlink1);
    let auto = link(&mut r, "auto", |_| {});
    let signed = link(&mut r, "signed", |c| {
        c.signing = Some(SigningConfig::new(k.clone(), 4))
    });
    let mut payload = [0u8; 255];
    let len = hb().encode(&mut payload);
    let own = (r.config().system_id, r.config().component_id);

    assert_eq!(
        r.send(T0, SendTo::Target, Heartbeat::ID, &payload[..len]),
        3
    );
    let out = drain(&mut r);
    let on = |l: LinkId| -> Vec<Vec<u8>> {
        out.iter()
            .filter(|(d, _)| *d == l)
            .map(|(_, b)| b.clone())
            .collect()
    };
    // MAVLink 1 on the version=1 link and on the auto link that has heard nothing yet.
    for l in [v1, auto] {
        let frames = on(l);
        assert_eq!(frames.len(), 1);
        let f = Frame::new_checked(&frames[0][..]).unwrap();
        assert_eq!(f.version(), Version::V1);
        assert_eq!((f.sysid(), f.compid()), own);
        assert!(f.check_crc(Heartbeat::CRC_EXTRA));
        assert_eq!(f.msg_id(), Heartbeat::ID);
    }
    let s = on(signed);
    let f = Frame::new_checked(&s[0][..]).unwrap();
    assert_eq!(f.version(), Version::V2);
    assert!(verify(&f, &k).is_ok());

    // The auto link's peer speaks MAVLink 2: from then on, so does the router there; and a
    // message to that peer goes only there.
    r.handle_datagram(T0, auto, &frame(&hb(), Version::V2, (7, 1), 0, None));
    drain(&mut r);
    let mut payload = [0u8; 255];
    let len = command((7, 1)).encode(&mut payload);
    assert_eq!(
        r.send(T0, SendTo::Target, CommandLong::ID, &payload[..len]),
        1
    );
    let out = drain(&mut r);
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].0, auto);
    let f = Frame::new_checked(&out[0].1[..]).unwrap();
    assert_eq!(f.version(), Version::V2);
    assert_eq!(f.seq(), 1, "the auto link's second frame of ours");

    // An id above 255 cannot go on the MAVLink 1 link: counted there, sent on the others.
    let mut payload = [0u8; 255];
    let len = ProtocolVersion::default().encode(&mut payload);
    assert_eq!(
        r.send(T0, SendTo::Target, ProtocolVersion::ID, &payload[..len]),
        2
    );
    assert_eq!(
        r.link_status(v1).unwrap().counters.dropped.cannot_convert,
        1
    );
    let out = drain(&mut r);
    assert!(out.iter().all(|(l, _)| *l != v1));
    // One link named: only there.
    let len = hb().encode(&mut payload);
    assert_eq!(
        r.send(T0, SendTo::Link(signed), Heartbeat::ID, &payload[..len]),
        1
    );
    assert_eq!(drain(&mut r).len(), 1);
}

#[test]
fn vehicle_links_answer_the_handshake_in_their_own_version_and_set_the_capability_per_link() {
    use mavstack_dialects::common::{AutopilotVersion, MavProtocolCapability, MavResult};
    use mavstack_router::{Event, LinkRole};
    let mut config = RouterConfig::default();
    config.component_id = 1;
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let vehicle = LinkRole::Vehicle {
        protocol_version: mavstack_router::ProtocolVersionSupport::Answer,
    };
    let v1 = link(&mut r, "v1", |c| {
        c.version = VersionMode::Mavlink1;
        c.role = vehicle;
    });
    let auto = link(&mut r, "auto", |c| c.role = vehicle);
    let relay = link(&mut r, "relay", |_| {});

    // The handshake request, in MAVLink 2 from a ground station, on each link.
    let request = frame(&command((1, 1)), Version::V2, (255, 190), 0, None);
    r.handle_datagram(T0, v1, &request);
    r.handle_datagram(T0, auto, &request);
    r.handle_datagram(T0, relay, &request);
    let mut events = Vec::new();
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    while let Some(t) = r.poll_transmit(&mut buf) {
        out.push((t.link, buf[..t.len].to_vec()));
    }
    while let Some(e) = r.poll_event() {
        events.push(e);
    }
    let decoded = |frames: Vec<Vec<u8>>| -> Vec<(Version, MavMessage)> {
        frames
            .iter()
            .map(|b| {
                let f = Frame::new_checked(&b[..]).unwrap();
                let m = MavMessage::decode(f.msg_id(), f.payload()).unwrap();
                (f.version(), m)
            })
            .collect()
    };
    // version=1: a failure COMMAND_ACK in MAVLink 1, nothing else of the vehicle's own.
    let on_v1 = decoded(on(&out, v1));
    let acks: Vec<_> = on_v1
        .iter()
        .filter_map(|(v, m)| match m {
            MavMessage::CommandAck(a) => Some((*v, a.result)),
            _ => None,
        })
        .collect();
    assert_eq!(acks, [(Version::V1, MavResult::UNSUPPORTED)]);
    assert!(on_v1.iter().all(|(v, _)| *v == Version::V1));
    // auto: the ACK, then PROTOCOL_VERSION in MAVLink 2, and the link is MAVLink 2 now.
    let on_auto = decoded(on(&out, auto));
    assert!(
        on_auto
            .iter()
            .any(|(v, m)| *v == Version::V2 && matches!(m, MavMessage::ProtocolVersion(_)))
    );
    // A relay link answers nothing of its own: it only forwards (the request went on to the
    // other links, as a frame for system 1 heard on no link yet is not).
    assert!(decoded(on(&out, relay)).iter().all(|(_, m)| !matches!(
        m,
        MavMessage::ProtocolVersion(_) | MavMessage::CommandAck(_)
    )));
    let answered: Vec<LinkId> = events
        .iter()
        .filter_map(|e| match e {
            Event::ProtocolVersionRequested { link, from, .. } => {
                assert_eq!(*from, (255, 190));
                Some(*link)
            }
            _ => None,
        })
        .collect();
    assert_eq!(answered, [v1, auto]);

    // The component's own AUTOPILOT_VERSION: the MAVLINK2 bit only where MAVLink 2 goes.
    let mut payload = [0u8; 255];
    let own = AutopilotVersion {
        capabilities: MavProtocolCapability::MISSION_INT | MavProtocolCapability::MAVLINK2,
        ..AutopilotVersion::default()
    };
    let len = own.encode(&mut payload);
    assert_eq!(
        r.send(T0, SendTo::Target, AutopilotVersion::ID, &payload[..len]),
        3
    );
    let caps: Vec<(LinkId, u64)> = core::iter::from_fn(|| {
        r.poll_transmit(&mut buf).map(|t| {
            let f = Frame::new_checked(&buf[..t.len]).unwrap();
            match MavMessage::decode(f.msg_id(), f.payload()).unwrap() {
                MavMessage::AutopilotVersion(a) => (t.link, a.capabilities.0),
                m => panic!("{m:?}"),
            }
        })
    })
    .collect();
    let mission_int = MavProtocolCapability::MISSION_INT.0;
    let mavlink2 = MavProtocolCapability::MAVLINK2.0;
    assert!(caps.contains(&(v1, mission_int)));
    assert!(caps.contains(&(auto, mission_int | mavlink2)));
    // A relay link's frames are not the router's business: sent as given.
    assert!(caps.contains(&(relay, mission_int | mavlink2)));
}

#[test]
fn a_ground_station_link_runs_the_handshake_with_a_vehicle_link() {
    use mavstack_channel::{
        CommandEncoding, HandshakeMethod, HandshakeResult, LinkVersion, Target,
    };
    use mavstack_router::{Event, LinkRole};
    let mut gcs_config = RouterConfig::default();
    gcs_config.system_id = 255;
    gcs_config.component_id = 190;
    let mut gcs = Router::new(gcs_config, MessageTable::of::<MavMessage>());
    let mut veh_config = RouterConfig::default();
    veh_config.component_id = 1;
    let mut veh = Router::new(veh_config, MessageTable::of::<MavMessage>());
    let g = link(&mut gcs, "to vehicle", |c| c.role = LinkRole::GroundStation);
    let v = link(&mut veh, "to gcs", |c| {
        c.role = LinkRole::Vehicle {
            protocol_version: mavstack_router::ProtocolVersionSupport::Answer,
        }
    });
    assert!(
        veh.start_handshake(
            T0,
            v,
            Target::new(255, 190),
            HandshakeMethod::RequestMessage300,
            CommandEncoding::Long
        )
        .is_err(),
        "a vehicle link answers the handshake, it does not run it"
    );
    gcs.start_handshake(
        T0,
        g,
        Target::new(1, 1),
        HandshakeMethod::RequestMessage300,
        CommandEncoding::Long,
    )
    .unwrap();
    let mut outcome = None;
    let mut buf = [0u8; MAX_FRAME_LEN];
    for _ in 0..4 {
        while let Some(t) = gcs.poll_transmit(&mut buf) {
            veh.handle_datagram(T0, v, &buf[..t.len]);
        }
        while let Some(t) = veh.poll_transmit(&mut buf) {
            gcs.handle_datagram(T0, g, &buf[..t.len]);
        }
        while let Some(e) = gcs.poll_event() {
            if let Event::Handshake { link, outcome: o } = e {
                assert_eq!(link, g);
                outcome = Some(o);
            }
        }
    }
    let outcome = outcome.expect("the handshake ended");
    assert!(matches!(
        outcome.result,
        HandshakeResult::ProtocolVersion(_)
    ));
    assert_eq!(gcs.channel(g).unwrap().version(), LinkVersion::Mavlink2);
    assert_eq!(veh.channel(v).unwrap().version(), LinkVersion::Mavlink2);

    // Signing turned on by hand on both ends (what SETUP_SIGNING does on the vehicle's).
    let k = key(3);
    gcs.set_signing(T0, g, Some(SigningConfig::new(k.clone(), 1)))
        .unwrap();
    assert_eq!(
        gcs.channel(g).unwrap().version(),
        LinkVersion::SignedMavlink2
    );
    let mut payload = [0u8; 255];
    let len = hb().encode(&mut payload);
    assert_eq!(
        gcs.send(T0, SendTo::Target, Heartbeat::ID, &payload[..len]),
        1
    );
    let t = gcs.poll_transmit(&mut buf).unwrap();
    let f = Frame::new_checked(&buf[..t.len]).unwrap();
    assert!(verify(&f, &k).is_ok());
}

#[test]
fn with_forwarding_off_links_carry_only_the_routers_own_traffic() {
    use mavstack_router::LocalDelivery;
    let mut config = RouterConfig::default();
    config.forward = false;
    config.local = LocalDelivery::All;
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let a = link(&mut r, "a", |_| {});
    let b = link(&mut r, "b", |_| {});
    r.handle_datagram(T0, a, &frame(&hb(), Version::V2, (1, 1), 0, None));
    let mut buf = [0u8; MAX_FRAME_LEN];
    assert!(r.poll_transmit(&mut buf).is_none(), "nothing forwarded");
    let mut local = LocalFrames::new();
    r.take_local(&mut local);
    assert_eq!(local.iter().map(|f| f.link).collect::<Vec<_>>(), [a]);
    // Its own messages still go out, routed: the command for 1/1 only where 1/1 was heard.
    let mut payload = [0u8; 255];
    let len = command((1, 1)).encode(&mut payload);
    assert_eq!(
        r.send(T0, SendTo::Target, CommandLong::ID, &payload[..len]),
        1
    );
    assert_eq!(r.poll_transmit(&mut buf).map(|t| t.link), Some(a));
    assert!(r.link_status(b).is_some());
}

#[test]
fn a_transparent_monitor_link_gets_every_frame_as_it_arrived() {
    let mut r = router();
    let vehicle = link(&mut r, "vehicle", |c| c.version = VersionMode::Mavlink2);
    let gcs = link(&mut r, "gcs", |_| {});
    let bridge = link(&mut r, "bridge", |c| {
        c.version = VersionMode::Transparent;
        c.monitor = true;
    });
    let legacy = link(&mut r, "legacy", |c| c.version = VersionMode::Mavlink1);
    // A MAVLink 1 frame stays MAVLink 1 on the bridge (the vehicle's link converts it).
    let v1 = frame(&hb(), Version::V1, (9, 1), 0, None);
    r.handle_datagram(T0, legacy, &v1);
    let out = drain(&mut r);
    assert_eq!(on(&out, bridge), vec![v1.clone()]);
    assert_ne!(on(&out, vehicle), vec![v1]);
    // A signed frame keeps its signature there (the plain ground station's copy loses it).
    let k = key(3);
    let signed = frame(&hb(), Version::V2, (1, 1), 0, Some((&k, 1_000)));
    r.handle_datagram(T0, vehicle, &signed);
    let out = drain(&mut r);
    assert_eq!(on(&out, bridge), vec![signed.clone()]);
    assert_ne!(on(&out, gcs), vec![signed]);
    // A targeted frame reaches it wherever its target is, and never goes back to it.
    r.handle_datagram(T0, gcs, &frame(&hb(), Version::V2, (255, 190), 0, None));
    drain(&mut r);
    let cmd = frame(&command((1, 1)), Version::V2, (255, 190), 1, None);
    r.handle_datagram(T0, gcs, &cmd);
    let out = drain(&mut r);
    assert_eq!(
        (on(&out, vehicle), on(&out, bridge)),
        (vec![cmd.clone()], vec![cmd])
    );
    let from_cloud = frame(&command((1, 1)), Version::V2, (250, 1), 0, None);
    r.handle_datagram(T0, bridge, &from_cloud);
    let out = drain(&mut r);
    assert_eq!(out, vec![(vehicle, from_cloud)]);
    assert_eq!(r.link_status(bridge).unwrap().mode.as_str(), "transparent");
}

#[test]
fn setup_signing_held_by_the_router_is_refused_on_every_link_until_released() {
    use mavstack_channel::RejectReason;
    use mavstack_dialects::common::SetupSigning;
    use mavstack_router::{Event, LinkRole};
    let mut config = RouterConfig::default();
    config.component_id = 1;
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let vehicle = |c: &mut LinkConfig| {
        c.role = LinkRole::Vehicle {
            protocol_version: mavstack_router::ProtocolVersionSupport::Answer,
        };
        c.secure = true;
    };
    let before = link(&mut r, "before", vehicle);
    r.hold_setup_signing(true);
    let after = link(&mut r, "after", vehicle);
    let setup = SetupSigning {
        target_system: 1,
        target_component: 1,
        secret_key: [9; 32],
        initial_timestamp: 1,
    };
    let held = |r: &mut R| {
        let mut reasons = Vec::new();
        while let Some(e) = r.poll_event() {
            if let Event::Rejected { rejected, .. } = e {
                reasons.push(rejected.reason);
            }
        }
        reasons
    };
    for l in [before, after] {
        r.handle_datagram(T0, l, &frame(&setup, Version::V2, (255, 190), 0, None));
        assert_eq!(held(&mut r), [RejectReason::SetupSigningHeld]);
        assert!(r.channel(l).unwrap().signing().is_none());
    }
    r.hold_setup_signing(false);
    r.handle_datagram(T0, after, &frame(&setup, Version::V2, (255, 190), 1, None));
    assert!(held(&mut r).is_empty());
    assert!(r.channel(after).unwrap().signing().is_some());
}
