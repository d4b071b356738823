//! The fuzzing entry point of the bridge's parsers of outside input: link strings, keys
//! heard from a broker, command requests and the frames that answer them, and the sysid
//! remapping of frames from vehicles (cargo-fuzz target `bridge`; the seeds are replayed
//! by `tests/fuzz_corpus.rs`). Across the last two: no frame that fails its checksum ever
//! leaves the command tracker or the remap with a valid one.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_core::wire::{Frame, FrameHeader, Version, emit_message};
use mavstack_core::{Message as _, MessageSet as _};
use mavstack_dialects::common::{
    CommandAck, CommandInt, CommandLong, Heartbeat, MavCmd, MavMessage, MavResult,
};

use crate::checksum::{Checksum, check};
use crate::command::{CommandTiming, Commands, Reply};
use crate::keys::{FleetTopic, fleet_topic};
use crate::remap::{Remapped, SysidMap};
use crate::{BridgeSpec, Keys, Side, Topic, Transport};

/// Fuzzing entry point: the first byte picks the part under test, the rest is its input.
///
/// - `0`: a link string. It parses or gives an error; a password never shows in the error
///   nor in the spec's debug form (unless the text also spells it elsewhere); a parsed
///   spec has a host and a port (none for a Zenoh peer, which alone may listen) and key-safe
///   ids.
/// - `1`: a topic heard from a broker. What a vehicle's bridge takes for its `in` or `@cmd`
///   key is exactly the key it writes for that; what a ground bridge takes for a vehicle's
///   frame or liveliness key names a vehicle id that is a key segment (and, for a frame, a
///   sysid, a compid and a message name or number).
/// - `2`: records driving the command tracker (requests, ACKs built from the data, some with
///   a byte flipped, raw frames, time passing). Every request it takes gets exactly one
///   final reply, only requests it took get replies, resends are whole COMMAND_LONG/INT
///   frames, and after enough time nothing waits. A request whose checksum fails is never
///   taken: every frame the tracker lets out (a request, a resend) has a good checksum and
///   comes of a request that had one; a corrupt ACK answers nothing.
/// - `3`: records of frames from and to four vehicles through the sysid map (some with a
///   byte flipped). A rewritten frame has a good checksum and the mapped sysid (or target);
///   a frame whose checksum fails is dropped as corrupt, one that cannot be checked (an
///   unknown id) is never rewritten; local ids are never 0, 254 or 255, and each maps back
///   to the one (vehicle, sysid) it was given for.
#[doc(hidden)]
pub fn fuzz_bridge(data: &[u8]) {
    let Some((&part, rest)) = data.split_first() else {
        return;
    };
    match part % 4 {
        0 => link_string(&String::from_utf8_lossy(rest)),
        1 => topic(&String::from_utf8_lossy(rest)),
        2 => commands(rest),
        _ => remap(rest),
    }
}

fn link_string(text: &str) {
    match BridgeSpec::parse(text) {
        Ok(spec) => {
            let peer = spec.transport == Transport::ZenohPeer;
            assert_eq!(peer, spec.host.is_empty(), "{spec:?}");
            assert_eq!(peer, spec.port == 0, "{spec:?}");
            assert!(peer || spec.listen.is_none(), "{spec:?}");
            match &spec.side {
                Side::Vehicle(keys) => assert_eq!(keys.fleet(), spec.fleet),
                Side::Ground(vids) => {
                    for v in vids {
                        assert!(Keys::new(&spec.fleet, v).is_ok(), "{v:?}");
                    }
                }
            }
            if let Some((user, password)) = &spec.credentials
                && !password.is_empty()
            {
                // Shown only if the other fields spell it too.
                let mut without = spec.clone();
                without.credentials = Some((user.clone(), String::new()));
                let elsewhere = format!("{without:?}").contains(password.as_str());
                assert!(elsewhere || !format!("{spec:?}").contains(password.as_str()));
            }
        }
        Err(e) => {
            let shown = e.to_string();
            let password = text
                .split_once('?')
                .map_or("", |(_, o)| o)
                .split('&')
                .find_map(|o| o.strip_prefix("password="))
                .filter(|p| !p.is_empty() && text.matches(*p).count() == 1);
            if let Some(p) = password {
                // Shown only if the same text without it spells it too (the error's own
                // words, or another part of the text).
                let without = text.replacen(&format!("password={p}"), "password=", 1);
                let elsewhere = BridgeSpec::parse(&without)
                    .err()
                    .is_none_or(|e| e.to_string().contains(p));
                assert!(
                    elsewhere || !shown.contains(p),
                    "the password shows in {shown:?}"
                );
            }
        }
    }
}

