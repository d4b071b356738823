//! Run-time payload codec for any message of a loaded [`Dialect`](crate::Dialect).
//!
//! Values follow the model's wire order: [`decode`] returns one [`Value`] per field of
//! [`Message::fields`], and [`encode`] takes them in that order. The rules are those of the
//! generated code: short payloads are zero-extended, long ones cut, and encoding writes the
//! full untruncated payload (MAVLink 2 truncation is the frame layer's job).
//!
//! ```
//! use mavstack_xml::codec::{self, Value};
//! let dialect = mavstack_xml::load("minimal")?;
//! let heartbeat = dialect.message(0).expect("HEARTBEAT");
//! let payload = [0, 0, 0, 0, 2, 12, 0x51, 4, 3];
//! let values = codec::decode(heartbeat, &payload);
//! assert_eq!(values[1], Value::U8(2)); // `type`, second in wire order
//! let mut out = [0u8; 255];
//! let len = codec::encode(heartbeat, &values, &mut out).expect("same shape");
//! assert_eq!(&out[..len], &payload);
//! # Ok::<(), mavstack_xml::Error>(())
//! ```

use mavstack_core::MAX_PAYLOAD_LEN;
use mavstack_core::payload::{get, put};

use crate::model::{Field, FieldType, Message, PrimitiveType};

/// The value of one field.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// `uint8_t`.
    U8(u8),
    /// `int8_t`.
    I8(i8),
    /// `uint16_t`.
    U16(u16),
    /// `int16_t`.
    I16(i16),
    /// `uint32_t`.
    U32(u32),
    /// `int32_t`.
    I32(i32),
    /// `uint64_t`.
    U64(u64),
    /// `int64_t`.
    I64(i64),
    /// `float`.
    F32(f32),
    /// `double`.
    F64(f64),
    /// `char` or `char[N]`: the bytes up to the first NUL.
    Text(Vec<u8>),
    /// Any other array, all `N` elements.
    Array(Vec<Self>),
}

impl Value {
    /// The zero value of a field type (empty text, an array of zeros).
    #[must_use]
    pub fn zero(ty: &FieldType) -> Self {
        match (ty.primitive, ty.array_len) {
            (PrimitiveType::Char, _) => Self::Text(Vec::new()),
            (p, Some(n)) => Self::Array(vec![Self::scalar_zero(p); usize::from(n)]),
            (p, None) => Self::scalar_zero(p),
        }
    }

    fn scalar_zero(p: PrimitiveType) -> Self {
        read_scalar(p, &[0u8; 8], 0)
    }

    /// The value as `f64` if it is a number (an integer beyond 2^53 rounds); `None` for
    /// text and arrays.
    ///
    /// ```
    /// use mavstack_xml::codec::Value;
    /// assert_eq!(Value::I16(-3).as_f64(), Some(-3.0));
    /// assert_eq!(Value::Text(b"x".to_vec()).as_f64(), None);
    /// ```
    #[must_use]
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Self::U8(v) => Some(v.into()),
            Self::I8(v) => Some(v.into()),
            Self::U16(v) => Some(v.into()),
            Self::I16(v) => Some(v.into()),
            Self::U32(v) => Some(v.into()),
            Self::I32(v) => Some(v.into()),
            Self::U64(v) => Some(v as f64),
            Self::I64(v) => Some(v as f64),
            Self::F32(v) => Some(v.into()),
            Self::F64(v) => Some(v),
            Self::Text(_) | Self::Array(_) => None,
        }
    }

    /// The value as `u64` if it is an integer that fits.
    #[must_use]
    pub fn as_u64(&self) -> Option<u64> {
        match *self {
            Self::U8(v) => Some(v.into()),
            Self::U16(v) => Some(v.into()),
            Self::U32(v) => Some(v.into()),
            Self::U64(v) => Some(v),
            Self::I8(v) => u64::try_from(v).ok(),
            Self::I16(v) => u64::try_from(v).ok(),
            Self::I32(v) => u64::try_from(v).ok(),
            Self::I64(v) => u64::try_from(v).ok(),
            _ => None,
        }
    }
}

/// A value that does not fit the field it is meant for.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// Not one value per field.
    #[error("message {message} has {expected} fields, got {found} values")]
    FieldCount {
        /// The message.
        message: String,
        /// Its field count.
        expected: usize,
        /// The values given.
        found: usize,
    },
    /// A value of another type than the field's.
    #[error("field {field}: expected {expected}, got {found}")]
    Type {
        /// The field.
        field: String,
        /// The field's type, as in the XML.
        expected: String,
        /// What was given, e.g. `F32`.
        found: String,
    },
    /// An array or text of the wrong length.
    #[error("field {field}: at most {max} elements, got {found}")]
    Length {
        /// The field.
        field: String,
        /// The array length.
        max: usize,
        /// The elements given.
        found: usize,
    },
}

