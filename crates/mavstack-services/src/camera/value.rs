//! Camera settings' values as PARAM_EXT_* carries them: a MAV_PARAM_EXT_TYPE and 128 bytes,
//! numbers as their little-endian bytes at the start of the field, text (CUSTOM) as itself.

use alloc::string::{String, ToString};
use core::fmt;

use mavstack_dialects::common::MavParamExtType;

/// The bytes of PARAM_EXT_VALUE's and PARAM_EXT_SET's `param_value`.
pub const VALUE_LEN: usize = 128;

/// The longest setting name (PARAM_EXT_*'s `param_id`).
pub const NAME_LEN: usize = 16;

/// A setting's type, as a camera definition names it and PARAM_EXT_* numbers it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExtType {
    /// `uint8` (and `bool`, as 0 or 1).
    U8,
    /// `int8`.
    I8,
    /// `uint16`.
    U16,
    /// `int16`.
    I16,
    /// `uint32`.
    U32,
    /// `int32`.
    I32,
    /// `uint64`.
    U64,
    /// `int64`.
    I64,
    /// `float`.
    F32,
    /// `double`.
    F64,
    /// `custom`: text.
    Custom,
}

impl ExtType {
    /// The type a camera definition names (`uint8`, ..., `float`, `double`, `bool`,
    /// `custom`); `None` for another name.
    #[must_use]
    pub fn from_definition(name: &str) -> Option<Self> {
        Some(match name {
            "uint8" | "bool" => Self::U8,
            "int8" => Self::I8,
            "uint16" => Self::U16,
            "int16" => Self::I16,
            "uint32" => Self::U32,
            "int32" => Self::I32,
            "uint64" => Self::U64,
            "int64" => Self::I64,
            "float" => Self::F32,
            "double" => Self::F64,
            "custom" => Self::Custom,
            _ => return None,
        })
    }

    /// Its MAV_PARAM_EXT_TYPE.
    #[must_use]
    pub const fn wire(self) -> MavParamExtType {
        match self {
            Self::U8 => MavParamExtType::UINT8,
            Self::I8 => MavParamExtType::INT8,
            Self::U16 => MavParamExtType::UINT16,
            Self::I16 => MavParamExtType::INT16,
            Self::U32 => MavParamExtType::UINT32,
            Self::I32 => MavParamExtType::INT32,
            Self::U64 => MavParamExtType::UINT64,
            Self::I64 => MavParamExtType::INT64,
            Self::F32 => MavParamExtType::REAL32,
            Self::F64 => MavParamExtType::REAL64,
            Self::Custom => MavParamExtType::CUSTOM,
        }
    }

    /// The type MAV_PARAM_EXT_TYPE `t` is; `None` for a number it does not name.
    #[must_use]
    pub const fn from_wire(t: MavParamExtType) -> Option<Self> {
        Some(match t.0 {
            1 => Self::U8,
            2 => Self::I8,
            3 => Self::U16,
            4 => Self::I16,
            5 => Self::U32,
            6 => Self::I32,
            7 => Self::U64,
            8 => Self::I64,
            9 => Self::F32,
            10 => Self::F64,
            11 => Self::Custom,
            _ => return None,
        })
    }

    /// Its name in a camera definition.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::U8 => "uint8",
            Self::I8 => "int8",
            Self::U16 => "uint16",
            Self::I16 => "int16",
            Self::U32 => "uint32",
            Self::I32 => "int32",
            Self::U64 => "uint64",
            Self::I64 => "int64",
            Self::F32 => "float",
            Self::F64 => "double",
            Self::Custom => "custom",
        }
    }
}

/// A setting's value.
#[derive(Clone, Debug, PartialEq)]
pub enum ExtValue {
    /// `uint8`.
    U8(u8),
    /// `int8`.
    I8(i8),
    /// `uint16`.
    U16(u16),
    /// `int16`.
    I16(i16),
    /// `uint32`.
    U32(u32),
    /// `int32`.
    I32(i32),
    /// `uint64`.
    U64(u64),
    /// `int64`.
    I64(i64),
    /// `float`.
    F32(f32),
    /// `double`.
    F64(f64),
    /// `custom`: text of up to 128 bytes.
    Custom(String),
}

