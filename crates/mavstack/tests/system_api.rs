//! The `System` API of a ground-station `Node` against the in-process simulated vehicle:
//! discovery, the handshake, parameters, missions, commands and typed telemetry, over a
//! clean loopback link and through `tests-interop/lossy_relay.py` dropping 20 % of the
//! datagrams each way.
#![cfg(feature = "sim")]

use core::time::Duration;
use std::path::{Path, PathBuf};
use std::process::{Child, Command as Process};

use mavstack::channel::{FallbackReason, HandshakeResult};
use mavstack::core::Message as _;
use mavstack::dialects::common::{
    Attitude, CommandLong, MavCmd, MavMissionType, MavResult, MissionItemInt,
};
use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::services::command::Command;
use mavstack::services::command::CommandError;
use mavstack::services::heartbeat::HeartbeatEvent;
use mavstack::services::param::{Name, Value};
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{Discovery, System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

mod common;
use common::plan;

fn none(_: &str) -> Option<u32> {
    None
}

fn ground_station() -> mavstack::NodeBuilder {
    Node::ground_station(255, 190)
}

fn same_plan(a: &[MissionItemInt], b: &[MissionItemInt]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(a, b)| {
            (a.command, a.frame, a.x, a.y, a.z.to_bits())
                == (b.command, b.frame, b.x, b.y, b.z.to_bits())
        })
}

