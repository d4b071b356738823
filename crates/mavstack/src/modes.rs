//! Flight modes by name, as each autopilot numbers them (feature `services`).
//!
//! A HEARTBEAT's `custom_mode` means something only together with its autopilot and vehicle
//! type: ArduPilot numbers each vehicle's modes on its own (Copter's 6 is RTL, Plane's 11),
//! and PX4 packs a main mode in bits 16–23 and a sub mode of AUTO or POSCTL in bits 24–31.
//! MAV_CMD_DO_SET_MODE carries MAV_MODE_FLAG_CUSTOM_MODE_ENABLED in param1, the ArduPilot
//! number or the PX4 main mode in param2, and the PX4 sub mode in param3.
//!
//! ArduPilot's tables are read from the `ardupilotmega` dialect's own enums (COPTER_MODE,
//! PLANE_MODE, ROVER_MODE, SUB_MODE, TRACKER_MODE), so they follow the vendored XML. PX4's
//! come from its `px4_custom_mode.h`; names are accepted as PX4 writes them
//! (`AUTO.MISSION`), without the `AUTO.` prefix (`mission`), and as QGroundControl shows
//! them (`Hold`, `Return`, `Position`).
//!
//! ```
//! use mavstack::dialects::common::{MavAutopilot, MavType};
//! use mavstack::modes::{Flavour, by_name, name_of};
//! let plane = Flavour::of(MavAutopilot::ARDUPILOTMEGA, MavType::FIXED_WING).unwrap();
//! assert_eq!(by_name(plane, "rtl").unwrap().custom_mode, 11);
//! let copter = Flavour::of(MavAutopilot::ARDUPILOTMEGA, MavType::QUADROTOR).unwrap();
//! assert_eq!(by_name(copter, "rtl").unwrap().custom_mode, 6);
//! let px4 = Flavour::of(MavAutopilot::PX4, MavType::QUADROTOR).unwrap();
//! let hold = by_name(px4, "Hold").unwrap();
//! assert_eq!(name_of(px4, hold.custom_mode), Some("AUTO.LOITER"));
//! assert_eq!(px4.command_params(hold.custom_mode), (1.0, 4.0, 3.0));
//! ```

use std::fmt;

use mavstack_dialects::ardupilotmega::{CopterMode, PlaneMode, RoverMode, SubMode, TrackerMode};
use mavstack_dialects::common::{MavAutopilot, MavModeFlag, MavStandardMode, MavType};

/// Whose mode numbers apply.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Flavour {
    /// ArduPilot Copter (multicopters and helicopters).
    ArduCopter,
    /// ArduPilot Plane (fixed wing and QuadPlane VTOLs).
    ArduPlane,
    /// ArduPilot Rover (ground vehicles and boats).
    ArduRover,
    /// ArduPilot Sub.
    ArduSub,
    /// ArduPilot's antenna tracker.
    ArduTracker,
    /// PX4, any vehicle.
    Px4,
}

/// One mode: its name and its HEARTBEAT `custom_mode`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Mode {
    /// The name, as the autopilot writes it (`RTL`, `AUTO.MISSION`).
    pub name: &'static str,
    /// The `custom_mode` of HEARTBEAT in this mode.
    pub custom_mode: u32,
}

impl fmt::Display for Flavour {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::ArduCopter => "ArduPilot Copter",
            Self::ArduPlane => "ArduPilot Plane",
            Self::ArduRover => "ArduPilot Rover",
            Self::ArduSub => "ArduPilot Sub",
            Self::ArduTracker => "ArduPilot antenna tracker",
            Self::Px4 => "PX4",
        })
    }
}

impl Flavour {
    /// The flavour of a HEARTBEAT's autopilot and vehicle type; `None` for an autopilot
    /// whose modes are not known here (or an ArduPilot vehicle type it has no firmware for).
    #[must_use]
    pub fn of(autopilot: MavAutopilot, mav_type: MavType) -> Option<Self> {
        match autopilot {
            MavAutopilot::PX4 => Some(Self::Px4),
            MavAutopilot::ARDUPILOTMEGA => match mav_type {
                // Fixed wing, and the VTOL types 19-25 QuadPlanes report.
                MavType::FIXED_WING => Some(Self::ArduPlane),
                t if (19..=25).contains(&t.0) => Some(Self::ArduPlane),
                MavType::GROUND_ROVER | MavType::SURFACE_BOAT => Some(Self::ArduRover),
                MavType::SUBMARINE => Some(Self::ArduSub),
                MavType::ANTENNA_TRACKER => Some(Self::ArduTracker),
                MavType::QUADROTOR
                | MavType::HEXAROTOR
                | MavType::OCTOROTOR
                | MavType::TRICOPTER
                | MavType::COAXIAL
                | MavType::HELICOPTER
                | MavType::DECAROTOR
                | MavType::DODECAROTOR => Some(Self::ArduCopter),
                _ => None,
            },
            _ => None,
        }
    }

