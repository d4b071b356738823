//! Flying the simulated vehicle as ArduPilot and PX4 fly (seen on their SITL): PX4's OFFBOARD
//! (refused without setpoints, setpoints followed, left 1 s after the last one), ArduPilot's
//! GUIDED targets (local and global positions, velocities for 3 s, attitude), PX4's
//! MAV_CMD_DO_REPOSITION, sticks in position modes, LOCAL_POSITION_NED and
//! EXTENDED_SYS_STATE, and SETUP_SIGNING refused while armed (ArduPilot).

mod common;

use core::time::Duration;

use common::{M_PER_DEG, Sim, command_int};
use mavstack_core::{Message as _, MessageSet as _};
use mavstack_dialects::common::{
    AttitudeTargetTypemask, CurrentMode, ExtendedSysState, LocalPositionNed, MavCmd, MavDataStream,
    MavFrame, MavLandedState, MavMessage, MavResult, MavVtolState, PositionTargetTypemask,
    RequestDataStream, SetAttitudeTarget, SetPositionTargetGlobalInt, SetPositionTargetLocalNed,
};
use mavstack_sim::Autopilot;
use mavstack_sim::flight::{HOME, HOME_AMSL};

const SECOND: Duration = Duration::from_secs(1);

fn secs(s: f32) -> Duration {
    Duration::from_secs_f32(s)
}

/// SET_POSITION_TARGET_LOCAL_NED: a velocity (`position` false) or a position in `frame`.
fn local(frame: MavFrame, position: bool, v: [f32; 3], yaw_rate: Option<f32>) -> MavMessage {
    use PositionTargetTypemask as T;
    let accel = T::AX_IGNORE | T::AY_IGNORE | T::AZ_IGNORE;
    let mut mask = if position {
        T::VX_IGNORE | T::VY_IGNORE | T::VZ_IGNORE | accel
    } else {
        T::X_IGNORE | T::Y_IGNORE | T::Z_IGNORE | accel
    };
    mask |= T::YAW_IGNORE;
    if yaw_rate.is_none() {
        mask |= T::YAW_RATE_IGNORE;
    }
    let (xyz, vel) = if position {
        (v, [0.0; 3])
    } else {
        ([0.0; 3], v)
    };
    MavMessage::SetPositionTargetLocalNed(SetPositionTargetLocalNed {
        target_system: 1,
        target_component: 1,
        coordinate_frame: frame,
        type_mask: mask,
        x: xyz[0],
        y: xyz[1],
        z: xyz[2],
        vx: vel[0],
        vy: vel[1],
        vz: vel[2],
        yaw_rate: yaw_rate.unwrap_or(0.0),
        ..SetPositionTargetLocalNed::default()
    })
}

fn velocity(ned: [f32; 3]) -> MavMessage {
    local(MavFrame::LOCAL_NED, false, ned, None)
}

fn global(frame: MavFrame, north_m: f64, alt: f32) -> MavMessage {
    use PositionTargetTypemask as T;
    MavMessage::SetPositionTargetGlobalInt(SetPositionTargetGlobalInt {
        target_system: 1,
        target_component: 1,
        coordinate_frame: frame,
        type_mask: T::VX_IGNORE
            | T::VY_IGNORE
            | T::VZ_IGNORE
            | T::AX_IGNORE
            | T::AY_IGNORE
            | T::AZ_IGNORE
            | T::YAW_IGNORE
            | T::YAW_RATE_IGNORE,
        lat_int: ((HOME.lat + north_m / M_PER_DEG) * 1e7) as i32,
        lon_int: (HOME.lon * 1e7) as i32,
        alt,
        ..SetPositionTargetGlobalInt::default()
    })
}

/// SET_ATTITUDE_TARGET: pitch (degrees, nose down negative), heading north, `thrust`.
fn attitude(pitch_deg: f32, thrust: f32) -> MavMessage {
    let half = pitch_deg.to_radians() / 2.0;
    MavMessage::SetAttitudeTarget(SetAttitudeTarget {
        target_system: 1,
        target_component: 1,
        type_mask: AttitudeTargetTypemask::BODY_ROLL_RATE_IGNORE
            | AttitudeTargetTypemask::BODY_PITCH_RATE_IGNORE
            | AttitudeTargetTypemask::BODY_YAW_RATE_IGNORE,
        q: [half.cos(), 0.0, half.sin(), 0.0],
        thrust,
        ..SetAttitudeTarget::default()
    })
}

