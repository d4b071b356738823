//! The in-process simulated vehicle (`SimVehicle`, feature `sim`) driven by a ground station
//! built on `Node`, over a loopback UDP link.
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::core::MessageSet as _;
use mavstack::dialects::common::{
    Heartbeat, MavAutopilot, MavMessage, MavParamType, MavType, ParamRequestRead,
};
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::{LinkSpec, Node, Subscription};

/// The next message from 1/1 that `pick` takes, within `timeout`.
async fn next_from_vehicle<T>(
    frames: &mut Subscription,
    timeout: Duration,
    mut pick: impl FnMut(MavMessage) -> Option<T>,
) -> Option<T> {
    tokio::time::timeout(timeout, async {
        while let Some(incoming) = frames.recv().await {
            let f = incoming.frame.frame.view();
            if (f.sysid(), f.compid()) != (1, 1) {
                continue;
            }
            if let Ok(m) = MavMessage::decode(f.msg_id(), f.payload())
                && let Some(t) = pick(m)
            {
                return Some(t);
            }
        }
        None
    })
    .await
    .ok()
    .flatten()
}

#[tokio::test]
async fn a_ground_station_node_reads_telemetry_and_a_parameter_of_the_in_process_vehicle() {
    let none = |_: &str| None;
    let vehicle = SimVehicle::start(
        Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec")),
        SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
    )
    .await
    .expect("vehicle starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();

    let gcs = Node::builder()
        .identity(255, 190)
        .heartbeat(
            &Heartbeat {
                r#type: MavType::GCS,
                autopilot: MavAutopilot::INVALID,
                mavlink_version: 3,
                ..Heartbeat::default()
            },
            Duration::from_secs(1),
        )
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let mut frames = gcs.subscribe().await;

    let hb = next_from_vehicle(&mut frames, Duration::from_secs(5), |m| match m {
        MavMessage::Heartbeat(h) => Some(h),
        _ => None,
    })
    .await
    .expect("the vehicle's HEARTBEAT");
    assert_eq!(hb.autopilot, MavAutopilot::ARDUPILOTMEGA);
    let attitude = next_from_vehicle(&mut frames, Duration::from_secs(3), |m| match m {
        MavMessage::Attitude(a) => Some(a),
        _ => None,
    })
    .await;
    assert!(attitude.is_some(), "ATTITUDE streams");

    let mut param_id = [0u8; 16];
    param_id[..9].copy_from_slice(b"MAV_SYSID");
    let request = ParamRequestRead {
        target_system: 1,
        target_component: 1,
        param_id,
        param_index: -1,
    };
    assert_eq!(gcs.send(&request).await, 1);
    let value = next_from_vehicle(&mut frames, Duration::from_secs(3), |m| match m {
        MavMessage::ParamValue(v) if v.param_id == param_id => Some(v),
        _ => None,
    })
    .await
    .expect("PARAM_VALUE for MAV_SYSID");
    assert_eq!(value.param_value, 1.0, "ArduPilot's C-cast encoding of 1");
    assert_eq!(value.param_type, MavParamType::INT16);

    gcs.shutdown().await.expect("ground station stops");
    vehicle.shutdown().await.expect("vehicle stops");
}

#[tokio::test]
async fn a_vehicle_link_with_version_1_refuses_the_handshake_and_reports_it_as_an_event() {
    use mavstack::channel::ProtocolVersionAnswer;
    use mavstack::core::wire::Version;
    use mavstack::dialects::common::{CommandLong, MavCmd};
    use mavstack::{LinkEvent, NodeEvent};
    let none = |_: &str| None;
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0?version=1&name=legacy", &none).expect("spec")),
        SimVehicle::config(Autopilot::Px4, params::defaults(Autopilot::Px4)),
    )
    .await
    .expect("vehicle starts");
    let mut events = vehicle.node().handle().events().await;
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    // The ground station's link is MAVLink 2 from the start: the request goes in MAVLink 2.
    let gcs = Node::builder()
        .identity(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}?version=2"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let mut frames = gcs.subscribe().await;
    let request = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::REQUEST_MESSAGE,
        param1: 300.0,
        ..CommandLong::default()
    };
    assert_eq!(gcs.send(&request).await, 1);

    let event = tokio::time::timeout(Duration::from_secs(3), async {
        loop {
            match events.recv().await {
                Some(NodeEvent {
                    link,
                    kind: LinkEvent::ProtocolVersionRequested { from, answer },
                    ..
                }) => return Some((link, from, answer)),
                Some(_) => {}
                None => return None,
            }
        }
    })
    .await
    .ok()
    .flatten()
    .expect("the handshake request, as an event");
    assert_eq!(event.0, "legacy");
    assert_eq!(event.1, (255, 190));
    assert!(matches!(event.2, ProtocolVersionAnswer::Nacked(_)));
    // The refusal, in MAVLink 1.
    let ack = tokio::time::timeout(Duration::from_secs(3), async {
        while let Some(incoming) = frames.recv().await {
            let f = incoming.frame.frame.view();
            if let Ok(MavMessage::CommandAck(a)) = MavMessage::decode(f.msg_id(), f.payload()) {
                return Some((f.version(), a.command, a.result));
            }
        }
        None
    })
    .await
    .ok()
    .flatten()
    .expect("COMMAND_ACK");
    assert_eq!(ack.0, Version::V1);
    assert_eq!(ack.1, MavCmd::REQUEST_MESSAGE);
    assert_ne!(ack.2, mavstack::dialects::common::MavResult::ACCEPTED);

    gcs.shutdown().await.expect("ground station stops");
    vehicle.shutdown().await.expect("vehicle stops");
}
