//! Messages as mavlink2rest 1.0.2 writes and reads them, for every message of a dialect.
//!
//! mavlink2rest serializes rust-mavlink's typed messages with serde; this module writes the
//! same objects from the run-time dialect model ([`mavstack_xml::Dialect`]), so that web
//! clients written against mavlink2rest read ours unchanged:
//!
//! - a message is an object with its name under `"type"` and one key per field, extension
//!   fields included, keys in alphabetical order (what 1.0.2's `serde_json::Value` keeps); a
//!   field called `type` is written `mavtype` (rust-mavlink's name for it);
//! - an enum field is `{"type":"ENTRY_NAME"}`; a bitmask field (an enum marked
//!   `bitmask="true"`, or a field with `display="bitmask"`) is the names of its set flags
//!   joined by `" | "` (`""` for none), in the enum's order;
//! - `char[N]` is a string (the bytes up to the first NUL); a lone `char` and every other
//!   array are numbers;
//! - floats are written as the `f64` of their value (a `float` 0.1 reads 0.10000000149011612,
//!   as 1.0.2's REST paths and WebSocket show it); NaN and the infinities are `null`.
//!
//! Where 1.0.2 drops a whole frame (an enum value with no entry, bits no flag names, a
//! `char[N]` that is not UTF-8), this module still writes it: the enum field as the plain
//! number, the unnamed bits as a hex term (`"FLAG_A | 0x40"`, bitflags' own text form), the
//! text with U+FFFD for the bad bytes.
//!
//! Reading ([`JsonMapping::parse_message`]) takes what 1.0.2 takes (every base field
//! required, extension fields optional and zero when left out) and also the forms above;
//! it is stricter where 1.0.2 would silently change the message: an unknown key, a string
//! longer than its field or holding a NUL, an integer out of its field's range, a float out
//! of `float` range are errors naming the field. `null` in a float field is NaN.

use std::collections::HashMap;
use std::sync::Arc;

use mavstack_core::MAX_PAYLOAD_LEN;
use mavstack_core::MessageInfo;
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit};
use mavstack_xml::codec::{self, Value};
use mavstack_xml::{Dialect, Field, Message, PrimitiveType};
use serde_json::{Map, Value as Json};

/// A message, header or request object that does not fit the dialect (the reason names the
/// key or the field).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct JsonError(String);

fn err<T>(text: impl Into<String>) -> Result<T, JsonError> {
    Err(JsonError(text.into()))
}

/// A frame's header as mavlink2rest writes it: `{"component_id","sequence","system_id"}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Header {
    /// The sender's system id.
    pub system_id: u8,
    /// The sender's component id.
    pub component_id: u8,
    /// The frame's sequence number.
    pub sequence: u8,
}

impl Default for Header {
    /// rust-mavlink's default header, the one 1.0.2's templates show: system 255,
    /// component 0, sequence 0.
    fn default() -> Self {
        Self {
            system_id: 255,
            component_id: 0,
            sequence: 0,
        }
    }
}

impl Header {
    /// The header object.
    #[must_use]
    pub fn to_json(self) -> Json {
        let mut map = Map::new();
        map.insert("component_id".into(), self.component_id.into());
        map.insert("sequence".into(), self.sequence.into());
        map.insert("system_id".into(), self.system_id.into());
        Json::Object(map)
    }

    /// Reads a header object: all three keys required, each a number from 0 to 255.
    ///
    /// # Errors
    /// A missing, unknown or out-of-range key.
    pub fn from_json(value: &Json) -> Result<Self, JsonError> {
        let Json::Object(map) = value else {
            return err("header: expected an object");
        };
        if let Some(k) = map
            .keys()
            .find(|k| !matches!(k.as_str(), "system_id" | "component_id" | "sequence"))
        {
            return err(format!("header: unknown key `{k}`"));
        }
        let get = |key: &str| -> Result<u8, JsonError> {
            let v = map
                .get(key)
                .ok_or_else(|| JsonError(format!("header: missing field `{key}`")))?;
            v.as_u64()
                .and_then(|n| u8::try_from(n).ok())
                .ok_or_else(|| JsonError(format!("header: `{key}` must be 0 to 255, got {v}")))
        };
        Ok(Self {
            system_id: get("system_id")?,
            component_id: get("component_id")?,
            sequence: get("sequence")?,
        })
    }
}

