//! Serving from a `Node`: a companion computer's own parameter table, mission store and
//! command handler (`mavstack::serve::Served` over `mavstack-services` servers), operated by
//! a ground station through the `System` API; a dropped operation's future cancels it
//! cleanly, and a stopped node frees its socket. A peripheral's telemetry streams at the
//! rate a ground station sets (`StreamServer`).
#![cfg(feature = "services")]

use core::time::Duration;

use mavstack::core::Message as _;
use mavstack::dialects::common::{
    CommandLong, DistanceSensor, Heartbeat, MavAutopilot, MavCmd, MavFrame, MavMessage,
    MavMissionType, MavResult, MavType, MissionItemInt,
};
use mavstack::router::LinkRole;
use mavstack::serve::Served;
use mavstack::services::Address;
use mavstack::services::command::{
    Command, CommandError, CommandHandler, CommandServer, CommandServerConfig, Request, Response,
};
use mavstack::services::mission::{MissionConfig, MissionServer};
use mavstack::services::param::{Encoding, Name, ParamServer, Value};
use mavstack::services::stream::{Due, MessageSource, StreamServer};
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

fn none(_: &str) -> Option<u32> {
    None
}

/// The companion's commands: it triggers its camera, and knows nothing else.
#[derive(Debug, Default)]
struct Camera {
    shots: u32,
}

impl CommandHandler for Camera {
    fn handle_command(
        &mut self,
        _now: mavstack::core::time::Instant,
        request: &Request,
    ) -> Response {
        if request.command.id() == MavCmd::IMAGE_START_CAPTURE {
            self.shots += 1;
            Response::done(MavResult::ACCEPTED)
        } else {
            Response::done(MavResult::UNSUPPORTED)
        }
    }
}

type Companion = (ParamServer, (MissionServer, CommandServer<Camera>));

#[tokio::test]
async fn a_ground_station_uses_a_companions_own_parameters_missions_and_commands() {
    let own = Address::new(1, 191);
    let node = Node::builder()
        .identity(1, 191)
        .role(LinkRole::Vehicle {
            protocol_version: mavstack::router::ProtocolVersionSupport::Answer,
        })
        .heartbeat(
            &Heartbeat {
                r#type: MavType::ONBOARD_CONTROLLER,
                autopilot: MavAutopilot::INVALID,
                mavlink_version: 3,
                ..Heartbeat::default()
            },
            Duration::from_secs(1),
        )
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("companion starts");
    let port = node.local_addrs()[0].expect("bound").port();
    let mut params = ParamServer::new(own, Encoding::Bytewise);
    let exposure = Name::new("CAM_EXPOSURE").expect("name");
    params.insert(exposure, Value::F32(0.01)).expect("insert");
    params
        .insert(Name::new("CAM_MODE").expect("name"), Value::U8(1))
        .expect("insert");
    let companion: Companion = (
        params,
        (
            MissionServer::new(own, MissionConfig::default()),
            CommandServer::new(own, CommandServerConfig::default(), Camera::default()),
        ),
    );
    let served = Served::start(&node.handle(), companion).await;

    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}?version=2"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let c = System::wait(
        &gcs.handle(),
        Wanted::System(1, Some(191)),
        Duration::from_secs(5),
    )
    .await
    .expect("the companion is found");

    // A dropped operation is cancelled (polled once: its request is on its way), and the
    // next one works.
    let params = c.params();
    let cut = tokio::select! {
        biased;
        r = params.get_all() => Some(r),
        () = core::future::ready(()) => None,
    };
    assert!(cut.is_none(), "the list could not finish in one poll");
    let table = c.params().get_all().await.expect("the companion's table");
    assert_eq!(table.len(), 2);
    let set = c
        .params()
        .set(exposure, Value::F32(0.02))
        .await
        .expect("set confirmed");
    assert_eq!(set.value, Value::F32(0.02));
    let held = served
        .with(move |(params, _)| params.get(exposure))
        .await
        .flatten();
    assert_eq!(
        held,
        Some(Value::F32(0.02)),
        "the served table holds the new value"
    );

    let survey: Vec<MissionItemInt> = (0..3)
        .map(|i| MissionItemInt {
            seq: i,
            frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
            command: MavCmd::NAV_WAYPOINT,
            x: 473_977_420 + i32::from(i),
            y: 85_455_940,
            z: 30.0,
            autocontinue: 1,
            ..MissionItemInt::default()
        })
        .collect();
    c.mission()
        .upload(MavMissionType::MISSION, survey.clone())
        .await
        .expect("upload");
    let stored = served
        .with(|(_, (missions, _))| missions.plan(MavMissionType::MISSION).to_vec())
        .await
        .expect("served");
    assert_eq!(stored.len(), 3);
    assert_eq!(stored[2].x, survey[2].x);

    let shoot = Command::Long(CommandLong {
        command: MavCmd::IMAGE_START_CAPTURE,
        ..CommandLong::default()
    });
    let ack = c
        .commands()
        .send_with_progress(shoot, |_| {})
        .await
        .expect("accepted");
    assert_eq!(ack.result, MavResult::ACCEPTED);
    let refused = c
        .commands()
        .send_with_progress(
            Command::Long(CommandLong {
                command: MavCmd::NAV_TAKEOFF,
                ..CommandLong::default()
            }),
            |_| {},
        )
        .await;
    assert!(matches!(
        refused,
        Err(SystemError::Command {
            reason: CommandError::Rejected {
                result: MavResult::UNSUPPORTED,
                ..
            },
            ..
        })
    ));

    drop(c);
    gcs.shutdown().await.expect("ground station stops");
    let (_, (_, commands)) = served.stop().await.expect("the service comes back");
    assert_eq!(commands.handler().shots, 1);
    node.shutdown().await.expect("companion stops");
    // Its socket is closed: the port can be bound again.
    std::net::UdpSocket::bind(("127.0.0.1", port)).expect("the port is free again");
}

