//! `mavstack router` as a process: usage errors, mavlink-router's configuration file run as
//! it is, and faults (a TCP client that vanishes and comes back, a flooding link while
//! commands pass, a truncated or corrupted datagram).

use crate::router;

use router::Router;

use core::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use core::time::Duration;
use std::io::{Read as _, Write as _};
use std::net::{TcpListener, TcpStream, UdpSocket};
use std::process::Command;
use std::sync::Arc;
use std::time::Instant;

use mavstack_core::message::Message;
use mavstack_core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::{Attitude, CommandLong, Heartbeat, MavCmd};

fn mavstack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
}

fn frame<M: Message>(m: &M, sysid: u8, seq: u8) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME_LEN];
    let header = FrameHeader {
        version: Version::V2,
        seq,
        sysid,
        compid: 1,
        signed: false,
    };
    let len = wire::emit_message(&header, m, &mut buf).unwrap();
    buf[..len].to_vec()
}

fn command_to(sysid: u8, n: u16) -> CommandLong {
    CommandLong {
        command: MavCmd(n),
        target_system: sysid,
        target_component: 1,
        ..CommandLong::default()
    }
}

fn free_udp() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn free_tcp() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// How long a test waits for a frame that must come: long enough for any machine, so that
/// only a frame that never comes fails the test (and it fails instead of hanging).
const DEADLINE: Duration = Duration::from_secs(30);

/// The frames that reach `sock`, in order, up to and including the first one equal to `last`.
/// A test that must see that something did not happen sends `last` after it: whatever the
/// router sent before `last` has arrived by then.
fn frames_until(sock: &UdpSocket, last: &[u8]) -> Vec<Vec<u8>> {
    sock.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let deadline = Instant::now() + DEADLINE;
    let mut out = Vec::new();
    let mut buf = [0u8; 2048];
    while Instant::now() < deadline {
        let Ok(n) = sock.recv(&mut buf) else {
            continue;
        };
        let mut rest = &buf[..n];
        while let Ok(f) = Frame::new_checked(rest) {
            let len = f.frame_len();
            out.push(rest[..len].to_vec());
            if rest[..len] == *last {
                return out;
            }
            rest = &rest[len..];
        }
    }
    panic!("the awaited frame did not come in {DEADLINE:?}; before it: {out:?}");
}

#[test]
fn bad_options_and_files_are_usage_errors_naming_what_is_wrong() {
    let key = "ab".repeat(32);
    let cases = [
        (
            vec!["udpin:127.0.0.1:0?version=3".to_owned()],
            "error: link \"udpin:127.0.0.1:0?version=3\": link option \"version\": \"3\" is not 1, 2 or auto",
        ),
        (
            vec![format!("udpin:127.0.0.1:0?version=1&key={key}")],
            "link option \"key\": a signed link is MAVLink 2",
        ),
        (
            vec!["udpin:127.0.0.1:0?colour=red".to_owned()],
            "link option \"colour\": unknown option",
        ),
        (vec!["foo:1.2.3.4:5".to_owned()], "unknown scheme \"foo\""),
        (vec![], "error: no links"),
        (
            vec![
                "udpin:127.0.0.1:0".to_owned(),
                "--dialect".to_owned(),
                "nope".to_owned(),
            ],
            "unknown dialect \"nope\"",
        ),
    ];
    for (args, want) in cases {
        let out = mavstack().arg("router").args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
        assert!(!err.contains(&key), "the key is never printed");
    }
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("main.conf");
    std::fs::write(
        &conf,
        "[UdpEndpoint alpha]\nMode = Server\nAddress = 0.0.0.0\nPort = 14a50\n",
    )
    .unwrap();
    let out = mavstack()
        .arg("router")
        .arg("--conf")
        .arg(&conf)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.starts_with(&format!("error: {}:4: ", conf.display())),
        "{err}"
    );
    assert!(err.contains("Port") && err.contains("14a50"), "{err}");
}

