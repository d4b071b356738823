//! The standard modes protocol and mode changes as each flight stack answers them (seen on
//! ArduPilot Copter 4.7-dev SITL and PX4 1.16 SITL): AVAILABLE_MODES on request, CURRENT_MODE,
//! MAV_CMD_DO_SET_STANDARD_MODE, MAV_CMD_DO_SET_MODE's answers and reasons.

mod common;

use core::time::Duration;

use common::{Sim, acks};
use mavstack_core::Message as _;
use mavstack_dialects::common::{
    AvailableModes, CurrentMode, MavCmd, MavFrame, MavMessage, MavModeProperty, MavResult,
    MavStandardMode, PositionTargetTypemask, SetPositionTargetLocalNed,
};
use mavstack_sim::Autopilot;

fn listed(messages: &[MavMessage]) -> Vec<AvailableModes> {
    messages
        .iter()
        .filter_map(|m| match m {
            MavMessage::AvailableModes(a) => Some(*a),
            _ => None,
        })
        .collect()
}

fn name(m: &AvailableModes) -> String {
    let end = m.mode_name.iter().position(|&b| b == 0).unwrap_or(35);
    String::from_utf8_lossy(&m.mode_name[..end]).into_owned()
}

fn request(sim: &mut Sim, msg_id: u32, param2: f32) -> (Vec<MavResult>, Vec<MavMessage>) {
    let mark = sim.mark();
    let results = sim.command(
        MavCmd::REQUEST_MESSAGE,
        [msg_id as f32, param2, 0., 0., 0., 0., 0.],
    );
    (results, sim.since(mark))
}

#[test]
fn px4_lists_every_mode_with_standard_modes_and_properties() {
    let mut sim = Sim::new(Autopilot::Px4);
    let (acked, sent) = request(&mut sim, AvailableModes::ID, 0.0);
    assert_eq!(acked, [MavResult::ACCEPTED]);
    let modes = listed(&sent);
    assert_eq!(modes.len(), 25);
    for (i, m) in modes.iter().enumerate() {
        assert_eq!((m.mode_index, m.number_modes), (i as u8 + 1, 25));
    }
    let row = |i: usize| {
        let m = &modes[i];
        (name(m), m.standard_mode, m.custom_mode, m.properties)
    };
    use MavStandardMode as S;
    let adv = MavModeProperty::ADVANCED;
    assert_eq!(row(0), ("Manual".into(), S::NON_STANDARD, 0x1_0000, adv));
    assert_eq!(
        row(1),
        (
            String::new(),
            S::ALTITUDE_HOLD,
            0x2_0000,
            MavModeProperty(0)
        )
    );
    assert_eq!(
        row(2),
        (
            String::new(),
            S::POSITION_HOLD,
            0x3_0000,
            MavModeProperty(0)
        )
    );
    assert_eq!(row(4), ("Hold".into(), S::NON_STANDARD, 0x0304_0000, adv));
    assert_eq!(row(5), (String::new(), S::SAFE_RECOVERY, 0x0504_0000, adv));
    assert_eq!(
        row(8),
        (
            "Termination".into(),
            S::NON_STANDARD,
            0xa_0000,
            MavModeProperty(adv.0 | MavModeProperty::NOT_USER_SELECTABLE.0)
        )
    );
    assert_eq!(row(9), ("Offboard".into(), S::NON_STANDARD, 0x6_0000, adv));
    assert_eq!(row(15), (String::new(), S::ORBIT, 0x0103_0000, adv));
    assert_eq!(
        row(17),
        (
            "(Mode not available)".into(),
            S::NON_STANDARD,
            0x0b04_0000,
            MavModeProperty::NOT_USER_SELECTABLE
        )
    );
    // One by index; beyond the list DENIED.
    let (acked, sent) = request(&mut sim, AvailableModes::ID, 3.0);
    assert_eq!(acked, [MavResult::ACCEPTED]);
    assert_eq!(
        listed(&sent)
            .iter()
            .map(|m| m.mode_index)
            .collect::<Vec<_>>(),
        [3]
    );
    let (acked, sent) = request(&mut sim, AvailableModes::ID, 26.0);
    assert_eq!((acked, listed(&sent).len()), (vec![MavResult::DENIED], 0));
}