/// A rangefinder's telemetry: the last distance measured.
#[derive(Debug)]
struct Rangefinder {
    distance_cm: u16,
}

impl MessageSource for Rangefinder {
    fn message(&mut self, now: mavstack::core::time::Instant, _due: &Due) -> Option<MavMessage> {
        Some(MavMessage::DistanceSensor(DistanceSensor {
            time_boot_ms: (now.as_micros() / 1000) as u32,
            current_distance: self.distance_cm,
            max_distance: 4000,
            ..DistanceSensor::default()
        }))
    }
}

/// How long a test waits for samples it expects before it fails: a bound on the wait, far
/// above the rates involved, not a measure of them.
const WAIT: Duration = Duration::from_secs(10);

/// Reads DISTANCE_SENSOR samples until one says `distance_cm`; returns how many came before
/// it. Fails after [`WAIT`].
async fn until_distance(
    telemetry: &mut mavstack::system::TelemetryStream<DistanceSensor>,
    distance_cm: u16,
) -> usize {
    let mut before = 0;
    let found = tokio::time::timeout(WAIT, async {
        while let Some(s) = telemetry.recv().await {
            if s.message.current_distance == distance_cm {
                return true;
            }
            before += 1;
        }
        false
    })
    .await;
    assert_eq!(
        found,
        Ok(true),
        "no sample of {distance_cm} cm ({before} others)"
    );
    before
}

/// Counts the DISTANCE_SENSOR samples of `within` and returns them with the last distance.
async fn samples(
    telemetry: &mut mavstack::system::TelemetryStream<DistanceSensor>,
    within: Duration,
) -> (usize, Option<u16>) {
    let mut n = 0;
    let mut last = None;
    let _ = tokio::time::timeout(within, async {
        while let Some(s) = telemetry.recv().await {
            n += 1;
            last = Some(s.message.current_distance);
        }
    })
    .await;
    (n, last)
}

#[tokio::test]
async fn a_peripheral_streams_at_the_rate_a_ground_station_sets() {
    let own = Address::new(1, 158);
    let node = Node::builder()
        .identity(1, 158)
        .heartbeat(
            &Heartbeat {
                r#type: MavType::GENERIC,
                autopilot: MavAutopilot::INVALID,
                mavlink_version: 3,
                ..Heartbeat::default()
            },
            Duration::from_secs(1),
        )
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("peripheral starts");
    let port = node.local_addrs()[0].expect("bound").port();
    let mut streams = StreamServer::new(own, Rangefinder { distance_cm: 412 });
    streams.support(DistanceSensor::ID, None);
    let served = Served::start(&node.handle(), streams).await;

    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}?version=2"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let p = System::wait(
        &gcs.handle(),
        Wanted::System(1, Some(158)),
        Duration::from_secs(5),
    )
    .await
    .expect("the peripheral is found");
    let mut range = p.telemetry().subscribe::<DistanceSensor>().await;
    assert_eq!(
        samples(&mut range, Duration::from_millis(300)).await.0,
        0,
        "off until asked for"
    );
    let ack = p
        .commands()
        .set_message_interval(DistanceSensor::ID, Some(Duration::from_millis(50)))
        .await
        .expect("accepted");
    assert_eq!(ack.result, MavResult::ACCEPTED);
    // The peripheral schedules at the interval asked for (how a scheduler keeps an interval
    // is tested on a virtual clock in crates/mavstack-services/tests/stream.rs), and samples
    // flow: ten of them, each built from the source.
    assert_eq!(
        served
            .with(|s| s.scheduler().interval(DistanceSensor::ID))
            .await
            .expect("served"),
        Some(Duration::from_millis(50))
    );
    for _ in 0..10 {
        assert_eq!(until_distance(&mut range, 412).await, 0);
    }
    // The state the messages are built from, changed from outside: a sample of the new
    // state follows.
    served
        .with(|s| s.source_mut().distance_cm = 97)
        .await
        .expect("served");
    until_distance(&mut range, 97).await;
    // Off again: once the stop is acknowledged no sample is built (samples already on the
    // way carry 97; one built after the stop would carry 1).
    p.commands()
        .set_message_interval(DistanceSensor::ID, None)
        .await
        .expect("accepted");
    assert_eq!(
        served
            .with(|s| {
                s.source_mut().distance_cm = 1;
                s.scheduler().interval(DistanceSensor::ID)
            })
            .await
            .expect("served"),
        None
    );
    let (_, last) = samples(&mut range, Duration::from_millis(300)).await;
    assert_ne!(last, Some(1), "a sample built after the stop");
    // A message the peripheral does not produce is refused.
    let refused = p
        .commands()
        .set_message_interval(30, Some(Duration::from_millis(100)))
        .await;
    assert!(matches!(
        refused,
        Err(SystemError::Command {
            reason: CommandError::Rejected {
                result: MavResult::DENIED,
                ..
            },
            ..
        })
    ));
    drop(p);
    gcs.shutdown().await.expect("ground station stops");
    let back = served.stop().await.expect("the service comes back");
    assert_eq!(back.scheduler().interval(DistanceSensor::ID), None);
    node.shutdown().await.expect("peripheral stops");
}
