use alloc::vec::Vec;

use mavstack_dialects::common::{
    CommandAck, CommandLong, GimbalManagerSetAttitude, GlobalPositionInt, MavCmd,
};

use super::*;
use crate::gimbal::{Control, GimbalInfo};

const GCS: Address = Address::new(255, 190);
const OTHER: Address = Address::new(254, 190);
const OWN: Address = Address::new(1, 154);

fn t(ms: u64) -> Instant {
    Instant::from_millis(ms)
}

fn manager() -> GimbalManager {
    let mut config = ManagerConfig::new(OWN, 1);
    config.own_component = true;
    let mut m = GimbalManager::new(t(0), config);
    drain(&mut m);
    m
}

fn drain(m: &mut GimbalManager) -> Vec<MavMessage> {
    core::iter::from_fn(|| m.poll_transmit())
        .map(|o| o.message)
        .collect()
}

fn events(m: &mut GimbalManager) -> Vec<ManagerEvent> {
    core::iter::from_fn(|| m.poll_event()).collect()
}

/// What the manager says about itself, as a client reads it.
fn info(m: &mut GimbalManager) -> GimbalInfo {
    let request = MavMessage::CommandLong(CommandLong {
        target_system: 1,
        target_component: 0,
        command: MavCmd::REQUEST_MESSAGE,
        param1: 280.0,
        ..Default::default()
    });
    assert!(m.handle_message(t(10), GCS, &request));
    let out = drain(m);
    assert!(matches!(
        out[0],
        MavMessage::CommandAck(CommandAck {
            result: MavResult::ACCEPTED,
            ..
        })
    ));
    let MavMessage::GimbalManagerInformation(i) = &out[1] else {
        panic!("{out:?}")
    };
    GimbalInfo::from_information(OWN, i)
}

fn send(m: &mut GimbalManager, from: Address, command: Command) -> MavResult {
    let mut command = command;
    let message = match &mut command {
        Command::Long(c) => {
            (c.target_system, c.target_component) = (OWN.system, OWN.component);
            MavMessage::CommandLong(*c)
        }
        Command::Int(c) => {
            (c.target_system, c.target_component) = (OWN.system, OWN.component);
            MavMessage::CommandInt(*c)
        }
    };
    assert!(m.handle_message(t(20), from, &message));
    drain(m)
        .into_iter()
        .find_map(|msg| match msg {
            MavMessage::CommandAck(a) => Some(a.result),
            _ => None,
        })
        .expect("an ACK")
}

#[test]
fn a_clients_requests_reach_the_owner() {
    let mut m = manager();
    let g = info(&mut m);
    assert_eq!(g.device_id, 1);
    assert!(
        g.pitch
            .is_some_and(|r| (r.min + 90.0).abs() < 1e-3 && (r.max - 30.0).abs() < 1e-3)
    );
    let command = g.set_angles(-30.0, 45.0, YawFrame::Earth).unwrap();
    assert_eq!(send(&mut m, GCS, command), MavResult::ACCEPTED);
    assert_eq!(
        events(&mut m),
        [ManagerEvent::Setpoint {
            setpoint: Setpoint {
                pitch_deg: Some(-30.0),
                yaw_deg: Some(45.0),
                pitch_rate_dps: None,
                yaw_rate_dps: None,
                frame: YawFrame::Earth,
            },
            from: GCS,
        }]
    );
    let rates = g.set_rates(5.0, -10.0, YawFrame::Vehicle).unwrap();
    assert_eq!(send(&mut m, GCS, rates), MavResult::ACCEPTED);
    let [ManagerEvent::Setpoint { setpoint, .. }] = events(&mut m)[..] else {
        panic!()
    };
    assert_eq!(
        (setpoint.pitch_rate_dps, setpoint.yaw_rate_dps),
        (Some(5.0), Some(-10.0))
    );
    assert_eq!(setpoint.pitch_deg, None);
}

