//! Plans as people write them, missions as each autopilot stores them.
//!
//! A QGroundControl plan file (`QGC WPL 110`, [`crate::wpl`]) always starts with home: item 0
//! is the home position, whatever the autopilot. The autopilots differ:
//!
//! - **ArduPilot** stores home as mission item 0 too, and replaces whatever item 0 it is sent
//!   with its own home: the plan goes as it is, and comes back with the vehicle's home at 0.
//! - **PX4** has no home item (home is HOME_POSITION): item 0 of the plan is left out on
//!   upload and the vehicle's home put back in front on download. PX4 also refuses an item
//!   whose command has no position unless its frame is MAV_FRAME_MISSION
//!   (MAV_MISSION_UNSUPPORTED), and answers with the `_INT` frames (GLOBAL_INT for GLOBAL).
//!
//! [`to_vehicle`] and [`from_vehicle`] make the conversions, and [`same`] compares a plan
//! with what was read back under those rules: the frames that mean the same place compare
//! equal, the frame of an item without a position does not count, nor does `current`, nor
//! home's position (which the vehicle owns).
//!
//! ```
//! use mavstack_dialects::common::{MavCmd, MavFrame, MissionItemInt};
//! use mavstack_services::plan::{Convention, from_vehicle, same, to_vehicle};
//! let item = |command, frame| MissionItemInt { command, frame, autocontinue: 1, ..MissionItemInt::default() };
//! let plan = vec![
//!     item(MavCmd::NAV_WAYPOINT, MavFrame::GLOBAL),               // home
//!     item(MavCmd::NAV_TAKEOFF, MavFrame::GLOBAL_RELATIVE_ALT),
//!     item(MavCmd::NAV_RETURN_TO_LAUNCH, MavFrame::GLOBAL_RELATIVE_ALT),
//! ];
//! let sent = to_vehicle(Convention::Px4, &plan);
//! assert_eq!(sent.len(), 2);
//! assert_eq!(sent[1].frame, MavFrame::MISSION);
//! // PX4 answers with the _INT frames; home comes back from HOME_POSITION.
//! let mut stored = sent.clone();
//! stored[0].frame = MavFrame::GLOBAL_RELATIVE_ALT_INT;
//! let back = from_vehicle(Convention::Px4, &stored, Some(plan[0]));
//! assert!(same(&plan, &back));
//! ```

use alloc::vec::Vec;

use mavstack_dialects::common::{MavAutopilot, MavCmd, MavFrame, MissionItemInt};

/// Whose mission conventions apply.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Convention {
    /// ArduPilot: item 0 is home.
    ArduPilot,
    /// PX4: no home item; items without a position in MAV_FRAME_MISSION.
    Px4,
    /// Anyone else: the plan goes and comes as it is.
    Plain,
}

impl Convention {
    /// The convention of a HEARTBEAT's autopilot.
    #[must_use]
    pub fn of(autopilot: MavAutopilot) -> Self {
        match autopilot {
            MavAutopilot::ARDUPILOTMEGA => Self::ArduPilot,
            MavAutopilot::PX4 => Self::Px4,
            _ => Self::Plain,
        }
    }
}

/// Whether an item's command has a position (a place to go or look at), so that its frame
/// matters. Navigation commands below 95 (waypoints, loiters, land, take-off, ...) and the
/// region of interest have one, except return-to-launch; DO_ and CONDITION_ commands do
/// not, but for the few that carry a location.
#[must_use]
pub fn has_position(command: MavCmd) -> bool {
    match command {
        MavCmd::NAV_RETURN_TO_LAUNCH => false,
        MavCmd::DO_SET_ROI_LOCATION
        | MavCmd::DO_SET_HOME
        | MavCmd::DO_REPOSITION
        | MavCmd::DO_LAND_START => true,
        c => c.0 < 95 || (c.0 >= 3000 && c.0 < 3100),
    }
}

