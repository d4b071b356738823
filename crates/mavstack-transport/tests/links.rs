//! Real links on loopback, pseudo-terminals and temporary files.

mod common;

use core::time::Duration;
use std::collections::BTreeSet;

use common::{
    Conn, WAIT, event, frame, heartbeat, open, peer_added, peer_removed, proto, spec, until,
};
use mavstack_transport::frame::{FrameCommand, FrameEvent};
use mavstack_transport::protocol::{Framing, PeerAddr};
use mavstack_transport::{Connection, Dest, FileMode, Options};
use tokio::io::{AsyncReadExt as _, AsyncWriteExt as _};

fn send(dest: Dest, sysid: u8) -> FrameCommand {
    FrameCommand::Send {
        dest,
        frame: heartbeat(sysid, 0),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn udpin_answers_three_peers_each_at_its_own_address() {
    let mut server = open("udpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let mut clients: Vec<Conn> = Vec::new();
    for _ in 0..3 {
        clients.push(open(&format!("udpout:127.0.0.1:{port}")).await);
    }
    for (i, client) in clients.iter_mut().enumerate() {
        // Each client's only peer is the server, from the start.
        let p = peer_added(client).await;
        assert_eq!(p.addr, PeerAddr::Udp(([127, 0, 0, 1], port).into()));
        assert_eq!(p.framing, Framing::Datagram);
        client.send(send(Dest::All, 10 + i as u8)).await.unwrap();
    }
    // The server sees three peers and answers each one alone.
    let mut seen = BTreeSet::new();
    for _ in 0..3 {
        let f = frame(&mut server).await;
        seen.insert(f.frame.sysid());
        let reply = 100 + f.frame.sysid();
        server.send(send(Dest::Peer(f.peer), reply)).await.unwrap();
    }
    assert_eq!(seen, BTreeSet::from([10, 11, 12]));
    assert_eq!(server.peers().len(), 3);
    for (i, client) in clients.iter_mut().enumerate() {
        assert_eq!(frame(client).await.frame.sysid(), 110 + i as u8);
    }
    // Dest::All reaches every one of them, once.
    server.send(send(Dest::All, 7)).await.unwrap();
    for client in &mut clients {
        assert_eq!(frame(client).await.frame.sysid(), 7);
    }
    // The driver publishes its counters after the step that sent the datagrams, which can
    // come just after the clients have them.
    until("six datagrams counted", || {
        server.stats().link.tx_chunks >= 6
    })
    .await;
    let stats = server.stats();
    assert_eq!(stats.protocol.frames, 3);
    assert_eq!((stats.link.peers_added, stats.link.tx_chunks), (3, 6));
    for mut client in clients {
        assert!(client.try_recv().is_err());
        client.close().await.unwrap();
    }
    server.close().await.unwrap();
}

#[tokio::test]
async fn quiet_udp_peers_expire() {
    let mut options = Options::default();
    options.peer_timeout = Duration::from_millis(150);
    let mut server = Connection::open_with(&spec("udp://127.0.0.1:0"), proto(), &options)
        .await
        .unwrap();
    let port = server.local_addr().unwrap().port();
    let client = open(&format!("udpout://127.0.0.1:{port}")).await;
    client.send(send(Dest::All, 1)).await.unwrap();
    let p = peer_added(&mut server).await;
    let started = tokio::time::Instant::now();
    assert_eq!(peer_removed(&mut server).await, p.id);
    assert!(started.elapsed() >= Duration::from_millis(100));
    assert!(server.peers().is_empty());
    // Nobody left to send to: dropped and counted.
    server.send(send(Dest::All, 2)).await.unwrap();
    until("drop counted", || server.stats().link.tx_dropped == 1).await;
}

#[tokio::test]
async fn udpbcast_sends_to_the_broadcast_address() {
    let mut server = open("udpin:0.0.0.0:0").await;
    let port = server.local_addr().unwrap().port();
    let client = open(&format!("udpbcast:127.255.255.255:{port}")).await;
    client.send(send(Dest::All, 42)).await.unwrap();
    let f = frame(&mut server).await;
    assert_eq!(f.frame.sysid(), 42);
    assert_eq!(client.stats().link.tx_errors, 0);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_clients_and_server_talk_both_ways() {
    let mut server = open("tcpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let mut clients: Vec<Conn> = Vec::new();
    for _ in 0..3 {
        clients.push(open(&format!("tcp:127.0.0.1:{port}")).await);
    }
    for (i, client) in clients.iter_mut().enumerate() {
        assert_eq!(peer_added(client).await.framing, Framing::Stream);
        client.send(send(Dest::All, 20 + i as u8)).await.unwrap();
    }
    let mut seen = BTreeSet::new();
    for _ in 0..3 {
        let f = frame(&mut server).await;
        seen.insert(f.frame.sysid());
        server
            .send(send(Dest::Peer(f.peer), 100 + f.frame.sysid()))
            .await
            .unwrap();
    }
    assert_eq!(seen, BTreeSet::from([20, 21, 22]));
    for (i, client) in clients.iter_mut().enumerate() {
        assert_eq!(frame(client).await.frame.sysid(), 120 + i as u8);
    }
    server.send(send(Dest::All, 9)).await.unwrap();
    for client in &mut clients {
        assert_eq!(frame(client).await.frame.sysid(), 9);
    }
    // A client that leaves is removed.
    let leaving = clients.pop().unwrap();
    leaving.close().await.unwrap();
    peer_removed(&mut server).await;
    assert_eq!(server.peers().len(), 2);
    server.close().await.unwrap();
}

#[tokio::test]
async fn tcp_frames_split_anywhere_are_found() {
    let mut server = open("tcpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let mut raw = tokio::net::TcpStream::connect(("127.0.0.1", port))
        .await
        .unwrap();
    raw.set_nodelay(true).unwrap();
    let mut bytes = Vec::new();
    for seq in 0..5 {
        bytes.extend_from_slice(heartbeat(3, seq).as_bytes());
        bytes.extend_from_slice(b"noise\xfd");
    }
    for piece in bytes.chunks(7) {
        raw.write_all(piece).await.unwrap();
        raw.flush().await.unwrap();
    }
    for seq in 0..5 {
        assert_eq!(frame(&mut server).await.frame.frame().seq(), seq);
    }
    // The last noise byte is a false start, decided when the stream ends.
    drop(raw);
    peer_removed(&mut server).await;
    let stats = server.stats().protocol;
    assert_eq!((stats.frames, stats.skipped_bytes), (5, 30));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tcp_client_reconnects_after_the_server_comes_back() {
    let mut server = open("tcpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let mut options = Options::default();
    options.reconnect_min = Duration::from_millis(20);
    options.reconnect_max = Duration::from_millis(100);
    let mut client =
        Connection::open_with(&spec(&format!("tcp:127.0.0.1:{port}")), proto(), &options)
            .await
            .unwrap();
    let first = peer_added(&mut client).await;
    client.send(send(Dest::All, 1)).await.unwrap();
    assert_eq!(frame(&mut server).await.frame.sysid(), 1);

    // The server goes away: the client loses its peer, and what it sends meanwhile is
    // dropped and counted.
    server.close().await.unwrap();
    assert_eq!(peer_removed(&mut client).await, first.id);
    client.send(send(Dest::All, 2)).await.unwrap();
    until("drop counted", || client.stats().link.tx_dropped >= 1).await;

    // A new server on the same port: the client comes back by itself.
    let again = format!("tcpin:127.0.0.1:{port}");
    let mut server = loop {
        match Connection::open(&spec(&again), proto()).await {
            Ok(s) => break s,
            // The old listener may take a moment to go.
            Err(e) => {
                assert!(e.to_string().contains("address in use"), "{e}");
                tokio::time::sleep(Duration::from_millis(10)).await;
            }
        }
    };
    let second = peer_added(&mut client).await;
    assert_ne!(second.id, first.id);
    client.send(send(Dest::All, 3)).await.unwrap();
    assert_eq!(frame(&mut server).await.frame.sysid(), 3);
    let stats = client.stats().link;
    assert_eq!((stats.peers_added, stats.peers_removed), (2, 1));
    client.close().await.unwrap();
    server.close().await.unwrap();
}

#[tokio::test]
async fn serial_over_a_pseudo_terminal() {
    let (mut master, slave) = tokio_serial::SerialStream::pair().unwrap();
    let device = tokio_serial::SerialPort::name(&slave).unwrap();
    let mut conn = open(&format!("serial:{device}:57600")).await;
    drop(slave);
    let p = peer_added(&mut conn).await;
    assert_eq!(p.addr, PeerAddr::Serial(device.clone()));
    // In: bytes written to the other end, split.
    let hb = heartbeat(5, 9);
    master.write_all(&hb.as_bytes()[..4]).await.unwrap();
    master.write_all(&hb.as_bytes()[4..]).await.unwrap();
    let f = frame(&mut conn).await;
    assert_eq!((f.peer, f.frame), (p.id, hb));
    // Out: what the connection sends comes out at the other end.
    conn.send(send(Dest::All, 6)).await.unwrap();
    let want = heartbeat(6, 0);
    let mut got = vec![0u8; want.as_bytes().len()];
    tokio::time::timeout(WAIT, master.read_exact(&mut got))
        .await
        .unwrap()
        .unwrap();
    assert_eq!(got, want.as_bytes());
    conn.close().await.unwrap();
}

#[tokio::test]
async fn tlog_written_by_one_connection_is_read_by_another() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.tlog");
    let mut options = Options::default();
    options.file_mode = FileMode::Write;
    let before = mavstack_transport::clock::now();
    let sink = Connection::open_with(
        &spec(&format!("file:{}", path.display())),
        proto(),
        &options,
    )
    .await
    .unwrap();
    for seq in 0..100 {
        sink.send(FrameCommand::to_all(heartbeat(1, seq)))
            .await
            .unwrap();
    }
    sink.close().await.unwrap();
    let after = mavstack_transport::clock::now();

    // Read it back with the tlog reader...
    let reader = mavstack_transport::tlog::Reader::new(std::fs::File::open(&path).unwrap());
    let records: Vec<_> = reader.map(Result::unwrap).collect();
    assert_eq!(records.len(), 100);
    for (seq, r) in records.iter().enumerate() {
        assert_eq!(r.frame, heartbeat(1, seq as u8));
        assert!(before <= r.time() && r.time() <= after);
    }
    // ...and with a connection, which stamps each frame with its recorded time and ends.
    let mut source = open(&format!("file:{}", path.display())).await;
    let p = peer_added(&mut source).await;
    assert_eq!(p.framing, Framing::Datagram);
    for r in &records {
        let f = frame(&mut source).await;
        assert_eq!((f.time, f.frame), (r.time(), r.frame));
    }
    assert_eq!(peer_removed(&mut source).await, p.id);
    assert!(source.recv().await.is_none());
    assert_eq!(source.stats().protocol.frames, 100);
    source.close().await.unwrap();
}

#[tokio::test]
async fn corrupt_tlog_through_a_connection_gives_the_frames_pymavlink_gives() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.tlog");
    let mut w = mavstack_transport::tlog::Writer::new(Vec::new());
    for seq in 0..10 {
        w.write_record(
            1_700_000_000_000_000 + u64::from(seq),
            heartbeat(1, seq).as_bytes(),
        )
        .unwrap();
    }
    let mut data = w.into_inner().unwrap();
    let record = 8 + heartbeat(1, 0).as_bytes().len();
    data[3 * record + 8 + 10] ^= 0xff; // a payload byte of record 3: bad checksum
    data.splice(6 * record..6 * record, *b"\xfd\x00garbage");
    std::fs::write(&path, &data).unwrap();
    let mut source = open(&format!("file:{}", path.display())).await;
    let mut seqs = Vec::new();
    while let Some(e) = source.recv().await {
        if let FrameEvent::Frame(f) = e
            && f.frame.frame().msg_id() == 0
        {
            seqs.push(f.frame.frame().seq());
        }
    }
    // pymavlink 2.4.50 reads these bytes (mavutil.mavlink_connection) as HEARTBEAT 0, 1, 2,
    // BAD_DATA, HEARTBEAT 4, 5, then damage and two "frames" of unknown ids made of the
    // garbage: the garbage's bytes were taken for a timestamp, and the rest of the log is
    // lost with it (docs/protocol-notes.md, "Reading past damage").
    assert_eq!(seqs, [0, 1, 2, 4, 5]);
    source.close().await.unwrap();
}

#[tokio::test]
async fn raw_file_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("capture.bin");
    let file = spec(&format!("file:{}", path.display()));
    let mut options = Options::default();
    options.file_mode = FileMode::Write;
    let sink = Connection::open_with(&file, proto(), &options)
        .await
        .unwrap();
    for seq in 0..50 {
        sink.send(FrameCommand::to_all(heartbeat(2, seq)))
            .await
            .unwrap();
    }
    sink.close().await.unwrap();
    assert_eq!(std::fs::metadata(&path).unwrap().len(), 50 * 21);
    let mut source = Connection::open(&file, proto()).await.unwrap();
    assert_eq!(peer_added(&mut source).await.framing, Framing::Stream);
    for seq in 0..50 {
        assert_eq!(frame(&mut source).await.frame, heartbeat(2, seq));
    }
    peer_removed(&mut source).await;
    assert!(source.recv().await.is_none());
}

#[test]
fn blocking_api_round_trip() {
    use mavstack_transport::blocking;
    use mavstack_transport::error::{RecvTimeoutError, TryRecvError};
    let mut server = blocking::Connection::open(&spec("tcpin:127.0.0.1:0"), proto()).unwrap();
    let port = server.local_addr().unwrap().port();
    let mut client =
        blocking::Connection::open(&spec(&format!("tcp:127.0.0.1:{port}")), proto()).unwrap();
    let wait_frame = |c: &mut blocking::Connection<common::Proto>| loop {
        match c.recv_timeout(WAIT) {
            Ok(FrameEvent::Frame(f)) => return f,
            Ok(_) => {}
            Err(e) => panic!("{e}"),
        }
    };
    client.send(send(Dest::All, 1)).unwrap();
    let f = wait_frame(&mut server);
    assert_eq!(f.frame.sysid(), 1);
    server.send(send(Dest::Peer(f.peer), 2)).unwrap();
    assert_eq!(wait_frame(&mut client).frame.sysid(), 2);
    assert_eq!(client.try_recv(), Err(TryRecvError::Empty));
    assert_eq!(
        client.recv_timeout(Duration::from_millis(20)),
        Err(RecvTimeoutError::Timeout)
    );
    assert_eq!(server.peers().len(), 1);
    assert_eq!(client.stats().protocol.frames, 1);
    client.close().unwrap();
    server.close().unwrap();
}

#[tokio::test]
async fn bad_connection_strings_say_what_is_wrong() {
    let err = "foo:1.2.3.4:5"
        .parse::<mavstack_transport::ConnSpec>()
        .unwrap_err();
    assert!(
        err.to_string().starts_with(
            r#"unknown scheme "foo" in "foo:1.2.3.4:5"; expected one of udpin, udpout"#
        )
    );
    let err = "serial:/dev/ttyUSB0"
        .parse::<mavstack_transport::ConnSpec>()
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        r#"missing baud rate in "serial:/dev/ttyUSB0"; expected serial:DEVICE:BAUD or DEVICE,BAUD"#
    );
}

#[tokio::test]
async fn opening_errors_name_the_thing() {
    let taken = open("udpin:127.0.0.1:0").await;
    let port = taken.local_addr().unwrap().port();
    let err = Connection::open(&spec(&format!("udpin:127.0.0.1:{port}")), proto())
        .await
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("cannot bind udp 127.0.0.1:{port}: address in use")
    );
    let taken = open("tcpin:127.0.0.1:0").await;
    let port = taken.local_addr().unwrap().port();
    let err = Connection::open(&spec(&format!("tcpin:127.0.0.1:{port}")), proto())
        .await
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("cannot bind tcp 127.0.0.1:{port}: address in use")
    );
    // A port nobody listens on (just released by a listener).
    let port = {
        let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        l.local_addr().unwrap().port()
    };
    let err = Connection::open(&spec(&format!("tcp:127.0.0.1:{port}")), proto())
        .await
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("cannot connect tcp 127.0.0.1:{port}: connection refused")
    );
    let err = Connection::open(&spec("serial:/dev/ttyMAVSTACKNONE:57600"), proto())
        .await
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot open serial /dev/ttyMAVSTACKNONE: no such file"
    );
    let err = Connection::open(&spec("file:/nonexistent/dir/x.tlog"), proto())
        .await
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot open file /nonexistent/dir/x.tlog: no such file"
    );
    let err = Connection::open(&spec("tcp:host.invalid:5760"), proto())
        .await
        .unwrap_err();
    assert!(
        err.to_string()
            .starts_with("cannot resolve tcp host.invalid:5760: "),
        "{err}"
    );
}