#[tokio::test]
async fn a_ground_station_finds_handshakes_and_operates_the_simulated_vehicle() {
    let (vehicle, gcs) = vehicle_and_gcs(
        ProtocolVersionSupport::Answer,
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await;
    let mut discovery = Discovery::new(&gcs.handle()).await;

    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    assert_eq!((v.target().system, v.target().component), (1, 1));
    // It started in MAVLink 1: the handshake ran and succeeded.
    let outcome = v.handshake().expect("a handshake ran");
    assert!(matches!(
        outcome.result,
        HandshakeResult::ProtocolVersion(_)
    ));
    let appeared = tokio::time::timeout(Duration::from_secs(3), discovery.next())
        .await
        .expect("discovery reports")
        .expect("an event");
    assert!(matches!(appeared, HeartbeatEvent::New(p) if p.address == v.target()));

    let table = v.params().get_all().await.expect("the parameter table");
    assert_eq!(table.len(), params::defaults(Autopilot::Ardupilot).len());
    let name = Name::new("WPNAV_SPEED").expect("name");
    let set = v
        .params()
        .set(name, Value::F32(640.0))
        .await
        .expect("set confirmed");
    assert_eq!(set.value.as_f64(), 640.0);
    assert_eq!(
        v.params().get(name).await.expect("read").value.as_f64(),
        640.0
    );

    let items = plan(8);
    v.mission()
        .upload(MavMissionType::MISSION, items.clone())
        .await
        .expect("upload");
    let back = v
        .mission()
        .download(MavMissionType::MISSION)
        .await
        .expect("download");
    assert!(same_plan(&back, &items), "read back {back:?}");

    let ack = v
        .commands()
        .send_with_progress(
            Command::Long(CommandLong {
                command: MavCmd::COMPONENT_ARM_DISARM,
                param1: 1.0,
                ..CommandLong::default()
            }),
            |_| {},
        )
        .await
        .expect("arming is accepted");
    assert_eq!(ack.result, MavResult::ACCEPTED);

    let mut attitude = v.telemetry().subscribe::<Attitude>().await;
    let sample = tokio::time::timeout(Duration::from_secs(3), attitude.recv())
        .await
        .expect("ATTITUDE streams")
        .expect("a sample");
    assert_eq!(sample.from, v.target());
    assert!(sample.message.roll.is_finite());
    // The same subscription read as a `Stream`.
    let next = core::future::poll_fn(|cx| {
        futures_core::Stream::poll_next(core::pin::Pin::new(&mut attitude), cx)
    });
    let sample = tokio::time::timeout(Duration::from_secs(3), next)
        .await
        .expect("ATTITUDE streams")
        .expect("a sample");
    assert_eq!(sample.from, v.target());

    // The vehicle goes away: discovery says so within its 3 s timeout.
    vehicle.shutdown().await.expect("vehicle stops");
    let lost = tokio::time::timeout(Duration::from_secs(6), async {
        loop {
            match discovery.next().await {
                Some(HeartbeatEvent::Lost(a)) => return Some(a),
                Some(_) => {}
                None => return None,
            }
        }
    })
    .await
    .expect("lost in time");
    assert_eq!(lost, Some(v.target()));
    drop(v);
    gcs.shutdown().await.expect("ground station stops");
}

/// `tests-interop/lossy_relay.py` between `listen` and `forward`, dropping `loss` each way.
struct Relay(Child);

/// The peers' python, as the CLI's interop tests find it: `$MAVSTACK_PYTHON` (which
/// `scripts/test.sh` exports), else the workspace's `.venv/bin/python` (made by
/// `scripts/setup-peers.sh`). Missing, the relay fails to start and the test with it:
/// another python is never taken in its place.
fn peers_python(root: &Path) -> PathBuf {
    std::env::var_os("MAVSTACK_PYTHON")
        .filter(|p| !p.is_empty())
        .map_or_else(|| root.join(".venv/bin/python"), PathBuf::from)
}

impl Relay {
    fn start(listen: u16, forward: u16, loss: f64) -> Self {
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
        let python = peers_python(&root);
        let child = Process::new(&python)
            .arg(root.join("tests-interop/lossy_relay.py"))
            .args(["--listen", &format!("127.0.0.1:{listen}")])
            .args(["--forward", &format!("127.0.0.1:{forward}")])
            .args(["--loss", &loss.to_string(), "--seed", "7"])
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "cannot run the peers' python {} ({e}): run scripts/setup-peers.sh (it makes \
                     .venv) or set MAVSTACK_PYTHON",
                    python.display()
                )
            });
        Self(child)
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[tokio::test]
async fn parameters_and_a_mission_go_through_a_link_that_drops_a_fifth_of_the_datagrams() {
    let gcs = ground_station()
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let gcs_port = gcs.local_addrs()[0].expect("bound").port();
    let listen = std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port();
    let _relay = Relay::start(listen, gcs_port, 0.2);
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{listen}"), &none).expect("spec")),
        SimVehicle::config(Autopilot::Px4, params::defaults(Autopilot::Px4)),
    )
    .await
    .expect("vehicle starts");

    let v = System::wait(
        &gcs.handle(),
        Wanted::System(1, Some(1)),
        Duration::from_secs(10),
    )
    .await
    .expect("the vehicle is found through the relay");
    let table = v
        .params()
        .get_all()
        .await
        .expect("every parameter despite the loss");
    assert_eq!(table.len(), params::defaults(Autopilot::Px4).len());
    let items = plan(40);
    let mut sent = Vec::new();
    v.mission()
        .upload_with_progress(MavMissionType::MISSION, items.clone(), |n, of| {
            sent.push((n, of));
        })
        .await
        .expect("upload despite the loss");
    assert_eq!(sent.last(), Some(&(40, 40)), "{sent:?}");
    let mut got = Vec::new();
    let back = v
        .mission()
        .download_with_progress(MavMissionType::MISSION, |n, of| got.push((n, of)))
        .await
        .expect("download despite the loss");
    assert!(same_plan(&back, &items));
    assert_eq!(got.last(), Some(&(40, 40)), "{got:?}");
    assert!(got.windows(2).all(|w| w[0].0 <= w[1].0), "{got:?}");

    drop(v);
    vehicle.shutdown().await.expect("vehicle stops");
    gcs.shutdown().await.expect("ground station stops");
}

#[tokio::test]
async fn signing_is_set_up_over_a_secure_link_and_the_list_reports_its_progress() {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0?secure=true", &none).expect("spec")),
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = ground_station()
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let v = System::wait(
        &gcs.handle(),
        Wanted::System(1, Some(1)),
        Duration::from_secs(5),
    )
    .await
    .expect("found");
    assert_eq!(v.link_version().await, Some("2"), "after the handshake");

    let check = v
        .signing()
        .setup(mavstack::core::signing::SecretKey::new([7; 32]), 3)
        .await
        .expect("signing set up");
    assert!(
        check.proven(),
        "a signed request got a signed answer: {check:?}"
    );
    assert_eq!(v.link_version().await, Some("signed"));
    let mut seen = Vec::new();
    let table = v
        .params()
        .get_all_with_progress(|got, of| seen.push((got, of)))
        .await
        .expect("the table, over the signed link");
    let n = table.len();
    assert_eq!(
        seen.last(),
        Some(&(n, n)),
        "progress ends at the count: {seen:?}"
    );
    assert!(
        seen.windows(2).all(|w| w[0].0 < w[1].0),
        "progress only grows: {seen:?}"
    );
    // The vehicle's side is signed too: its frames to us verified with the key.
    let report = vehicle.node().report().await.expect("report");
    assert!(report.links.iter().any(|l| l.version == "signed"));
    // And off again: the all-zero key, signed with the current one; then unsigned answers.
    let check = v.signing().remove().await.expect("signing removed");
    assert!(
        check.proven(),
        "an unsigned request was answered: {check:?}"
    );
    assert_eq!(v.link_version().await, Some("2"));
    let report = vehicle.node().report().await.expect("report");
    assert!(
        report.links.iter().all(|l| l.version != "signed"),
        "{report:?}"
    );

    drop(v);
    gcs.shutdown().await.expect("ground station stops");
    vehicle.shutdown().await.expect("vehicle stops");
}