#[test]
fn ardupilot_lists_its_modes_as_non_standard_and_sends_only_the_first_of_all() {
    let mut sim = Sim::new(Autopilot::Ardupilot);
    let (acked, sent) = request(&mut sim, AvailableModes::ID, 0.0);
    assert_eq!(acked, [MavResult::ACCEPTED]);
    let first = listed(&sent);
    assert_eq!(first.len(), 1, "ArduPilot 4.7 sends the first only");
    assert_eq!((first[0].mode_index, first[0].number_modes), (1, 24));
    assert_eq!(
        (name(&first[0]).as_str(), first[0].custom_mode),
        ("AUTO RTL", 27)
    );
    // Each by index.
    let mut all = Vec::new();
    for i in 1..=24 {
        let (acked, sent) = request(&mut sim, AvailableModes::ID, i as f32);
        assert_eq!(acked, [MavResult::ACCEPTED]);
        all.extend(listed(&sent));
    }
    assert_eq!(all.len(), 24);
    assert!(
        all.iter()
            .all(|m| m.standard_mode == MavStandardMode::NON_STANDARD && m.properties.0 == 0)
    );
    let names: Vec<(String, u32)> = all.iter().map(|m| (name(m), m.custom_mode)).collect();
    assert!(names.contains(&("LOITER".into(), 5)));
    assert!(names.contains(&("SMARTRTL".into(), 21)));
    assert_eq!(names[23], ("TURTLE".into(), 28));
    // Beyond the list: ACCEPTED and nothing.
    let (acked, sent) = request(&mut sim, AvailableModes::ID, 30.0);
    assert_eq!((acked, listed(&sent).len()), (vec![MavResult::ACCEPTED], 0));
    // AVAILABLE_MODES_MONITOR every 5 s from the first request on.
    let mark = sim.mark();
    sim.run(Duration::from_secs(11));
    let monitors = sim
        .since(mark)
        .iter()
        .filter(|m| matches!(m, MavMessage::AvailableModesMonitor(_)))
        .count();
    assert_eq!(monitors, 2);
}

fn current_modes(messages: &[MavMessage]) -> Vec<CurrentMode> {
    messages
        .iter()
        .filter_map(|m| match m {
            MavMessage::CurrentMode(c) => Some(*c),
            _ => None,
        })
        .collect()
}

#[test]
fn px4_streams_current_mode_and_answers_a_request_ardupilot_has_none() {
    let mut px4 = Sim::new(Autopilot::Px4);
    let mark = px4.mark();
    px4.run(Duration::from_secs(10));
    let streamed = current_modes(&px4.since(mark));
    assert!((4..=6).contains(&streamed.len()), "{}", streamed.len());
    assert!(streamed.iter().all(|c| c.custom_mode == 0x0304_0000
        && c.intended_custom_mode == 0x0304_0000
        && c.standard_mode == MavStandardMode::NON_STANDARD));
    let (acked, sent) = request(&mut px4, CurrentMode::ID, 0.0);
    assert_eq!(acked, [MavResult::ACCEPTED]);
    assert_eq!(current_modes(&sent).len(), 1);

    let mut ap = Sim::new(Autopilot::Ardupilot);
    let mark = ap.mark();
    ap.run(Duration::from_secs(5));
    assert!(current_modes(&ap.since(mark)).is_empty());
    let (acked, sent) = request(&mut ap, CurrentMode::ID, 0.0);
    assert_eq!(
        (acked, current_modes(&sent).len()),
        (vec![MavResult::FAILED], 0)
    );
}

#[test]
fn px4_sets_standard_modes_ardupilot_does_not_know_the_command() {
    let mut px4 = Sim::new(Autopilot::Px4);
    use MavStandardMode as S;
    for (standard, custom) in [
        (S::POSITION_HOLD, 0x3_0000),
        (S::ORBIT, 0x0103_0000),
        (S::ALTITUDE_HOLD, 0x2_0000),
        (S::SAFE_RECOVERY, 0x0504_0000),
        (S::MISSION, 0x0404_0000),
        (S::LAND, 0x0604_0000),
        (S::TAKEOFF, 0x0204_0000),
    ] {
        let acked = px4.command(
            MavCmd::DO_SET_STANDARD_MODE,
            [f32::from(standard.0), 0., 0., 0., 0., 0., 0.],
        );
        assert_eq!(acked, [MavResult::ACCEPTED], "{standard:?}");
        assert_eq!(px4.mode(), custom, "{standard:?}");
    }
    for refused in [S::CRUISE.0, 0, 99] {
        let acked = px4.command(
            MavCmd::DO_SET_STANDARD_MODE,
            [f32::from(refused), 0., 0., 0., 0., 0., 0.],
        );
        assert_eq!(acked, [MavResult::FAILED], "{refused}");
    }
    let mut ap = Sim::new(Autopilot::Ardupilot);
    let acked = ap.command(MavCmd::DO_SET_STANDARD_MODE, [1., 0., 0., 0., 0., 0., 0.]);
    assert_eq!(acked, [MavResult::UNSUPPORTED]);
    assert_eq!(ap.mode(), 0);
}

