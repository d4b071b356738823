//! Frames as JSON lines (the `mavstack decode`/`encode` contract): a frame written as one
//! JSON object, and an object read back into a frame.
//!
//! A line holds `version`, `seq`, `sysid`, `compid`, `msgid`, `name` and `fields` (in XML
//! order; `char[N]` fields as text, one character per byte; floats as the shortest decimal
//! that reads back to the same value, NaN and the infinities as `"NaN"`, `"inf"`, `"-inf"`),
//! and, for signed frames, `signature` (`link_id`, `timestamp`, `status`). Reading back,
//! every key but `msgid` or `name` is optional.
//!
//! ```
//! use mavstack_core::wire::{Frame, MAX_FRAME_LEN};
//! use mavstack_xml::json::{self, EncodeDefaults};
//!
//! let dialect = mavstack_xml::load("common")?;
//! let obj = serde_json::from_str(r#"{"name":"HEARTBEAT","fields":{"type":2,"autopilot":3}}"#)?;
//! let mut buf = [0u8; MAX_FRAME_LEN];
//! let mut seq = 7;
//! let len = json::encode_object(&obj, &dialect, &EncodeDefaults::default(), None, &mut seq, &mut buf)?;
//! let frame = Frame::new_checked(&buf[..len])?;
//! assert_eq!((frame.seq(), frame.sysid(), frame.msg_id()), (7, 255, 0));
//!
//! let mut line = String::new();
//! json::frame_line(&mut line, &frame, dialect.message(0), None, None);
//! assert!(line.starts_with(r#"{"version":2,"seq":7,"sysid":255,"compid":190,"msgid":0,"name":"HEARTBEAT","fields":{"type":2,"autopilot":3,"#));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use core::fmt::Write as _;

use mavstack_core::signing::{self, SecretKey};
use mavstack_core::wire::{Frame, FrameHeader, MAX_FRAME_LEN, Version, emit};
use mavstack_core::{MAX_PAYLOAD_LEN, MessageInfo};
use serde_json::{Map, Value as Json};

use crate::codec::{self, Value};
use crate::{Dialect, Field, Message, PrimitiveType};