/// A vehicle of `config` on a loopback UDP server, and a ground-station node reaching it.
async fn vehicle_and_gcs(
    role: ProtocolVersionSupport,
    config: mavstack::sim::SimConfig,
) -> (SimVehicle, Node) {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
            .role(LinkRole::Vehicle {
                protocol_version: role,
            }),
        config,
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = ground_station()
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    (vehicle, gcs)
}

#[tokio::test]
async fn a_vehicle_that_refuses_protocol_version_is_switched_by_the_fallback() {
    // ArduPilot's answers: REQUEST_MESSAGE(300) → FAILED; AUTOPILOT_VERSION on request.
    let (vehicle, gcs) = vehicle_and_gcs(
        ProtocolVersionSupport::Refuse,
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let outcome = v.handshake().expect("a handshake ran (found in MAVLink 1)");
    assert_eq!(
        outcome.result,
        HandshakeResult::Message {
            msg_id: mavstack::dialects::common::AutopilotVersion::ID
        }
    );
    assert_eq!(
        outcome.fallback,
        Some(FallbackReason::Refused(MavResult::FAILED))
    );
    assert_eq!(v.link_version().await, Some("2"));
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
}

#[tokio::test]
async fn a_refused_command_carries_the_statustext_that_says_why() {
    let mut config =
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot));
    config.estimator_settle = Duration::from_secs(600);
    let (vehicle, gcs) = vehicle_and_gcs(ProtocolVersionSupport::Answer, config).await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let arm = Command::Long(CommandLong {
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 1.0,
        ..CommandLong::default()
    });
    let error = v
        .commands()
        .send_with_progress(arm, |_| {})
        .await
        .expect_err("refused");
    let SystemError::Command {
        reason, statustext, ..
    } = &error
    else {
        panic!("{error}");
    };
    assert!(
        matches!(reason, CommandError::Rejected { result, .. } if *result == MavResult::FAILED),
        "{reason}"
    );
    assert_eq!(statustext, &["PreArm: Need Position Estimate".to_owned()]);
    assert!(
        error
            .to_string()
            .ends_with("(PreArm: Need Position Estimate)"),
        "{error}"
    );
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
}

#[tokio::test]
async fn a_refusal_explained_in_events_carries_their_texts() {
    // As PX4 v1.16 while its estimator settles: TEMPORARILY_REJECTED, the reasons in EVENT
    // messages whose texts are in the metadata it serves over MAVFTP (COMPONENT_METADATA,
    // then two xz files).
    let mut config = SimVehicle::config(Autopilot::Px4, params::defaults(Autopilot::Px4));
    config.estimator_settle = Duration::from_secs(600);
    let (vehicle, gcs) = vehicle_and_gcs(ProtocolVersionSupport::Answer, config).await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let arm = Command::Long(CommandLong {
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 1.0,
        ..CommandLong::default()
    });
    for attempt in 0..2 {
        let error = v
            .commands()
            .send_with_progress(arm.clone(), |_| {})
            .await
            .expect_err("refused");
        let SystemError::Command {
            reason, statustext, ..
        } = &error
        else {
            panic!("{error}");
        };
        assert!(
            matches!(reason, CommandError::Rejected { result, .. } if *result == MavResult::TEMPORARILY_REJECTED),
            "{reason}"
        );
        assert_eq!(statustext.len(), 2, "attempt {attempt}: {statustext:?}");
        assert!(
            statustext[0].starts_with("Preflight Fail: position estimate not valid yet, about ")
                && statustext[0].ends_with(" s to go"),
            "{statustext:?}"
        );
        assert_eq!(
            statustext[1],
            "Arming denied: Resolve system health failures first"
        );
    }
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
}

