//! Flight modes as ArduPilot (Copter) and PX4 number, list and enter them, and what the
//! simulation does in each.
//!
//! ArduPilot puts the mode number in HEARTBEAT's `custom_mode`; PX4 packs a main mode in
//! bits 16–23 and a sub mode (of AUTO or POSCTL) in bits 24–31. MAV_CMD_DO_SET_MODE carries
//! the ArduPilot number or the PX4 main mode in param2 and the PX4 sub mode in param3.
//!
//! Each flavour's table is its AVAILABLE_MODES list, in the order and with the names,
//! standard modes and properties the flight stack sends (seen on ArduPilot Copter 4.7-dev
//! SITL, 90700977, and PX4 1.16 SITL with SIH):
//!
//! - ArduPilot lists 24 modes, each with its name and standard mode 0 (NON_STANDARD) and no
//!   property bits, starting with "AUTO RTL" (27) and "AUTO" (3)
//!   (`GCS_MAVLINK_Copter::send_available_mode`).
//! - PX4 lists every valid navigation state in nav-state order: the standard ones (Altitude,
//!   Position, Mission, Return, Takeoff, Land, Orbit) with their standard mode and an empty
//!   name, the others by name; all but Altitude and Position are ADVANCED, Termination and
//!   the eight unregistered external modes ("(Mode not available)") NOT_USER_SELECTABLE
//!   (`src/modules/mavlink/streams/AVAILABLE_MODES.hpp`, `src/lib/modes/ui.hpp`).
//!
//! [`Entry`] says how each answers a request to enter it.

use mavstack_dialects::common::{MavModeProperty, MavStandardMode};

use crate::Autopilot;

/// What the simulated vehicle does in a mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Behaviour {
    /// Pilot-controlled modes (STABILIZE, LOITER, POSHOLD, PX4 POSCTL...): the sticks of
    /// MANUAL_CONTROL set the velocities; with centred sticks (or none), hold altitude and
    /// position.
    Manual,
    /// Hold position by itself (PX4 Hold, ArduPilot BRAKE and CIRCLE), flying first to a
    /// reposition point if one was given; sticks are not read.
    Hold,
    /// Follow the guided target or the setpoints (ArduPilot GUIDED, PX4 OFFBOARD), and hold
    /// when there are none.
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

/// How a mode answers a request to enter it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Entry {
    /// Entered whenever asked.
    Free,
    /// ArduPilot: never entered in the simulation; MAV_RESULT_FAILED and these STATUSTEXT
    /// lines (severity WARNING), as ArduPilot SITL answers on the ground: modes whose
    /// `init()` fails without their hardware or setup (FLIP, AUTOTUNE, FLOWHOLD, FOLLOW,
    /// SYSTEMID, TURTLE) and AUTO RTL without a landing sequence.
    Refused(&'static [&'static str]),
    /// PX4: armed, it needs manual control input (MANUAL_CONTROL within the last 0.5 s).
    NeedsSticks,
    /// PX4: armed, it needs offboard setpoints (one within the last 1 s, COM_OF_LOSS_T).
    NeedsSetpoints,
    /// PX4: armed, it needs a mission.
    NeedsMission,
    /// PX4: armed, never (an external mode nobody registered).
    Disarmed,
}

/// One mode of a flavour.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mode {
    /// Its name as ground stations print it (ArduPilot's own; PX4's `AUTO.LOITER` style).
    pub name: &'static str,
    /// Its HEARTBEAT `custom_mode`.
    pub custom_mode: u32,
    /// What the simulation does in it.
    pub behaviour: Behaviour,
    /// The name AVAILABLE_MODES gives it (PX4: empty for a standard mode).
    pub listed: &'static str,
    /// The standard mode AVAILABLE_MODES and CURRENT_MODE say it is.
    pub standard: MavStandardMode,
    /// AVAILABLE_MODES' property bits.
    pub properties: MavModeProperty,
    /// How it answers a request to enter it.
    pub entry: Entry,
}

const NONE: MavStandardMode = MavStandardMode::NON_STANDARD;

const fn ardu(name: &'static str, number: u32, behaviour: Behaviour, entry: Entry) -> Mode {
    Mode {
        name,
        custom_mode: number,
        behaviour,
        listed: name,
        standard: NONE,
        properties: MavModeProperty(0),
        entry,
    }
}

/// A PX4 mode: its name, main and sub mode, behaviour, AVAILABLE_MODES name (empty for the
/// standard ones), standard mode, property bits (1 ADVANCED, 2 NOT_USER_SELECTABLE), entry.
#[allow(clippy::too_many_arguments)]
const fn px4(
    name: &'static str,
    main: u32,
    sub: u32,
    behaviour: Behaviour,
    listed: &'static str,
    standard: MavStandardMode,
    properties: u32,
    entry: Entry,
) -> Mode {
    Mode {
        name,
        custom_mode: (main << 16) | (sub << 24),
        behaviour,
        listed,
        standard,
        properties: MavModeProperty(properties),
        entry,
    }
}

