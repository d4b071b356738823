//! What pymavlink reads of a HEARTBEAT: whether it comes from a vehicle, and the flight
//! mode's name as pymavlink's `mode_string_v10` writes it.

use mavstack::modes::{self, Flavour};

use super::CUSTOM_MODE_ENABLED;
use crate::dialect::MessageType;
use crate::message::bytes_at;

/// HEARTBEAT `type` values pymavlink does not take for a vehicle: GCS, ONBOARD_CONTROLLER,
/// GIMBAL, ADSB.
const NOT_VEHICLE_TYPES: [u8; 4] = [6, 18, 26, 27];
/// MAV_AUTOPILOT_INVALID.
const AUTOPILOT_INVALID: u8 = 8;
/// MAV_COMP_ID_GIMBAL.
const COMP_GIMBAL: u8 = 154;

/// HEARTBEAT's fields pymavlink's `post_message` looks at.
pub(super) struct HeartbeatFields {
    pub(super) mav_type: u8,
    pub(super) autopilot: u8,
    pub(super) base_mode: u8,
    pub(super) custom_mode: u32,
}

pub(super) fn heartbeat_fields(ty: &MessageType, payload: &[u8]) -> HeartbeatFields {
    let byte = |name| {
        ty.field(name)
            .map_or(0, |f| bytes_at::<1>(payload, f.offset)[0])
    };
    HeartbeatFields {
        mav_type: byte("type"),
        autopilot: byte("autopilot"),
        base_mode: byte("base_mode"),
        custom_mode: ty
            .field("custom_mode")
            .map_or(0, |f| u32::from_le_bytes(bytes_at(payload, f.offset))),
    }
}

/// pymavlink's `probably_vehicle_heartbeat`.
pub(super) fn probably_vehicle(compid: u8, hb: &HeartbeatFields) -> bool {
    compid != COMP_GIMBAL
        && !NOT_VEHICLE_TYPES.contains(&hb.mav_type)
        && hb.autopilot != AUTOPILOT_INVALID
}

/// Where pymavlink names an ArduPilot mode otherwise than the dialect's enums (COPTER_MODE,
/// PLANE_MODE, ...): by flavour and number, its name there (`None`: pymavlink does not name
/// it). Scripts compare `flightmode` with these names and pass them to `set_mode`.
const PYMAVLINK_NAMES: &[(Flavour, u32, Option<&str>)] = &[
    (Flavour::ArduCopter, 8, Some("POSITION")),
    (Flavour::ArduCopter, 10, Some("OF_LOITER")),
    (Flavour::ArduCopter, 29, Some("RATE_ACRO")),
    (Flavour::ArduPlane, 5, Some("FBWA")),
    (Flavour::ArduPlane, 6, Some("FBWB")),
    (Flavour::ArduPlane, 16, Some("INITIALISING")),
    (Flavour::ArduPlane, 25, Some("LOITERALTQLAND")),
    (Flavour::ArduRover, 2, Some("LEARNING")),
    (Flavour::ArduRover, 16, Some("INITIALISING")),
    (Flavour::ArduSub, 20, None),
    (Flavour::ArduSub, 21, None),
];

/// The modes of an ArduPilot flavour by pymavlink's names (the dialect's, but where
/// [`PYMAVLINK_NAMES`] says otherwise), in number order; PX4's as the stack names them.
pub(super) fn ardupilot_modes(flavour: Flavour) -> Vec<(&'static str, u32)> {
    let mut out: Vec<(&'static str, u32)> = modes::modes(flavour)
        .into_iter()
        .filter_map(|m| match pymavlink_alias(flavour, m.custom_mode) {
            Some(alias) => alias.map(|a| (a, m.custom_mode)),
            None => Some((m.name, m.custom_mode)),
        })
        .collect();
    for &(f, number, name) in PYMAVLINK_NAMES {
        if f == flavour
            && let Some(name) = name
            && !out.iter().any(|(_, n)| *n == number)
        {
            out.push((name, number));
        }
    }
    out.sort_by_key(|(_, n)| *n);
    out
}

/// pymavlink's name of mode `number` where it differs from the dialect's.
fn pymavlink_alias(flavour: Flavour, number: u32) -> Option<Option<&'static str>> {
    PYMAVLINK_NAMES
        .iter()
        .find(|(f, n, _)| *f == flavour && *n == number)
        .map(|(_, _, name)| *name)
}

/// The flight mode's name, as pymavlink's `mode_string_v10` writes it. PX4: its name from
/// the main mode (and AUTO's sub mode), as pymavlink names them (`MISSION`, `POSCTL`,
/// `FOLLOWME`; `UNKNOWN` for the rest). Any other autopilot: `Mode(0xNN)` (the base mode)
/// without MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, else the mode's name in ArduPilot's table for the
/// vehicle type, else `Mode(N)`.
pub(super) fn mode_string(hb: &HeartbeatFields) -> String {
    use mavstack::dialects::common::{MavAutopilot, MavType};
    if MavAutopilot(hb.autopilot) == MavAutopilot::PX4 {
        return px4_mode_string(hb.custom_mode);
    }
    if hb.base_mode & CUSTOM_MODE_ENABLED == 0 {
        return format!("Mode(0x{:08x})", hb.base_mode);
    }
    Flavour::of(MavAutopilot::ARDUPILOTMEGA, MavType(hb.mav_type))
        .and_then(|f| {
            ardupilot_modes(f)
                .into_iter()
                .find(|(_, n)| *n == hb.custom_mode)
        })
        .map_or_else(
            || format!("Mode({})", hb.custom_mode),
            |(name, _)| name.to_owned(),
        )
}

/// PX4's mode as pymavlink names it: by the main mode alone, but AUTO by its sub mode
/// without the `AUTO.` prefix (AUTO.FOLLOW_TARGET is `FOLLOWME`), and `UNKNOWN` for what
/// pymavlink does not name (AUTO.READY, AUTO.PRECLAND, AUTO.VTOL_TAKEOFF, unknown modes);
/// AUTO's sub mode 7 is `RTGS`.
fn px4_mode_string(custom_mode: u32) -> String {
    const MAIN_AUTO: u32 = 4;
    const MAIN_RATTITUDE: u32 = 8;
    const AUTO_RTGS: u32 = 7;
    const AUTO_NAMED: core::ops::RangeInclusive<u32> = 2..=8;
    let main = (custom_mode >> 16) & 0xff;
    let sub = (custom_mode >> 24) & 0xff;
    let name = match main {
        MAIN_AUTO if sub == AUTO_RTGS => Some("RTGS"),
        MAIN_AUTO if AUTO_NAMED.contains(&sub) => {
            modes::name_of(Flavour::Px4, custom_mode & 0xffff_0000).map(|n| {
                match n.strip_prefix("AUTO.").unwrap_or(n) {
                    "FOLLOW_TARGET" => "FOLLOWME",
                    short => short,
                }
            })
        }
        MAIN_AUTO => None,
        MAIN_RATTITUDE => Some("RATTITUDE"),
        m => modes::name_of(Flavour::Px4, m << 16),
    };
    name.unwrap_or("UNKNOWN").to_owned()
}