fn topic(topic: &str) {
    let keys = Keys::new("f", "v").unwrap_or_else(|e| unreachable!("{e}"));
    match keys.parse(topic) {
        Some(Topic::In) => assert_eq!(topic, keys.input()),
        Some(Topic::Command { sysid, compid }) => assert_eq!(topic, keys.command(sysid, compid)),
        None => {}
    }
    match fleet_topic("f", topic) {
        Some(FleetTopic::Alive { vid }) => {
            let keys = Keys::new("f", vid).unwrap_or_else(|e| panic!("{topic:?}: {e}"));
            assert_eq!(topic, keys.alive());
        }
        Some(FleetTopic::Frame { vid }) => {
            assert!(Keys::new("f", vid).is_ok(), "{topic:?}");
            assert!(topic.starts_with(&format!("mav/f/{vid}/")), "{topic:?}");
            let name = topic.rsplit('/').next().unwrap_or_default();
            let named = name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_');
            assert!(
                named && !name.is_empty() && topic.split('/').count() == 6,
                "{topic:?}"
            );
        }
        None => {}
    }
}

/// Frames built from a few bytes of data: a COMMAND_LONG, a COMMAND_INT or a COMMAND_ACK
/// with ids and commands from a small set (so that they meet), signed or not.
fn built(kind: u8, b: &[u8; 6]) -> Vec<u8> {
    let id = |x: u8| x % 3;
    let command = MavCmd(400 + u16::from(b[4] % 3));
    let header = FrameHeader {
        version: if b[5] & 1 == 0 {
            Version::V2
        } else {
            Version::V1
        },
        seq: b[5],
        sysid: id(b[0]),
        compid: id(b[1]),
        signed: false,
    };
    let mut out = [0u8; 280];
    let n = match kind {
        0 => {
            let c = CommandLong {
                target_system: id(b[2]),
                target_component: id(b[3]),
                command,
                confirmation: b[5],
                ..Default::default()
            };
            emit_message(&header, &c, &mut out)
        }
        1 => {
            let c = CommandInt {
                target_system: id(b[2]),
                target_component: id(b[3]),
                command,
                ..Default::default()
            };
            emit_message(&header, &c, &mut out)
        }
        _ => {
            let results = [MavResult::ACCEPTED, MavResult(5), MavResult::DENIED];
            let a = CommandAck {
                command,
                result: results[usize::from(b[5] % 3)],
                target_system: id(b[2]),
                target_component: id(b[3]),
                ..Default::default()
            };
            emit_message(&header, &a, &mut out)
        }
    };
    n.map_or_else(|_| Vec::new(), |n| out[..n].to_vec())
}

/// Splits `data` into records: an op byte, then six bytes (or, for raw frames, a length
/// byte and that many bytes).
fn records(mut data: &[u8], mut each: impl FnMut(u8, &[u8])) {
    while let Some((&op, rest)) = data.split_first() {
        let len = if op % 8 >= 6 {
            rest.first().map_or(0, |&n| usize::from(n) + 1)
        } else {
            6
        };
        let len = len.min(rest.len());
        let (record, tail) = rest.split_at(len);
        each(op, record);
        data = tail;
    }
}

/// `frame` with one byte flipped when `op` says so (bit 6), at a place `at` picks.
fn damaged(op: u8, mut frame: Vec<u8>, at: u8) -> Vec<u8> {
    if op & 0x40 != 0 && !frame.is_empty() {
        let i = usize::from(at) % frame.len();
        frame[i] ^= 1 << (at % 8);
    }
    frame
}

/// The checksum of `frame` by the common dialect.
fn checksum(frame: &[u8]) -> Checksum {
    check(frame, |id| MavMessage::info(id).copied())
}

fn six(record: &[u8]) -> [u8; 6] {
    let mut b = [0u8; 6];
    for (d, s) in b.iter_mut().zip(record) {
        *d = *s;
    }
    b
}

fn commands(data: &[u8]) {
    let timing = CommandTiming::default();
    let mut tracker = Commands::<u32>::new(timing);
    let mut now = Instant::from_micros(1_000_000);
    let mut taken = Vec::new();
    let mut finals = Vec::new();
    let mut replies = Vec::new();
    let mut resend = Vec::new();
    let mut next = 0u32;
    let mut check = |replies: &mut Vec<Reply<u32>>, resend: &mut Vec<Vec<u8>>, taken: &[u32]| {
        for r in replies.drain(..) {
            let (to, last) = match r {
                Reply::Ack { to, frame, last } => {
                    let view = Frame::new_checked(&frame[..]).unwrap_or_else(|e| panic!("{e:?}"));
                    assert_eq!(view.msg_id(), CommandAck::ID);
                    (to, last)
                }
                Reply::Timeout { to } => (to, true),
            };
            assert!(taken.contains(&to), "a reply to request {to}, never taken");
            assert!(!finals.contains(&to), "two final replies to request {to}");
            if last {
                finals.push(to);
            }
        }
        for f in resend.drain(..) {
            let view = Frame::new_checked(&f[..]).unwrap_or_else(|e| panic!("{e:?}"));
            assert!([CommandLong::ID, CommandInt::ID].contains(&view.msg_id()));
            assert_eq!(checksum(&f), Checksum::Good, "a resend's checksum");
        }
    };
    records(data, |op, record| {
        let b = six(record);
        match op % 8 {
            0 | 1 => {
                let frame = damaged(op, built(op % 8, &b), b[4]);
                let key = (b[2] % 3, b[3] % 3);
                if let Ok(out) = tracker.handle_request(now, key, &frame, next) {
                    taken_good(&frame, &out);
                    taken.push(next);
                }
                next += 1;
            }
            2 | 3 => {
                let ack = damaged(op, built(2, &b), b[4]);
                let before = replies.len();
                tracker.handle_frame(now, &ack, &mut replies);
                if checksum(&ack) != Checksum::Good {
                    assert_eq!(replies.len(), before, "a corrupt ACK answered a request");
                }
            }
            4 | 5 => {
                now += Duration::from_millis(u64::from(b[0]) * 10);
                tracker.handle_timeout(now, &mut resend, &mut replies);
            }
            6 => {
                let key = (b[0] % 3, b[1] % 3);
                if let Ok(out) = tracker.handle_request(now, key, record, next) {
                    taken_good(record, &out);
                    taken.push(next);
                }
                next += 1;
            }
            _ => tracker.handle_frame(now, record, &mut replies),
        }
        check(&mut replies, &mut resend, &taken);
    });
    // Long enough for every resend and the longest wait.
    let rounds = u32::from(timing.retries) + 2;
    for _ in 0..rounds {
        now += timing.in_progress_timeout + timing.timeout;
        tracker.handle_timeout(now, &mut resend, &mut replies);
        check(&mut replies, &mut resend, &taken);
    }
    assert!(tracker.is_empty(), "requests still waiting");
    for t in &taken {
        assert!(finals.contains(t), "request {t} got no final reply");
    }
}