/// What a field holds beyond its primitive type.
#[derive(Debug)]
enum Kind {
    Plain,
    Enum(Arc<EnumNames>),
    Bitmask(Arc<EnumNames>),
}

/// An enum's entries: by value (the first name of a value wins) and by name, in order.
#[derive(Debug, Default)]
struct EnumNames {
    ordered: Vec<(String, u64)>,
    by_value: HashMap<u64, usize>,
    by_name: HashMap<String, u64>,
}

#[derive(Debug)]
struct FieldMap {
    /// The key: the field's name, `type` written `mavtype`.
    key: String,
    /// Index in wire order.
    index: usize,
    kind: Kind,
}

#[derive(Debug)]
struct MessageMap {
    /// Fields sorted by key (the order of the object's keys, `type` among them).
    fields: Vec<FieldMap>,
    /// Where `"type"` goes among the sorted keys.
    type_at: usize,
}

/// The mavlink2rest JSON of every message of one dialect.
#[derive(Debug)]
pub struct JsonMapping {
    dialect: Dialect,
    maps: HashMap<u32, MessageMap>,
    by_name: HashMap<String, u32>,
}

/// rust-mavlink's name of a field (it cannot call a field `type`).
fn key_of(name: &str) -> String {
    if name == "type" {
        "mavtype".to_owned()
    } else {
        name.to_owned()
    }
}

impl JsonMapping {
    /// The mapping of `dialect`'s messages.
    #[must_use]
    pub fn new(dialect: Dialect) -> Self {
        let mut enums: HashMap<&str, Arc<EnumNames>> = HashMap::new();
        for e in &dialect.enums {
            let mut names = EnumNames::default();
            for (i, entry) in e.entries.iter().enumerate() {
                names.ordered.push((entry.name.clone(), entry.value));
                names.by_value.entry(entry.value).or_insert(i);
                names.by_name.insert(entry.name.clone(), entry.value);
            }
            enums.insert(e.name.as_str(), Arc::new(names));
        }
        let mut maps = HashMap::new();
        let mut by_name = HashMap::new();
        for m in &dialect.messages {
            let mut fields: Vec<FieldMap> = m
                .fields
                .iter()
                .enumerate()
                .map(|(index, f)| FieldMap {
                    key: key_of(&f.name),
                    index,
                    kind: kind_of(&dialect, &enums, f),
                })
                .collect();
            fields.sort_by(|a, b| a.key.cmp(&b.key));
            let type_at = fields.partition_point(|f| f.key.as_str() < "type");
            maps.insert(m.id, MessageMap { fields, type_at });
            by_name.insert(m.name.clone(), m.id);
        }
        Self {
            dialect,
            maps,
            by_name,
        }
    }

    /// The dialect the mapping is made of.
    #[must_use]
    pub const fn dialect(&self) -> &Dialect {
        &self.dialect
    }

    /// The message called `name`.
    #[must_use]
    pub fn message_by_name(&self, name: &str) -> Option<&Message> {
        self.by_name
            .get(name)
            .and_then(|id| self.dialect.message(*id))
    }

    /// The object of message `id` with `payload` (as received: truncated, full or longer);
    /// `None` for a message the dialect does not have.
    #[must_use]
    pub fn message_json(&self, id: u32, payload: &[u8]) -> Option<Json> {
        let message = self.dialect.message(id)?;
        let map = self.maps.get(&id)?;
        let values = codec::decode(message, payload);
        let mut out = Map::new();
        for (i, f) in map.fields.iter().enumerate() {
            if i == map.type_at {
                out.insert("type".into(), message.name.clone().into());
            }
            let field = &message.fields[f.index];
            out.insert(f.key.clone(), field_json(field, &f.kind, &values[f.index]));
        }
        if map.type_at == map.fields.len() {
            out.insert("type".into(), message.name.clone().into());
        }
        Some(Json::Object(out))
    }