/// Appends `s` as a JSON string.
fn push_str(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if u32::from(c) < 0x20 || c == '\u{7f}' => {
                let _ = write!(out, "\\u{:04x}", u32::from(c));
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

/// `char[N]` bytes as text: one character per byte, bytes that are not ASCII mapping to
/// U+0080–U+00FF (Latin-1), so no byte is lost.
fn text_of(bytes: &[u8]) -> String {
    bytes.iter().map(|&b| char::from(b)).collect()
}

/// A float as the shortest decimal that reads back to the same value of its type (`Debug`
/// prints exactly that), with NaN and the infinities as the strings of the contract.
fn push_float(out: &mut String, v: impl core::fmt::Debug, nan: bool, infinite: Option<bool>) {
    match (nan, infinite) {
        (true, _) => out.push_str("\"NaN\""),
        (false, Some(positive)) => out.push_str(if positive { "\"inf\"" } else { "\"-inf\"" }),
        (false, None) => {
            let _ = write!(out, "{v:?}");
        }
    }
}

/// Appends one value as JSON.
fn push_value(out: &mut String, v: &Value) {
    match v {
        Value::U8(x) => push_int(out, *x),
        Value::I8(x) => push_int(out, *x),
        Value::U16(x) => push_int(out, *x),
        Value::I16(x) => push_int(out, *x),
        Value::U32(x) => push_int(out, *x),
        Value::I32(x) => push_int(out, *x),
        Value::U64(x) => push_int(out, *x),
        Value::I64(x) => push_int(out, *x),
        Value::F32(x) => push_float(out, x, x.is_nan(), x.is_infinite().then_some(*x > 0.0)),
        Value::F64(x) => push_float(out, x, x.is_nan(), x.is_infinite().then_some(*x > 0.0)),
        Value::Text(bytes) => push_str(out, &text_of(bytes)),
        Value::Array(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                push_value(out, item);
            }
            out.push(']');
        }
    }
}

fn push_int(out: &mut String, v: impl core::fmt::Display) {
    let _ = write!(out, "{v}");
}

/// Appends `"fields":{...}` for a decoded message, fields in XML order.
fn push_fields(out: &mut String, message: &Message, values: &[Value]) {
    out.push_str("\"fields\":{");
    let mut order: Vec<usize> = (0..message.fields.len()).collect();
    order.sort_by_key(|&i| {
        (
            message.fields[i].location.line,
            message.fields[i].location.column,
        )
    });
    for (n, &i) in order.iter().enumerate() {
        if n > 0 {
            out.push(',');
        }
        push_str(out, &message.fields[i].name);
        out.push(':');
        push_value(out, &values[i]);
    }
    out.push('}');
}

/// A JSON value read back into the value of `field`.
///
/// # Errors
/// A message naming the field and what is wrong.
fn value_from_json(field: &Field, json: &Json) -> Result<Value, String> {
    let p = field.ty.primitive;
    if p == PrimitiveType::Char {
        let Json::String(s) = json else {
            return Err(format!(
                "field {}: expected a string, got {json}",
                field.name
            ));
        };
        let mut bytes = Vec::with_capacity(s.len());
        for c in s.chars() {
            let b = u8::try_from(u32::from(c)).map_err(|_| {
                format!(
                    "field {}: character {c:?} is not one byte (U+0000 to U+00FF)",
                    field.name
                )
            })?;
            bytes.push(b);
        }
        let max = usize::from(field.ty.array_len.unwrap_or(1));
        if bytes.len() > max {
            return Err(format!(
                "field {}: text of {} bytes is longer than {max}",
                field.name,
                bytes.len()
            ));
        }
        return Ok(Value::Text(bytes));
    }
    match field.ty.array_len {
        Some(n) => {
            let Json::Array(items) = json else {
                return Err(format!(
                    "field {}: expected an array, got {json}",
                    field.name
                ));
            };
            if items.len() > usize::from(n) {
                return Err(format!(
                    "field {}: {} elements, at most {n}",
                    field.name,
                    items.len()
                ));
            }
            items
                .iter()
                .map(|j| scalar_from_json(field, p, j))
                .collect::<Result<Vec<_>, _>>()
                .map(Value::Array)
        }
        None => scalar_from_json(field, p, json),
    }
}

fn scalar_from_json(field: &Field, p: PrimitiveType, json: &Json) -> Result<Value, String> {
    let bad = || format!("field {}: {json} is not a valid {}", field.name, p.c_name());
    if p.is_float() {
        let v = match json {
            Json::Number(n) => n.as_f64().ok_or_else(bad)?,
            Json::String(s) if s == "NaN" => f64::NAN,
            Json::String(s) if s == "inf" => f64::INFINITY,
            Json::String(s) if s == "-inf" => f64::NEG_INFINITY,
            _ => return Err(bad()),
        };
        return Ok(if p == PrimitiveType::F32 {
            // The shortest decimal of an f32 reads back exactly through f64.
            Value::F32(v as f32)
        } else {
            Value::F64(v)
        });
    }
    let Json::Number(n) = json else {
        return Err(bad());
    };
    let v = n
        .as_i64()
        .map(i128::from)
        .or_else(|| n.as_u64().map(i128::from))
        .ok_or_else(bad)?;
    let out = match p {
        PrimitiveType::U8 => u8::try_from(v).ok().map(Value::U8),
        PrimitiveType::I8 => i8::try_from(v).ok().map(Value::I8),
        PrimitiveType::U16 => u16::try_from(v).ok().map(Value::U16),
        PrimitiveType::I16 => i16::try_from(v).ok().map(Value::I16),
        PrimitiveType::U32 => u32::try_from(v).ok().map(Value::U32),
        PrimitiveType::I32 => i32::try_from(v).ok().map(Value::I32),
        PrimitiveType::U64 => u64::try_from(v).ok().map(Value::U64),
        PrimitiveType::I64 => i64::try_from(v).ok().map(Value::I64),
        PrimitiveType::F32 | PrimitiveType::F64 | PrimitiveType::Char => None,
    };
    out.ok_or_else(bad)
}

/// What [`frame_line`] found of a frame's signature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SignatureStatus {
    /// The frame is not signed.
    Unsigned,
    /// Signed, and no key was given to check it.
    Unchecked,
    /// Signed, and it verifies with the key.
    Valid,
    /// Signed, and it does not verify with the key.
    Invalid,
}

/// Appends `frame` as one JSON line (with its newline) to `out`: decoded with `message`
/// when given, else with `"name":null` and the payload as `"payload_hex"`; `ts_us` (a tlog
/// record's time) as `"ts_us"`; a signature checked with `key` when given.
pub fn frame_line(
    out: &mut String,
    frame: &Frame<&[u8]>,
    message: Option<&Message>,
    ts_us: Option<u64>,
    key: Option<&SecretKey>,
) -> SignatureStatus {
    out.push('{');
    if let Some(ts) = ts_us {
        let _ = write!(out, "\"ts_us\":{ts},");
    }
    let _ = write!(
        out,
        "\"version\":{},\"seq\":{},\"sysid\":{},\"compid\":{},\"msgid\":{},\"name\":",
        frame.version().number(),
        frame.seq(),
        frame.sysid(),
        frame.compid(),
        frame.msg_id()
    );
    match message {
        Some(m) => {
            push_str(out, &m.name);
            out.push(',');
            let values = codec::decode(m, frame.payload());
            push_fields(out, m, &values);
        }
        None => {
            out.push_str("null,\"payload_hex\":\"");
            for b in frame.payload() {
                let _ = write!(out, "{b:02x}");
            }
            out.push('"');
        }
    }
    let mut status = SignatureStatus::Unsigned;
    if let Some(sig) = frame.signature() {
        status = match key {
            None => SignatureStatus::Unchecked,
            Some(k) if signing::verify(frame, k).is_ok() => SignatureStatus::Valid,
            Some(_) => SignatureStatus::Invalid,
        };
        let name = match status {
            SignatureStatus::Valid => "valid",
            SignatureStatus::Invalid => "invalid",
            _ => "unchecked",
        };
        let _ = write!(
            out,
            ",\"signature\":{{\"link_id\":{},\"timestamp\":{},\"status\":\"{name}\"}}",
            sig.link_id, sig.timestamp
        );
    }
    out.push_str("}\n");
    status
}