const HOLD: u32 = 0x0304_0000;
const OFFBOARD: u32 = 0x6_0000;
const POSCTL: u32 = 0x3_0000;

#[test]
fn px4_refuses_offboard_without_setpoints_and_follows_them_once_in() {
    let mut sim = Sim::new(Autopilot::Px4);
    sim.take_off(Autopilot::Px4, 10.0);
    // Setpoints older than COM_OF_LOSS_T (1 s) do not count.
    sim.send(velocity([0.0; 3]));
    sim.run(secs(1.2));
    let mark = sim.mark();
    let acked = sim.set_mode(Autopilot::Px4, OFFBOARD);
    assert_eq!(
        acked,
        [MavResult::ACCEPTED, MavResult::TEMPORARILY_REJECTED]
    );
    assert_eq!(
        sim.texts(mark),
        [(
            2,
            "Switching to Offboard is currently not available".to_owned()
        )]
    );
    assert_eq!(sim.mode(), HOLD);

    // Streamed, they let it in; 3 m/s north for 5 s.
    let start = sim.local();
    sim.run_with(secs(0.5), secs(0.05), |s| s.send(velocity([0.0; 3])));
    assert_eq!(
        sim.set_mode(Autopilot::Px4, OFFBOARD),
        [MavResult::ACCEPTED, MavResult::ACCEPTED]
    );
    sim.run_with(secs(5.0), secs(0.05), |s| s.send(velocity([3.0, 0.0, 0.0])));
    let moved = sim.local()[0] - start[0];
    assert!((14.0..=16.0).contains(&moved), "{moved} m north");
    // A position 10 m east, held.
    let [n, e, d] = sim.local();
    sim.run_with(secs(6.0), secs(0.05), |s| {
        s.send(local(MavFrame::LOCAL_NED, true, [n, e + 10.0, d], None));
    });
    let [n2, e2, d2] = sim.local();
    assert!((n2 - n).abs() < 0.5 && (e2 - e - 10.0).abs() < 0.5 && (d2 - d).abs() < 0.5);
    // Body frame: forward is north while the craft faces north.
    sim.run_with(secs(2.0), secs(0.05), |s| {
        s.send(local(MavFrame::BODY_NED, false, [2.0, 0.0, 0.0], None));
    });
    let [n3, e3, _] = sim.local();
    assert!(
        (n3 - n2 - 4.0).abs() < 0.5 && (e3 - e2).abs() < 0.5,
        "{n3} {e3}"
    );
    // Attitude: nose down flies forward, thrust above 0.5 climbs.
    sim.run_with(secs(3.0), secs(0.05), |s| s.send(attitude(-10.0, 0.75)));
    let [n4, _, d4] = sim.local();
    assert!(n4 - n3 > 2.0, "{n4} {n3}");
    assert!(d4 < d2 - 1.0, "climbed: {d4} against {d2}");
    assert_eq!(sim.mode(), OFFBOARD);
}

#[test]
fn px4_leaves_offboard_for_position_a_second_after_the_last_setpoint_and_sinks() {
    let mut sim = Sim::new(Autopilot::Px4);
    sim.take_off(Autopilot::Px4, 10.0);
    sim.run_with(secs(0.5), secs(0.05), |s| s.send(velocity([0.0; 3])));
    sim.set_mode(Autopilot::Px4, OFFBOARD);
    sim.run_with(secs(2.0), secs(0.05), |s| s.send(velocity([0.0; 3])));
    let mark = sim.mark();
    sim.run(secs(0.8));
    assert!(sim.texts(mark).is_empty(), "still within COM_OF_LOSS_T");
    sim.run(secs(0.4));
    assert_eq!(sim.texts(mark), [(2, "Failsafe activated".to_owned())]);
    assert_eq!(sim.mode(), POSCTL);
    let MavMessage::CurrentMode(current) = sim.now_message(CurrentMode::ID) else {
        panic!("CURRENT_MODE");
    };
    assert_eq!(
        (current.custom_mode, current.intended_custom_mode),
        (POSCTL, OFFBOARD)
    );
    // Without manual control it sinks, lands and disarms, then is in OFFBOARD again.
    let [_, _, before] = sim.local();
    sim.run(secs(5.0));
    let [_, _, after] = sim.local();
    assert!(after - before > 2.0, "sank from {before} to {after}");
    sim.run(secs(20.0));
    assert!(!sim.armed());
    assert_eq!(sim.mode(), OFFBOARD);
}