    /// What `GET /helper/mavlink?name=NAME` answers: `{"header","message"}` with the
    /// default header and the message's default values (zeros, empty strings, the first
    /// entry of each enum and bitmask, the dialect's version in `mavlink_version`), as
    /// rust-mavlink's `default_message_from_id` makes them. `None` for an unknown name.
    #[must_use]
    pub fn template(&self, name: &str) -> Option<Json> {
        let message = self.message_by_name(name)?;
        let map = self.maps.get(&message.id)?;
        let mut values: Vec<Value> = message.fields.iter().map(|f| Value::zero(&f.ty)).collect();
        for f in &map.fields {
            let field = &message.fields[f.index];
            if field.ty.array_len.is_some() {
                continue;
            }
            let first = match &f.kind {
                Kind::Enum(names) | Kind::Bitmask(names) => names.ordered.first().map(|e| e.1),
                Kind::Plain if field.ty.mavlink_version => self.dialect.version.map(u64::from),
                Kind::Plain => None,
            };
            if let Some(v) = first {
                values[f.index] =
                    integer(field, v as i128).unwrap_or_else(|_| Value::zero(&field.ty));
            }
        }
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = codec::encode(message, &values, &mut payload).ok()?;
        let body = self.message_json(message.id, &payload[..len])?;
        Some(request_json(Header::default(), body))
    }

    /// Reads a message object into its id and full payload.
    ///
    /// # Errors
    /// Not an object, no `type` or one the dialect does not have, a missing base field, an
    /// unknown key, a value that does not fit its field.
    pub fn parse_message(&self, value: &Json) -> Result<(u32, Vec<u8>), JsonError> {
        let Json::Object(object) = value else {
            return err("message: expected an object");
        };
        let name = match object.get("type") {
            Some(Json::String(s)) => s.as_str(),
            Some(other) => return err(format!("message: `type` must be a string, got {other}")),
            None => return err("message: missing field `type` (the message's name)"),
        };
        let Some(message) = self.message_by_name(name) else {
            return err(format!(
                "unknown message `{name}` in dialect {}",
                self.dialect.name
            ));
        };
        let map = self
            .maps
            .get(&message.id)
            .ok_or_else(|| JsonError(format!("unknown message `{name}`")))?;
        if let Some(k) = object
            .keys()
            .find(|k| *k != "type" && !map.fields.iter().any(|f| &f.key == *k))
        {
            return err(format!("{name}: unknown field `{k}`"));
        }
        let mut values = Vec::with_capacity(message.fields.len());
        for (index, field) in message.fields.iter().enumerate() {
            let Some(f) = map.fields.iter().find(|f| f.index == index) else {
                return err(format!("{name}: no mapping for field {}", field.name));
            };
            let value = match object.get(&f.key) {
                Some(v) => field_value(field, &f.kind, v)
                    .map_err(|e| JsonError(format!("{name}.{}: {}", f.key, e.0)))?,
                None if field.extension => Value::zero(&field.ty),
                None => return err(format!("{name}: missing field `{}`", f.key)),
            };
            values.push(value);
        }
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = codec::encode(message, &values, &mut payload)
            .map_err(|e| JsonError(format!("{name}: {e}")))?;
        Ok((message.id, payload[..len].to_vec()))
    }

    /// Reads a `{"header","message"}` object (what `POST /mavlink` and the WebSocket take)
    /// into the MAVLink 2 frame it describes.
    ///
    /// # Errors
    /// As [`parse_message`](Self::parse_message) and [`Header::from_json`], or other keys
    /// than those two.
    pub fn parse_request(&self, value: &Json) -> Result<(Header, Vec<u8>), JsonError> {
        let Json::Object(object) = value else {
            return err("expected an object with `header` and `message`");
        };
        if let Some(k) = object.keys().find(|k| *k != "header" && *k != "message") {
            return err(format!(
                "unknown key `{k}` (expected `header` and `message`)"
            ));
        }
        let header = Header::from_json(
            object
                .get("header")
                .ok_or_else(|| JsonError("missing field `header`".into()))?,
        )?;
        let (id, payload) = self.parse_message(
            object
                .get("message")
                .ok_or_else(|| JsonError("missing field `message`".into()))?,
        )?;
        let frame = self.frame(header, id, &payload)?;
        Ok((header, frame))
    }

