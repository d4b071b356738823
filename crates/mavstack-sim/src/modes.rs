//! Flight modes as ArduPilot (Copter) and PX4 number them, and what the simulation does in
//! each.
//!
//! ArduPilot puts the mode number in HEARTBEAT's `custom_mode`; PX4 packs a main mode in
//! bits 16–23 and a sub mode (of AUTO) in bits 24–31. MAV_CMD_DO_SET_MODE carries the
//! ArduPilot number or the PX4 main mode in param2 and the PX4 sub mode in param3.

use crate::Autopilot;

/// What the simulated vehicle does in a mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Behaviour {
    /// Pilot-controlled modes: with no sticks, hold altitude and position.
    Manual,
    /// Hold position (LOITER, POSHOLD, PX4 HOLD).
    Hold,
    /// Fly to the guided target, if any, and hold there.
    Guided,
    /// Run the stored mission.
    Mission,
    /// Climb to the return altitude, fly home and land.
    ReturnToLaunch,
    /// Descend and land where we are.
    Land,
    /// Climb to the take-off altitude, then hold (PX4 AUTO.TAKEOFF).
    Takeoff,
}

/// One mode of a flavour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mode {
    /// Its name as ground stations print it.
    pub name: &'static str,
    /// Its HEARTBEAT `custom_mode`.
    pub custom_mode: u32,
    /// What the simulation does in it.
    pub behaviour: Behaviour,
}

const fn ardu(name: &'static str, number: u32, behaviour: Behaviour) -> Mode {
    Mode {
        name,
        custom_mode: number,
        behaviour,
    }
}

const fn px4(name: &'static str, main: u32, sub: u32, behaviour: Behaviour) -> Mode {
    Mode {
        name,
        custom_mode: (main << 16) | (sub << 24),
        behaviour,
    }
}

const ARDUPILOT: &[Mode] = &[
    ardu("STABILIZE", 0, Behaviour::Manual),
    ardu("ACRO", 1, Behaviour::Manual),
    ardu("ALT_HOLD", 2, Behaviour::Manual),
    ardu("AUTO", 3, Behaviour::Mission),
    ardu("GUIDED", 4, Behaviour::Guided),
    ardu("LOITER", 5, Behaviour::Hold),
    ardu("RTL", 6, Behaviour::ReturnToLaunch),
    ardu("CIRCLE", 7, Behaviour::Hold),
    ardu("LAND", 9, Behaviour::Land),
    ardu("POSHOLD", 16, Behaviour::Hold),
    ardu("BRAKE", 17, Behaviour::Hold),
    ardu("SMART_RTL", 21, Behaviour::ReturnToLaunch),
];

const PX4: &[Mode] = &[
    px4("MANUAL", 1, 0, Behaviour::Manual),
    px4("ALTCTL", 2, 0, Behaviour::Manual),
    // AUTO.LOITER ("Hold") first: the mode PX4 holds position in after take-off.
    px4("AUTO.LOITER", 4, 3, Behaviour::Hold),
    px4("POSCTL", 3, 0, Behaviour::Hold),
    px4("AUTO.READY", 4, 1, Behaviour::Hold),
    px4("AUTO.TAKEOFF", 4, 2, Behaviour::Takeoff),
    px4("AUTO.MISSION", 4, 4, Behaviour::Mission),
    px4("AUTO.RTL", 4, 5, Behaviour::ReturnToLaunch),
    px4("AUTO.LAND", 4, 6, Behaviour::Land),
    px4("ACRO", 5, 0, Behaviour::Manual),
    px4("OFFBOARD", 6, 0, Behaviour::Guided),
    px4("STABILIZED", 7, 0, Behaviour::Manual),
];

/// The modes of a flavour, the mode it boots in first.
pub fn modes(autopilot: Autopilot) -> &'static [Mode] {
    match autopilot {
        Autopilot::Ardupilot => ARDUPILOT,
        Autopilot::Px4 => PX4,
    }
}

/// The mode with this `custom_mode`.
pub fn by_custom_mode(autopilot: Autopilot, custom_mode: u32) -> Option<Mode> {
    modes(autopilot)
        .iter()
        .copied()
        .find(|m| m.custom_mode == custom_mode)
}

/// The mode with this name (case-insensitive; PX4 names also without the `AUTO.` prefix).
pub fn by_name(autopilot: Autopilot, name: &str) -> Option<Mode> {
    modes(autopilot).iter().copied().find(|m| {
        m.name.eq_ignore_ascii_case(name)
            || m.name
                .strip_prefix("AUTO.")
                .is_some_and(|short| short.eq_ignore_ascii_case(name))
    })
}

/// The first mode of a flavour with `behaviour`.
pub fn with_behaviour(autopilot: Autopilot, behaviour: Behaviour) -> Mode {
    modes(autopilot)
        .iter()
        .copied()
        .find(|m| m.behaviour == behaviour)
        .unwrap_or(modes(autopilot)[0])
}

/// The `custom_mode` MAV_CMD_DO_SET_MODE's param2 (and PX4's param3) stand for.
pub fn custom_mode_of_command(autopilot: Autopilot, param2: f32, param3: f32) -> u32 {
    let whole = |p: f32| {
        if p.is_finite() && p >= 0.0 {
            p as u32
        } else {
            0
        }
    };
    match autopilot {
        Autopilot::Ardupilot => whole(param2),
        Autopilot::Px4 => ((whole(param2) & 0xff) << 16) | ((whole(param3) & 0xff) << 24),
    }
}

/// MAV_CMD_DO_SET_MODE's param2 and param3 for a mode (the inverse of
/// [`custom_mode_of_command`]).
pub fn command_params(autopilot: Autopilot, mode: Mode) -> (f32, f32) {
    match autopilot {
        Autopilot::Ardupilot => (mode.custom_mode as f32, 0.0),
        Autopilot::Px4 => (
            ((mode.custom_mode >> 16) & 0xff) as f32,
            ((mode.custom_mode >> 24) & 0xff) as f32,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn px4_modes_pack_main_and_sub_mode() {
        let mission = by_name(Autopilot::Px4, "mission").expect("AUTO.MISSION");
        assert_eq!(mission.custom_mode, 0x0404_0000);
        assert_eq!(command_params(Autopilot::Px4, mission), (4.0, 4.0));
        assert_eq!(
            custom_mode_of_command(Autopilot::Px4, 4.0, 4.0),
            mission.custom_mode
        );
    }

    #[test]
    fn ardupilot_modes_are_plain_numbers() {
        let guided = by_name(Autopilot::Ardupilot, "guided").expect("GUIDED");
        assert_eq!(guided.custom_mode, 4);
        assert_eq!(
            by_custom_mode(Autopilot::Ardupilot, 6).map(|m| m.name),
            Some("RTL")
        );
        assert_eq!(
            with_behaviour(Autopilot::Ardupilot, Behaviour::Land).name,
            "LAND"
        );
    }
}
