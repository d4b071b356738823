//! The simulated vehicle's parameter table: each flavour's defaults, and parameter files.
//!
//! A parameter file has one parameter per line, in any of the formats ground stations
//! save: `NAME VALUE` (MAVProxy), `NAME,VALUE` (Mission Planner) or QGroundControl's
//! tab-separated `SYSID COMPID NAME VALUE TYPE`. `#` starts a comment. Without a type, a
//! value written as an integer (`12`, `-3`) is an INT32 and any other (`12.0`, `1e3`) a
//! REAL32.

use mavstack_dialects::common::MavParamType;
use mavstack_services::param::{Name, Value};

use crate::Autopilot;

/// ArduPilot Copter's names, types and defaults (a representative subset, with the names of
/// ArduPilot 4.7, which renamed `SYSID_THISMAV`, `SYSID_MYGCS`, `GPS_TYPE` and `SRn_*` to
/// `MAV_SYSID`, `MAV_GCS_SYSID`, `GPS1_TYPE` and `MAVn_*`; types as its SITL reports them).
const ARDUPILOT: &[(&str, Value)] = &[
    ("MAV_SYSID", Value::I16(1)),
    ("MAV_GCS_SYSID", Value::I16(255)),
    ("FORMAT_VERSION", Value::I16(120)),
    ("FRAME_CLASS", Value::I8(1)),
    ("FRAME_TYPE", Value::I8(1)),
    ("ARMING_CHECK", Value::I32(1)),
    ("DISARM_DELAY", Value::I8(10)),
    ("PILOT_TKOFF_ALT", Value::F32(0.0)),
    ("WPNAV_SPEED", Value::F32(500.0)),
    ("WPNAV_SPEED_UP", Value::F32(250.0)),
    ("WPNAV_SPEED_DN", Value::F32(150.0)),
    ("WPNAV_RADIUS", Value::F32(200.0)),
    ("LAND_SPEED", Value::I16(50)),
    ("RTL_ALT", Value::I32(1500)),
    ("RTL_SPEED", Value::I16(0)),
    ("LOIT_SPEED", Value::F32(1250.0)),
    ("ANGLE_MAX", Value::I16(3000)),
    ("BATT_MONITOR", Value::I8(4)),
    ("BATT_CAPACITY", Value::I32(5000)),
    ("BATT_LOW_VOLT", Value::F32(14.0)),
    ("FENCE_ENABLE", Value::I8(0)),
    ("FENCE_ALT_MAX", Value::F32(100.0)),
    ("FENCE_RADIUS", Value::F32(300.0)),
    ("FS_THR_ENABLE", Value::I8(1)),
    ("FS_GCS_ENABLE", Value::I8(0)),
    ("MOT_SPIN_ARM", Value::F32(0.1)),
    ("MOT_SPIN_MIN", Value::F32(0.15)),
    ("ATC_RAT_RLL_P", Value::F32(0.135)),
    ("ATC_RAT_PIT_P", Value::F32(0.135)),
    ("ATC_RAT_YAW_P", Value::F32(0.18)),
    ("COMPASS_USE", Value::I8(1)),
    ("GPS1_TYPE", Value::I8(1)),
    ("SERIAL0_BAUD", Value::I32(115)),
    ("MAV1_POSITION", Value::I16(4)),
    ("MAV1_EXTRA1", Value::I16(4)),
];