#[test]
fn angles_outside_its_limits_are_denied() {
    let mut m = manager();
    let mut g = info(&mut m);
    // A client that did not check: the manager does.
    g.pitch = None;
    let command = g.set_angles(60.0, 0.0, YawFrame::Vehicle).unwrap();
    assert_eq!(send(&mut m, GCS, command), MavResult::DENIED);
    assert_eq!(events(&mut m), []);
    // Another device of the system is not this manager's.
    let mut other = g.clone();
    other.device_id = 2;
    let command = other.set_angles(0.0, 0.0, YawFrame::Vehicle).unwrap();
    assert_eq!(send(&mut m, GCS, command), MavResult::DENIED);
}

#[test]
fn control_decides_who_moves_it() {
    let mut m = manager();
    let g = info(&mut m);
    assert_eq!(
        send(&mut m, GCS, g.configure(GCS, Control::Primary)),
        MavResult::ACCEPTED
    );
    assert_eq!(m.control(), (Some(GCS), None));
    assert_eq!(
        events(&mut m),
        [ManagerEvent::Control {
            primary: Some(GCS),
            secondary: None
        }]
    );
    let command = g.set_angles(-10.0, 0.0, YawFrame::Vehicle).unwrap();
    assert_eq!(send(&mut m, OTHER, command.clone()), MavResult::DENIED);
    // A streamed request from the other is dropped too.
    let stream = g
        .pitch_yaw_message((Some(-20.0), None), (None, None), YawFrame::Vehicle)
        .unwrap();
    assert!(m.handle_message(t(30), OTHER, &MavMessage::GimbalManagerSetPitchyaw(stream)));
    assert_eq!(events(&mut m), []);
    // Secondary control lets the other in.
    assert_eq!(
        send(&mut m, OTHER, g.configure(OTHER, Control::Secondary)),
        MavResult::ACCEPTED
    );
    assert_eq!(m.control(), (Some(GCS), Some(OTHER)));
    events(&mut m);
    assert_eq!(send(&mut m, OTHER, command), MavResult::ACCEPTED);
    assert_eq!(events(&mut m).len(), 1);
    // Releasing removes only the sender.
    assert_eq!(
        send(&mut m, GCS, g.configure(GCS, Control::Release)),
        MavResult::ACCEPTED
    );
    assert_eq!(m.control(), (None, Some(OTHER)));
    // The status says so at once.
    assert_eq!(
        send(&mut m, OTHER, g.configure(OTHER, Control::Release)),
        MavResult::ACCEPTED
    );
    assert_eq!(m.control(), (None, None));
}

