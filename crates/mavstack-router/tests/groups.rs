//! Link groups (the peers of an `isolate_peers` link) and many links on one router: what
//! reaches whom, and that the tables stay one entry per link and per source.

use mavstack_core::message::Message;
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{CommandLong, Heartbeat, MavCmd, MavMessage};
use mavstack_router::{LinkConfig, LinkId, MessageTable, Router, RouterConfig};

const T0: Instant = Instant::from_secs(1_767_225_600);

fn router() -> Router {
    Router::new(RouterConfig::default(), MessageTable::of::<MavMessage>())
}

fn frame<M: Message>(msg: &M, src: (u8, u8), seq: u8) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version: Version::V2,
        seq,
        sysid: src.0,
        compid: src.1,
        signed: false,
    };
    let len = wire::emit_message(&header, msg, &mut buf).unwrap();
    buf[..len].to_vec()
}

fn hb(src: (u8, u8)) -> Vec<u8> {
    frame(&Heartbeat::default(), src, 0)
}

fn command(src: (u8, u8), target: (u8, u8)) -> Vec<u8> {
    let cmd = CommandLong {
        command: MavCmd::REQUEST_MESSAGE,
        param1: 33.0,
        target_system: target.0,
        target_component: target.1,
        ..CommandLong::default()
    };
    frame(&cmd, src, 1)
}

/// The links the router sends to, in order.
fn sent_to(r: &mut Router) -> Vec<LinkId> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut out = Vec::new();
    while let Some(t) = r.poll_transmit(&mut buf) {
        out.push(t.link);
    }
    out.sort();
    out
}

fn link(r: &mut Router, name: &str, group: Option<u32>) -> LinkId {
    let mut c = LinkConfig::new(name);
    c.group = group;
    r.add_link(c).unwrap()
}

#[test]
fn links_of_one_group_forward_nothing_to_each_other() {
    let mut r = router();
    let a = link(&mut r, "fleet", Some(7));
    let b = link(&mut r, "fleet", Some(7));
    let gcs = link(&mut r, "gcs", None);
    let other = link(&mut r, "other fleet", Some(8));
    // A vehicle's broadcast: to the ground station and the other group, not to its fellow.
    r.handle_datagram(T0, a, &hb((1, 1)));
    assert_eq!(sent_to(&mut r), [gcs, other]);
    r.handle_datagram(T0, b, &hb((2, 1)));
    assert_eq!(sent_to(&mut r), [gcs, other]);
    // Targeted at its fellow, whose route is known: nowhere.
    r.handle_datagram(T0, a, &command((1, 1), (2, 1)));
    assert_eq!(sent_to(&mut r), []);
    // The ground station reaches every vehicle with a broadcast, one with a command.
    r.handle_datagram(T0, gcs, &hb((255, 190)));
    assert_eq!(sent_to(&mut r), [a, b, other]);
    r.handle_datagram(T0, gcs, &command((255, 190), (2, 1)));
    assert_eq!(sent_to(&mut r), [b]);
    // A link of another group is reached by a targeted frame too.
    r.handle_datagram(T0, other, &hb((3, 1)));
    assert_eq!(sent_to(&mut r), [a, b, gcs]);
    r.handle_datagram(T0, a, &command((1, 1), (3, 1)));
    assert_eq!(sent_to(&mut r), [other]);
}

#[test]
fn a_thousand_links_keep_one_route_each_and_take_them_when_they_go() {
    let mut r = router();
    let gcs = link(&mut r, "gcs", None);
    let fleet: Vec<LinkId> = (0..1000).map(|_| link(&mut r, "fleet", Some(1))).collect();
    let id = |i: usize| (1 + (i % 250) as u8, 1 + (i / 250) as u8);
    for round in 0..3u32 {
        let now = T0 + core::time::Duration::from_millis(u64::from(round) * 50);
        for (i, &l) in fleet.iter().enumerate() {
            r.handle_datagram(now, l, &hb(id(i)));
            assert_eq!(sent_to(&mut r), [gcs], "vehicle {i}, round {round}");
        }
    }
    r.handle_datagram(T0, gcs, &hb((255, 190)));
    assert_eq!(sent_to(&mut r).len(), 1000);
    assert_eq!(r.links().count(), 1001);
    assert_eq!(r.routes().count(), 1001);
    assert_eq!(r.systems().count(), 1001);
    // No handshake runs: no link has a timer, only the route sweep.
    assert!(r.poll_timeout().is_some_and(|t| t > T0));
    for (i, &l) in fleet.iter().enumerate() {
        r.handle_datagram(T0, gcs, &command((255, 190), id(i)));
        assert_eq!(sent_to(&mut r), [l], "command to vehicle {i}");
    }
    for &l in &fleet[..500] {
        r.remove_link(l);
    }
    assert_eq!(r.links().count(), 501);
    assert_eq!(r.routes().count(), 501);
    // The places of removed links are taken again, still in their group.
    let again: Vec<LinkId> = (0..500).map(|_| link(&mut r, "fleet", Some(1))).collect();
    assert!(again.iter().all(|l| l.index() <= 1000));
    r.handle_datagram(T0, again[0], &hb((1, 9)));
    assert_eq!(sent_to(&mut r), [gcs]);
}