/// The frame that means the same as `frame` (the `_INT` frames are the same places).
fn canonical(frame: MavFrame) -> MavFrame {
    match frame {
        MavFrame::GLOBAL_INT => MavFrame::GLOBAL,
        MavFrame::GLOBAL_RELATIVE_ALT_INT => MavFrame::GLOBAL_RELATIVE_ALT,
        MavFrame::GLOBAL_TERRAIN_ALT_INT => MavFrame::GLOBAL_TERRAIN_ALT,
        f => f,
    }
}

fn renumber(items: &mut [MissionItemInt]) {
    for (seq, item) in (0u16..).zip(items.iter_mut()) {
        item.seq = seq;
    }
}

/// The mission to upload for `plan` (item 0: home), under `convention`.
#[must_use]
pub fn to_vehicle(convention: Convention, plan: &[MissionItemInt]) -> Vec<MissionItemInt> {
    match convention {
        Convention::ArduPilot | Convention::Plain => plan.to_vec(),
        Convention::Px4 => {
            let mut items: Vec<MissionItemInt> = plan.iter().skip(1).copied().collect();
            for item in &mut items {
                if !has_position(item.command) {
                    item.frame = MavFrame::MISSION;
                }
            }
            renumber(&mut items);
            items
        }
    }
}

/// The plan (item 0: home) for a mission read back under `convention`; `home` is the
/// vehicle's home as a plan's item 0 (PX4: from HOME_POSITION; a zero item when `None`).
#[must_use]
pub fn from_vehicle(
    convention: Convention,
    items: &[MissionItemInt],
    home: Option<MissionItemInt>,
) -> Vec<MissionItemInt> {
    match convention {
        Convention::ArduPilot | Convention::Plain => items.to_vec(),
        Convention::Px4 => {
            let home = home.unwrap_or(MissionItemInt {
                command: MavCmd::NAV_WAYPOINT,
                frame: MavFrame::GLOBAL,
                autocontinue: 1,
                ..MissionItemInt::default()
            });
            let mut plan = Vec::with_capacity(items.len() + 1);
            plan.push(home);
            plan.extend_from_slice(items);
            renumber(&mut plan);
            plan
        }
    }
}

/// Whether two plans (item 0: home) are the same mission: the same items in order, each with
/// the same command, parameters, position and `autocontinue`; frames compared as places
/// (GLOBAL and GLOBAL_INT alike; ignored for items without a position); `current` and
/// home's position ignored (the vehicle sets them). Parameters that are NaN match NaN;
/// a command's unused position may come back as 0 or NaN.
#[must_use]
pub fn same(sent: &[MissionItemInt], back: &[MissionItemInt]) -> bool {
    sent.len() == back.len() && items_match(sent, back, 0)
}

/// Whether `back`, the items of a plan read back from item `first` on, are the items of
/// `sent` from `first` on, as [`same`] compares them, each read back with its number: the
/// plan then has as many items as `sent`, and ends as it does.
#[must_use]
pub fn same_from(sent: &[MissionItemInt], first: usize, back: &[MissionItemInt]) -> bool {
    sent.len() == first + back.len()
        && back
            .iter()
            .zip(first..)
            .all(|(b, i)| usize::from(b.seq) == i)
        && items_match(sent.get(first..).unwrap_or_default(), back, first)
}

/// Whether `a` and `b`, both starting at item `first` of their plans, hold the same items
/// (home, item 0, matches any).
fn items_match(a: &[MissionItemInt], b: &[MissionItemInt], first: usize) -> bool {
    a.iter()
        .zip(b)
        .zip(first..)
        .all(|((a, b), i)| i == 0 || same_item(a, b))
}

fn same_f32(a: f32, b: f32) -> bool {
    a == b || (a.is_nan() && b.is_nan()) || ((a.is_nan() || a == 0.0) && (b.is_nan() || b == 0.0))
}