impl ExtValue {
    /// Its type.
    #[must_use]
    pub const fn ty(&self) -> ExtType {
        match self {
            Self::U8(_) => ExtType::U8,
            Self::I8(_) => ExtType::I8,
            Self::U16(_) => ExtType::U16,
            Self::I16(_) => ExtType::I16,
            Self::U32(_) => ExtType::U32,
            Self::I32(_) => ExtType::I32,
            Self::U64(_) => ExtType::U64,
            Self::I64(_) => ExtType::I64,
            Self::F32(_) => ExtType::F32,
            Self::F64(_) => ExtType::F64,
            Self::Custom(_) => ExtType::Custom,
        }
    }

    /// `text` read as a value of type `ty` (a decimal number, `true`/`false` for the
    /// unsigned types, the text itself for `custom`); `None` when it is not one (out of the
    /// type's range, not a number, NaN, over 128 bytes).
    #[must_use]
    pub fn parse(ty: ExtType, text: &str) -> Option<Self> {
        let t = text.trim();
        let int = |t: &str| -> Option<i128> {
            match t {
                "true" => Some(1),
                "false" => Some(0),
                _ => t.parse::<i128>().ok(),
            }
        };
        Some(match ty {
            ExtType::U8 => Self::U8(u8::try_from(int(t)?).ok()?),
            ExtType::I8 => Self::I8(i8::try_from(int(t)?).ok()?),
            ExtType::U16 => Self::U16(u16::try_from(int(t)?).ok()?),
            ExtType::I16 => Self::I16(i16::try_from(int(t)?).ok()?),
            ExtType::U32 => Self::U32(u32::try_from(int(t)?).ok()?),
            ExtType::I32 => Self::I32(i32::try_from(int(t)?).ok()?),
            ExtType::U64 => Self::U64(u64::try_from(int(t)?).ok()?),
            ExtType::I64 => Self::I64(i64::try_from(int(t)?).ok()?),
            ExtType::F32 => Self::F32(t.parse::<f32>().ok().filter(|v| v.is_finite())?),
            ExtType::F64 => Self::F64(t.parse::<f64>().ok().filter(|v| v.is_finite())?),
            ExtType::Custom => {
                if text.len() > VALUE_LEN || text.contains('\0') {
                    return None;
                }
                Self::Custom(text.to_string())
            }
        })
    }

    /// As `param_value`: the number's little-endian bytes first, or the text, then zeros.
    #[must_use]
    pub fn encode(&self) -> [u8; VALUE_LEN] {
        let mut out = [0u8; VALUE_LEN];
        let mut put = |b: &[u8]| out[..b.len()].copy_from_slice(b);
        match self {
            Self::U8(v) => put(&v.to_le_bytes()),
            Self::I8(v) => put(&v.to_le_bytes()),
            Self::U16(v) => put(&v.to_le_bytes()),
            Self::I16(v) => put(&v.to_le_bytes()),
            Self::U32(v) => put(&v.to_le_bytes()),
            Self::I32(v) => put(&v.to_le_bytes()),
            Self::U64(v) => put(&v.to_le_bytes()),
            Self::I64(v) => put(&v.to_le_bytes()),
            Self::F32(v) => put(&v.to_le_bytes()),
            Self::F64(v) => put(&v.to_le_bytes()),
            Self::Custom(s) => {
                let b = s.as_bytes();
                put(&b[..b.len().min(VALUE_LEN)]);
            }
        }
        out
    }

    /// The value of type `ty` in `param_value`; `None` for a type it does not name, or text
    /// that is not UTF-8.
    #[must_use]
    pub fn decode(ty: MavParamExtType, bytes: &[u8; VALUE_LEN]) -> Option<Self> {
        let a = |n: usize| -> [u8; 8] {
            let mut b = [0u8; 8];
            b[..n].copy_from_slice(&bytes[..n]);
            b
        };
        Some(match ExtType::from_wire(ty)? {
            ExtType::U8 => Self::U8(bytes[0]),
            ExtType::I8 => Self::I8(bytes[0] as i8),
            ExtType::U16 => Self::U16(u16::from_le_bytes([bytes[0], bytes[1]])),
            ExtType::I16 => Self::I16(i16::from_le_bytes([bytes[0], bytes[1]])),
            ExtType::U32 => Self::U32(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])),
            ExtType::I32 => Self::I32(i32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])),
            ExtType::U64 => Self::U64(u64::from_le_bytes(a(8))),
            ExtType::I64 => Self::I64(i64::from_le_bytes(a(8))),
            ExtType::F32 => Self::F32(f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])),
            ExtType::F64 => Self::F64(f64::from_le_bytes(a(8))),
            ExtType::Custom => {
                let end = bytes.iter().position(|&b| b == 0).unwrap_or(VALUE_LEN);
                Self::Custom(String::from(core::str::from_utf8(&bytes[..end]).ok()?))
            }
        })
    }

    /// As a number (`None` for text).
    #[must_use]
    pub fn as_f64(&self) -> Option<f64> {
        Some(match *self {
            Self::U8(v) => f64::from(v),
            Self::I8(v) => f64::from(v),
            Self::U16(v) => f64::from(v),
            Self::I16(v) => f64::from(v),
            Self::U32(v) => f64::from(v),
            Self::I32(v) => f64::from(v),
            Self::U64(v) => v as f64,
            Self::I64(v) => v as f64,
            Self::F32(v) => f64::from(v),
            Self::F64(v) => v,
            Self::Custom(_) => return None,
        })
    }
}