    /// MAV_CMD_DO_SET_MODE's param1 (base mode), param2 and param3 for `custom_mode`.
    #[must_use]
    pub fn command_params(self, custom_mode: u32) -> (f32, f32, f32) {
        let base = MavModeFlag::CUSTOM_MODE_ENABLED.0 as f32;
        match self {
            Self::Px4 => (
                base,
                ((custom_mode >> 16) & 0xff) as f32,
                ((custom_mode >> 24) & 0xff) as f32,
            ),
            _ => (base, custom_mode as f32, 0.0),
        }
    }
}

const fn px4(name: &'static str, main: u32, sub: u32) -> Mode {
    Mode {
        name,
        custom_mode: (main << 16) | (sub << 24),
    }
}

/// PX4's modes (`px4_custom_mode.h`: main modes 1–7, AUTO's sub modes 1–10, POSCTL's 0–2).
const PX4: &[Mode] = &[
    px4("MANUAL", 1, 0),
    px4("ALTCTL", 2, 0),
    px4("POSCTL", 3, 0),
    px4("POSCTL.ORBIT", 3, 1),
    px4("POSCTL.SLOW", 3, 2),
    px4("AUTO.READY", 4, 1),
    px4("AUTO.TAKEOFF", 4, 2),
    px4("AUTO.LOITER", 4, 3),
    px4("AUTO.MISSION", 4, 4),
    px4("AUTO.RTL", 4, 5),
    px4("AUTO.LAND", 4, 6),
    px4("AUTO.FOLLOW_TARGET", 4, 8),
    px4("AUTO.PRECLAND", 4, 9),
    px4("AUTO.VTOL_TAKEOFF", 4, 10),
    px4("ACRO", 5, 0),
    px4("OFFBOARD", 6, 0),
    px4("STABILIZED", 7, 0),
];

/// QGroundControl's names for PX4's modes.
const PX4_ALIASES: &[(&str, &str)] = &[
    ("manual", "MANUAL"),
    ("altitude", "ALTCTL"),
    ("position", "POSCTL"),
    ("orbit", "POSCTL.ORBIT"),
    ("ready", "AUTO.READY"),
    ("hold", "AUTO.LOITER"),
    ("loiter", "AUTO.LOITER"),
    ("return", "AUTO.RTL"),
    ("follow me", "AUTO.FOLLOW_TARGET"),
    ("precision land", "AUTO.PRECLAND"),
    ("stabilized", "STABILIZED"),
];

/// An ArduPilot table from one of the dialect's mode enums: every value it names, the
/// prefix stripped.
fn ardupilot(name_of: impl Fn(u8) -> Option<&'static str>, prefix: &str) -> Vec<Mode> {
    (0..=u8::MAX)
        .filter_map(|v| {
            name_of(v).map(|n| Mode {
                name: n.strip_prefix(prefix).unwrap_or(n),
                custom_mode: u32::from(v),
            })
        })
        .collect()
}

/// Every mode of a flavour, by number.
#[must_use]
pub fn modes(flavour: Flavour) -> Vec<Mode> {
    match flavour {
        Flavour::ArduCopter => ardupilot(|v| CopterMode(v).name(), "COPTER_MODE_"),
        Flavour::ArduPlane => ardupilot(|v| PlaneMode(v).name(), "PLANE_MODE_"),
        Flavour::ArduRover => ardupilot(|v| RoverMode(v).name(), "ROVER_MODE_"),
        Flavour::ArduSub => ardupilot(|v| SubMode(v).name(), "SUB_MODE_"),
        Flavour::ArduTracker => ardupilot(|v| TrackerMode(v).name(), "TRACKER_MODE_"),
        Flavour::Px4 => PX4.to_vec(),
    }
}