use Behaviour::{Guided, Hold, Land, Manual, Mission, ReturnToLaunch, Takeoff};
use Entry::{Free, Refused};

const INIT_FAILED_FLIP: &[&str] = &["Mode change to FLIP failed: init failed"];
const INIT_FAILED_AUTOTUNE: &[&str] = &["Mode change to AUTOTUNE failed: init failed"];
const INIT_FAILED_FLOWHOLD: &[&str] = &["Mode change to FLOWHOLD failed: init failed"];
const INIT_FAILED_FOLLOW: &[&str] = &[
    "Set FOLL_ENABLE = 1",
    "Mode change to FOLLOW failed: init failed",
];
const INIT_FAILED_SYSTEMID: &[&str] = &[
    "No axis selected, SID_AXIS = 0",
    "Mode change to SYSTEMID failed: init failed",
];
const INIT_FAILED_TURTLE: &[&str] = &["Mode change to TURTLE failed: init failed"];
const NO_LANDING_SEQUENCE: &[&str] = &[
    "Unable to start landing sequence",
    "Mode change to AUTO RTL failed: No return path or landing sequence found",
];

/// ArduPilot Copter's AVAILABLE_MODES, in its order.
const ARDUPILOT: &[Mode] = &[
    ardu("AUTO RTL", 27, ReturnToLaunch, Refused(NO_LANDING_SEQUENCE)),
    ardu("AUTO", 3, Mission, Free),
    ardu("ACRO", 1, Manual, Free),
    ardu("STABILIZE", 0, Manual, Free),
    ardu("ALT_HOLD", 2, Manual, Free),
    ardu("CIRCLE", 7, Hold, Free),
    ardu("LOITER", 5, Manual, Free),
    ardu("GUIDED", 4, Guided, Free),
    ardu("LAND", 9, Land, Free),
    ardu("RTL", 6, ReturnToLaunch, Free),
    ardu("DRIFT", 11, Manual, Free),
    ardu("FLIP", 14, Manual, Refused(INIT_FAILED_FLIP)),
    ardu("AUTOTUNE", 15, Manual, Refused(INIT_FAILED_AUTOTUNE)),
    ardu("POSHOLD", 16, Manual, Free),
    ardu("BRAKE", 17, Hold, Free),
    ardu("THROW", 18, Hold, Free),
    ardu("AVOID_ADSB", 19, Hold, Free),
    ardu("GUIDED_NOGPS", 20, Guided, Free),
    ardu("SMARTRTL", 21, ReturnToLaunch, Free),
    ardu("FLOWHOLD", 22, Manual, Refused(INIT_FAILED_FLOWHOLD)),
    ardu("FOLLOW", 23, Hold, Refused(INIT_FAILED_FOLLOW)),
    ardu("ZIGZAG", 24, Manual, Free),
    ardu("SYSTEMID", 25, Manual, Refused(INIT_FAILED_SYSTEMID)),
    ardu("TURTLE", 28, Manual, Refused(INIT_FAILED_TURTLE)),
];

const ADV: u32 = 1;
const NOT_SELECTABLE: u32 = 2;

