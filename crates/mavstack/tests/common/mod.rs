//! What several of this crate's test files share.

use mavstack::dialects::common::{MavCmd, MavFrame, MissionItemInt};

/// `n` waypoints around the simulator's home.
pub(crate) fn plan(n: u16) -> Vec<MissionItemInt> {
    (0..n)
        .map(|i| MissionItemInt {
            seq: i,
            frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
            command: MavCmd::NAV_WAYPOINT,
            autocontinue: 1,
            x: -353_632_610 + i32::from(i) * 100,
            y: 1_491_652_300 + i32::from(i) * 100,
            z: 20.0 + f32::from(i),
            ..MissionItemInt::default()
        })
        .collect()
}