#[test]
fn px4_repositions_in_hold_by_command_int_and_long() {
    let mut sim = Sim::new(Autopilot::Px4);
    // Disarmed: Hold, nothing to fly.
    let lat = ((HOME.lat + 30.0 / M_PER_DEG) * 1e7) as i32;
    let lon = (HOME.lon * 1e7) as i32;
    let amsl = HOME_AMSL + 10.0;
    let repo = |p2: f32, z: f32| {
        command_int(
            MavCmd::DO_REPOSITION,
            MavFrame::GLOBAL,
            [-1.0, p2, 0.0, f32::NAN],
            lat,
            lon,
            z,
        )
    };
    assert_eq!(sim.command_int(repo(1.0, amsl)), [MavResult::ACCEPTED]);
    assert_eq!(sim.mode(), HOLD);
    sim.run(secs(5.0));
    assert!(sim.local()[0].abs() < 0.1, "disarmed, it does not move");
    sim.take_off(Autopilot::Px4, 5.0);
    assert_eq!(sim.command_int(repo(1.0, amsl)), [MavResult::ACCEPTED]);
    sim.run(secs(12.0));
    let [n, e, d] = sim.local();
    assert!((n - 30.0).abs() < 1.0 && e.abs() < 1.0 && (d + 10.0).abs() < 0.5);
    assert_eq!(sim.mode(), HOLD);
    // The COMMAND_LONG form, back home; without the change-mode flag UNSUPPORTED.
    let nan = f32::NAN;
    let back = [-1.0, 1.0, 0.0, nan, HOME.lat as f32, HOME.lon as f32, amsl];
    assert_eq!(
        sim.command(MavCmd::DO_REPOSITION, back),
        [MavResult::ACCEPTED]
    );
    sim.run(secs(12.0));
    assert!(sim.local()[0].abs() < 1.5);
    assert_eq!(sim.command_int(repo(0.0, amsl)), [MavResult::UNSUPPORTED]);
}

#[test]
fn ardupilot_follows_guided_targets_and_stops_velocity_after_its_timeout() {
    let mut sim = Sim::new(Autopilot::Ardupilot);
    // Not in GUIDED: NAV_TAKEOFF fails, targets are ignored.
    sim.command(MavCmd::COMPONENT_ARM_DISARM, [1., 0., 0., 0., 0., 0., 0.]);
    let nan = f32::NAN;
    assert_eq!(
        sim.command(MavCmd::NAV_TAKEOFF, [0., 0., 0., nan, nan, nan, 10.0]),
        [MavResult::FAILED]
    );
    sim.send(velocity([0.0, 0.0, -2.0]));
    sim.run(secs(2.0));
    assert!(sim.local()[2].abs() < 0.1);
    sim.command(MavCmd::COMPONENT_ARM_DISARM, [0., 0., 0., 0., 0., 0., 0.]);
    sim.take_off(Autopilot::Ardupilot, 10.0);
    // One velocity target: followed for 3 s (GUID_TIMEOUT), then it stops.
    let start = sim.local();
    sim.send(velocity([3.0, 0.0, 0.0]));
    sim.run(secs(6.0));
    let [n, _, _] = sim.local();
    assert!((n - start[0] - 9.0).abs() < 0.5, "{} m", n - start[0]);
    // A local position, held without being sent again.
    sim.send(local(MavFrame::LOCAL_NED, true, [n, 10.0, -10.0], None));
    sim.run(secs(8.0));
    let [n2, e2, _] = sim.local();
    assert!((n2 - n).abs() < 0.5 && (e2 - 10.0).abs() < 0.5);
    // Global positions: above home, and above mean sea level.
    sim.send(global(MavFrame::GLOBAL_RELATIVE_ALT_INT, 20.0, 15.0));
    sim.run(secs(10.0));
    let p = sim.global();
    let north = (f64::from(p.lat) / 1e7 - HOME.lat) * M_PER_DEG;
    assert!((north - 20.0).abs() < 1.0 && (p.relative_alt - 15_000).abs() < 300);
    sim.send(global(MavFrame::GLOBAL_INT, 0.0, HOME_AMSL + 12.0));
    sim.run(secs(10.0));
    let p = sim.global();
    let north = (f64::from(p.lat) / 1e7 - HOME.lat) * M_PER_DEG;
    assert!(north.abs() < 1.0 && (p.relative_alt - 12_000).abs() < 300);
    // An attitude target: tilted forward for 3 s, then level again and stopped.
    let [n, _, d] = sim.local();
    sim.send(attitude(-10.0, 0.5));
    sim.run(secs(3.0));
    let [n2, _, d2] = sim.local();
    assert!(
        n2 - n > 2.0 && (d2 - d).abs() < 0.3,
        "{n} → {n2}, {d} → {d2}"
    );
    sim.run(secs(3.0));
    let [n3, ..] = sim.local();
    sim.run(secs(3.0));
    assert!(
        (sim.local()[0] - n3).abs() < 0.1,
        "stopped after the timeout"
    );
}

