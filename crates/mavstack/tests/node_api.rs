//! `Node` as a component of its own: frames addressed to it come out of `subscribe`, what it
//! sends goes out on each link in that link's version, and shutting it down frees every
//! socket. The peers are plain UDP sockets writing frames by hand (the same behaviour is
//! checked against pymavlink by `tests-interop/router_interop.py own_heartbeat`).

use core::time::Duration;
use std::net::UdpSocket;

use mavstack::core::Message as _;
use mavstack::core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack::dialects::common::{CommandAck, CommandLong, Heartbeat, MavCmd, MavResult};
use mavstack::{LinkSpec, Node};

fn frame<M: mavstack::core::Message>(msg: &M, version: Version, src: (u8, u8)) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version,
        seq: 0,
        sysid: src.0,
        compid: src.1,
        signed: false,
    };
    let len = wire::emit_message(&header, msg, &mut buf).expect("fits");
    buf[..len].to_vec()
}

/// The next frame from `sock` (one per datagram here), as (version, sysid, compid, msg id).
fn next(sock: &UdpSocket) -> Option<(Version, u8, u8, u32)> {
    let mut buf = [0u8; 2048];
    let n = sock.recv(&mut buf).ok()?;
    let f = Frame::new_checked(&buf[..n]).ok()?;
    Some((f.version(), f.sysid(), f.compid(), f.msg_id()))
}

fn peer(port: u16) -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").expect("bind");
    s.connect(("127.0.0.1", port)).expect("connect");
    s.set_read_timeout(Some(Duration::from_secs(3)))
        .expect("timeout");
    s
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_receives_what_is_addressed_to_it_and_sends_in_each_links_version() {
    receives_and_sends(false).await;
}

/// The same on a thread of its own (its UDP sockets on its own epoll, as `mavstack router`
/// runs it).
#[tokio::test(flavor = "current_thread")]
async fn a_node_on_its_own_thread_receives_and_sends_in_each_links_version() {
    receives_and_sends(true).await;
}