    /// The MAVLink 2 frame of message `id` with `payload`, sent as `header` says.
    ///
    /// # Errors
    /// A message the dialect does not have, a payload longer than it.
    pub fn frame(&self, header: Header, id: u32, payload: &[u8]) -> Result<Vec<u8>, JsonError> {
        let Some(message) = self.dialect.message(id) else {
            return err(format!("unknown message id {id}"));
        };
        let info = MessageInfo {
            id,
            name: "",
            crc_extra: message.crc_extra,
            min_len: u8::try_from(message.min_len).unwrap_or(u8::MAX),
            max_len: u8::try_from(message.max_len).unwrap_or(u8::MAX),
            target_system_offset: None,
            target_component_offset: None,
        };
        let fh = FrameHeader {
            version: Version::V2,
            seq: header.sequence,
            sysid: header.system_id,
            compid: header.component_id,
            signed: false,
        };
        let mut out = [0u8; MAX_FRAME_LEN];
        let len = emit(&fh, &info, payload, &mut out)
            .map_err(|e| JsonError(format!("{}: {e}", message.name)))?;
        Ok(out[..len].to_vec())
    }
}

/// `{"header": header, "message": message}`.
#[must_use]
pub fn request_json(header: Header, message: Json) -> Json {
    let mut map = Map::new();
    map.insert("header".into(), header.to_json());
    map.insert("message".into(), message);
    Json::Object(map)
}

fn kind_of(dialect: &Dialect, enums: &HashMap<&str, Arc<EnumNames>>, field: &Field) -> Kind {
    let Some(name) = field.enum_name.as_deref() else {
        return Kind::Plain;
    };
    // rust-mavlink keeps enum arrays as arrays of numbers, and only integer fields typed.
    if field.ty.array_len.is_some()
        || matches!(
            field.ty.primitive,
            PrimitiveType::F32 | PrimitiveType::F64 | PrimitiveType::Char
        )
    {
        return Kind::Plain;
    }
    let Some(names) = enums.get(name) else {
        return Kind::Plain;
    };
    let bitmask = field.display.as_deref() == Some("bitmask")
        || dialect.enum_by_name(name).is_some_and(|e| e.bitmask);
    if bitmask {
        Kind::Bitmask(Arc::clone(names))
    } else {
        Kind::Enum(Arc::clone(names))
    }
}

fn scalar_json(value: &Value) -> Json {
    match *value {
        Value::U8(v) => v.into(),
        Value::I8(v) => v.into(),
        Value::U16(v) => v.into(),
        Value::I16(v) => v.into(),
        Value::U32(v) => v.into(),
        Value::I32(v) => v.into(),
        Value::U64(v) => v.into(),
        Value::I64(v) => v.into(),
        Value::F32(v) => {
            serde_json::Number::from_f64(f64::from(v)).map_or(Json::Null, Json::Number)
        }
        Value::F64(v) => serde_json::Number::from_f64(v).map_or(Json::Null, Json::Number),
        Value::Text(ref t) => Json::String(String::from_utf8_lossy(t).into_owned()),
        Value::Array(ref items) => Json::Array(items.iter().map(scalar_json).collect()),
    }
}

fn field_json(field: &Field, kind: &Kind, value: &Value) -> Json {
    if field.ty.primitive == PrimitiveType::Char && field.ty.array_len.is_none() {
        // A lone char is a number in rust-mavlink.
        if let Value::Text(t) = value {
            return t.first().copied().unwrap_or(0).into();
        }
    }
    let raw = || value.as_u64().or_else(|| bits_of(value));
    match kind {
        Kind::Plain => scalar_json(value),
        Kind::Enum(names) => match raw().and_then(|v| names.by_value.get(&v)) {
            Some(&i) => {
                let mut map = Map::new();
                map.insert("type".into(), names.ordered[i].0.clone().into());
                Json::Object(map)
            }
            None => scalar_json(value),
        },
        Kind::Bitmask(names) => {
            let Some(source) = raw() else {
                return scalar_json(value);
            };
            Json::String(flags_text(names, source))
        }
    }
}

/// A signed field's bits as unsigned (a bitmask in a signed field).
fn bits_of(value: &Value) -> Option<u64> {
    match *value {
        Value::I8(v) => Some(u64::from(v as u8)),
        Value::I16(v) => Some(u64::from(v as u16)),
        Value::I32(v) => Some(u64::from(v as u32)),
        Value::I64(v) => Some(v as u64),
        _ => None,
    }
}

/// bitflags' text: the flags whose bits are all set and not yet named, in the enum's
/// order, then the bits left as `0x..`.
fn flags_text(names: &EnumNames, source: u64) -> String {
    let mut remaining = source;
    let mut parts: Vec<String> = Vec::new();
    for (name, bits) in &names.ordered {
        if remaining == 0 {
            break;
        }
        if *bits != 0 && source & bits == *bits && remaining & bits != 0 {
            remaining &= !bits;
            parts.push(name.clone());
        }
    }
    if remaining != 0 {
        parts.push(format!("{remaining:#x}"));
    }
    parts.join(" | ")
}