fn same_item(a: &MissionItemInt, b: &MissionItemInt) -> bool {
    let placed = has_position(a.command);
    a.command == b.command
        && a.autocontinue == b.autocontinue
        && [a.param1, a.param2, a.param3, a.param4]
            .into_iter()
            .zip([b.param1, b.param2, b.param3, b.param4])
            .all(|(x, y)| same_f32(x, y))
        && (!placed
            || (canonical(a.frame) == canonical(b.frame)
                && a.x == b.x
                && a.y == b.y
                && same_f32(a.z, b.z)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use alloc::vec;

    fn item(command: MavCmd, frame: MavFrame, x: i32, z: f32) -> MissionItemInt {
        MissionItemInt {
            command,
            frame,
            x,
            y: x,
            z,
            autocontinue: 1,
            ..MissionItemInt::default()
        }
    }

    fn plan() -> Vec<MissionItemInt> {
        let mut p = vec![
            item(MavCmd::NAV_WAYPOINT, MavFrame::GLOBAL, 1, 488.0),
            item(MavCmd::NAV_TAKEOFF, MavFrame::GLOBAL_RELATIVE_ALT, 2, 10.0),
            item(MavCmd::NAV_WAYPOINT, MavFrame::GLOBAL_RELATIVE_ALT, 3, 10.0),
            item(
                MavCmd::DO_CHANGE_SPEED,
                MavFrame::GLOBAL_RELATIVE_ALT,
                0,
                0.0,
            ),
            item(
                MavCmd::NAV_RETURN_TO_LAUNCH,
                MavFrame::GLOBAL_RELATIVE_ALT,
                0,
                0.0,
            ),
        ];
        renumber(&mut p);
        p
    }

    #[test]
    fn ardupilot_keeps_the_plan_and_owns_home() {
        let sent = to_vehicle(Convention::ArduPilot, &plan());
        assert_eq!(sent, plan());
        // ArduPilot's answer: its own home at 0, frames of items without position as 0.
        let mut back = sent.clone();
        back[0] = item(MavCmd::NAV_WAYPOINT, MavFrame::GLOBAL, 99, 584.0);
        back[4].frame = MavFrame::GLOBAL;
        assert!(same(
            &plan(),
            &from_vehicle(Convention::ArduPilot, &back, None)
        ));
    }

    #[test]
    fn px4_leaves_home_out_and_puts_items_without_position_in_the_mission_frame() {
        let sent = to_vehicle(Convention::Px4, &plan());
        assert_eq!(sent.len(), 4);
        assert_eq!(sent.iter().map(|i| i.seq).collect::<Vec<_>>(), [0, 1, 2, 3]);
        assert_eq!(sent[2].frame, MavFrame::MISSION);
        assert_eq!(sent[3].frame, MavFrame::MISSION);
        assert_eq!(sent[0].frame, MavFrame::GLOBAL_RELATIVE_ALT);
        let mut back = sent;
        back[0].frame = MavFrame::GLOBAL_RELATIVE_ALT_INT;
        back[1].frame = MavFrame::GLOBAL_RELATIVE_ALT_INT;
        back[0].current = 1;
        assert!(same(&plan(), &from_vehicle(Convention::Px4, &back, None)));
    }

    #[test]
    fn a_different_item_is_not_the_same_plan() {
        let mut other = plan();
        other[2].x += 1;
        assert!(!same(&plan(), &other));
        let mut fewer = plan();
        fewer.pop();
        assert!(!same(&plan(), &fewer));
        let mut frame = plan();
        frame[2].frame = MavFrame::GLOBAL;
        assert!(!same(&plan(), &frame));
    }

    #[test]
    fn a_plan_read_back_from_an_item_on_must_end_as_it_and_have_its_length() {
        let sent = plan();
        assert!(same_from(&sent, 4, &sent[4..]));
        assert!(same_from(&sent, 2, &sent[2..]));
        assert!(same_from(&sent, 0, &sent));
        // The count read back said one more item: it came too.
        assert!(!same_from(
            &sent,
            3,
            &plan()[3..]
                .iter()
                .chain(&sent[4..])
                .copied()
                .collect::<Vec<_>>()
        ));
        // One fewer: nothing came from item 4.
        assert!(!same_from(&sent, 4, &[]));
        // The last item differs.
        let mut other = sent[4];
        other.command = MavCmd::NAV_LAND;
        assert!(!same_from(&sent, 4, &[other]));
        // The right item under another number.
        let mut moved = sent[4];
        moved.seq = 3;
        assert!(!same_from(&sent, 4, &[moved]));
    }
}