/// What [`encode_object`] puts in a frame whose object does not say.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncodeDefaults {
    /// System id (default 255, a ground station's).
    pub sysid: u8,
    /// Component id (default 190, `MAV_COMP_ID_MISSIONPLANNER`).
    pub compid: u8,
    /// Link id of signed frames (default 0).
    pub link_id: u8,
    /// Signing timestamp (10 µs units since 2015) of signed frames; `None` for the wall
    /// clock.
    pub timestamp: Option<u64>,
}

impl Default for EncodeDefaults {
    fn default() -> Self {
        Self {
            sysid: 255,
            compid: 190,
            link_id: 0,
            timestamp: None,
        }
    }
}

/// Why an object could not be encoded: the message names the key and what is wrong with it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct JsonError(String);

impl From<String> for JsonError {
    fn from(message: String) -> Self {
        Self(message)
    }
}

fn field_of<'o>(obj: &'o Map<String, Json>, key: &str) -> Option<&'o Json> {
    obj.get(key).filter(|v| !v.is_null())
}

fn small(obj: &Map<String, Json>, key: &str, max: u64) -> Result<Option<u64>, String> {
    match field_of(obj, key) {
        None => Ok(None),
        Some(v) => v
            .as_u64()
            .filter(|&n| n <= max)
            .map(Some)
            .ok_or_else(|| format!("{key}: {v} is not a number from 0 to {max}")),
    }
}

fn byte(obj: &Map<String, Json>, key: &str, default: u8) -> Result<u8, String> {
    Ok(small(obj, key, 255)?.map_or(default, |v| u8::try_from(v).unwrap_or(u8::MAX)))
}