#[tokio::test]
async fn a_rate_is_asked_with_set_message_interval_and_else_with_request_data_stream() {
    use mavstack::dialects::common::{Attitude, MavDataStream};
    use mavstack::system::RateMethod;
    for (streams_only, want) in [
        (false, RateMethod::MessageInterval),
        (true, RateMethod::DataStream(MavDataStream::EXTRA1)),
    ] {
        let mut config =
            SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot));
        config.data_streams_only = streams_only;
        let (vehicle, gcs) = vehicle_and_gcs(ProtocolVersionSupport::Answer, config).await;
        let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
            .await
            .expect("the vehicle is found");
        // Off first, so that only the request can bring it back.
        v.commands()
            .set_message_interval(Attitude::ID, None)
            .await
            .ok();
        let rate = v
            .telemetry()
            .request_rate(Attitude::ID, 10.0)
            .await
            .expect("asked");
        assert_eq!(rate.how, want, "data streams only: {streams_only}");
        assert!(rate.arrived, "ATTITUDE came: {rate:?}");
        gcs.shutdown().await.expect("stops");
        vehicle.shutdown().await.expect("stops");
    }
}

/// `streams_on_request`: the vehicle sends HEARTBEAT and nothing else of its streams until a
/// rate is asked for, as ArduPilot does on SITL's SERIAL0; then the message comes.
#[tokio::test]
async fn a_vehicle_streaming_on_request_sends_only_what_is_asked() {
    use mavstack::dialects::common::Attitude;
    let mut config =
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot));
    config.streams_on_request = true;
    let (vehicle, gcs) = vehicle_and_gcs(ProtocolVersionSupport::Answer, config).await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(5))
        .await
        .expect("the vehicle is found");
    let mut attitude = v.telemetry().subscribe::<Attitude>().await;
    let unasked = tokio::time::timeout(Duration::from_millis(1500), attitude.recv()).await;
    assert!(unasked.is_err(), "ATTITUDE came unasked: {unasked:?}");
    let rate = v
        .telemetry()
        .request_rate(Attitude::ID, 10.0)
        .await
        .expect("asked");
    assert!(rate.arrived, "{rate:?}");
    let asked = tokio::time::timeout(Duration::from_secs(2), attitude.recv()).await;
    assert!(matches!(asked, Ok(Some(_))), "{asked:?}");
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
}

/// A vehicle that restarts behind the ground station's `udpin` link comes back from another
/// source port, i.e. as another peer link of the node: the handle's requests follow its
/// HEARTBEAT there, so the rate it had asked for is asked for again where the vehicle now
/// is (before, they went on to the dead peer and the restarted vehicle, streaming nothing
/// unasked, stayed silent).
#[tokio::test]
async fn a_vehicle_restarted_from_another_port_is_asked_again_where_it_is() {
    use mavstack::dialects::common::Attitude;
    let gcs = ground_station()
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let port = gcs.local_addrs()[0].expect("bound").port();
    let start = || async {
        let mut config =
            SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot));
        config.streams_on_request = true;
        SimVehicle::start(
            Node::builder()
                .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
                .role(LinkRole::Vehicle {
                    protocol_version: ProtocolVersionSupport::Answer,
                }),
            config,
        )
        .await
        .expect("vehicle starts")
    };
    let first = start().await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(10))
        .await
        .expect("the vehicle is found");
    let mut attitude = v.telemetry().subscribe::<Attitude>().await;
    let rate = v
        .telemetry()
        .request_rate(Attitude::ID, 10.0)
        .await
        .expect("asked");
    assert!(rate.arrived, "{rate:?}");
    first.shutdown().await.expect("stops");
    // The same vehicle again, from a new socket: a new source port.
    let second = start().await;
    while tokio::time::timeout(Duration::from_millis(50), attitude.recv())
        .await
        .is_ok()
    {}
    // Its first ATTITUDE: it streams nothing unasked, so the handle asked it again (the
    // keeper, once ATTITUDE had stayed away for 3 s with HEARTBEAT coming).
    let again = tokio::time::timeout(Duration::from_secs(30), attitude.recv()).await;
    assert!(matches!(again, Ok(Some(_))), "{again:?}");
    gcs.shutdown().await.expect("stops");
    second.shutdown().await.expect("stops");
}
