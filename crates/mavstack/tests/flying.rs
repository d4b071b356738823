//! Flying through the library (`System::modes`, `action`, `offboard`, `manual_control`) the
//! in-process simulated vehicle of each flavour, which answers as ArduPilot 4.7 and PX4 1.16
//! SITL do: every mode it lists set, standard names, take-off, goto and landing, offboard
//! velocity and position setpoints, PX4's refusal of OFFBOARD before setpoints and its
//! failsafe after the last one, and sticks in a position mode.
//!
//! Waits are for conditions, with generous deadlines: the simulator flies on the wall clock,
//! so a busy machine slows the test, not the vehicle.
#![cfg(feature = "sim")]

use core::time::Duration;
use std::collections::BTreeSet;

use mavstack::dialects::common::{
    CommandAck, CurrentMode, LocalPositionNed, MavCmd, MavResult, MavStandardMode, Statustext,
};
use mavstack::modes::{self as tables, Flavour};
use mavstack::router::{LinkRole, ProtocolVersionSupport};
use mavstack::services::command::Command;
use mavstack::services::statustext::text_of;
use mavstack::sim::{Autopilot, params};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{Setpoint, Sticks, System, SystemError, TelemetryStream, Wanted};
use mavstack::{LinkSpec, Node};

/// The longest any condition is waited for.
const DEADLINE: Duration = Duration::from_secs(60);

fn none(_: &str) -> Option<u32> {
    None
}

