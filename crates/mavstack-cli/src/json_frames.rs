//! Frames as JSON lines (shared/DESIGN.md, "Frames as JSON lines"): writing decoded frames,
//! and reading objects back into field values.

use core::fmt::Write as _;

use mavstack_dialect::codec::Value;
use mavstack_dialect::{Field, Message, PrimitiveType};
use serde_json::Value as Json;

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
pub(crate) fn text_of(bytes: &[u8]) -> String {
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
pub(crate) fn push_value(out: &mut String, v: &Value) {
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
pub(crate) fn push_fields(out: &mut String, message: &Message, values: &[Value]) {
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

/// Appends `s` as a JSON string (public for callers writing other keys).
pub(crate) fn push_json_str(out: &mut String, s: &str) {
    push_str(out, s);
}

/// A JSON value read back into the value of `field`.
///
/// # Errors
/// A message naming the field and what is wrong.
pub(crate) fn value_from_json(field: &Field, json: &Json) -> Result<Value, String> {
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
            #[allow(clippy::cast_possible_truncation)]
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