#[test]
fn sticks_fly_position_modes_and_px4_holds_then_returns_when_they_stop() {
    for (autopilot, mode) in [(Autopilot::Ardupilot, 5), (Autopilot::Px4, POSCTL)] {
        let mut sim = Sim::new(autopilot);
        sim.take_off(autopilot, 10.0);
        sim.run_with(secs(0.3), secs(0.05), |s| s.sticks(0, 0, 500, 0));
        let acked = sim.set_mode(autopilot, mode);
        assert_eq!(acked.last(), Some(&MavResult::ACCEPTED), "{autopilot}");
        let start = sim.local();
        sim.run_with(secs(4.0), secs(0.05), |s| s.sticks(1000, 0, 500, 0));
        let moved = sim.local()[0] - start[0];
        assert!(moved > 20.0, "{autopilot}: {moved} m forward");
        // Centred sticks hold; the throttle's middle keeps the height.
        sim.run_with(secs(1.0), secs(0.05), |s| s.sticks(0, 0, 500, 0));
        let here = sim.local();
        sim.run_with(secs(3.0), secs(0.05), |s| s.sticks(0, 0, 500, 0));
        let there = sim.local();
        assert!(
            (0..3).all(|i| (there[i] - here[i]).abs() < 0.1),
            "{autopilot}: {here:?} {there:?}"
        );
        // Full throttle climbs, right stick goes east.
        sim.run_with(secs(2.0), secs(0.05), |s| s.sticks(0, 1000, 1000, 0));
        let up = sim.local();
        assert!(up[2] < there[2] - 3.0 && up[1] > there[1] + 10.0, "{up:?}");
        let mark = sim.mark();
        sim.run(secs(2.0));
        match autopilot {
            // ArduPilot: back to SITL's own (centred) sticks; LOITER holds.
            Autopilot::Ardupilot => {
                sim.run(secs(3.0));
                assert_eq!(sim.mode(), 5);
            }
            Autopilot::Px4 => {
                assert_eq!(
                    sim.texts(mark),
                    [(
                        2,
                        "Failsafe activated: entering Hold for 5 seconds".to_owned()
                    )]
                );
                assert_eq!(sim.mode(), HOLD);
                sim.run(secs(5.0));
                assert_eq!(sim.mode(), 0x0504_0000, "Return after the Hold");
            }
        }
    }
}