#[test]
fn mavlink_router_sample_configuration_runs_as_it_is() {
    // mavlink-router's examples/config.sample with its addresses pointed at this test: a
    // pseudo-terminal for the UART, free ports for the UDP and TCP endpoints.
    let sample = include_str!("../../mavstack/tests/data/config.sample");
    let pty = nix::pty::openpty(None, None).unwrap();
    let tty = nix::unistd::ttyname(&pty.slave).unwrap();
    // The sockets the test binds itself take their ports from the kernel: a port picked free and
    // bound later can be taken in between by a parallel test.
    let tcp = TcpListener::bind("127.0.0.1:0").unwrap();
    let delta = tcp.local_addr().unwrap().port();
    let gcs = UdpSocket::bind("127.0.0.1:0").unwrap();
    let charlie = gcs.local_addr().unwrap().port();
    let bravo = free_udp();
    let text = sample
        .replace("/dev/ttyS0", &tty.display().to_string())
        .replace("Port = 10000", &format!("Port = {bravo}"))
        .replace("Port = 11000", &format!("Port = {charlie}"))
        .replace("Port = 25760", &format!("Port = {delta}"));
    assert_ne!(text, sample);
    let dir = tempfile::tempdir().unwrap();
    let conf = dir.path().join("main.conf");
    std::fs::write(&conf, text).unwrap();
    let router = Router::start(&[
        "--conf".into(),
        conf.display().to_string(),
        "--tcp-server".into(),
        free_tcp().to_string(),
        "--stats".into(),
        "1".into(),
    ]);
    let (mut companion, _) = tcp.accept().unwrap();
    // A vehicle sends into bravo (a UDP server endpoint), then a second HEARTBEAT: what the
    // router sent charlie before the second is there when the second is.
    let vehicle = UdpSocket::bind("127.0.0.1:0").unwrap();
    let hb = frame(&Heartbeat::default(), 1, 0);
    let next = frame(&Heartbeat::default(), 1, 1);
    vehicle.send_to(&hb, ("127.0.0.1", bravo)).unwrap();
    vehicle.send_to(&next, ("127.0.0.1", bravo)).unwrap();
    assert_eq!(
        frames_until(&gcs, &next),
        vec![hb.clone(), next],
        "charlie (udpout) gets it, once"
    );
    companion.set_read_timeout(Some(DEADLINE)).unwrap();
    let mut got = vec![0u8; hb.len()];
    companion.read_exact(&mut got).unwrap();
    assert_eq!(got, hb, "delta (tcp client) gets it");
    let mut master = std::fs::File::from(pty.master);
    let mut got = vec![0u8; hb.len()];
    master.read_exact(&mut got).unwrap();
    assert_eq!(got, hb, "alpha (the UART) gets it");
    let stats = router.stop();
    let last: serde_json::Value = serde_json::from_str(stats.lines().last().unwrap()).unwrap();
    let names: Vec<&str> = last["links"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l["name"].as_str().unwrap())
        .collect();
    for name in ["alpha", "bravo", "charlie", "delta", "tcp-server"] {
        assert!(names.contains(&name), "{name} in {names:?}");
    }
}

#[test]
fn a_tcp_client_that_vanishes_and_comes_back_is_served_again() {
    let port = free_tcp();
    let listener = UdpSocket::bind("127.0.0.1:0").unwrap();
    let out = listener.local_addr().unwrap().port();
    let router = Router::start(&[
        format!("tcpin:127.0.0.1:{port}?name=tcp"),
        format!("udpout:127.0.0.1:{out}?name=gcs"),
    ]);
    for round in 0..3u8 {
        let mut client = TcpStream::connect(("127.0.0.1", port)).unwrap();
        let hb = frame(&Heartbeat::default(), 1, round);
        let next = frame(&Heartbeat::default(), 1, 100 + round);
        // Half a frame, then the rest: a stream link reassembles it.
        client.write_all(&hb[..7]).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        client.write_all(&hb[7..]).unwrap();
        client.write_all(&next).unwrap();
        assert_eq!(
            frames_until(&listener, &next),
            vec![hb, next],
            "round {round}"
        );
        // The client goes away; the router closes its side once it has seen that.
        client.shutdown(std::net::Shutdown::Write).unwrap();
        client.set_read_timeout(Some(DEADLINE)).unwrap();
        let mut rest = Vec::new();
        client
            .read_to_end(&mut rest)
            .expect("the router closes a client that went away");
    }
    // A router endpoint that is not up yet: the router keeps trying (as mavlink-router does).
    let later = free_tcp();
    let router2 = Router::start(&[
        format!("tcp:127.0.0.1:{later}?name=late"),
        format!("udpout:127.0.0.1:{out}"),
    ]);
    std::thread::sleep(Duration::from_millis(300));
    let server = TcpListener::bind(("127.0.0.1", later)).unwrap();
    server.set_nonblocking(false).unwrap();
    let (mut conn, _) = server.accept().unwrap();
    let hb = frame(&Heartbeat::default(), 2, 0);
    let next = frame(&Heartbeat::default(), 2, 1);
    conn.write_all(&hb).unwrap();
    conn.write_all(&next).unwrap();
    assert_eq!(frames_until(&listener, &next), vec![hb, next]);
    router2.stop();
    router.stop();
}

