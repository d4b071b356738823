//! Who becomes a peer of a `udpin` link ([`Link::admit_peers`]): only a source whose datagram
//! holds a MAVLink frame with a good checksum, and at most `max_peers` of them; at the limit
//! the peer quiet for 3 s makes room, a busy link refuses the newcomer, and both are counted.

mod common;

use core::time::Duration;
use std::net::UdpSocket;
use std::sync::Arc;

use common::heartbeat;
use mavstack_core::MessageSet as _;
use mavstack_core::parse::CrcExtra;
use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_transport::{ConnSpec, Input, Link, LinkStats, Options, PeerId, PeerInfo};

#[derive(Default)]
struct Seen {
    added: Vec<PeerInfo>,
    removed: Vec<PeerId>,
    inputs: usize,
}

impl Input for Seen {
    fn handle_peer_added(&mut self, _now: Instant, peer: &PeerInfo) {
        self.added.push(peer.clone());
    }
    fn handle_peer_removed(&mut self, _now: Instant, peer: PeerId) {
        self.removed.push(peer);
    }
    fn handle_input(&mut self, _now: Instant, _peer: PeerId, _data: &[u8]) {
        self.inputs += 1;
    }
}

fn crc() -> Arc<dyn CrcExtra + Send + Sync> {
    Arc::new(|id: u32| MavMessage::info(id).map(|i| i.crc_extra))
}

/// Sends `data` from a socket of its own (a new source) and returns it (to send again).
fn from_new_source(port: u16, data: &[u8]) -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.send_to(data, ("127.0.0.1", port)).unwrap();
    s
}

/// Dispatches until `inputs` datagrams have been taken (counted in rx_chunks).
async fn take(link: &mut Link, seen: &mut Seen, chunks: u64) -> LinkStats {
    tokio::time::timeout(Duration::from_secs(5), async {
        while link.stats().rx_chunks < chunks {
            core::future::poll_fn(|cx| link.poll_ready(cx)).await;
            link.dispatch(seen);
        }
    })
    .await
    .expect("datagrams arrive");
    link.stats()
}

#[tokio::test]
async fn new_sources_need_a_frame_and_room() {
    let spec: ConnSpec = "udpin:127.0.0.1:0".parse().unwrap();
    let mut link = Link::open(&spec, &Options::default()).await.unwrap();
    link.admit_peers("gcs", 2, Some(crc()));
    let port = link.local_addr().unwrap().port();
    let mut seen = Seen::default();
    link.start(&mut seen);

    // Garbage, and a frame whose checksum is wrong: no peer.
    let mut bad = heartbeat(1, 0).as_bytes().to_vec();
    let n = bad.len();
    bad[n - 1] ^= 0xff;
    let _g = from_new_source(port, b"GET / HTTP/1.1\r\n\r\n");
    let _b = from_new_source(port, &bad);
    let stats = take(&mut link, &mut seen, 2).await;
    assert_eq!(
        (stats.rx_unadmitted, seen.added.len(), seen.inputs),
        (2, 0, 0)
    );

    // Two HEARTBEATs make two peers; the third source is refused (both busy).
    let hb = heartbeat(1, 0);
    let a = from_new_source(port, hb.as_bytes());
    let _b = from_new_source(port, hb.as_bytes());
    let stats = take(&mut link, &mut seen, 4).await;
    assert_eq!((seen.added.len(), seen.inputs), (2, 2));
    let _c = from_new_source(port, hb.as_bytes());
    let stats2 = take(&mut link, &mut seen, 5).await;
    assert_eq!(stats.peers_refused, 0);
    assert_eq!((stats2.peers_refused, seen.added.len()), (1, 2));
    // A known peer still gets through, garbage or not (its router link judges it).
    a.send_to(b"junk", ("127.0.0.1", port)).unwrap();
    take(&mut link, &mut seen, 6).await;
    assert_eq!(seen.inputs, 3);

    // After 3 s of quiet from `b` (and `a` still talking), a newcomer takes `b`'s place.
    tokio::time::sleep(Duration::from_millis(3100)).await;
    a.send_to(hb.as_bytes(), ("127.0.0.1", port)).unwrap();
    take(&mut link, &mut seen, 7).await;
    let _d = from_new_source(port, hb.as_bytes());
    let stats = take(&mut link, &mut seen, 8).await;
    assert_eq!((stats.peers_evicted, stats.peers_refused), (1, 1));
    assert_eq!(seen.removed, [seen.added[1].id]);
    assert_eq!((seen.added.len(), link.peers().len()), (3, 2));
}

#[tokio::test]
async fn without_a_dialect_any_datagram_makes_a_peer_up_to_the_default_limit() {
    let spec: ConnSpec = "udpin:127.0.0.1:0".parse().unwrap();
    let mut link = Link::open(&spec, &Options::default()).await.unwrap();
    let port = link.local_addr().unwrap().port();
    let mut seen = Seen::default();
    link.start(&mut seen);
    let total = Link::DEFAULT_MAX_PEERS + 6;
    let _sockets: Vec<UdpSocket> = (0..total).map(|_| from_new_source(port, b"x")).collect();
    let stats = take(&mut link, &mut seen, total as u64).await;
    assert_eq!(seen.added.len(), Link::DEFAULT_MAX_PEERS);
    assert_eq!((stats.peers_refused, stats.rx_unadmitted), (6, 0));
}