#[test]
fn local_position_and_landed_state_as_each_stack_sends_them() {
    let mut px4 = Sim::new(Autopilot::Px4);
    let mark = px4.mark();
    px4.run(Duration::from_secs(3));
    let sent = px4.since(mark);
    let count = |id: u32| sent.iter().filter(|m| m.id() == id).count();
    assert!(count(LocalPositionNed::ID) >= 10 && count(ExtendedSysState::ID) >= 2);
    px4.take_off(Autopilot::Px4, 10.0);
    let ext = px4
        .sent
        .iter()
        .rev()
        .find_map(|(_, o)| match &o.message {
            MavMessage::ExtendedSysState(e) => Some(*e),
            _ => None,
        })
        .expect("EXTENDED_SYS_STATE");
    assert_eq!(
        (ext.vtol_state, ext.landed_state),
        (MavVtolState::UNDEFINED, MavLandedState::IN_AIR)
    );

    // ArduPilot on a link with no stream rates: LOCAL_POSITION_NED in the POSITION group,
    // EXTENDED_SYS_STATE in no group (on request only).
    let mut config = common::config(Autopilot::Ardupilot);
    config.streams_on_request = true;
    let mut ap = Sim::with(config);
    let rates = |group: MavDataStream| {
        MavMessage::RequestDataStream(RequestDataStream {
            target_system: 1,
            target_component: 1,
            req_stream_id: group,
            req_message_rate: 4,
            start_stop: 1,
        })
    };
    ap.send(rates(MavDataStream::POSITION));
    ap.send(rates(MavDataStream::EXTRA3));
    let mark = ap.mark();
    ap.run(Duration::from_secs(3));
    let sent = ap.since(mark);
    let count = |id: u32| sent.iter().filter(|m| m.id() == id).count();
    assert!(count(LocalPositionNed::ID) >= 10);
    assert_eq!(count(ExtendedSysState::ID), 0);
    let mark = ap.mark();
    let acked = ap.command(
        MavCmd::REQUEST_MESSAGE,
        [ExtendedSysState::ID as f32, 0., 0., 0., 0., 0., 0.],
    );
    assert_eq!(acked, [MavResult::ACCEPTED]);
    let ext = ap
        .since(mark)
        .into_iter()
        .find_map(|m| match m {
            MavMessage::ExtendedSysState(e) => Some(e),
            _ => None,
        })
        .expect("on request");
    assert_eq!(
        (ext.vtol_state, ext.landed_state),
        (MavVtolState::MC, MavLandedState::ON_GROUND)
    );
}

#[test]
fn ardupilot_refuses_setup_signing_while_armed_px4_never_does() {
    let mut ap = Sim::new(Autopilot::Ardupilot);
    assert!(!ap.vehicle.refuses_setup_signing());
    ap.command(MavCmd::COMPONENT_ARM_DISARM, [1., 0., 0., 0., 0., 0., 0.]);
    assert!(ap.vehicle.refuses_setup_signing());
    let mark = ap.mark();
    ap.vehicle.setup_signing_refused();
    while let Some(o) = ap.vehicle.poll_transmit() {
        ap.sent.push((ap.now, o));
    }
    assert_eq!(
        ap.texts(mark),
        [(4, "ERROR: Won't setup signing when armed".to_owned())]
    );
    ap.command(MavCmd::COMPONENT_ARM_DISARM, [0., 0., 0., 0., 0., 0., 0.]);
    assert!(!ap.vehicle.refuses_setup_signing());

    let mut px4 = Sim::new(Autopilot::Px4);
    px4.command(MavCmd::COMPONENT_ARM_DISARM, [1., 0., 0., 0., 0., 0., 0.]);
    assert!(!px4.vehicle.refuses_setup_signing());
}

#[test]
fn the_yaw_stick_turns_the_craft_and_forward_follows_the_heading() {
    let mut sim = Sim::new(Autopilot::Ardupilot);
    sim.take_off(Autopilot::Ardupilot, 10.0);
    sim.set_mode(Autopilot::Ardupilot, 5);
    // Turn right for about 90° (202.5°/s beyond the dead zone, full stick).
    let quarter = 90.0 / 202.5;
    sim.run_with(secs(quarter), SECOND / 100, |s| s.sticks(0, 0, 500, 1000));
    sim.sticks(0, 0, 500, 0);
    let start = sim.local();
    sim.run_with(secs(2.0), secs(0.05), |s| s.sticks(1000, 0, 500, 0));
    let [n, e, _] = sim.local();
    assert!(e - start[1] > 15.0 && (n - start[0]).abs() < 5.0, "{n} {e}");
}
