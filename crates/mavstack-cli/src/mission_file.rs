//! Mission plans on disk: QGroundControl's `QGC WPL 110` text format (also MAVProxy's and
//! Mission Planner's; read and written by `mavstack_services::wpl`) and JSON.
//!
//! JSON: `{"mission_type": "mission", "items": [...]}`,
//! each item with `seq`, `frame`, `command` (numbers), `current`, `autocontinue`,
//! `param1`–`param4`, `x`/`y` (degE7 for global frames, as MISSION_ITEM_INT carries them),
//! `z`; NaN parameters are `null`. Items read from either format are renumbered in order.

use anyhow::{Context, anyhow, bail};
use mavstack_dialects::common::{MavCmd, MavFrame, MavMissionType, MissionItemInt};
use mavstack_services::wpl::{self, WplError};
use serde_json::{Map, Value as Json, json};

/// A QGC WPL 110 text's items; errors start with the line number (`2: ...`), as the file
/// name is put before them (`plan.waypoints:2: ...`).
pub(crate) fn from_wpl(text: &str) -> anyhow::Result<Vec<MissionItemInt>> {
    wpl::parse(text).map_err(|e| match e {
        WplError::Line { line, what } => anyhow!("{line}: {what}"),
        WplError::Header { found } => anyhow!("1: expected \"QGC WPL 110\", got {found:?}"),
        e => anyhow!("{e}"),
    })
}

/// The plan's type as JSON names it.
pub(crate) fn type_name(t: MavMissionType) -> &'static str {
    match t {
        MavMissionType::FENCE => "fence",
        MavMissionType::RALLY => "rally",
        _ => "mission",
    }
}

fn json_f32(v: f32) -> Json {
    if v.is_finite() { json!(v) } else { Json::Null }
}

/// One item as a JSON object.
pub(crate) fn item_json(it: &MissionItemInt) -> Json {
    let mut m = Map::new();
    m.insert("seq".into(), json!(it.seq));
    m.insert("frame".into(), json!(it.frame.0));
    m.insert("command".into(), json!(it.command.0));
    if let Some(name) = it.command.name() {
        m.insert("command_name".into(), json!(name));
    }
    m.insert("current".into(), json!(it.current));
    m.insert("autocontinue".into(), json!(it.autocontinue));
    m.insert("param1".into(), json_f32(it.param1));
    m.insert("param2".into(), json_f32(it.param2));
    m.insert("param3".into(), json_f32(it.param3));
    m.insert("param4".into(), json_f32(it.param4));
    m.insert("x".into(), json!(it.x));
    m.insert("y".into(), json!(it.y));
    m.insert("z".into(), json_f32(it.z));
    Json::Object(m)
}

/// The plan as a JSON document.
pub(crate) fn to_json(mission_type: MavMissionType, items: &[MissionItemInt]) -> Json {
    json!({
        "mission_type": type_name(mission_type),
        "items": items.iter().map(item_json).collect::<Vec<_>>(),
    })
}

/// A JSON plan's items; errors name the item and field.
pub(crate) fn from_json(text: &str) -> anyhow::Result<Vec<MissionItemInt>> {
    let doc: Json = serde_json::from_str(text).context("not JSON")?;
    let items = doc
        .get("items")
        .and_then(Json::as_array)
        .ok_or_else(|| anyhow!("expected an object with an \"items\" array"))?;
    items
        .iter()
        .enumerate()
        .map(|(i, v)| json_item(v, i).map_err(|e| anyhow!("item {i}: {e}")))
        .collect()
}

fn json_item(v: &Json, seq: usize) -> anyhow::Result<MissionItemInt> {
    let int = |key: &str, default: Option<i64>| -> anyhow::Result<i64> {
        match v.get(key) {
            None => default.ok_or_else(|| anyhow!("missing \"{key}\"")),
            Some(x) => x
                .as_i64()
                .ok_or_else(|| anyhow!("\"{key}\" must be an integer, got {x}")),
        }
    };
    let float = |key: &str| -> anyhow::Result<f32> {
        match v.get(key) {
            None | Some(Json::Null) => Ok(if key == "z" { 0.0 } else { f32::NAN }),
            Some(x) => x
                .as_f64()
                .map(|f| f as f32)
                .ok_or_else(|| anyhow!("\"{key}\" must be a number or null, got {x}")),
        }
    };
    let ranged = |key: &str, value: i64, max: i64| -> anyhow::Result<i64> {
        if (0..=max).contains(&value) {
            Ok(value)
        } else {
            bail!("\"{key}\" {value} is out of range 0-{max}")
        }
    };
    let coordinate = |key: &str| -> anyhow::Result<i32> {
        let x = int(key, Some(0))?;
        i32::try_from(x).map_err(|_| anyhow!("\"{key}\" {x} does not fit degE7"))
    };
    Ok(MissionItemInt {
        seq: u16::try_from(seq).map_err(|_| anyhow!("more than 65,535 items"))?,
        frame: MavFrame(ranged("frame", int("frame", None)?, 255)? as u8),
        command: MavCmd(ranged("command", int("command", None)?, 65_535)? as u16),
        current: u8::from(int("current", Some(0))? != 0),
        autocontinue: u8::from(int("autocontinue", Some(1))? != 0),
        param1: float("param1")?,
        param2: float("param2")?,
        param3: float("param3")?,
        param4: float("param4")?,
        x: coordinate("x")?,
        y: coordinate("y")?,
        z: float("z")?,
        ..MissionItemInt::default()
    })
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
