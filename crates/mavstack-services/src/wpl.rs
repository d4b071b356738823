//! Mission plans as QGroundControl's `QGC WPL 110` text (also MAVProxy's and Mission
//! Planner's `.waypoints` files).
//!
//! A `QGC WPL 110` line, then one tab- or space-separated line per item:
//! `SEQ CURRENT FRAME COMMAND P1 P2 P3 P4 X Y Z AUTOCONTINUE`, with X/Y in degrees for global
//! frames (metres for local ones); `nan` is a parameter left unset. Items are renumbered in
//! file order (the SEQ column is not trusted).
//!
//! ```
//! use mavstack_services::wpl;
//! let text = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.363261\t149.165230\t584\t1\n";
//! let items = wpl::parse(text).unwrap();
//! assert_eq!(items[0].x, -353_632_610); // degE7, as MISSION_ITEM_INT carries it
//! assert_eq!(wpl::parse(&wpl::to_text(&items)).unwrap(), items);
//! let err = wpl::parse("QGC WPL 110\n0 1 0 16\n").unwrap_err();
//! assert_eq!(err.to_string(), "line 2: expected 12 fields (SEQ CURRENT FRAME COMMAND P1 P2 P3 P4 X Y Z AUTOCONTINUE), got 4");
//! ```

use alloc::format;
use alloc::string::String;
use alloc::vec::Vec;
use core::fmt::Write as _;

use mavstack_dialects::common::{MavCmd, MavFrame, MissionItemInt};

use crate::mission::is_global;

/// Why a WPL text cannot be read.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum WplError {
    /// The first line is not `QGC WPL 110`.
    #[error("line 1: expected \"QGC WPL 110\", got {found:?}")]
    Header {
        /// What it was (at most 40 characters of it).
        found: String,
    },
    /// The text is empty.
    #[error("empty file: expected \"QGC WPL 110\"")]
    Empty,
    /// An item line is wrong.
    #[error("line {line}: {what}")]
    Line {
        /// Its number, from 1.
        line: usize,
        /// What is wrong.
        what: String,
    },
    /// More items than a plan can hold.
    #[error("more than 65,535 items")]
    TooMany,
}

/// The scale between file units and MISSION_ITEM_INT's integers.
fn scale(frame: MavFrame) -> f64 {
    if is_global(frame) { 1e7 } else { 1e4 }
}

fn push_f32(out: &mut String, v: f32) {
    if v.is_nan() {
        out.push_str("nan");
    } else {
        let _ = write!(out, "{v}");
    }
}

/// The plan as `QGC WPL 110` text, items numbered from 0 in order.
#[must_use]
pub fn to_text(items: &[MissionItemInt]) -> String {
    let mut out = String::from("QGC WPL 110\n");
    for (i, it) in items.iter().enumerate() {
        let s = scale(it.frame);
        let _ = write!(
            out,
            "{i}\t{}\t{}\t{}\t",
            it.current, it.frame.0, it.command.0
        );
        for p in [it.param1, it.param2, it.param3, it.param4] {
            push_f32(&mut out, p);
            out.push('\t');
        }
        for v in [it.x, it.y] {
            if is_global(it.frame) {
                let _ = write!(out, "{:.8}\t", f64::from(v) / s);
            } else {
                let _ = write!(out, "{}\t", f64::from(v) / s);
            }
        }
        push_f32(&mut out, it.z);
        let _ = writeln!(out, "\t{}", it.autocontinue);
    }
    out
}

/// The items of a `QGC WPL 110` text.
///
/// # Errors
/// [`WplError`] naming the line and the field at fault.
pub fn parse(text: &str) -> Result<Vec<MissionItemInt>, WplError> {
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, first)) if first.trim().starts_with("QGC WPL 110") => {}
        Some((_, first)) => {
            return Err(WplError::Header {
                found: first.trim().chars().take(40).collect(),
            });
        }
        None => return Err(WplError::Empty),
    }
    let mut items = Vec::new();
    for (i, line) in lines {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let seq = u16::try_from(items.len()).map_err(|_| WplError::TooMany)?;
        let item = item(line, seq).map_err(|what| WplError::Line { line: i + 1, what })?;
        items.push(item);
    }
    Ok(items)
}

