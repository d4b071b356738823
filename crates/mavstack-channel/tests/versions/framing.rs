//! The framing rules a link relies on (§1–2): MAVLink 2-only messages on a MAVLink 1 link,
//! sequences, both versions interleaved, truncated payloads, noise, unknown flags and ids, a
//! full event queue.

use mavstack_channel::{Channel, Event, GroundPolicy, LinkVersion, SendError, VehicleVersion};
use mavstack_core::message::Message;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{CommandAck, Heartbeat, MavCmd, MavResult, ProtocolVersion};

use super::util::{Pair, T0, feed, frame};
use super::{gcs, vehicle};

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