/// A simulated vehicle of `autopilot`, a ground station on loopback, and the vehicle found.
async fn fly(autopilot: Autopilot) -> (SimVehicle, Node, System) {
    let vehicle = SimVehicle::start(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
            .role(LinkRole::Vehicle {
                protocol_version: ProtocolVersionSupport::Answer,
            }),
        SimVehicle::config(autopilot, params::defaults(autopilot)),
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
    (vehicle, gcs, system)
}

/// Waits until `done` holds (checked every 100 ms), at most [`DEADLINE`].
async fn until(what: &str, mut done: impl AsyncFnMut() -> bool) {
    let end = tokio::time::Instant::now() + DEADLINE;
    while !done().await {
        assert!(tokio::time::Instant::now() < end, "never: {what}");
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
}

/// The vehicle's local position (north, east, down), the newest of `stream`.
async fn local(stream: &mut TelemetryStream<LocalPositionNed>) -> [f32; 3] {
    // Drain what queued up, then take the next one: it is current.
    loop {
        let next = tokio::time::timeout(Duration::from_millis(5), stream.recv()).await;
        if next.is_err() {
            break;
        }
    }
    let p = tokio::time::timeout(DEADLINE, stream.recv())
        .await
        .expect("LOCAL_POSITION_NED comes")
        .expect("the node runs")
        .message;
    [p.x, p.y, p.z]
}

fn flavour(autopilot: Autopilot) -> Flavour {
    match autopilot {
        Autopilot::Ardupilot => Flavour::ArduCopter,
        Autopilot::Px4 => Flavour::Px4,
    }
}

async fn current(system: &System) -> u32 {
    system.modes().current().await.expect("a mode").custom_mode
}

/// Arms and takes off to 10 m through the library.
async fn take_off(system: &System) {
    system.action().arm().await.expect("arms");
    system
        .action()
        .takeoff(10.0, |_| {})
        .await
        .expect("takes off");
    let height = system
        .telemetry()
        .last_position()
        .expect("a position")
        .height_m;
    assert!(height >= 9.5, "at {height} m");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_mode_listed_is_set_or_refused_with_the_vehicles_reason() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let (vehicle, gcs, system) = fly(autopilot).await;
        let list = system.modes().list().await;
        // From the vehicle (names as it gives them), not the built-in table.
        let (count, named) = match autopilot {
            Autopilot::Ardupilot => (24, "AUTO RTL"),
            Autopilot::Px4 => (25, "Position Slow"),
        };
        assert_eq!(list.len(), count, "{autopilot}");
        assert!(
            list.iter().any(|m| m.name == named),
            "{autopilot}: {list:?}"
        );
        let mut refused = BTreeSet::new();
        for mode in list.iter().filter(|m| m.selectable) {
            match system.modes().set_mode(mode).await {
                Ok(()) => assert_eq!(current(&system).await, mode.custom_mode, "{}", mode.name),
                Err(
                    SystemError::Command { statustext, .. }
                    | SystemError::NotDone { statustext, .. },
                ) => {
                    assert!(
                        !statustext.is_empty(),
                        "{}: refused without a reason",
                        mode.name
                    );
                    refused.insert(mode.name.clone());
                }
                Err(e) => panic!("{autopilot} {}: {e}", mode.name),
            }
        }
        let expected: BTreeSet<String> = match autopilot {
            Autopilot::Ardupilot => [
                "AUTO RTL", "FLIP", "AUTOTUNE", "FLOWHOLD", "FOLLOW", "SYSTEMID", "TURTLE",
            ]
            .into_iter()
            .map(str::to_owned)
            .collect(),
            Autopilot::Px4 => ["VTOL Takeoff".to_owned()].into(),
        };
        assert_eq!(refused, expected, "{autopilot}");
        // Standard names find the custom modes the built-in tables give them.
        let f = flavour(autopilot);
        for standard in (1..=8).map(MavStandardMode) {
            let name = tables::standard_name(standard).expect("a standard name");
            let found = system.modes().find(&name).await.ok().map(|m| m.custom_mode);
            let table = tables::by_standard(f, standard).map(|m| m.custom_mode);
            assert_eq!(found, table, "{autopilot} {name}");
        }
        drop(system);
        let _ = gcs.shutdown().await;
        let _ = vehicle.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn take_off_go_30_m_north_and_land() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let (vehicle, gcs, system) = fly(autopilot).await;
        take_off(&system).await;
        let here = system.telemetry().last_position().expect("a position");
        let north = here.lat_deg + 30.0 / 111_319.49;
        system
            .action()
            .goto(north, here.lon_deg, 10.0, None, true, |_| {})
            .await
            .expect("goes there");
        let there = system.telemetry().last_position().expect("a position");
        let off = mavstack::system::distance_m(there.lat_deg, there.lon_deg, north, here.lon_deg);
        assert!(off <= 1.5, "{autopilot}: {off} m from the point");
        system.action().land().await.expect("lands");
        system
            .action()
            .wait_landed(DEADLINE, |_| {})
            .await
            .expect("landed and disarmed");
        assert!(!system.action().armed(), "{autopilot}");
        drop(system);
        let _ = gcs.shutdown().await;
        let _ = vehicle.shutdown().await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn offboard_velocity_and_position_setpoints_then_holding() {
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        let (vehicle, gcs, system) = fly(autopilot).await;
        take_off(&system).await;
        let mut positions = system.telemetry().subscribe::<LocalPositionNed>().await;
        let session = system
            .offboard()
            .start(20.0, Setpoint::STILL)
            .await
            .expect("offboard starts");
        let before = local(&mut positions).await;
        session
            .set_velocity_ned(3.0, 0.0, 0.0, None)
            .expect("a setpoint");
        tokio::time::sleep(Duration::from_secs(5)).await;
        session.set(Setpoint::STILL).expect("a setpoint");
        tokio::time::sleep(Duration::from_secs(1)).await;
        let after = local(&mut positions).await;
        let moved = after[0] - before[0];
        assert!(
            (13.0..=17.0).contains(&moved),
            "{autopilot}: {moved} m north"
        );

        // A position 10 m east, held within 1 m.
        let [n, e, d] = after;
        session
            .set_position_ned(n, e + 10.0, d, None)
            .expect("a setpoint");
        until("10 m east", async || {
            let p = local(&mut positions).await;
            (p[0] - n).hypot(p[1] - e - 10.0) < 1.0
        })
        .await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        let held = local(&mut positions).await;
        assert!(
            (held[0] - n).hypot(held[1] - e - 10.0) < 1.0,
            "{autopilot}: {held:?}"
        );

        // Stopped: the hold mode, staying put.
        session.stop().await.expect("stops and holds");
        let hold = match autopilot {
            Autopilot::Ardupilot => 5,
            Autopilot::Px4 => 0x0304_0000,
        };
        assert_eq!(current(&system).await, hold, "{autopilot}");
        let a = local(&mut positions).await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        let b = local(&mut positions).await;
        assert!(
            (0..3).all(|i| (a[i] - b[i]).abs() < 0.5),
            "{autopilot}: {a:?} {b:?}"
        );
        drop(system);
        let _ = gcs.shutdown().await;
        let _ = vehicle.shutdown().await;
    }
}

/// The STATUSTEXT lines of `stream` until one contains `text` (at most [`DEADLINE`]).
async fn said(stream: &mut TelemetryStream<Statustext>, text: &str) -> bool {
    let end = tokio::time::Instant::now() + DEADLINE;
    while let Ok(Some(s)) = tokio::time::timeout_at(end, stream.recv()).await {
        if text_of(&s.message.text).contains(text) {
            return true;
        }
    }
    false
}

fn set_mode_offboard() -> Command {
    // PX4's OFFBOARD: main mode 6.
    Command::long(MavCmd::DO_SET_MODE, [1.0, 6.0, 0.0, 0.0, 0.0, 0.0, 0.0])
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn px4_refuses_offboard_before_setpoints_and_leaves_it_after_the_last() {
    let (vehicle, gcs, system) = fly(Autopilot::Px4).await;
    take_off(&system).await;
    let hold = 0x0304_0000;
    until("Hold after the take-off", async || {
        current(&system).await == hold
    })
    .await;
    let mut acks = system.telemetry().subscribe::<CommandAck>().await;
    let mut texts = system.telemetry().subscribe::<Statustext>().await;
    // PX4 acknowledges DO_SET_MODE twice: its MAVLink receiver at once (ACCEPTED), then its
    // commander, which refuses OFFBOARD without setpoints and says why.
    let first = system
        .commands()
        .send(set_mode_offboard())
        .await
        .expect("the receiver's ACK");
    assert_eq!(first.result, MavResult::ACCEPTED);
    let mut results = Vec::new();
    while results.len() < 2 {
        let ack = tokio::time::timeout(DEADLINE, acks.recv())
            .await
            .expect("both ACKs")
            .expect("the node runs")
            .message;
        if ack.command == MavCmd::DO_SET_MODE {
            results.push(ack.result);
        }
    }
    assert_eq!(
        results,
        [MavResult::ACCEPTED, MavResult::TEMPORARILY_REJECTED]
    );
    assert!(
        said(
            &mut texts,
            "Switching to Offboard is currently not available"
        )
        .await
    );
    assert_eq!(current(&system).await, hold);

    // Setpoints flowing, it enters; after the last one it falls back to Position mode.
    let node = system.node().clone();
    let target = (system.target().system, system.target().component);
    let stream = tokio::spawn(async move {
        loop {
            node.send_message(&Setpoint::STILL.message(target, 0)).await;
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    });
    tokio::time::sleep(Duration::from_millis(500)).await;
    system
        .commands()
        .send(set_mode_offboard())
        .await
        .expect("accepted");
    until("OFFBOARD", async || current(&system).await == 0x6_0000).await;
    let mut modes = system.telemetry().subscribe::<CurrentMode>().await;
    stream.abort();
    assert!(said(&mut texts, "Failsafe activated").await);
    until("Position mode", async || current(&system).await == 0x3_0000).await;
    let intended = loop {
        let m = tokio::time::timeout(DEADLINE, modes.recv())
            .await
            .expect("CURRENT_MODE")
            .expect("the node runs")
            .message;
        if m.custom_mode == 0x3_0000 {
            break m.intended_custom_mode;
        }
    };
    assert_eq!(intended, 0x6_0000, "OFFBOARD is still the mode asked for");
    drop(system);
    let _ = gcs.shutdown().await;
    let _ = vehicle.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sticks_move_the_vehicle_in_a_position_mode_and_centred_hold_it() {
    for (autopilot, mode) in [(Autopilot::Ardupilot, "LOITER"), (Autopilot::Px4, "POSCTL")] {
        let (vehicle, gcs, system) = fly(autopilot).await;
        take_off(&system).await;
        let mut positions = system.telemetry().subscribe::<LocalPositionNed>().await;
        let sticks = system.manual_control().start(20.0).expect("sticks");
        tokio::time::sleep(Duration::from_millis(500)).await;
        system.modes().set(mode).await.expect("a position mode");
        let before = local(&mut positions).await;
        sticks
            .set(Sticks {
                x: 1.0,
                ..Sticks::CENTRED
            })
            .expect("sticks");
        until("forward", async || {
            local(&mut positions).await[0] - before[0] > 10.0
        })
        .await;
        sticks.set(Sticks::CENTRED).expect("sticks");
        tokio::time::sleep(Duration::from_secs(1)).await;
        let a = local(&mut positions).await;
        tokio::time::sleep(Duration::from_secs(2)).await;
        let b = local(&mut positions).await;
        assert!(
            (0..3).all(|i| (a[i] - b[i]).abs() < 0.5),
            "{autopilot}: {a:?} {b:?}"
        );
        drop(sticks);
        drop(system);
        let _ = gcs.shutdown().await;
        let _ = vehicle.shutdown().await;
    }
}

#[test]
fn the_tables_name_the_modes_the_vehicles_list() {
    // The simulator's lists and the library's built-in tables agree on every number.
    for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
        for m in mavstack::sim::modes::modes(autopilot) {
            let known = tables::name_of(flavour(autopilot), m.custom_mode);
            let external = m.name.starts_with("AUTO.EXTERNAL") || m.name == "TERMINATION";
            assert!(known.is_some() || external, "{autopilot} {}", m.name);
        }
    }
}