/// One item line; the error says what is wrong.
fn item(line: &str, seq: u16) -> Result<MissionItemInt, String> {
    let fields: Vec<&str> = line.split_whitespace().collect();
    if fields.len() != 12 {
        return Err(format!(
            "expected 12 fields (SEQ CURRENT FRAME COMMAND P1 P2 P3 P4 X Y Z AUTOCONTINUE), got {}",
            fields.len()
        ));
    }
    let quoted = |i: usize| -> String { fields[i].chars().take(40).collect() };
    let int = |i: usize, what: &str| -> Result<u16, String> {
        fields[i]
            .parse::<u16>()
            .map_err(|_| format!("{what} {:?} is not a number 0-65535", quoted(i)))
    };
    let float = |i: usize, what: &str| -> Result<f64, String> {
        fields[i]
            .parse::<f64>()
            .map_err(|_| format!("{what} {:?} is not a number", quoted(i)))
    };
    // A parameter is an f32: a value beyond its range is an error, not infinity.
    let param = |i: usize, what: &str| -> Result<f32, String> {
        let v = float(i, what)?;
        let narrowed = v as f32;
        if v.is_finite() && !narrowed.is_finite() {
            return Err(format!("{what} {v} is beyond the range of a 32-bit float"));
        }
        Ok(narrowed)
    };
    let frame = MavFrame(
        u8::try_from(int(2, "frame")?)
            .map_err(|_| format!("frame {:?} is above 255", quoted(2)))?,
    );
    let s = scale(frame);
    let fixed = |i: usize, what: &str| -> Result<i32, String> {
        let v = float(i, what)?;
        let scaled = (v * s).round();
        if scaled.is_nan() {
            return Ok(0);
        }
        if scaled.abs() > f64::from(i32::MAX) {
            return Err(format!("{what} {v} is out of range"));
        }
        Ok(scaled as i32)
    };
    Ok(MissionItemInt {
        seq,
        current: u8::from(int(1, "current")? != 0),
        frame,
        command: MavCmd(int(3, "command")?),
        param1: param(4, "param1")?,
        param2: param(5, "param2")?,
        param3: param(6, "param3")?,
        param4: param(7, "param4")?,
        x: fixed(8, "x")?,
        y: fixed(9, "y")?,
        z: param(10, "z")?,
        autocontinue: u8::from(int(11, "autocontinue")? != 0),
        ..MissionItemInt::default()
    })
}

/// Fuzzing entry point: any bytes, as text, parse to items or a line-numbered error, never a
/// panic; what parses writes back to text that parses to the same items.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_wpl(data: &[u8]) {
    use alloc::string::ToString as _;

    let text = String::from_utf8_lossy(data);
    match parse(&text) {
        Ok(items) => {
            let again = parse(&to_text(&items));
            let same = again.as_ref().is_ok_and(|a| {
                a.len() == items.len()
                    && a.iter().zip(&items).all(|(a, b)| {
                        (
                            a.seq,
                            a.frame,
                            a.command,
                            a.x,
                            a.y,
                            a.current,
                            a.autocontinue,
                        ) == (
                            b.seq,
                            b.frame,
                            b.command,
                            b.x,
                            b.y,
                            b.current,
                            b.autocontinue,
                        ) && [a.param1, a.param2, a.param3, a.param4, a.z]
                            .iter()
                            .zip([b.param1, b.param2, b.param3, b.param4, b.z])
                            .all(|(x, y)| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()))
                    })
            });
            assert!(same, "{items:?} wrote back as {again:?}");
        }
        Err(WplError::Line { line, .. }) => {
            assert!(line >= 2 && line <= text.lines().count(), "line {line}");
        }
        Err(e) => {
            let _ = e.to_string();
        }
    }
}