/// A request the tracker took had a good checksum, and what it lets out is that frame.
fn taken_good(request: &[u8], out: &[u8]) {
    assert_eq!(
        checksum(request),
        Checksum::Good,
        "a request taken with a bad checksum"
    );
    assert_eq!(checksum(out), Checksum::Good);
    assert!(request.starts_with(out), "the request let out changed");
}

fn remap(data: &[u8]) {
    const VIDS: [&str; 4] = ["a", "b", "c", "d"];
    let info = |id: u32| MavMessage::info(id).copied();
    let mut map = SysidMap::default();
    records(data, |op, record| {
        let b = six(record);
        let vid = VIDS[usize::from(b[0] % 4)];
        let frame = match op % 8 {
            0..=2 => {
                let header = FrameHeader {
                    version: Version::V2,
                    seq: b[2],
                    sysid: b[1],
                    compid: b[3],
                    signed: false,
                };
                let mut out = [0u8; 280];
                match emit_message(&header, &Heartbeat::default(), &mut out) {
                    Ok(n) => out[..n].to_vec(),
                    Err(_) => return,
                }
            }
            3..=5 => {
                let mut f = built(op % 2, &b);
                if let Ok(mut view) = Frame::new_checked(&mut f[..]) {
                    // COMMAND_LONG's and COMMAND_INT's target_system sits at 30 (after their
                    // params and command); the checksum made good again.
                    let info = MavMessage::info(view.msg_id()).copied();
                    if let (Some(t), Some(info)) = (view.payload_mut().get_mut(30), info) {
                        *t = b[2];
                        view.fill_checksum(info.crc_extra);
                    }
                }
                f
            }
            _ => record.to_vec(),
        };
        let frame = damaged(op, frame, b[4]);
        let sum = checksum(&frame);
        let towards = op & 0x80 != 0;
        let before = Frame::new_checked(&frame[..])
            .ok()
            .map(|v| (v.sysid(), v.msg_id()));
        let result = if towards {
            map.to_vehicle(vid, &frame, info)
        } else {
            map.from_vehicle(vid, &frame, info)
        };
        match sum {
            Checksum::Bad => assert_eq!(result, Remapped::Corrupt, "a corrupt frame went on"),
            Checksum::Unknown => assert!(
                matches!(result, Remapped::Same | Remapped::Dropped),
                "a frame that cannot be checked: {result:?}"
            ),
            Checksum::Good | Checksum::NotAFrame => {
                assert_ne!(result, Remapped::Corrupt, "a good frame taken for corrupt");
            }
        }
        if let Remapped::Rewritten(out) = result {
            let view = Frame::new_checked(&out[..]).unwrap_or_else(|e| panic!("{e:?}"));
            let message = info(view.msg_id()).unwrap_or_else(|| panic!("{}", view.msg_id()));
            assert!(
                view.check_crc(message.crc_extra),
                "a rewritten frame's checksum"
            );
            let (sysid, msg_id) = before.unwrap_or_else(|| panic!("rewrote a non-frame"));
            assert_eq!(view.msg_id(), msg_id);
            if !towards {
                let local = map.local(vid, sysid);
                assert_eq!(Some(view.sysid()), local);
            }
        }
    });
    for local in 0..=255u8 {
        if let Some((vid, sysid)) = map.vehicle(local) {
            assert!(
                ![0, 254, 255].contains(&local),
                "local id {local} handed out"
            );
            let vid = vid.to_owned();
            assert_eq!(map.local(&vid, sysid), Some(local));
        }
    }
}