/// PX4's names, types and defaults (a representative subset; PX4 uses only INT32/REAL32).
const PX4: &[(&str, Value)] = &[
    ("SYS_AUTOSTART", Value::I32(4001)),
    ("SYS_HITL", Value::I32(0)),
    ("MAV_SYS_ID", Value::I32(1)),
    ("MAV_COMP_ID", Value::I32(1)),
    ("MAV_TYPE", Value::I32(2)),
    ("COM_ARM_WO_GPS", Value::I32(1)),
    ("COM_DISARM_LAND", Value::F32(2.0)),
    ("COM_RC_IN_MODE", Value::I32(1)),
    ("MIS_TAKEOFF_ALT", Value::F32(2.5)),
    ("MPC_XY_CRUISE", Value::F32(5.0)),
    ("MPC_Z_VEL_MAX_UP", Value::F32(3.0)),
    ("MPC_Z_VEL_MAX_DN", Value::F32(1.5)),
    ("MPC_LAND_SPEED", Value::F32(0.7)),
    ("NAV_ACC_RAD", Value::F32(2.0)),
    ("NAV_DLL_ACT", Value::I32(0)),
    ("RTL_RETURN_ALT", Value::F32(30.0)),
    ("RTL_DESCEND_ALT", Value::F32(10.0)),
    ("BAT1_CAPACITY", Value::F32(5000.0)),
    ("BAT1_N_CELLS", Value::I32(4)),
    ("BAT1_V_CHARGED", Value::F32(4.2)),
    ("BAT1_V_EMPTY", Value::F32(3.5)),
    ("GF_ACTION", Value::I32(2)),
    ("GF_MAX_HOR_DIST", Value::F32(0.0)),
    ("GF_MAX_VER_DIST", Value::F32(0.0)),
    ("MC_ROLLRATE_P", Value::F32(0.15)),
    ("MC_PITCHRATE_P", Value::F32(0.15)),
    ("MC_YAWRATE_P", Value::F32(0.2)),
    ("CAL_ACC0_ID", Value::I32(1_310_988)),
    ("CAL_GYRO0_ID", Value::I32(1_310_988)),
    ("CAL_MAG0_ID", Value::I32(197_388)),
    ("SENS_BOARD_ROT", Value::I32(0)),
    ("EKF2_HGT_REF", Value::I32(1)),
];

/// A flavour's default table.
pub fn defaults(autopilot: Autopilot) -> Vec<(Name, Value)> {
    let table = match autopilot {
        Autopilot::Ardupilot => ARDUPILOT,
        Autopilot::Px4 => PX4,
    };
    table
        .iter()
        // The names above are valid (checked by a test).
        .filter_map(|&(name, value)| Name::new(name).ok().map(|n| (n, value)))
        .collect()
}

/// Why a parameter file could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ParamFileError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A line is not a parameter (`LINE: what`, prefixed with the file by [`load`]).
    #[error("{}{line}: {message}", path.as_ref().map(|p| format!("{p}:")).unwrap_or_default())]
    Line {
        /// The file, when read by [`load`].
        path: Option<String>,
        /// The line, from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// More parameters than the protocol can index.
    #[error("{count} parameters: at most 65,534 fit the protocol")]
    TooMany {
        /// How many the file has.
        count: usize,
    },
}

/// A parameter file's table, in file order (a name given twice keeps its last value).
///
/// # Errors
/// [`ParamFileError`]: the file cannot be read, or a line is not a parameter (naming the
/// file and line).
pub fn load(path: &str) -> Result<Vec<(Name, Value)>, ParamFileError> {
    let text = std::fs::read_to_string(path).map_err(|source| ParamFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    parse(&text).map_err(|e| match e {
        ParamFileError::Line { line, message, .. } => ParamFileError::Line {
            path: Some(path.to_owned()),
            line,
            message,
        },
        other => other,
    })
}

/// Fuzzing entry point: any bytes, as text, parse to a table or a line-numbered error,
/// never a panic; every value parsed is finite and names are unique.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_param_file(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    match parse(&text) {
        Ok(table) => {
            for (i, (name, value)) in table.iter().enumerate() {
                assert!(value.as_f64().is_finite(), "{name}: {value:?}");
                assert!(
                    table[..i].iter().all(|(n, _)| n != name),
                    "{name} twice in the table"
                );
            }
        }
        Err(ParamFileError::Line { line, .. }) => {
            assert!(line >= 1 && line <= text.lines().count(), "line {line}");
        }
        Err(_) => {}
    }
}

/// Parses a parameter file's text.
///
/// # Errors
/// [`ParamFileError::Line`] for a line that is not a parameter, [`ParamFileError::TooMany`].
pub fn parse(text: &str) -> Result<Vec<(Name, Value)>, ParamFileError> {
    let mut table: Vec<(Name, Value)> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let (name, value) = parse_line(line).map_err(|message| ParamFileError::Line {
            path: None,
            line: i + 1,
            message,
        })?;
        match table.iter_mut().find(|(n, _)| *n == name) {
            Some(slot) => slot.1 = value,
            None => table.push((name, value)),
        }
    }
    if table.len() >= usize::from(u16::MAX) {
        return Err(ParamFileError::TooMany { count: table.len() });
    }
    Ok(table)
}