async fn receives_and_sends(own_thread: bool) {
    let none = |_: &str| None;
    let node = Node::builder()
        .own_thread(own_thread)
        .identity(1, 191)
        .link(LinkSpec::parse("udpin:127.0.0.1:0?version=1&name=legacy", &none).expect("spec"))
        .link(LinkSpec::parse("udpin:127.0.0.1:0?name=gcs", &none).expect("spec"))
        .start()
        .await
        .expect("starts");
    let ports: Vec<u16> = node
        .local_addrs()
        .iter()
        .map(|a| a.expect("bound").port())
        .collect();
    let mut frames = node.subscribe().await;
    let legacy = peer(ports[0]);
    let gcs = peer(ports[1]);

    let command = CommandLong {
        command: MavCmd::REQUEST_MESSAGE,
        target_system: 1,
        target_component: 191,
        ..CommandLong::default()
    };
    gcs.send(&frame(&command, Version::V2, (255, 190)))
        .expect("send");
    let mut got = Vec::new();
    let mut recv = async || {
        let incoming = tokio::time::timeout(Duration::from_secs(3), frames.recv())
            .await
            .expect("a frame for the node")
            .expect("subscribed");
        let f = incoming.frame.frame.view();
        (incoming.link.clone(), f.msg_id(), f.version())
    };
    got.push(recv().await);
    // Now that the ground station is a link, a broadcast HEARTBEAT from the legacy side
    // reaches the node and is forwarded to the ground station.
    legacy
        .send(&frame(&Heartbeat::default(), Version::V1, (1, 50)))
        .expect("send");
    got.push(recv().await);
    assert_eq!(
        got,
        [
            ("gcs".to_owned(), CommandLong::ID, Version::V2),
            ("legacy".to_owned(), Heartbeat::ID, Version::V1),
        ]
    );
    assert_eq!(
        next(&gcs),
        Some((Version::V2, 1, 50, Heartbeat::ID)),
        "forwarded, converted"
    );

    // The answer goes only to the ground station (its route), in MAVLink 2.
    let ack = CommandAck {
        command: MavCmd::REQUEST_MESSAGE,
        result: MavResult::ACCEPTED,
        target_system: 255,
        target_component: 190,
        ..CommandAck::default()
    };
    assert_eq!(node.send(&ack).await, 1);
    assert_eq!(next(&gcs), Some((Version::V2, 1, 191, CommandAck::ID)));
    // A broadcast goes to both, as MAVLink 1 on the version=1 link.
    assert_eq!(node.send(&Heartbeat::default()).await, 2);
    assert_eq!(next(&legacy), Some((Version::V1, 1, 191, Heartbeat::ID)));
    assert_eq!(next(&gcs), Some((Version::V2, 1, 191, Heartbeat::ID)));

    let report = node.shutdown().await.expect("clean shutdown");
    assert_eq!(report.subscriber_drops, 0);
    // Every socket is closed: the ports can be bound again.
    for port in ports {
        UdpSocket::bind(("127.0.0.1", port)).expect("the node's port is free after shutdown");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_node_with_a_heartbeat_announces_itself_on_every_link() {
    announces_itself(false).await;
}

/// Its deadlines on a thread of its own: the thread's timer wakes it for each HEARTBEAT (three
/// arrive with no input to wake it). The period itself is tested on a virtual clock where the
/// timer lives (`crates/mavstack/src/node/heartbeat.rs`).
#[tokio::test(flavor = "current_thread")]
async fn a_node_on_its_own_thread_wakes_for_its_heartbeats() {
    announces_itself(true).await;
}

async fn announces_itself(own_thread: bool) {
    let none = |_: &str| None;
    let listener = UdpSocket::bind("127.0.0.1:0").expect("bind");
    listener
        .set_read_timeout(Some(Duration::from_secs(3)))
        .expect("timeout");
    let port = listener.local_addr().expect("addr").port();
    let node = Node::builder()
        .own_thread(own_thread)
        .identity(7, 191)
        .heartbeat(&Heartbeat::default(), Duration::from_millis(100))
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}?version=2"), &none).expect("spec"))
        .start()
        .await
        .expect("starts");
    for _ in 0..3 {
        assert_eq!(next(&listener), Some((Version::V2, 7, 191, Heartbeat::ID)));
    }
    node.shutdown().await.expect("clean shutdown");
}

/// On a thread of its own, a node's TCP link stays with the runtime (its reader and writer
/// are tasks) and wakes the thread: frames go both ways between a TCP client and a UDP peer,
/// and the node stops on shutdown.
#[tokio::test(flavor = "current_thread")]
async fn a_node_on_its_own_thread_forwards_between_tcp_and_udp() {
    use std::io::{Read as _, Write as _};

    let none = |_: &str| None;
    let node = Node::builder()
        .own_thread(true)
        .link(LinkSpec::parse("tcpin:127.0.0.1:0", &none).expect("spec"))
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("starts");
    let addrs: Vec<_> = node
        .local_addrs()
        .iter()
        .map(|a| a.expect("bound"))
        .collect();
    let udp = peer(addrs[1].port());
    let mut tcp = tokio::task::spawn_blocking(move || {
        let tcp = std::net::TcpStream::connect(addrs[0]).expect("connect");
        tcp.set_read_timeout(Some(Duration::from_secs(3)))
            .expect("timeout");
        tcp
    })
    .await
    .expect("connected");

    // The UDP peer is known once it has sent; then the TCP client's frame reaches it.
    udp.send(&frame(&Heartbeat::default(), Version::V2, (2, 1)))
        .expect("send");
    tokio::time::sleep(Duration::from_millis(200)).await;
    let from_tcp = frame(&Heartbeat::default(), Version::V2, (3, 1));
    tcp.write_all(&from_tcp).expect("write");
    let got = tokio::task::spawn_blocking(move || (next(&udp), udp))
        .await
        .expect("read");
    assert_eq!(got.0, Some((Version::V2, 3, 1, Heartbeat::ID)));
    let udp = got.1;

    // And a UDP frame reaches the TCP client, byte for byte.
    let from_udp = frame(&Heartbeat::default(), Version::V2, (2, 1));
    udp.send(&from_udp).expect("send");
    let read = tokio::task::spawn_blocking(move || {
        let mut buf = vec![0u8; from_udp.len()];
        tcp.read_exact(&mut buf).map(|()| (buf, from_udp))
    })
    .await
    .expect("read");
    let (buf, want) = read.expect("a frame on the TCP link");
    assert_eq!(buf, want);
    node.shutdown().await.expect("clean shutdown");
}

/// A batch subscription on a node on its own thread: every frame reaches the reader thread
/// in order, byte for byte, with the router link it came from and several frames of one
/// datagram in one batch; after shutdown the reader is told the node has stopped.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_batch_subscription_gets_every_frame_in_order_then_the_end() {
    use mavstack::{BatchWait, FrameBatch};

    let none = |_: &str| None;
    let node = Node::builder()
        .own_thread(true)
        .identity(1, 191)
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("starts");
    let port = node.local_addrs()[0].expect("bound").port();
    let mut frames = node.subscribe_batched().await;
    let sender = peer(port);
    let mut sent = Vec::new();
    // 50 datagrams of 4 frames each, sequence numbers 0..200.
    for d in 0..50u8 {
        let mut datagram = Vec::new();
        for k in 0..4u8 {
            let header = FrameHeader {
                version: Version::V2,
                seq: d * 4 + k,
                sysid: 2,
                compid: 1,
                signed: false,
            };
            let mut buf = [0u8; MAX_FRAME_LEN];
            let len = wire::emit_message(&header, &Heartbeat::default(), &mut buf).expect("fits");
            let f = buf[..len].to_vec();
            datagram.extend_from_slice(&f);
            sent.push(f);
        }
        sender.send(&datagram).expect("send");
    }
    let reader = tokio::task::spawn_blocking(move || {
        let mut batch = FrameBatch::new();
        let mut got: Vec<Vec<u8>> = Vec::new();
        let mut links = Vec::new();
        let mut largest = 0;
        while got.len() < 200 {
            match frames.wait(&mut batch, Duration::from_secs(10)) {
                BatchWait::Frames => {}
                other => panic!("{other:?} after {} frames", got.len()),
            }
            largest = largest.max(batch.len());
            for f in batch.iter() {
                got.push(f.bytes.to_vec());
                links.push(f.link);
            }
        }
        (got, links, largest, frames)
    });
    let (got, links, largest, mut frames) = reader.await.expect("the reader ends");
    assert_eq!(got, sent);
    assert!(
        links.iter().all(|l| *l == links[0]),
        "one peer, one router link"
    );
    assert!(largest >= 4, "the frames of one datagram come in one batch");
    let report = node.shutdown().await.expect("clean shutdown");
    assert_eq!(report.subscriber_drops, 0);
    let mut batch = FrameBatch::new();
    let end = tokio::task::spawn_blocking(move || frames.wait(&mut batch, Duration::from_secs(10)))
        .await
        .expect("waits");
    assert_eq!(end, BatchWait::Closed);
}