fn flags_value(names: &EnumNames, text: &str) -> Result<u64, JsonError> {
    let mut bits = 0u64;
    if text.trim().is_empty() {
        return Ok(0);
    }
    for term in text.split('|') {
        let term = term.trim();
        if term.is_empty() {
            return err(format!("empty flag in \"{text}\""));
        }
        bits |= match term.strip_prefix("0x") {
            Some(hex) => u64::from_str_radix(hex, 16)
                .map_err(|_| JsonError(format!("bad hex flag `{term}`")))?,
            None => *names
                .by_name
                .get(term)
                .ok_or_else(|| JsonError(format!("unknown flag `{term}`")))?,
        };
    }
    Ok(bits)
}

/// The integer `v` as the field's primitive type.
fn integer(field: &Field, v: i128) -> Result<Value, JsonError> {
    let range = || JsonError(format!("{v} is out of range for {:?}", field.ty.primitive));
    Ok(match field.ty.primitive {
        PrimitiveType::U8 => Value::U8(u8::try_from(v).map_err(|_| range())?),
        PrimitiveType::I8 => Value::I8(i8::try_from(v).map_err(|_| range())?),
        PrimitiveType::U16 => Value::U16(u16::try_from(v).map_err(|_| range())?),
        PrimitiveType::I16 => Value::I16(i16::try_from(v).map_err(|_| range())?),
        PrimitiveType::U32 => Value::U32(u32::try_from(v).map_err(|_| range())?),
        PrimitiveType::I32 => Value::I32(i32::try_from(v).map_err(|_| range())?),
        PrimitiveType::U64 => Value::U64(u64::try_from(v).map_err(|_| range())?),
        PrimitiveType::I64 => Value::I64(i64::try_from(v).map_err(|_| range())?),
        PrimitiveType::Char => {
            let b = u8::try_from(v).map_err(|_| range())?;
            Value::Text(if b == 0 { Vec::new() } else { vec![b] })
        }
        PrimitiveType::F32 | PrimitiveType::F64 => return err("not an integer field"),
    })
}

/// Bits of a bitmask as the field's type (a signed field takes them as two's complement).
fn bits_value(field: &Field, bits: u64) -> Result<Value, JsonError> {
    let size = field.ty.primitive.size();
    if size < 8 && bits >> (size * 8) != 0 {
        return err(format!("flags {bits:#x} do not fit {size} bytes"));
    }
    Ok(match field.ty.primitive {
        PrimitiveType::I8 => Value::I8(bits as u8 as i8),
        PrimitiveType::I16 => Value::I16(bits as u16 as i16),
        PrimitiveType::I32 => Value::I32(bits as u32 as i32),
        PrimitiveType::I64 => Value::I64(bits as i64),
        _ => integer(field, i128::from(bits))?,
    })
}

fn number(field: &Field, json: &Json) -> Result<Value, JsonError> {
    match field.ty.primitive {
        PrimitiveType::F32 => match json {
            Json::Null => Ok(Value::F32(f32::NAN)),
            Json::Number(n) => {
                let v = n.as_f64().unwrap_or(f64::NAN);
                let f = v as f32;
                if v.is_finite() && !f.is_finite() {
                    return err(format!("{v} is out of range for float"));
                }
                Ok(Value::F32(f))
            }
            other => err(format!("expected a number, got {other}")),
        },
        PrimitiveType::F64 => match json {
            Json::Null => Ok(Value::F64(f64::NAN)),
            Json::Number(n) => Ok(Value::F64(n.as_f64().unwrap_or(f64::NAN))),
            other => err(format!("expected a number, got {other}")),
        },
        _ => {
            let v = match json {
                Json::Number(n) => n
                    .as_i64()
                    .map(i128::from)
                    .or_else(|| n.as_u64().map(i128::from)),
                _ => None,
            };
            match v {
                Some(v) => integer(field, v),
                None => err(format!("expected an integer, got {json}")),
            }
        }
    }
}