/// PX4's AVAILABLE_MODES (a multicopter), in nav-state order.
const PX4: &[Mode] = {
    use Entry::{Disarmed, NeedsMission, NeedsSetpoints, NeedsSticks};
    use MavStandardMode as S;
    &[
        px4("MANUAL", 1, 0, Manual, "Manual", NONE, ADV, NeedsSticks),
        px4("ALTCTL", 2, 0, Manual, "", S::ALTITUDE_HOLD, 0, NeedsSticks),
        px4("POSCTL", 3, 0, Manual, "", S::POSITION_HOLD, 0, NeedsSticks),
        px4(
            "AUTO.MISSION",
            4,
            4,
            Mission,
            "",
            S::MISSION,
            ADV,
            NeedsMission,
        ),
        px4("AUTO.LOITER", 4, 3, Hold, "Hold", NONE, ADV, Free),
        px4(
            "AUTO.RTL",
            4,
            5,
            ReturnToLaunch,
            "",
            S::SAFE_RECOVERY,
            ADV,
            Free,
        ),
        px4(
            "POSCTL.SLOW",
            3,
            2,
            Manual,
            "Position Slow",
            NONE,
            ADV,
            NeedsSticks,
        ),
        px4("ACRO", 5, 0, Manual, "Acro", NONE, ADV, NeedsSticks),
        px4(
            "TERMINATION",
            10,
            0,
            Land,
            "Termination",
            NONE,
            ADV | NOT_SELECTABLE,
            Free,
        ),
        px4(
            "OFFBOARD",
            6,
            0,
            Guided,
            "Offboard",
            NONE,
            ADV,
            NeedsSetpoints,
        ),
        px4(
            "STABILIZED",
            7,
            0,
            Manual,
            "Stabilized",
            NONE,
            ADV,
            NeedsSticks,
        ),
        px4("AUTO.TAKEOFF", 4, 2, Takeoff, "", S::TAKEOFF, ADV, Free),
        px4("AUTO.LAND", 4, 6, Land, "", S::LAND, ADV, Free),
        px4(
            "AUTO.FOLLOW_TARGET",
            4,
            8,
            Hold,
            "Follow Target",
            NONE,
            ADV,
            Free,
        ),
        px4(
            "AUTO.PRECLAND",
            4,
            9,
            Land,
            "Precision Landing",
            NONE,
            ADV,
            Free,
        ),
        px4("POSCTL.ORBIT", 3, 1, Hold, "", S::ORBIT, ADV, Free),
        px4(
            "AUTO.VTOL_TAKEOFF",
            4,
            10,
            Takeoff,
            "VTOL Takeoff",
            NONE,
            ADV,
            Free,
        ),
        px4(
            "AUTO.EXTERNAL1",
            4,
            11,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL2",
            4,
            12,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL3",
            4,
            13,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL4",
            4,
            14,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL5",
            4,
            15,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL6",
            4,
            16,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL7",
            4,
            17,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
        px4(
            "AUTO.EXTERNAL8",
            4,
            18,
            Hold,
            UNREGISTERED,
            NONE,
            NOT_SELECTABLE,
            Disarmed,
        ),
    ]
};

/// The AVAILABLE_MODES name of PX4's external modes that no external component registered.
const UNREGISTERED: &str = "(Mode not available)";

/// The modes of a flavour, in its AVAILABLE_MODES order.
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

/// Names compare without case, with `_` and spaces alike.
fn same(a: &str, b: &str) -> bool {
    let norm = |c: char| {
        if c == ' ' {
            '_'
        } else {
            c.to_ascii_uppercase()
        }
    };
    a.len() == b.len() && a.chars().map(norm).eq(b.chars().map(norm))
}

/// The mode with this name (case-insensitive, `_` and a space alike; PX4 names also
/// without the `AUTO.` prefix and as AVAILABLE_MODES gives them).
pub fn by_name(autopilot: Autopilot, name: &str) -> Option<Mode> {
    modes(autopilot).iter().copied().find(|m| {
        same(m.name, name)
            || (!m.listed.is_empty() && m.listed != UNREGISTERED && same(m.listed, name))
            || m.name
                .strip_prefix("AUTO.")
                .is_some_and(|short| same(short, name))
    })
}

/// The mode a flavour uses for `behaviour` when it picks one itself (after a take-off, for
/// a LAND or RTL command...).
pub fn with_behaviour(autopilot: Autopilot, behaviour: Behaviour) -> Mode {
    let name = match (autopilot, behaviour) {
        (Autopilot::Ardupilot, Manual) => "STABILIZE",
        (Autopilot::Ardupilot, Hold) => "BRAKE",
        (Autopilot::Ardupilot, Guided | Takeoff) => "GUIDED",
        (Autopilot::Ardupilot, Mission) => "AUTO",
        (Autopilot::Ardupilot, ReturnToLaunch) => "RTL",
        (Autopilot::Ardupilot, Land) => "LAND",
        (Autopilot::Px4, Manual) => "POSCTL",
        (Autopilot::Px4, Hold) => "AUTO.LOITER",
        (Autopilot::Px4, Guided) => "OFFBOARD",
        (Autopilot::Px4, Mission) => "AUTO.MISSION",
        (Autopilot::Px4, ReturnToLaunch) => "AUTO.RTL",
        (Autopilot::Px4, Land) => "AUTO.LAND",
        (Autopilot::Px4, Takeoff) => "AUTO.TAKEOFF",
    };
    by_name(autopilot, name).unwrap_or(modes(autopilot)[0])
}

/// The mode a flavour enters for MAV_CMD_DO_SET_STANDARD_MODE's `standard`: `None` where it
/// has none (ArduPilot has none at all; PX4 on a multicopter none for CRUISE).
pub fn by_standard(autopilot: Autopilot, standard: MavStandardMode) -> Option<Mode> {
    if standard == NONE {
        return None;
    }
    modes(autopilot)
        .iter()
        .copied()
        .find(|m| m.standard == standard)
}

/// What MAV_CMD_DO_SET_MODE asks of PX4 (`Commander::handle_command`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Px4Request {
    /// This mode.
    Mode(Mode),
    /// A sub mode of AUTO PX4 does not take by this command (READY, VTOL_TAKEOFF, unknown):
    /// TEMPORARILY_REJECTED with "Unsupported auto mode".
    UnsupportedAuto,
    /// Nothing (a main mode it does not switch to by this command, TERMINATION among them,
    /// or no custom mode flag): ACCEPTED, and nothing changes.
    Nothing,
}