#[tokio::test]
async fn closing_sends_what_was_queued_first() {
    let mut server = open("udpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let client = open(&format!("udpout:127.0.0.1:{port}")).await;
    for seq in 0..20 {
        client
            .send(FrameCommand::to_all(heartbeat(4, seq)))
            .await
            .unwrap();
    }
    client.close().await.unwrap();
    for seq in 0..20 {
        assert_eq!(frame(&mut server).await.frame.frame().seq(), seq);
    }
    let _ = event;
}

#[tokio::test]
async fn ipv6_loopback_round_trip() {
    // The precondition is IPv6 on the loopback interface (`::1`): without it the test fails
    // and says so, rather than passing without testing anything.
    let mut server = match Connection::open(&spec("udpin:[::1]:0"), proto()).await {
        Ok(s) => s,
        Err(e) => panic!(
            "{e}: this test needs IPv6 on the loopback interface \
             (`ip -6 addr show lo` lists ::1; enable it with `sysctl -w \
             net.ipv6.conf.lo.disable_ipv6=0`)"
        ),
    };
    let port = server.local_addr().unwrap().port();
    let client = open(&format!("udpout://[::1]:{port}")).await;
    client.send(send(Dest::All, 61)).await.unwrap();
    let f = frame(&mut server).await;
    assert_eq!(f.frame.sysid(), 61);
    let peers = server.peers();
    assert!(matches!(peers[0].addr, PeerAddr::Udp(a) if a.is_ipv6()));
}

#[tokio::test]
async fn all_except_skips_one_peer_and_unknown_peers_are_dropped() {
    let mut server = open("tcpin:127.0.0.1:0").await;
    let port = server.local_addr().unwrap().port();
    let mut a = open(&format!("tcp:127.0.0.1:{port}")).await;
    let mut b = open(&format!("tcp:127.0.0.1:{port}")).await;
    a.send(send(Dest::All, 1)).await.unwrap();
    let from_a = frame(&mut server).await.peer;
    b.send(send(Dest::All, 2)).await.unwrap();
    frame(&mut server).await;
    // Forward what `a` sent to everyone else.
    server.send(send(Dest::AllExcept(from_a), 3)).await.unwrap();
    assert_eq!(frame(&mut b).await.frame.sysid(), 3);
    server
        .send(send(Dest::Peer(mavstack_transport::PeerId::new(999)), 4))
        .await
        .unwrap();
    server.send(send(Dest::Peer(from_a), 5)).await.unwrap();
    // `a` gets only the frame meant for it: the forwarded one never came.
    assert_eq!(frame(&mut a).await.frame.sysid(), 5);
    assert_eq!(server.stats().link.tx_dropped, 1);
}

#[test]
fn blocking_close_writes_out_what_was_queued_on_tcp() {
    use mavstack_transport::blocking;
    let mut server = blocking::Connection::open(&spec("tcpin:127.0.0.1:0"), proto()).unwrap();
    let port = server.local_addr().unwrap().port();
    let client =
        blocking::Connection::open(&spec(&format!("tcp:127.0.0.1:{port}")), proto()).unwrap();
    for i in 0..500u32 {
        client
            .send(FrameCommand::to_all(heartbeat(9, (i % 256) as u8)))
            .unwrap();
    }
    // The client's runtime stops right after this: its writer must have written everything.
    client.close().unwrap();
    let mut frames = 0;
    while frames < 500 {
        match server.recv_timeout(WAIT) {
            Ok(FrameEvent::Frame(_)) => frames += 1,
            Ok(_) => {}
            Err(e) => panic!("after {frames} frames: {e}"),
        }
    }
}