/// Encodes one JSON object (a line of [`frame_line`], or any object with `msgid` or `name`)
/// into `buf` and returns the frame's length. `seq` is used for objects without `"seq"` and
/// advanced past the sequence number sent; with `key`, MAVLink 2 frames are signed.
///
/// # Errors
/// A [`JsonError`] naming what is wrong: no message, a message not in `dialect`, a field
/// the message does not have, or a value that does not fit its field.
pub fn encode_object(
    obj: &Map<String, Json>,
    dialect: &Dialect,
    defaults: &EncodeDefaults,
    key: Option<&SecretKey>,
    seq: &mut u8,
    buf: &mut [u8; MAX_FRAME_LEN],
) -> Result<usize, JsonError> {
    let message = match (field_of(obj, "msgid"), field_of(obj, "name")) {
        (Some(id), _) => {
            let id = id
                .as_u64()
                .and_then(|i| u32::try_from(i).ok())
                .ok_or_else(|| format!("msgid: {id} is not a message id"))?;
            dialect
                .message(id)
                .ok_or_else(|| format!("message id {id} is not in dialect {}", dialect.name))?
        }
        (None, Some(Json::String(name))) => dialect
            .message_by_name(name)
            .ok_or_else(|| format!("message {name} is not in dialect {}", dialect.name))?,
        _ => return Err(JsonError("no \"msgid\" or \"name\"".to_owned())),
    };
    let version = match small(obj, "version", 2)? {
        None | Some(2) => Version::V2,
        Some(1) => Version::V1,
        Some(v) => return Err(JsonError(format!("version: {v} is neither 1 nor 2"))),
    };
    let empty = Map::new();
    let fields = match field_of(obj, "fields") {
        None => &empty,
        Some(Json::Object(f)) => f,
        Some(other) => {
            return Err(JsonError(format!(
                "fields: expected an object, got {other}"
            )));
        }
    };
    if let Some(unknown) = fields.keys().find(|k| message.field(k).is_none()) {
        return Err(JsonError(format!(
            "message {} has no field {unknown:?}",
            message.name
        )));
    }
    let values: Vec<Value> = message
        .fields
        .iter()
        .map(|f| {
            fields
                .get(&f.name)
                .map_or_else(|| Ok(Value::zero(&f.ty)), |j| value_from_json(f, j))
        })
        .collect::<Result<_, _>>()?;
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let len =
        codec::encode(message, &values, &mut payload).map_err(|e| JsonError(e.to_string()))?;
    let this_seq = byte(obj, "seq", *seq)?;
    *seq = this_seq.wrapping_add(1);
    let header = FrameHeader {
        version,
        seq: this_seq,
        sysid: byte(obj, "sysid", defaults.sysid)?,
        compid: byte(obj, "compid", defaults.compid)?,
        signed: key.is_some() && version == Version::V2,
    };
    // MAVLink 1 carries the base fields only (as the C library sends them). An object whose
    // extension fields are not all zero cannot be said that way: it goes out with the whole
    // payload, as pymavlink sends it, so that decode(encode(x)) == x still holds.
    let v1_len = if payload[message.min_len..len].iter().any(|&b| b != 0) {
        message.max_len
    } else {
        message.min_len
    };
    let info = MessageInfo {
        id: message.id,
        name: "",
        crc_extra: message.crc_extra,
        min_len: u8::try_from(v1_len).unwrap_or(u8::MAX),
        max_len: u8::try_from(message.max_len).unwrap_or(u8::MAX),
        target_system_offset: None,
        target_component_offset: None,
    };
    let frame_len =
        emit(&header, &info, &payload[..len], buf).map_err(|e| JsonError(e.to_string()))?;
    let Some(k) = key.filter(|_| header.signed) else {
        return Ok(frame_len);
    };
    let sig = field_of(obj, "signature").and_then(Json::as_object);
    let link_id = match sig {
        Some(s) => byte(s, "link_id", defaults.link_id)?,
        None => defaults.link_id,
    };
    let given = sig
        .map(|s| small(s, "timestamp", signing::MAX_TIMESTAMP))
        .transpose()?
        .flatten();
    let timestamp = given.or(defaults.timestamp).unwrap_or_else(|| {
        let now = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(u64::MAX));
        signing::timestamp_from_unix_micros(now)
    });
    signing::append_signature(buf, frame_len, link_id, timestamp, k)
        .map_err(|e| JsonError(e.to_string()))
}

/// Fuzzing entry point for JSON frame objects: every line of `data` that is a JSON object
/// is encoded with the `common` dialect (signed with a fixed key when its length is even);
/// whatever encodes must be a frame with the right checksum (and signature) whose JSON line
/// encodes again to a frame with the same JSON line (a line is a fixed point of decode ∘
/// encode). Never panics unless that fails.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_json_frames(data: &[u8]) {
    static COMMON: std::sync::OnceLock<Option<Dialect>> = std::sync::OnceLock::new();
    let Some(dialect) = COMMON.get_or_init(|| crate::load("common").ok()) else {
        return;
    };
    let Ok(text) = core::str::from_utf8(data) else {
        return;
    };
    let key = SecretKey::new([0x5a; 32]);
    let defaults = EncodeDefaults {
        timestamp: Some(1_000_000),
        ..EncodeDefaults::default()
    };
    for line in text.lines() {
        let Ok(obj) = serde_json::from_str::<Map<String, Json>>(line) else {
            continue;
        };
        let key = (line.len() % 2 == 0).then_some(&key);
        let (mut buf, mut seq) = ([0u8; MAX_FRAME_LEN], 0u8);
        let Ok(len) = encode_object(&obj, dialect, &defaults, key, &mut seq, &mut buf) else {
            continue;
        };
        let first = line_of(&buf[..len], dialect, key);
        let again: Map<String, Json> =
            serde_json::from_str(&first).expect("frame_line writes a JSON object");
        let len = encode_object(&again, dialect, &defaults, key, &mut seq, &mut buf)
            .expect("a written line encodes");
        assert_eq!(
            line_of(&buf[..len], dialect, key),
            first,
            "a JSON line is not a fixed point"
        );
    }
}

/// The JSON line of a frame [`encode_object`] wrote, checking what it must hold.
#[cfg(feature = "fuzzing")]
fn line_of(bytes: &[u8], dialect: &Dialect, key: Option<&SecretKey>) -> String {
    let frame = Frame::new_checked(bytes).expect("encode_object writes a frame");
    assert_eq!(frame.frame_len(), bytes.len(), "the frame's length");
    let message = dialect
        .message(frame.msg_id())
        .expect("a message of the dialect");
    assert!(frame.check_crc(message.crc_extra), "a bad checksum");
    let mut line = String::new();
    let status = frame_line(&mut line, &frame, Some(message), None, key);
    assert!(matches!(
        status,
        SignatureStatus::Unsigned | SignatureStatus::Valid
    ));
    line
}