fn field_value(field: &Field, kind: &Kind, json: &Json) -> Result<Value, JsonError> {
    if let Some(n) = field.ty.array_len {
        let n = usize::from(n);
        if field.ty.primitive == PrimitiveType::Char {
            let Json::String(s) = json else {
                return err(format!(
                    "expected a string of at most {n} bytes, got {json}"
                ));
            };
            if s.len() > n {
                return err(format!("\"{s}\" is {} bytes, the field holds {n}", s.len()));
            }
            if s.contains('\0') {
                return err("a NUL inside the string");
            }
            return Ok(Value::Text(s.as_bytes().to_vec()));
        }
        let Json::Array(items) = json else {
            return err(format!("expected an array of {n} numbers, got {json}"));
        };
        if items.len() != n {
            return err(format!("expected {n} elements, got {}", items.len()));
        }
        let items = items
            .iter()
            .map(|item| number(field, item))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(Value::Array(items));
    }
    match (kind, json) {
        (Kind::Enum(names), Json::Object(map)) => {
            if let Some(k) = map.keys().find(|k| *k != "type") {
                return err(format!("unknown key `{k}` in an enum value"));
            }
            let Some(Json::String(entry)) = map.get("type") else {
                return err("expected {\"type\": \"ENTRY_NAME\"}");
            };
            let Some(&v) = names.by_name.get(entry) else {
                return err(format!("unknown entry `{entry}`"));
            };
            if matches!(
                field.ty.primitive,
                PrimitiveType::I8 | PrimitiveType::I16 | PrimitiveType::I32 | PrimitiveType::I64
            ) {
                integer(field, i128::from(v))
            } else {
                bits_value(field, v)
            }
        }
        (Kind::Bitmask(names), Json::String(text)) => bits_value(field, flags_value(names, text)?),
        _ => number(field, json),
    }
}

/// Fuzzing entry point for the JSON → message path, on the built-in `ardupilotmega`
/// mapping. The first byte picks the input's form:
///
/// - even: the rest is the text of a request (`{"header","message"}`). What reads is a frame
///   whose own object, written back, reads to the very same frame (the header, the id and
///   every payload byte): valid objects round-trip; anything else must be an error, never a
///   panic.
/// - odd: the rest chooses a message (two bytes of index) and its payload (the bytes after);
///   the object written for a payload whose text fields are UTF-8 must read back, and the
///   payload read writes the same object again (NaN's bits and other non-canonical floats
///   aside, which only the object compares).
///
/// # Panics
/// When a property fails (a bug).
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_web_json(data: &[u8]) {
    let mapping = super::default_mapping();
    let Some((&form, rest)) = data.split_first() else {
        return;
    };
    if form % 2 == 0 {
        let Ok(text) = core::str::from_utf8(rest) else {
            return;
        };
        let Ok(value) = serde_json::from_str::<Json>(text) else {
            return;
        };
        let Ok((header, frame)) = mapping.parse_request(&value) else {
            return;
        };
        let view = mavstack_core::wire::Frame::new_checked(&frame[..]).expect("a whole frame");
        let object = mapping
            .message_json(view.msg_id(), view.payload())
            .expect("a message the mapping just read");
        let again = request_json(header, object);
        let (header2, frame2) = mapping
            .parse_request(&again)
            .unwrap_or_else(|e| panic!("our own object is refused: {e}: {again}"));
        assert_eq!(header2, header);
        assert_eq!(frame2, frame, "{again}");
        return;
    }
    if rest.len() < 2 {
        return;
    }
    let messages = &mapping.dialect().messages;
    let index = usize::from(u16::from_le_bytes([rest[0], rest[1]])) % messages.len();
    let message = &messages[index];
    let payload = &rest[2..];
    let mut buf = [0u8; MAX_PAYLOAD_LEN];
    let n = payload.len().min(message.max_len);
    buf[..n].copy_from_slice(&payload[..n]);
    let text_ok = message.fields.iter().all(|f| {
        f.ty.primitive != PrimitiveType::Char
            || f.ty.array_len.is_none()
            || matches!(codec::decode_field(f, &buf), Value::Text(t) if core::str::from_utf8(&t).is_ok())
    });
    if !text_ok {
        return;
    }
    let object = mapping
        .message_json(message.id, payload)
        .expect("a message of the dialect");
    let (id, back) = mapping
        .parse_message(&object)
        .unwrap_or_else(|e| panic!("{}: our own object is refused: {e}: {object}", message.name));
    assert_eq!(id, message.id);
    let again = mapping.message_json(id, &back).expect("the same message");
    assert_eq!(again, object, "{}", message.name);
}
