//! Dedup tells frames apart by their bytes: frames whose hashes collide are both forwarded,
//! the same frame again within the window is dropped as a duplicate.

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{Heartbeat, MavMessage};
use mavstack_router::{LinkConfig, LinkId, MessageTable, Router, RouterConfig};

const T0: Instant = Instant::from_secs(1_767_225_600);

fn heartbeat(custom_mode: u32) -> Vec<u8> {
    let header = FrameHeader {
        version: Version::V2,
        seq: 0,
        sysid: 1,
        compid: 1,
        signed: false,
    };
    let hb = Heartbeat {
        custom_mode,
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = wire::emit_message(&header, &hb, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// What the router sent on `link`.
fn sent_on(r: &mut Router, link: LinkId) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut buf = [0u8; MAX_FRAME_LEN];
    while let Some(t) = r.poll_transmit(&mut buf) {
        if t.link == link {
            out.push(buf[..t.len].to_vec());
        }
    }
    while r.poll_event().is_some() {}
    out
}

#[test]
fn frames_in_one_hash_bucket_are_both_forwarded_and_a_repeat_is_dropped() {
    let mut config = RouterConfig::default();
    config.dedup = Some(Duration::from_millis(200));
    // Every frame hashes alike: only the bytes can tell them apart.
    config.dedup_hash = Some(|_| 0x5EED);
    let mut r = Router::new(config, MessageTable::of::<MavMessage>());
    let radio1 = r.add_link(LinkConfig::new("r1")).unwrap();
    let radio2 = r.add_link(LinkConfig::new("r2")).unwrap();
    let gcs = r.add_link(LinkConfig::new("gcs")).unwrap();
    let (a, b) = (heartbeat(1), heartbeat(2));
    assert_ne!(a, b);
    r.handle_datagram(T0, radio1, &a);
    r.handle_datagram(T0 + Duration::from_millis(1), radio1, &b);
    assert_eq!(sent_on(&mut r, gcs), vec![a.clone(), b.clone()]);
    // The same bytes over the other radio within the window: a duplicate.
    r.handle_datagram(T0 + Duration::from_millis(2), radio2, &a);
    r.handle_datagram(T0 + Duration::from_millis(3), radio2, &b);
    assert!(sent_on(&mut r, gcs).is_empty());
    let dropped = &r.link_status(gcs).unwrap().counters.dropped;
    assert_eq!(dropped.duplicate, 2);
}
