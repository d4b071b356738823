//! The shell and RTK corrections through the library (`System::shell`, `System::rtk`)
//! against the in-process simulated vehicle of each flavour over loopback UDP: a command's
//! output, a session's raw bytes, ArduPilot's silence; corrections one by one and a stream
//! with garbage and damaged frames forwarded, each message counted by the vehicle.
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::services::rtcm::{RtcmError, frame};
use mavstack::services::shell::ShellError;
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};
use tokio::sync::mpsc;

const DEADLINE: Duration = Duration::from_secs(60);

fn none(_: &str) -> Option<u32> {
    None
}

/// A simulated vehicle of `autopilot` saying what it does, a ground station, the vehicle
/// found.
async fn connect(
    autopilot: Autopilot,
) -> (SimVehicle, Node, System, mpsc::UnboundedReceiver<String>) {
    let (tx, lines) = mpsc::unbounded_channel();
    let vehicle = SimVehicle::start_logged(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec")),
        SimVehicle::config(autopilot, params::defaults(autopilot)),
        Some(tx),
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let system = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(10))
        .await
        .expect("the vehicle is found");
    (vehicle, gcs, system, lines)
}

/// The vehicle's `rtk:` lines, until `count` have come.
async fn rtk_lines(lines: &mut mpsc::UnboundedReceiver<String>, count: usize) -> Vec<String> {
    let mut got = Vec::new();
    while got.len() < count {
        let line = tokio::time::timeout(DEADLINE, lines.recv())
            .await
            .expect("the vehicle tells what it got")
            .expect("the vehicle runs");
        if let Some(rest) = line.strip_prefix("vehicle: rtk: ") {
            got.push(rest.to_owned());
        }
    }
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_shell_commands_and_a_session() {
    let (vehicle, gcs, system, _lines) = connect(Autopilot::Px4).await;
    let shell = system.shell();
    let ver = shell.run("ver all", DEADLINE).await.expect("ver all");
    assert!(ver.starts_with("HW arch: MAVSTACK_SIM\n"), "{ver}");
    assert!(
        ver.contains("\nPX4 version: Release 4.1.0 (67174655)\n"),
        "{ver}"
    );
    let help = shell.run("help", DEADLINE).await.expect("help");
    assert!(help.lines().count() > 50, "{help}");
    let unknown = shell.run("frobnicate", DEADLINE).await.expect("answered");
    assert_eq!(unknown, "nsh: frobnicate: command not found\n");
    let two = shell.run("ver\nhelp", DEADLINE).await.unwrap_err();
    assert!(
        matches!(two, SystemError::Shell(ShellError::LineBreak)),
        "{two}"
    );

    let mut session = shell.open().await;
    session.write(b"echo hello\n").expect("open");
    let mut seen = Vec::new();
    let end = tokio::time::Instant::now() + DEADLINE;
    while !String::from_utf8_lossy(&seen).ends_with("hello\nnsh> ") {
        let bytes = tokio::time::timeout_at(end, session.read())
            .await
            .expect("the shell answers")
            .expect("the session runs");
        seen.extend_from_slice(&bytes);
    }
    let seen = String::from_utf8_lossy(&seen).into_owned();
    assert!(seen.starts_with("\nNuttShell (NSH)"), "{seen:?}");
    session.close().await.expect("closed");
    // Closed, the shell greets the next session again: the vehicle saw the close.
    let mut again = shell.open().await;
    again.write(b"\n").expect("open");
    let first = tokio::time::timeout(DEADLINE, again.read())
        .await
        .expect("answers")
        .expect("runs");
    assert!(first.starts_with(b"\nNuttShell"), "{first:?}");
    again.close().await.expect("closed");
    gcs.shutdown().await.expect("gcs");
    vehicle.shutdown().await.expect("vehicle");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ardupilot_has_no_shell() {
    let (vehicle, gcs, system, _lines) = connect(Autopilot::Ardupilot).await;
    let err = system.shell().run("ver all", DEADLINE).await.unwrap_err();
    assert!(
        matches!(err, SystemError::Shell(ShellError::NoAnswer { .. })),
        "{err}"
    );
    assert!(
        mavstack::error_chain(&err).contains("ArduPilot has no such device"),
        "{}",
        mavstack::error_chain(&err)
    );
    gcs.shutdown().await.expect("gcs");
    vehicle.shutdown().await.expect("vehicle");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn corrections_one_by_one_and_as_a_stream() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let (vehicle, gcs, system, mut lines) = connect(autopilot).await;
        let rtk = system.rtk();
        let first = rtk.next_sequence().await;
        assert_eq!(rtk.inject(&[0x55; 360]).await.expect("sent"), 3);
        assert_eq!(rtk.inject(&[0x56; 100]).await.expect("sent"), 1);
        assert_eq!(rtk.next_sequence().await, (first + 2) % 32);
        let err = rtk.inject(&[0; 721]).await.unwrap_err();
        assert!(
            matches!(err, SystemError::Rtcm(RtcmError::TooLong { len: 721 })),
            "{err}"
        );
        assert_eq!(rtk.next_sequence().await, (first + 2) % 32, "nothing sent");
        let got = rtk_lines(&mut lines, 2).await;
        assert!(got[0].starts_with("data, 360 bytes; 1 messages"), "{got:?}");
        assert!(got[1].starts_with("data, 100 bytes; 2 messages"), "{got:?}");

        // A stream: noise, a 1005, a damaged frame, an MSM of 360 bytes, one too long.
        let mut stream = b"\x00\x01noise\xd3\xff".to_vec();
        stream.extend_from_slice(&frame(&[0x3e, 0xd0, 0, 1, 2]));
        let mut damaged = frame(&[0x43, 0x20, 9, 9, 9]);
        damaged[4] ^= 1;
        stream.extend_from_slice(&damaged);
        let mut msm = vec![0x43, 0x50];
        msm.resize(354, 7);
        stream.extend_from_slice(&frame(&msm));
        stream.extend_from_slice(&frame(&[0x44; 800]));
        let mut reports = 0;
        let report = rtk
            .forward(&stream[..], Duration::from_secs(1), |_| reports += 1)
            .await
            .expect("forwarded");
        assert!(reports >= 1);
        assert_eq!(report.read, stream.len() as u64);
        assert_eq!((report.frames, report.damaged, report.too_long), (3, 1, 1));
        assert_eq!((report.sent, report.fragments), (2, 1 + 3));
        assert_eq!(report.sent_bytes, 11 + 360);
        let got = rtk_lines(&mut lines, 2).await;
        assert!(
            got[0].starts_with("RTCM 1005, 11 bytes; 3 messages"),
            "{got:?}"
        );
        assert!(
            got[1].starts_with("RTCM 1077, 360 bytes; 4 messages"),
            "{got:?}"
        );
        assert!(got[1].ends_with("0 fragments discarded"), "{got:?}");
        gcs.shutdown().await.expect("gcs");
        vehicle.shutdown().await.expect("vehicle");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stream_of_garbage_sends_nothing() {
    let (vehicle, gcs, system, mut lines) = connect(Autopilot::Px4).await;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let garbage: Vec<u8> = (0..100_000)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        })
        .collect();
    let report = system
        .rtk()
        .forward(&garbage[..], Duration::from_secs(1), |_| {})
        .await
        .expect("read to its end");
    assert_eq!((report.frames, report.sent, report.fragments), (0, 0, 0));
    assert_eq!(report.skipped, garbage.len() as u64);
    assert!(report.damaged > 0, "{report:?}");
    // A correction after it is the vehicle's first.
    system.rtk().inject(&[1, 2, 3]).await.expect("sent");
    let got = rtk_lines(&mut lines, 1).await;
    assert!(got[0].starts_with("data, 3 bytes; 1 messages"), "{got:?}");
    gcs.shutdown().await.expect("gcs");
    vehicle.shutdown().await.expect("vehicle");
}