fn parse_line(line: &str) -> Result<(Name, Value), String> {
    let tabbed: Vec<&str> = line.split('\t').map(str::trim).collect();
    let (name, value, ty) = if tabbed.len() == 5 {
        // QGroundControl: SYSID COMPID NAME VALUE TYPE.
        let ty: u8 = tabbed[4]
            .parse()
            .map_err(|_| format!("type {:?} is not a MAV_PARAM_TYPE number", tabbed[4]))?;
        (tabbed[2], tabbed[3], Some(MavParamType(ty)))
    } else {
        let fields: Vec<&str> = line
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|f| !f.is_empty())
            .collect();
        match fields.as_slice() {
            [name, value] => (*name, *value, None),
            _ => {
                return Err(format!(
                    "expected NAME VALUE, NAME,VALUE or a QGroundControl line, got {line:?}"
                ));
            }
        }
    };
    let name = Name::new(name).map_err(|e| format!("parameter name {name:?}: {e}"))?;
    let number: f64 = value
        .parse()
        .map_err(|_| format!("value {value:?} of {name} is not a number"))?;
    if !number.is_finite() {
        return Err(format!("value {value:?} of {name} is not finite"));
    }
    let written_as_integer = value
        .bytes()
        .all(|b| b.is_ascii_digit() || b == b'-' || b == b'+');
    let ty = ty.unwrap_or(if written_as_integer {
        MavParamType::INT32
    } else {
        MavParamType::REAL32
    });
    let value = typed(number, ty)
        .ok_or_else(|| format!("value {value} of {name} does not fit type {ty:?}"))?;
    Ok((name, value))
}

/// `number` as a value of type `ty`, if it is exactly representable (for REAL32: any
/// number within its range, rounded).
fn typed(number: f64, ty: MavParamType) -> Option<Value> {
    if ty == MavParamType::REAL32 {
        // Beyond f32's range the cast gives infinity: not a value a vehicle can hold.
        let value = number as f32;
        return value.is_finite().then_some(Value::F32(value));
    }
    if number.fract() != 0.0 {
        return None;
    }
    // Integral and finite: `as i64` is exact below 2^63, the range checks do the rest.
    let n = number as i64;
    Some(match ty {
        MavParamType::UINT8 => Value::U8(u8::try_from(n).ok()?),
        MavParamType::INT8 => Value::I8(i8::try_from(n).ok()?),
        MavParamType::UINT16 => Value::U16(u16::try_from(n).ok()?),
        MavParamType::INT16 => Value::I16(i16::try_from(n).ok()?),
        MavParamType::UINT32 => Value::U32(u32::try_from(n).ok()?),
        MavParamType::INT32 => Value::I32(i32::try_from(n).ok()?),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_real_beyond_f32_is_an_error() {
        // Found by the param_file fuzz target: 255e303 is a finite f64 but an infinite f32.
        let e = parse("BIG 255e303\n").unwrap_err().to_string();
        assert!(e.contains("does not fit type"), "{e}");
        assert!(parse("BIG 3.4e38\n").is_ok());
    }

    #[test]
    fn every_default_name_is_valid() {
        assert_eq!(defaults(Autopilot::Ardupilot).len(), ARDUPILOT.len());
        assert_eq!(defaults(Autopilot::Px4).len(), PX4.len());
    }

    #[test]
    fn reads_the_three_file_formats() {
        let table = parse(
            "# saved by hand\nRTL_ALT 2000\nWPNAV_SPEED,750.5\nANGLE 30.0\n1\t1\tFENCE_ENABLE\t1\t2\n\nRTL_ALT 2500\n",
        )
        .expect("valid");
        let got: Vec<(String, Value)> = table
            .iter()
            .map(|(n, v)| (n.as_str().to_owned(), *v))
            .collect();
        assert_eq!(
            got,
            [
                ("RTL_ALT".to_owned(), Value::I32(2500)),
                ("WPNAV_SPEED".to_owned(), Value::F32(750.5)),
                ("ANGLE".to_owned(), Value::F32(30.0)),
                ("FENCE_ENABLE".to_owned(), Value::I8(1)),
            ]
        );
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse("A 1\nB x\n").expect_err("bad value");
        assert_eq!(e.to_string(), "2: value \"x\" of B is not a number");
        let e = parse("THIS_NAME_IS_FAR_TOO_LONG 1\n").expect_err("long name");
        assert!(e.to_string().starts_with("1: parameter name"), "{e}");
        let e = parse("1\t1\tX\t300\t2\n").expect_err("INT8 overflow");
        assert!(e.to_string().contains("does not fit"), "{e}");
    }
}
