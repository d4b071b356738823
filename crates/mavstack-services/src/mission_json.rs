//! Mission plans as JSON (feature `json`), the format `mavstack mission` reads and writes
//! beside QGroundControl's text format ([`crate::wpl`]):
//! `{"mission_type": "mission", "items": [...]}`, each item with `seq`, `frame`, `command`
//! (numbers; `command_name` too when the command is known), `current`, `autocontinue`,
//! `param1`–`param4`, `x`/`y` (degE7 for global frames, as MISSION_ITEM_INT carries them)
//! and `z`. A parameter or altitude that is not a finite number (NaN: "unused") is `null`;
//! an absent parameter is NaN, an absent `z` 0. Items read back are numbered in order,
//! whatever their `seq` says.
//!
//! ```
//! use mavstack_dialects::common::{MavCmd, MavMissionType, MissionItemInt};
//! use mavstack_services::mission_json;
//!
//! let items = mission_json::parse(r#"{"items": [{"frame": 3, "command": 22, "z": 20}]}"#)?;
//! assert_eq!((items[0].command, items[0].z, items[0].autocontinue), (MavCmd::NAV_TAKEOFF, 20.0, 1));
//! assert!(items[0].param1.is_nan());
//! let text = mission_json::to_json(MavMissionType::MISSION, &items).to_string();
//! assert!(text.starts_with(r#"{"mission_type":"mission","items":[{"seq":0,"frame":3,"command":22,"command_name":"MAV_CMD_NAV_TAKEOFF""#));
//! # Ok::<(), mavstack_services::mission_json::MissionJsonError>(())
//! ```

use alloc::format;
use alloc::string::{String, ToString as _};
use alloc::vec::Vec;

use mavstack_dialects::common::{MavCmd, MavFrame, MavMissionType, MissionItemInt};
use serde_json::{Map, Value as Json, json};

/// Why a JSON plan was not read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MissionJsonError {
    /// The text is not JSON, or not an object with an `items` array.
    #[error("{0}")]
    Document(String),
    /// An item is wrong: its index and what is wrong with which key.
    #[error("item {index}: {what}")]
    Item {
        /// The item's index in `items`.
        index: usize,
        /// What is wrong, naming the key.
        what: String,
    },
}

/// The plan type's name in the JSON format (`mission`, `fence`, `rally`).
#[must_use]
pub fn type_name(t: MavMissionType) -> &'static str {
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
#[must_use]
pub fn item_json(it: &MissionItemInt) -> Json {
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

/// A plan as a JSON document.
#[must_use]
pub fn to_json(mission_type: MavMissionType, items: &[MissionItemInt]) -> Json {
    json!({
        "mission_type": type_name(mission_type),
        "items": items.iter().map(item_json).collect::<Vec<_>>(),
    })
}

/// A JSON plan's items.
///
/// # Errors
/// [`MissionJsonError::Document`] for text that is not a JSON object with an `items`
/// array, [`MissionJsonError::Item`] naming the item and key that are wrong.
pub fn parse(text: &str) -> Result<Vec<MissionItemInt>, MissionJsonError> {
    let doc: Json = serde_json::from_str(text)
        .map_err(|e| MissionJsonError::Document(format!("not JSON: {e}")))?;
    let items = doc.get("items").and_then(Json::as_array).ok_or_else(|| {
        MissionJsonError::Document("expected an object with an \"items\" array".to_string())
    })?;
    items
        .iter()
        .enumerate()
        .map(|(index, v)| item(v, index).map_err(|what| MissionJsonError::Item { index, what }))
        .collect()
}

fn item(v: &Json, seq: usize) -> Result<MissionItemInt, String> {
    let int = |key: &str, default: Option<i64>| -> Result<i64, String> {
        match v.get(key) {
            None => default.ok_or_else(|| format!("missing \"{key}\"")),
            Some(x) => x
                .as_i64()
                .ok_or_else(|| format!("\"{key}\" must be an integer, got {x}")),
        }
    };
    let float = |key: &str| -> Result<f32, String> {
        match v.get(key) {
            // Absent: unused (NaN) for a parameter, 0 for the altitude.
            None => Ok(if key == "z" { 0.0 } else { f32::NAN }),
            // What the writer writes for NaN (and the infinities).
            Some(Json::Null) => Ok(f32::NAN),
            Some(x) => {
                let f = x
                    .as_f64()
                    .ok_or_else(|| format!("\"{key}\" must be a number or null, got {x}"))?;
                // The nearest f32, which is what MISSION_ITEM_INT carries.
                let narrowed = f as f32;
                if narrowed.is_finite() {
                    Ok(narrowed)
                } else {
                    Err(format!(
                        "\"{key}\" {f} is beyond the range of a 32-bit float"
                    ))
                }
            }
        }
    };
    let ranged = |key: &str, max: u16| -> Result<u16, String> {
        let value = int(key, None)?;
        u16::try_from(value)
            .ok()
            .filter(|&n| n <= max)
            .ok_or_else(|| format!("\"{key}\" {value} is out of range 0-{max}"))
    };
    let coordinate = |key: &str| -> Result<i32, String> {
        let x = int(key, Some(0))?;
        i32::try_from(x).map_err(|_| format!("\"{key}\" {x} does not fit degE7"))
    };
    Ok(MissionItemInt {
        seq: u16::try_from(seq).map_err(|_| "more than 65,535 items".to_string())?,
        frame: MavFrame(u8::try_from(ranged("frame", 255)?).unwrap_or(u8::MAX)),
        command: MavCmd(ranged("command", u16::MAX)?),
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

/// Fuzzing entry point: any bytes, as text, parse to items or an error naming the item,
/// never a panic; what parses is written back to a document that reads back to itself
/// (the written form is a fixed point).
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_mission_json(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let Ok(items) = parse(&text) else { return };
    let written = to_json(MavMissionType::MISSION, &items).to_string();
    let again = parse(&written).expect("a written plan reads back");
    assert_eq!(again.len(), items.len());
    assert_eq!(
        to_json(MavMissionType::MISSION, &again).to_string(),
        written,
        "a written plan does not read back to itself"
    );
}