/// How PX4 reads MAV_CMD_DO_SET_MODE's param1 (base mode), param2 (main mode) and param3
/// (sub mode): POSCTL's sub modes other than SLOW are POSCTL itself (ORBIT is entered by
/// MAV_CMD_DO_SET_STANDARD_MODE or MAV_CMD_DO_ORBIT, not by this command), AUTO without a
/// sub mode is MISSION.
pub fn px4_request(param1: f32, param2: f32, param3: f32) -> Px4Request {
    let whole = |p: f32| {
        if p.is_finite() && p >= 0.0 {
            (p as u32) & 0xff
        } else {
            0
        }
    };
    // MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.
    if whole(param1) & 1 == 0 {
        return Px4Request::Nothing;
    }
    let (main, sub) = (whole(param2), whole(param3));
    let name = match (main, sub) {
        (1, _) => "MANUAL",
        (2, _) => "ALTCTL",
        (3, 2) => "POSCTL.SLOW",
        (3, _) => "POSCTL",
        (4, 0) => "AUTO.MISSION",
        (4, 2..=6 | 8 | 9 | 11..=18) => {
            return by_custom_mode(Autopilot::Px4, (4 << 16) | (sub << 24))
                .map_or(Px4Request::UnsupportedAuto, Px4Request::Mode);
        }
        (4, _) => return Px4Request::UnsupportedAuto,
        (5, _) => "ACRO",
        (6, _) => "OFFBOARD",
        (7, _) => "STABILIZED",
        _ => return Px4Request::Nothing,
    };
    by_name(Autopilot::Px4, name).map_or(Px4Request::Nothing, Px4Request::Mode)
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
        assert_eq!(
            by_name(Autopilot::Px4, "Hold").map(|m| m.name),
            Some("AUTO.LOITER")
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
        assert_eq!(with_behaviour(Autopilot::Ardupilot, Land).name, "LAND");
        assert_eq!(
            by_name(Autopilot::Ardupilot, "auto_rtl").map(|m| m.custom_mode),
            Some(27)
        );
    }

    #[test]
    fn every_flavour_picks_a_mode_of_each_behaviour_that_has_it() {
        for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
            for b in [Manual, Hold, Guided, Mission, ReturnToLaunch, Land] {
                assert_eq!(
                    with_behaviour(autopilot, b).behaviour,
                    b,
                    "{autopilot} {b:?}"
                );
            }
        }
        assert_eq!(with_behaviour(Autopilot::Px4, Takeoff).name, "AUTO.TAKEOFF");
    }

    #[test]
    fn px4_reads_do_set_mode_as_its_commander_does() {
        let name = |p1, p2, p3| match px4_request(p1, p2, p3) {
            Px4Request::Mode(m) => Some(m.name),
            _ => None,
        };
        assert_eq!(name(1.0, 3.0, 1.0), Some("POSCTL"));
        assert_eq!(name(1.0, 3.0, 2.0), Some("POSCTL.SLOW"));
        assert_eq!(name(1.0, 4.0, 0.0), Some("AUTO.MISSION"));
        assert_eq!(name(1.0, 4.0, 11.0), Some("AUTO.EXTERNAL1"));
        assert_eq!(px4_request(1.0, 4.0, 10.0), Px4Request::UnsupportedAuto);
        assert_eq!(px4_request(1.0, 4.0, 1.0), Px4Request::UnsupportedAuto);
        assert_eq!(px4_request(1.0, 10.0, 0.0), Px4Request::Nothing);
        assert_eq!(px4_request(0.0, 6.0, 0.0), Px4Request::Nothing);
    }

    #[test]
    fn custom_modes_are_unique_in_each_table() {
        for autopilot in [Autopilot::Ardupilot, Autopilot::Px4] {
            let table = modes(autopilot);
            for (i, m) in table.iter().enumerate() {
                assert!(
                    table[i + 1..]
                        .iter()
                        .all(|o| o.custom_mode != m.custom_mode),
                    "{}",
                    m.name
                );
            }
        }
        assert_eq!(
            (
                modes(Autopilot::Ardupilot).len(),
                modes(Autopilot::Px4).len()
            ),
            (24, 25)
        );
    }
}
