//! An upload whose final MISSION_ACK is lost, against a scripted vehicle that keeps
//! ArduPilot's mission rules: it stores each item in place as it takes it, answers an item it
//! did not ask for with INVALID_SEQUENCE and an item after the upload with MAV_MISSION_ERROR.
//! `System` then reads back only the plan's last item (and its count), not the whole plan:
//! the vehicle asked for the last item, so it held every one before it.
#![cfg(feature = "services")]

use core::time::Duration;
use std::sync::{Arc, Mutex};

use mavstack::core::MessageSet as _;
use mavstack::dialects::common::{
    CommandAck, Heartbeat, MavAutopilot, MavMessage, MavMissionResult, MavMissionType, MavResult,
    MavState, MavType, MissionAck, MissionCount, MissionItemInt, MissionRequestInt,
};
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};

mod common;
use common::plan;

fn none(_: &str) -> Option<u32> {
    None
}

/// What the scripted vehicle saw and holds.
#[derive(Default)]
struct Vehicle {
    stored: Vec<MissionItemInt>,
    /// The next item of the upload it expects; `None` when no upload is open.
    expecting: Option<u16>,
    count: u16,
    /// The items asked for in downloads, in order.
    read: Vec<u16>,
}

/// Runs a vehicle (1/1, ArduPilot) that sends to `port` and never lets its final MISSION_ACK
/// out; `last_stored` turns the last item into what it stores instead (a vehicle that had
/// another last item).
async fn scripted_ardupilot(
    port: u16,
    last_stored: fn(MissionItemInt) -> MissionItemInt,
) -> (Node, Arc<Mutex<Vehicle>>) {
    let heartbeat = Heartbeat {
        r#type: MavType::QUADROTOR,
        autopilot: MavAutopilot::ARDUPILOTMEGA,
        system_status: MavState::STANDBY,
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let node = Node::builder()
        .identity(1, 1)
        .heartbeat(&heartbeat, Duration::from_millis(100))
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("vehicle starts");
    let state = Arc::new(Mutex::new(Vehicle::default()));
    let (handle, shared) = (node.handle(), state.clone());
    let mut frames = node.subscribe().await;
    tokio::spawn(async move {
        while let Some(incoming) = frames.recv().await {
            let f = incoming.frame.frame.view();
            let Ok(message) = MavMessage::decode(f.msg_id(), f.payload()) else {
                continue;
            };
            let answer = {
                let mut v = shared.lock().expect("not poisoned");
                answer(&mut v, &message, last_stored)
            };
            for m in answer {
                handle.send_message(&m).await;
            }
        }
    });
    (node, state)
}

fn ack(result: MavMissionResult) -> MavMessage {
    MavMessage::MissionAck(MissionAck {
        target_system: 255,
        target_component: 190,
        r#type: result,
        mission_type: MavMissionType::MISSION,
    })
}

fn request(seq: u16) -> MavMessage {
    MavMessage::MissionRequestInt(MissionRequestInt {
        target_system: 255,
        target_component: 190,
        seq,
        mission_type: MavMissionType::MISSION,
    })
}

/// ArduPilot's answers (`MissionItemProtocol.cpp`, `GCS_Common.cpp`), but for the final ACK.
fn answer(
    v: &mut Vehicle,
    message: &MavMessage,
    last_stored: fn(MissionItemInt) -> MissionItemInt,
) -> Vec<MavMessage> {
    match message {
        MavMessage::CommandLong(c) => vec![MavMessage::CommandAck(CommandAck {
            command: c.command,
            result: MavResult::UNSUPPORTED,
            target_system: 255,
            target_component: 190,
            ..CommandAck::default()
        })],
        MavMessage::MissionCount(c) => {
            v.stored.truncate(usize::from(c.count));
            (v.expecting, v.count) = (Some(0), c.count);
            vec![request(0)]
        }
        MavMessage::MissionItemInt(item) => match v.expecting {
            None => vec![ack(MavMissionResult::MAV_MISSION_ERROR)],
            Some(want) if item.seq != want => {
                vec![ack(MavMissionResult::MAV_MISSION_INVALID_SEQUENCE)]
            }
            Some(want) => {
                let last = want + 1 == v.count;
                let stored = if last { last_stored(*item) } else { *item };
                match v.stored.get_mut(usize::from(want)) {
                    Some(slot) => *slot = stored,
                    None => v.stored.push(stored),
                }
                if last {
                    // Complete; its ACCEPTED is lost on the way.
                    v.expecting = None;
                    Vec::new()
                } else {
                    v.expecting = Some(want + 1);
                    vec![request(want + 1)]
                }
            }
        },
        MavMessage::MissionRequestList(_) => vec![MavMessage::MissionCount(MissionCount {
            target_system: 255,
            target_component: 190,
            count: u16::try_from(v.stored.len()).expect("small"),
            mission_type: MavMissionType::MISSION,
        })],
        MavMessage::MissionRequestInt(r) => {
            v.read.push(r.seq);
            v.stored
                .get(usize::from(r.seq))
                .map(|item| {
                    MavMessage::MissionItemInt(MissionItemInt {
                        target_system: 255,
                        target_component: 190,
                        ..*item
                    })
                })
                .into_iter()
                .collect()
        }
        _ => Vec::new(),
    }
}

async fn upload_with_the_final_ack_lost(
    last_stored: fn(MissionItemInt) -> MissionItemInt,
) -> (Result<(), SystemError>, Vec<u16>) {
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let port = gcs.local_addrs()[0].expect("bound").port();
    let (vehicle, state) = scripted_ardupilot(port, last_stored).await;
    let v = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(10))
        .await
        .expect("the vehicle is found");
    let result = v.mission().upload(MavMissionType::MISSION, plan(30)).await;
    let read = state.lock().expect("not poisoned").read.clone();
    drop(v);
    gcs.shutdown().await.expect("stops");
    vehicle.shutdown().await.expect("stops");
    (result, read)
}

#[tokio::test]
async fn a_lost_final_ack_is_confirmed_by_reading_back_the_last_item_only() {
    let (result, read) = upload_with_the_final_ack_lost(|item| item).await;
    assert!(result.is_ok(), "{result:?}");
    assert_eq!(read, [29], "only the last item is read back");
}

#[tokio::test]
async fn a_last_item_read_back_different_fails_the_upload() {
    let (result, read) = upload_with_the_final_ack_lost(|item| MissionItemInt {
        z: item.z + 5.0,
        ..item
    })
    .await;
    assert!(
        matches!(result, Err(SystemError::Mission { what: "upload", .. })),
        "{result:?}"
    );
    assert_eq!(read, [29]);
}