#[test]
fn status_attitude_and_heartbeat_go_out_on_the_timers() {
    let mut m = manager();
    m.handle_timeout(t(200));
    let out = drain(&mut m);
    assert!(
        out.iter()
            .any(|o| matches!(o, MavMessage::GimbalManagerStatus(_)))
    );
    assert!(out.iter().any(|o| matches!(o, MavMessage::Heartbeat(_))));
    // No attitude before the owner measured one.
    assert!(
        !out.iter()
            .any(|o| matches!(o, MavMessage::GimbalDeviceAttitudeStatus(_)))
    );
    m.set_device_attitude(DeviceAttitude {
        euler: Euler {
            roll_deg: 0.0,
            pitch_deg: -20.0,
            yaw_deg: 15.0,
        },
        frame: YawFrame::Vehicle,
        rates_dps: [f32::NAN; 3],
        failure_flags: GimbalDeviceErrorFlags(0),
    });
    m.handle_timeout(t(1200));
    let out = drain(&mut m);
    assert!(
        out.iter()
            .any(|o| matches!(o, MavMessage::Heartbeat(h) if h.r#type == MavType::GIMBAL))
    );
    let status = out
        .iter()
        .find_map(|o| match o {
            MavMessage::GimbalDeviceAttitudeStatus(s) => Some(*s),
            _ => None,
        })
        .unwrap();
    let a = crate::gimbal::Attitude::from_status(&status).unwrap();
    assert!((a.euler.pitch_deg + 20.0).abs() < 1e-3 && (a.euler.yaw_deg - 15.0).abs() < 1e-3);
    assert_eq!(a.frame, YawFrame::Vehicle);
    assert_eq!(status.gimbal_device_id, 1);
}

#[test]
fn pointing_at_a_location_follows_the_vehicle() {
    let mut m = manager();
    let g = info(&mut m);
    // The vehicle 100 m up over home at 400 m.
    let position = GlobalPositionInt {
        lat: 470_000_000,
        lon: 80_000_000,
        alt: 500_000,
        relative_alt: 100_000,
        ..Default::default()
    };
    m.handle_message(
        t(0),
        Address::new(1, 1),
        &MavMessage::GlobalPositionInt(position),
    );
    // 100 m north of it on the ground (AMSL 400).
    let north = 100.0 / 111_319.49;
    let command = g.point_at(47.0 + north, 8.0, 400.0).unwrap();
    assert_eq!(send(&mut m, GCS, command), MavResult::ACCEPTED);
    let ev = events(&mut m);
    assert!(matches!(ev[0], ManagerEvent::Roi(Some(_))));
    let ManagerEvent::Setpoint { setpoint, from } = ev[1] else {
        panic!("{ev:?}")
    };
    assert_eq!(from, OWN);
    assert_eq!(setpoint.frame, YawFrame::Earth);
    assert!(
        (setpoint.pitch_deg.unwrap() + 45.0).abs() < 0.01,
        "{setpoint:?}"
    );
    assert!(setpoint.yaw_deg.unwrap().abs() < 0.01);
    // The vehicle moves 100 m north: now straight over it.
    let over = GlobalPositionInt {
        lat: (470_000_000.0 + north * 1e7) as i32,
        ..position
    };
    m.handle_message(
        t(100),
        Address::new(1, 1),
        &MavMessage::GlobalPositionInt(over),
    );
    let [ManagerEvent::Setpoint { setpoint, .. }] = events(&mut m)[..] else {
        panic!()
    };
    // Straight down is beyond nothing: its pitch limit is -90.
    assert!(
        (setpoint.pitch_deg.unwrap() + 90.0).abs() < 0.1,
        "{setpoint:?}"
    );
    // A location above home, in COMMAND_LONG, as ArduPilot reads it.
    let long = Command::Long(CommandLong {
        command: MavCmd::DO_SET_ROI_LOCATION,
        param5: 47.0,
        param6: 8.0,
        param7: 0.0,
        ..Default::default()
    });
    assert_eq!(send(&mut m, GCS, long), MavResult::ACCEPTED);
    assert_eq!(m.roi(), Some((47.0, 8.0, 400.0)));
    events(&mut m);
    assert_eq!(send(&mut m, GCS, g.clear_roi()), MavResult::ACCEPTED);
    assert_eq!(
        events(&mut m),
        [
            ManagerEvent::Roi(None),
            ManagerEvent::Setpoint {
                setpoint: Setpoint::NEUTRAL,
                from: GCS
            }
        ]
    );
}

#[test]
fn streamed_attitude_and_other_commands() {
    let mut m = manager();
    let q = quaternion_from_euler(0.0, -40.0, 10.0);
    let msg = MavMessage::GimbalManagerSetAttitude(GimbalManagerSetAttitude {
        target_system: 1,
        target_component: 154,
        q,
        angular_velocity_x: f32::NAN,
        angular_velocity_y: f32::NAN,
        angular_velocity_z: f32::NAN,
        ..Default::default()
    });
    assert!(m.handle_message(t(5), GCS, &msg));
    let [ManagerEvent::Setpoint { setpoint, .. }] = events(&mut m)[..] else {
        panic!()
    };
    assert!((setpoint.pitch_deg.unwrap() + 40.0).abs() < 1e-3);
    // A component of its own answers what it does not know.
    let arm = Command::long(MavCmd::COMPONENT_ARM_DISARM, [1.0, 0., 0., 0., 0., 0., 0.]);
    assert_eq!(send(&mut m, GCS, arm), MavResult::UNSUPPORTED);
    // Inside an autopilot, other commands are the autopilot's.
    let mut embedded = GimbalManager::new(t(0), ManagerConfig::new(Address::new(1, 1), 1));
    let arm = MavMessage::CommandLong(CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::COMPONENT_ARM_DISARM,
        ..Default::default()
    });
    assert!(!embedded.handle_message(t(5), GCS, &arm));
}
