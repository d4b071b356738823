//! Mission plans on disk: QGroundControl's `QGC WPL 110` text format (also MAVProxy's and
//! Mission Planner's; `mavstack_services::wpl`) and JSON (`mavstack_services::mission_json`).
//! Items read from either format are renumbered in order.

use anyhow::{Context, anyhow};
use mavstack_dialects::common::MissionItemInt;
use mavstack_services::mission_json;
use mavstack_services::wpl::{self, WplError};

/// A QGC WPL 110 text's items; errors start with the line number (`2: ...`), as the file
/// name is put before them (`plan.waypoints:2: ...`).
pub(crate) fn from_wpl(text: &str) -> anyhow::Result<Vec<MissionItemInt>> {
    wpl::parse(text).map_err(|e| match e {
        WplError::Line { line, what } => anyhow!("{line}: {what}"),
        WplError::Header { found } => anyhow!("1: expected \"QGC WPL 110\", got {found:?}"),
        e => e.into(),
    })
}

pub(crate) use mavstack_services::mission_json::{to_json, type_name};

/// A JSON plan's items; errors name the item and field.
pub(crate) fn from_json(text: &str) -> anyhow::Result<Vec<MissionItemInt>> {
    Ok(mission_json::parse(text)?)
}

/// Reads a plan, JSON for `.json` files and WPL otherwise; errors name the file.
pub(crate) fn load(path: &str) -> anyhow::Result<Vec<MissionItemInt>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {path}"))?;
    let items = if path.ends_with(".json") {
        from_json(&text)
    } else {
        from_wpl(&text)
    };
    items.map_err(|e| anyhow!("{path}:{e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::common::{MavCmd, MavMissionType};

    const PLAN: &str = "QGC WPL 110\n\
        0\t1\t0\t16\t0\t0\t0\t0\t-35.36326100\t149.16523000\t584.000000\t1\n\
        1\t0\t3\t22\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t20.000000\t1\n\
        2\t0\t3\t16\t0\t0\t0\tnan\t-35.36200000\t149.16400000\t30\t1\n";

    #[test]
    fn wpl_and_json_round_trip_through_mission_item_int() {
        let items = from_wpl(PLAN).expect("valid");
        assert_eq!(items.len(), 3);
        assert_eq!(items[0].x, -353_632_610);
        assert_eq!(items[2].y, 1_491_640_000);
        assert_eq!(items[1].command, MavCmd::NAV_TAKEOFF);
        assert!(items[2].param4.is_nan());
        let again = from_wpl(&wpl::to_text(&items)).expect("own output");
        assert_eq!(format!("{again:?}"), format!("{items:?}"));
        let json = to_json(MavMissionType::MISSION, &items).to_string();
        let back = from_json(&json).expect("own JSON");
        assert_eq!(format!("{back:?}"), format!("{items:?}"));
    }

    #[test]
    fn errors_name_the_line_and_field() {
        let e = from_wpl("QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t1\t2\t3\n").expect_err("short");
        assert!(e.to_string().starts_with("2: expected 12 fields"), "{e}");
        let e = from_wpl("QGC WPL 100\n").expect_err("version");
        assert!(e.to_string().contains("QGC WPL 110"), "{e}");
        let e = from_json(r#"{"items":[{"frame":3}]}"#).expect_err("no command");
        assert_eq!(e.to_string(), "item 0: missing \"command\"");
    }
}