/// Names compare without case, with `-`, `_` and spaces alike.
fn same(a: &str, b: &str) -> bool {
    let norm = |c: char| match c {
        '-' | ' ' => '_',
        c => c.to_ascii_uppercase(),
    };
    a.len() == b.len() && a.chars().map(norm).eq(b.chars().map(norm))
}

/// The mode called `name` (case-insensitive; PX4 modes also without their `AUTO.` prefix
/// and by QGroundControl's names).
#[must_use]
pub fn by_name(flavour: Flavour, name: &str) -> Option<Mode> {
    let table = modes(flavour);
    let direct = table.iter().copied().find(|m| {
        same(m.name, name)
            || m.name
                .strip_prefix("AUTO.")
                .is_some_and(|short| same(short, name))
    });
    if direct.is_some() || flavour != Flavour::Px4 {
        return direct;
    }
    let (_, real) = PX4_ALIASES.iter().find(|(alias, _)| same(alias, name))?;
    table.into_iter().find(|m| m.name == *real)
}

/// The name of `custom_mode` in a flavour, if it has one.
#[must_use]
pub fn name_of(flavour: Flavour, custom_mode: u32) -> Option<&'static str> {
    modes(flavour)
        .into_iter()
        .find(|m| m.custom_mode == custom_mode)
        .map(|m| m.name)
}

/// Our own mapping of each flavour's modes to the standard modes (MAV_STANDARD_MODE):
/// ArduPilot 4.7 lists every mode in AVAILABLE_MODES as non-standard, and vehicles without
/// AVAILABLE_MODES say nothing at all. (name, standard) by the names of [`modes`]; a mode
/// the standard forbids for the vehicle type (a fixed wing's position hold) is left out.
const STANDARD: &[(Flavour, &str, MavStandardMode)] = {
    use Flavour::{ArduCopter, ArduPlane, ArduRover, ArduSub, Px4};
    use MavStandardMode as S;
    &[
        (ArduCopter, "LOITER", S::POSITION_HOLD),
        (ArduCopter, "CIRCLE", S::ORBIT),
        (ArduCopter, "ALT_HOLD", S::ALTITUDE_HOLD),
        (ArduCopter, "RTL", S::SAFE_RECOVERY),
        (ArduCopter, "AUTO", S::MISSION),
        (ArduCopter, "LAND", S::LAND),
        (ArduPlane, "CIRCLE", S::ORBIT),
        (ArduPlane, "CRUISE", S::CRUISE),
        (ArduPlane, "FLY_BY_WIRE_B", S::ALTITUDE_HOLD),
        (ArduPlane, "RTL", S::SAFE_RECOVERY),
        (ArduPlane, "AUTO", S::MISSION),
        (ArduPlane, "TAKEOFF", S::TAKEOFF),
        (ArduRover, "RTL", S::SAFE_RECOVERY),
        (ArduRover, "AUTO", S::MISSION),
        (ArduSub, "POSHOLD", S::POSITION_HOLD),
        (ArduSub, "ALT_HOLD", S::ALTITUDE_HOLD),
        (ArduSub, "AUTO", S::MISSION),
        (Px4, "POSCTL", S::POSITION_HOLD),
        (Px4, "POSCTL.ORBIT", S::ORBIT),
        (Px4, "ALTCTL", S::ALTITUDE_HOLD),
        (Px4, "AUTO.RTL", S::SAFE_RECOVERY),
        (Px4, "AUTO.MISSION", S::MISSION),
        (Px4, "AUTO.LAND", S::LAND),
        (Px4, "AUTO.TAKEOFF", S::TAKEOFF),
    ]
};

/// The standard mode that `custom_mode` of a flavour stands for, by our own table.
///
/// ```
/// use mavstack::dialects::common::MavStandardMode;
/// use mavstack::modes::{Flavour, standard_of};
/// assert_eq!(standard_of(Flavour::ArduCopter, 6), Some(MavStandardMode::SAFE_RECOVERY));
/// assert_eq!(standard_of(Flavour::ArduCopter, 4), None); // GUIDED
/// ```
#[must_use]
pub fn standard_of(flavour: Flavour, custom_mode: u32) -> Option<MavStandardMode> {
    let name = name_of(flavour, custom_mode)?;
    STANDARD
        .iter()
        .find(|(f, n, _)| *f == flavour && *n == name)
        .map(|&(_, _, s)| s)
}