#[test]
fn ardupilot_refuses_modes_that_fail_to_start_with_its_reasons() {
    let mut sim = Sim::new(Autopilot::Ardupilot);
    let mark = sim.mark();
    assert_eq!(sim.set_mode(Autopilot::Ardupilot, 27), [MavResult::FAILED]);
    assert_eq!(
        sim.texts(mark),
        [
            (4, "Unable to start landing sequence".to_owned()),
            (
                4,
                "Mode change to AUTO RTL failed: No return path or landing sequence found"
                    .to_owned()
            ),
        ]
    );
    let mark = sim.mark();
    assert_eq!(sim.set_mode(Autopilot::Ardupilot, 8), [MavResult::FAILED]);
    assert_eq!(sim.texts(mark), [(4, "No such mode 8".to_owned())]);
    for number in [3, 1, 2, 5, 7, 9, 6, 11, 16, 17, 18, 19, 20, 21, 24, 4] {
        assert_eq!(
            sim.set_mode(Autopilot::Ardupilot, number),
            [MavResult::ACCEPTED]
        );
        assert_eq!(sim.mode(), number);
    }
}

#[test]
fn px4_answers_do_set_mode_twice_and_says_why_it_refuses() {
    let mut sim = Sim::new(Autopilot::Px4);
    // Disarmed, every mode it has is taken (also OFFBOARD without setpoints).
    assert_eq!(
        sim.set_mode(Autopilot::Px4, 0x6_0000),
        [MavResult::ACCEPTED, MavResult::ACCEPTED]
    );
    assert_eq!(sim.mode(), 0x6_0000);
    // VTOL Takeoff is not a sub mode DO_SET_MODE takes.
    let mark = sim.mark();
    assert_eq!(
        sim.set_mode(Autopilot::Px4, 0x0a04_0000),
        [MavResult::ACCEPTED, MavResult::TEMPORARILY_REJECTED]
    );
    assert_eq!(sim.texts(mark), [(2, "Unsupported auto mode".to_owned())]);
    sim.take_off(Autopilot::Px4, 10.0);
    assert_eq!(sim.mode(), 0x0304_0000, "Hold after the take-off");
    // Armed: OFFBOARD wants setpoints, Position wants manual control, Mission a mission.
    for (custom, said) in [
        (0x6_0000, "Switching to Offboard is currently not available"),
        (0x3_0000, "Switching to Position is currently not available"),
        (
            0x0404_0000,
            "Switching to Mission is currently not available",
        ),
    ] {
        let mark = sim.mark();
        let acked = sim.set_mode(Autopilot::Px4, custom);
        assert_eq!(
            acked,
            [MavResult::ACCEPTED, MavResult::TEMPORARILY_REJECTED]
        );
        assert_eq!(sim.texts(mark), [(2, said.to_owned())]);
        assert_eq!(sim.mode(), 0x0304_0000);
    }
    let acked = sim.command(MavCmd::DO_SET_STANDARD_MODE, [1., 0., 0., 0., 0., 0., 0.]);
    assert_eq!(acked, [MavResult::TEMPORARILY_REJECTED]);
    // A setpoint within the last second lets it in.
    sim.send(velocity_setpoint([0.0; 3]));
    sim.run(Duration::from_millis(600));
    let mark = sim.mark();
    sim.send(velocity_setpoint([0.0; 3]));
    let acked = sim.set_mode(Autopilot::Px4, 0x6_0000);
    assert_eq!(acked, [MavResult::ACCEPTED, MavResult::ACCEPTED]);
    assert_eq!(acks(&sim.since(mark), MavCmd::DO_SET_MODE).len(), 2);
}

fn velocity_setpoint(ned: [f32; 3]) -> MavMessage {
    use PositionTargetTypemask as T;
    MavMessage::SetPositionTargetLocalNed(SetPositionTargetLocalNed {
        target_system: 1,
        target_component: 1,
        coordinate_frame: MavFrame::LOCAL_NED,
        type_mask: T::X_IGNORE
            | T::Y_IGNORE
            | T::Z_IGNORE
            | T::AX_IGNORE
            | T::AY_IGNORE
            | T::AZ_IGNORE
            | T::YAW_IGNORE
            | T::YAW_RATE_IGNORE,
        vx: ned[0],
        vy: ned[1],
        vz: ned[2],
        ..SetPositionTargetLocalNed::default()
    })
}