impl fmt::Display for ExtValue {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::U8(v) => write!(f, "{v}"),
            Self::I8(v) => write!(f, "{v}"),
            Self::U16(v) => write!(f, "{v}"),
            Self::I16(v) => write!(f, "{v}"),
            Self::U32(v) => write!(f, "{v}"),
            Self::I32(v) => write!(f, "{v}"),
            Self::U64(v) => write!(f, "{v}"),
            Self::I64(v) => write!(f, "{v}"),
            Self::F32(v) => write!(f, "{v}"),
            Self::F64(v) => write!(f, "{v}"),
            Self::Custom(s) => f.write_str(s),
        }
    }
}

/// A setting name as `param_id`: up to 16 bytes, NUL-padded; `None` when longer or empty.
#[must_use]
pub fn name_field(name: &str) -> Option<[u8; NAME_LEN]> {
    if name.is_empty() || name.len() > NAME_LEN || name.contains('\0') {
        return None;
    }
    let mut field = [0u8; NAME_LEN];
    field[..name.len()].copy_from_slice(name.as_bytes());
    Some(field)
}

/// `param_id` as text (up to its first NUL; invalid UTF-8 replaced).
#[must_use]
pub fn name_of(field: &[u8; NAME_LEN]) -> String {
    let end = field.iter().position(|&b| b == 0).unwrap_or(NAME_LEN);
    String::from_utf8_lossy(&field[..end]).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_through_the_field() {
        let values = [
            ExtValue::U8(200),
            ExtValue::I8(-3),
            ExtValue::U16(65000),
            ExtValue::I16(-30000),
            ExtValue::U32(4_000_000_000),
            ExtValue::I32(-5),
            ExtValue::U64(u64::MAX),
            ExtValue::I64(i64::MIN),
            ExtValue::F32(0.016666),
            ExtValue::F64(-1.5e300),
            ExtValue::Custom("auto".into()),
        ];
        for v in values {
            let back = ExtValue::decode(v.ty().wire(), &v.encode());
            assert_eq!(back, Some(v));
        }
        // A float's bytes, as MAVSDK and QGroundControl put them.
        assert_eq!(&ExtValue::F32(1.0).encode()[..4], &[0, 0, 0x80, 0x3f]);
    }

    #[test]
    fn text_as_each_type() {
        assert_eq!(ExtValue::parse(ExtType::U8, "true"), Some(ExtValue::U8(1)));
        assert_eq!(ExtValue::parse(ExtType::U8, "256"), None);
        assert_eq!(
            ExtValue::parse(ExtType::I16, " -7 "),
            Some(ExtValue::I16(-7))
        );
        assert_eq!(
            ExtValue::parse(ExtType::F32, "4.3"),
            Some(ExtValue::F32(4.3))
        );
        assert_eq!(ExtValue::parse(ExtType::F32, "NaN"), None);
        assert_eq!(ExtValue::parse(ExtType::U32, "1.5"), None);
        assert_eq!(ExtValue::parse(ExtType::Custom, &"x".repeat(129)), None);
        assert_eq!(ExtType::from_definition("double"), Some(ExtType::F64));
        assert_eq!(ExtType::from_definition("string"), None);
        assert_eq!(ExtValue::decode(MavParamExtType(42), &[0; 128]), None);
    }

    #[test]
    fn names() {
        assert!(name_field("CAM_SHUTTERSPD").is_some());
        assert!(name_field("A_NAME_OF_17_BYTE").is_none());
        assert_eq!(name_of(&name_field("CAM_EV").unwrap()), "CAM_EV");
        let full = *b"SIXTEEN_BYTES_XX";
        assert_eq!(name_of(&full), "SIXTEEN_BYTES_XX");
    }
}