fn read_scalar(p: PrimitiveType, buf: &[u8], at: usize) -> Value {
    match p {
        PrimitiveType::U8 | PrimitiveType::Char => Value::U8(buf[at]),
        PrimitiveType::I8 => Value::I8(i8::from_le_bytes(get(buf, at))),
        PrimitiveType::U16 => Value::U16(u16::from_le_bytes(get(buf, at))),
        PrimitiveType::I16 => Value::I16(i16::from_le_bytes(get(buf, at))),
        PrimitiveType::U32 => Value::U32(u32::from_le_bytes(get(buf, at))),
        PrimitiveType::I32 => Value::I32(i32::from_le_bytes(get(buf, at))),
        PrimitiveType::U64 => Value::U64(u64::from_le_bytes(get(buf, at))),
        PrimitiveType::I64 => Value::I64(i64::from_le_bytes(get(buf, at))),
        PrimitiveType::F32 => Value::F32(f32::from_le_bytes(get(buf, at))),
        PrimitiveType::F64 => Value::F64(f64::from_le_bytes(get(buf, at))),
    }
}

/// Decodes `payload` (as received: truncated, full or longer) into one value per field, in
/// wire order.
#[must_use]
pub fn decode(message: &Message, payload: &[u8]) -> Vec<Value> {
    let mut buf = [0u8; MAX_PAYLOAD_LEN];
    let n = payload.len().min(message.max_len);
    buf[..n].copy_from_slice(&payload[..n]);
    message
        .fields
        .iter()
        .map(|f| decode_field(f, &buf))
        .collect()
}

/// Decodes one field from a zero-extended payload buffer.
#[must_use]
pub fn decode_field(field: &Field, buf: &[u8; MAX_PAYLOAD_LEN]) -> Value {
    let p = field.ty.primitive;
    let count = usize::from(field.ty.array_len.unwrap_or(1));
    if p == PrimitiveType::Char {
        let bytes = &buf[field.offset..field.offset + count];
        return Value::Text(mavstack_core::text::until_nul(bytes).to_vec());
    }
    match field.ty.array_len {
        None => read_scalar(p, buf, field.offset),
        Some(_) => Value::Array(
            (0..count)
                .map(|i| read_scalar(p, buf, field.offset + i * p.size()))
                .collect(),
        ),
    }
}

fn type_error(field: &Field, found: &Value) -> EncodeError {
    let expected = match field.ty.array_len {
        Some(n) => format!("{}[{n}]", field.ty.primitive.c_name()),
        None => field.ty.primitive.c_name().to_owned(),
    };
    let found = format!("{found:?}");
    let found = found.split('(').next().unwrap_or_default().to_owned();
    EncodeError::Type {
        field: field.name.clone(),
        expected,
        found,
    }
}

fn write_scalar(
    field: &Field,
    value: &Value,
    buf: &mut [u8],
    at: usize,
) -> Result<(), EncodeError> {
    match (field.ty.primitive, value) {
        (PrimitiveType::U8, Value::U8(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::I8, Value::I8(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::U16, Value::U16(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::I16, Value::I16(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::U32, Value::U32(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::I32, Value::I32(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::U64, Value::U64(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::I64, Value::I64(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::F32, Value::F32(v)) => put(buf, at, &v.to_le_bytes()),
        (PrimitiveType::F64, Value::F64(v)) => put(buf, at, &v.to_le_bytes()),
        (_, other) => return Err(type_error(field, other)),
    }
    Ok(())
}

/// Encodes one field into a payload buffer at its offset.
///
/// # Errors
/// The value does not match the field's type or length.
pub fn encode_field(
    field: &Field,
    value: &Value,
    buf: &mut [u8; MAX_PAYLOAD_LEN],
) -> Result<(), EncodeError> {
    let count = usize::from(field.ty.array_len.unwrap_or(1));
    let length_error = |found| EncodeError::Length {
        field: field.name.clone(),
        max: count,
        found,
    };
    match (field.ty.primitive, value, field.ty.array_len) {
        (PrimitiveType::Char, Value::Text(bytes), _) => {
            if bytes.len() > count {
                return Err(length_error(bytes.len()));
            }
            let slot = &mut buf[field.offset..field.offset + count];
            slot.fill(0);
            slot[..bytes.len()].copy_from_slice(bytes);
        }
        (_, Value::Array(items), Some(_)) => {
            if items.len() > count {
                return Err(length_error(items.len()));
            }
            let size = field.ty.primitive.size();
            buf[field.offset..field.offset + count * size].fill(0);
            for (i, item) in items.iter().enumerate() {
                write_scalar(field, item, buf, field.offset + i * size)?;
            }
        }
        (_, scalar, None) => write_scalar(field, scalar, buf, field.offset)?,
        (_, other, _) => return Err(type_error(field, other)),
    }
    Ok(())
}

/// Encodes one value per field (wire order) into `out` and returns the full payload length,
/// [`Message::max_len`]. Arrays and text may be shorter than the field; the rest is zero.
///
/// # Errors
/// The wrong number of values, or a value that does not match its field.
pub fn encode(
    message: &Message,
    values: &[Value],
    out: &mut [u8; MAX_PAYLOAD_LEN],
) -> Result<usize, EncodeError> {
    if values.len() != message.fields.len() {
        return Err(EncodeError::FieldCount {
            message: message.name.clone(),
            expected: message.fields.len(),
            found: values.len(),
        });
    }
    out[..message.max_len].fill(0);
    for (field, value) in message.fields.iter().zip(values) {
        encode_field(field, value, out)?;
    }
    Ok(message.max_len)
}