#[test]
fn commands_pass_while_another_link_floods_and_bad_datagrams_cost_only_themselves() {
    let (veh_port, gcs_port, flood_port) = (free_udp(), free_udp(), free_udp());
    let router = Router::start(&[
        // The vehicle is behind a radio with a byte budget: the flood's telemetry is cut to
        // it, control traffic never is.
        format!("udpin:127.0.0.1:{veh_port}?name=vehicle&bytes_per_s=20000"),
        format!("udpin:127.0.0.1:{gcs_port}?name=gcs"),
        format!("udpin:127.0.0.1:{flood_port}?name=flood"),
        "--stats".into(),
        "1".into(),
    ]);
    // The ground station's HEARTBEAT, then the vehicle's until one reaches the ground station:
    // the router knows both links (and the vehicle's system) before the first command.
    let gcs = UdpSocket::bind("127.0.0.1:0").unwrap();
    gcs.send_to(
        &frame(&Heartbeat::default(), 255, 0),
        ("127.0.0.1", gcs_port),
    )
    .unwrap();
    let vehicle = UdpSocket::bind("127.0.0.1:0").unwrap();
    gcs.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let deadline = Instant::now() + DEADLINE;
    let mut buf = [0u8; 65536];
    let mut seq = 0u8;
    loop {
        assert!(
            Instant::now() < deadline,
            "no vehicle HEARTBEAT reached the ground station"
        );
        vehicle
            .send_to(
                &frame(&Heartbeat::default(), 1, seq),
                ("127.0.0.1", veh_port),
            )
            .unwrap();
        if gcs.recv(&mut buf).is_ok() {
            break;
        }
        seq = seq.wrapping_add(1);
    }
    let stop = Arc::new(AtomicBool::new(false));
    let flood_sent = Arc::new(AtomicU64::new(0));
    let flooding = {
        let (stop, flood_sent) = (stop.clone(), flood_sent.clone());
        std::thread::spawn(move || {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            let att = frame(&Attitude::default(), 9, 0);
            while !stop.load(Ordering::Relaxed) {
                let _ = s.send_to(&att, ("127.0.0.1", flood_port));
                flood_sent.fetch_add(1, Ordering::Relaxed);
            }
        })
    };
    // The flood is under way before the first command.
    while flood_sent.load(Ordering::Relaxed) < 10_000 {
        std::thread::sleep(Duration::from_millis(10));
    }
    // 50 commands while the flood runs, each of which must reach the vehicle before the flood
    // stops (a starved command link gets nothing through until then), plus a truncated and a
    // corrupted datagram on the ground station's link. The wait for each is bounded only so
    // that a starved link fails instead of hanging; how fast a command passes is the router
    // benchmark's business (scripts/bench-router.sh).
    vehicle
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    for i in 0..50u16 {
        if i == 10 {
            let hb = frame(&Heartbeat::default(), 255, 1);
            gcs.send_to(&hb[..hb.len() - 4], ("127.0.0.1", gcs_port))
                .unwrap();
            let mut bad = hb.clone();
            bad[14] ^= 0x55;
            gcs.send_to(&bad, ("127.0.0.1", gcs_port)).unwrap();
        }
        let cmd = frame(&command_to(1, 1000 + i), 255, u8::try_from(i).unwrap());
        gcs.send_to(&cmd, ("127.0.0.1", gcs_port)).unwrap();
        let deadline = Instant::now() + DEADLINE;
        let mut found = false;
        while !found && Instant::now() < deadline {
            let Ok(n) = vehicle.recv(&mut buf) else {
                continue;
            };
            let mut rest = &buf[..n];
            while let Ok(f) = Frame::new_checked(rest) {
                let len = f.frame_len();
                found |= rest[..len] == cmd[..];
                rest = &rest[len..];
            }
        }
        if !found {
            stop.store(true, Ordering::Relaxed);
            let stats = router.stop();
            panic!(
                "command {i} did not reach the vehicle during a flood: {}",
                stats.lines().last().unwrap_or("")
            );
        }
    }
    stop.store(true, Ordering::Relaxed);
    flooding.join().unwrap();
    let stats = router.stop();
    let last: serde_json::Value = serde_json::from_str(stats.lines().last().unwrap()).unwrap();
    let gcs_link = last["links"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["name"] == "gcs")
        .unwrap()
        .clone();
    assert_eq!(gcs_link["dropped"]["bad_crc"], 1, "{gcs_link}");
    assert_eq!(
        gcs_link["rx_frames"], 51,
        "every good frame of the link was accepted: {gcs_link}"
    );
}

#[test]
fn two_ground_stations_on_one_udp_port_each_get_answers_at_their_own_address() {
    let port = free_udp();
    let router = Router::start(&[format!("udpin:127.0.0.1:{port}?name=gcs")]);
    let (a, b) = (
        UdpSocket::bind("127.0.0.1:0").unwrap(),
        UdpSocket::bind("127.0.0.1:0").unwrap(),
    );
    let (ha, hb) = (
        frame(&Heartbeat::default(), 254, 0),
        frame(&Heartbeat::default(), 255, 0),
    );
    // On loopback a datagram is in the router's socket when send_to returns: the router reads
    // a's HEARTBEAT first and knows a when b's comes.
    a.send_to(&ha, ("127.0.0.1", port)).unwrap();
    b.send_to(&hb, ("127.0.0.1", port)).unwrap();
    assert_eq!(frames_until(&a, &hb), vec![hb.clone()], "a sees b");
    a.send_to(&ha, ("127.0.0.1", port)).unwrap();
    assert_eq!(frames_until(&b, &ha), vec![ha], "b sees a");
    // b answers after a's frame has gone through the router: anything the router sent back
    // to a would be there before b's answer.
    let answer = frame(&Heartbeat::default(), 255, 1);
    b.send_to(&answer, ("127.0.0.1", port)).unwrap();
    assert_eq!(
        frames_until(&a, &answer),
        vec![answer],
        "nothing back to a before b's next frame"
    );
    router.stop();
}