/// The mode of a flavour that stands for `standard`, by our own table.
#[must_use]
pub fn by_standard(flavour: Flavour, standard: MavStandardMode) -> Option<Mode> {
    let (_, name, _) = STANDARD
        .iter()
        .find(|(f, _, s)| *f == flavour && *s == standard)?;
    modes(flavour).into_iter().find(|m| m.name == *name)
}

/// A standard mode's name as people write it: MAV_STANDARD_MODE's without its prefix, in
/// lower case (`position_hold`, `safe_recovery`); `None` for NON_STANDARD and numbers no
/// dialect names.
///
/// ```
/// use mavstack::dialects::common::MavStandardMode;
/// assert_eq!(mavstack::modes::standard_name(MavStandardMode::SAFE_RECOVERY).as_deref(), Some("safe_recovery"));
/// assert_eq!(mavstack::modes::standard_by_name("Position-Hold"), Some(MavStandardMode::POSITION_HOLD));
/// ```
#[must_use]
pub fn standard_name(standard: MavStandardMode) -> Option<String> {
    if standard == MavStandardMode::NON_STANDARD {
        return None;
    }
    standard
        .name()
        .and_then(|n| n.strip_prefix("MAV_STANDARD_MODE_"))
        .map(str::to_ascii_lowercase)
}

/// The standard mode called `name` (as [`standard_name`] writes it; any case, `-` or a
/// space for `_`).
#[must_use]
pub fn standard_by_name(name: &str) -> Option<MavStandardMode> {
    (1..=u8::MAX)
        .map(MavStandardMode)
        .find(|&s| standard_name(s).is_some_and(|n| same(&n, name)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_ardupilot_vehicle_numbers_its_own_modes() {
        let mode = |f, n| by_name(f, n).map(|m| m.custom_mode);
        assert_eq!(mode(Flavour::ArduCopter, "guided"), Some(4));
        assert_eq!(mode(Flavour::ArduCopter, "auto"), Some(3));
        assert_eq!(mode(Flavour::ArduPlane, "guided"), Some(15));
        assert_eq!(mode(Flavour::ArduPlane, "auto"), Some(10));
        assert_eq!(mode(Flavour::ArduPlane, "fly-by-wire-a"), Some(5));
        assert_eq!(mode(Flavour::ArduRover, "hold"), Some(4));
        assert_eq!(mode(Flavour::ArduRover, "rtl"), Some(11));
        assert_eq!(mode(Flavour::ArduCopter, "hold"), None);
    }

    #[test]
    fn px4_modes_by_their_names_short_names_and_qgcs() {
        let custom = |n| by_name(Flavour::Px4, n).map(|m| m.custom_mode);
        assert_eq!(custom("AUTO.MISSION"), Some((4 << 16) | (4 << 24)));
        assert_eq!(custom("mission"), custom("AUTO.MISSION"));
        assert_eq!(custom("Return"), custom("rtl"));
        assert_eq!(custom("position"), Some(3 << 16));
        assert_eq!(custom("offboard"), Some(6 << 16));
        assert_eq!(custom("guided"), None);
    }

    #[test]
    fn every_standard_mapping_names_a_mode_of_its_flavour() {
        for &(flavour, name, standard) in STANDARD {
            let mode = by_name(flavour, name).unwrap_or_else(|| panic!("{flavour}: {name}"));
            assert_eq!(standard_of(flavour, mode.custom_mode), Some(standard));
            assert_eq!(by_standard(flavour, standard), Some(mode));
        }
        assert_eq!(
            by_standard(Flavour::Px4, MavStandardMode::TAKEOFF).map(|m| m.name),
            Some("AUTO.TAKEOFF")
        );
    }

    #[test]
    fn vehicle_types_pick_the_flavour() {
        let ap = MavAutopilot::ARDUPILOTMEGA;
        assert_eq!(
            Flavour::of(ap, MavType::HELICOPTER),
            Some(Flavour::ArduCopter)
        );
        assert_eq!(
            Flavour::of(ap, MavType::VTOL_TILTROTOR),
            Some(Flavour::ArduPlane)
        );
        assert_eq!(
            Flavour::of(ap, MavType::SURFACE_BOAT),
            Some(Flavour::ArduRover)
        );
        assert_eq!(Flavour::of(ap, MavType::GCS), None);
        assert_eq!(Flavour::of(MavAutopilot::GENERIC, MavType::QUADROTOR), None);
    }
}
