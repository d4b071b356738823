//! Parameter names, typed values and the two encodings of a value in PARAM_VALUE's float.

use mavstack_dialects::common::{MavAutopilot, MavParamType, MavProtocolCapability};

/// A parameter name: up to 16 bytes, NUL-padded on the wire (a 16-byte name has no NUL).
#[derive(Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Name([u8; 16]);

/// Why a string is not a parameter name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum NameError {
    /// Longer than the 16 bytes of `param_id`.
    #[error("parameter name is {len} bytes long, more than 16")]
    TooLong {
        /// Its length in bytes.
        len: usize,
    },
    /// Empty, or containing a NUL.
    #[error("parameter name is empty or contains a NUL")]
    Invalid,
}

impl Name {
    /// The name `text`.
    ///
    /// # Errors
    ///
    /// [`NameError::TooLong`] past 16 bytes, [`NameError::Invalid`] if empty or with a NUL.
    ///
    /// ```
    /// use mavstack_services::param::Name;
    /// assert_eq!(Name::new("SYSID_THISMAV").unwrap().as_str(), "SYSID_THISMAV");
    /// assert!(Name::new("A_NAME_OF_17_BYTE").is_err());
    /// ```
    pub fn new(text: &str) -> Result<Self, NameError> {
        let bytes = text.as_bytes();
        if bytes.len() > 16 {
            return Err(NameError::TooLong { len: bytes.len() });
        }
        if bytes.is_empty() || bytes.contains(&0) {
            return Err(NameError::Invalid);
        }
        let mut id = [0u8; 16];
        id[..bytes.len()].copy_from_slice(bytes);
        Ok(Self(id))
    }

    /// The name in a `param_id` field (everything after the first NUL is ignored).
    #[must_use]
    pub fn from_field(field: &[u8; 16]) -> Self {
        let mut id = [0u8; 16];
        let len = field.iter().position(|&b| b == 0).unwrap_or(16);
        id[..len].copy_from_slice(&field[..len]);
        Self(id)
    }

    /// The `param_id` field.
    #[must_use]
    pub const fn to_field(self) -> [u8; 16] {
        self.0
    }

    /// The bytes of the name, without padding.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        let len = self.0.iter().position(|&b| b == 0).unwrap_or(16);
        &self.0[..len]
    }

    /// The name as text (`"?"` if it is not UTF-8).
    #[must_use]
    pub fn as_str(&self) -> &str {
        core::str::from_utf8(self.as_bytes()).unwrap_or("?")
    }
}

impl core::fmt::Debug for Name {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl core::fmt::Display for Name {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A typed parameter value. The 64-bit types do not fit the 4-byte field of this protocol
/// and are not represented.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// MAV_PARAM_TYPE_UINT8.
    U8(u8),
    /// MAV_PARAM_TYPE_INT8.
    I8(i8),
    /// MAV_PARAM_TYPE_UINT16.
    U16(u16),
    /// MAV_PARAM_TYPE_INT16.
    I16(i16),
    /// MAV_PARAM_TYPE_UINT32.
    U32(u32),
    /// MAV_PARAM_TYPE_INT32.
    I32(i32),
    /// MAV_PARAM_TYPE_REAL32.
    F32(f32),
}

/// `x` rounded half away from zero (no `f64::round` in `core`).
fn round(x: f64) -> f64 {
    // `as i64` truncates toward zero and saturates; NaN becomes 0.
    if x >= 0.0 {
        (x + 0.5) as i64 as f64
    } else {
        (x - 0.5) as i64 as f64
    }
}

impl Value {
    /// Its MAV_PARAM_TYPE.
    #[must_use]
    pub const fn param_type(self) -> MavParamType {
        match self {
            Self::U8(_) => MavParamType::UINT8,
            Self::I8(_) => MavParamType::INT8,
            Self::U16(_) => MavParamType::UINT16,
            Self::I16(_) => MavParamType::INT16,
            Self::U32(_) => MavParamType::UINT32,
            Self::I32(_) => MavParamType::INT32,
            Self::F32(_) => MavParamType::REAL32,
        }
    }

    /// The value as an `f64` (exact for every type).
    #[must_use]
    pub fn as_f64(self) -> f64 {
        match self {
            Self::U8(v) => v.into(),
            Self::I8(v) => v.into(),
            Self::U16(v) => v.into(),
            Self::I16(v) => v.into(),
            Self::U32(v) => v.into(),
            Self::I32(v) => v.into(),
            Self::F32(v) => v.into(),
        }
    }

    /// The value converted to `ty`: integers rounded and clamped to the type's range
    /// (NaN becomes 0), floats as the nearest `f32`. `None` for a type this protocol cannot
    /// carry.
    ///
    /// ```
    /// use mavstack_dialects::common::MavParamType;
    /// use mavstack_services::param::Value;
    /// assert_eq!(Value::F32(300.4).converted_to(MavParamType::UINT8), Some(Value::U8(255)));
    /// assert_eq!(Value::I32(-7).converted_to(MavParamType::REAL32), Some(Value::F32(-7.0)));
    /// ```
    #[must_use]
    pub fn converted_to(self, ty: MavParamType) -> Option<Self> {
        if self.param_type() == ty {
            return Some(self);
        }
        let x = self.as_f64();
        let r = round(x);
        let clamp = |lo: f64, hi: f64| if x.is_nan() { 0.0 } else { r.clamp(lo, hi) };
        Some(match ty {
            MavParamType::UINT8 => Self::U8(clamp(0.0, 255.0) as u8),
            MavParamType::INT8 => Self::I8(clamp(-128.0, 127.0) as i8),
            MavParamType::UINT16 => Self::U16(clamp(0.0, 65_535.0) as u16),
            MavParamType::INT16 => Self::I16(clamp(-32_768.0, 32_767.0) as i16),
            MavParamType::UINT32 => Self::U32(clamp(0.0, 4_294_967_295.0) as u32),
            MavParamType::INT32 => Self::I32(clamp(-2_147_483_648.0, 2_147_483_647.0) as i32),
            MavParamType::REAL32 => Self::F32(x as f32),
            _ => return None,
        })
    }

    /// Whether two values are the same type and the same bits (so NaN equals NaN).
    #[must_use]
    pub fn same_as(self, other: Self) -> bool {
        match (self, other) {
            (Self::F32(a), Self::F32(b)) => a.to_bits() == b.to_bits(),
            (a, b) => a == b,
        }
    }
}

/// How a value travels in the float `param_value` field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// The value's bytes copied into the float's 4 bytes (C `mavlink_param_union_t`); PX4
    /// and the spec's recommendation. Exact for every type.
    Bytewise,
    /// The value converted to float (`(float)value`); ArduPilot. Exact only to 24 bits.
    CCast,
}

impl Encoding {
    /// The encoding an autopilot uses, since neither PX4 nor ArduPilot advertises it:
    /// C-cast for ArduPilot, bytewise for everything else.
    #[must_use]
    pub fn for_autopilot(autopilot: MavAutopilot) -> Self {
        if autopilot == MavAutopilot::ARDUPILOTMEGA {
            Self::CCast
        } else {
            Self::Bytewise
        }
    }

    /// The encoding advertised by AUTOPILOT_VERSION's `capabilities`, if a bit is set.
    #[must_use]
    pub fn from_capabilities(capabilities: u64) -> Option<Self> {
        if capabilities & MavProtocolCapability::PARAM_ENCODE_BYTEWISE.0 != 0 {
            Some(Self::Bytewise)
        } else if capabilities & MavProtocolCapability::PARAM_ENCODE_C_CAST.0 != 0 {
            Some(Self::CCast)
        } else {
            None
        }
    }

    /// `value` in the float field.
    ///
    /// ```
    /// use mavstack_services::param::{Encoding, Value};
    /// assert_eq!(Encoding::CCast.encode(Value::I32(3)), 3.0);
    /// assert_eq!(Encoding::Bytewise.encode(Value::I32(3)).to_bits(), 3);
    /// ```
    #[must_use]
    pub fn encode(self, value: Value) -> f32 {
        match self {
            Self::CCast => value.as_f64() as f32,
            Self::Bytewise => {
                let mut b = [0u8; 4];
                match value {
                    Value::U8(v) => b[0] = v,
                    Value::I8(v) => b[0] = v.to_le_bytes()[0],
                    Value::U16(v) => b[..2].copy_from_slice(&v.to_le_bytes()),
                    Value::I16(v) => b[..2].copy_from_slice(&v.to_le_bytes()),
                    Value::U32(v) => b = v.to_le_bytes(),
                    Value::I32(v) => b = v.to_le_bytes(),
                    Value::F32(v) => b = v.to_le_bytes(),
                }
                f32::from_le_bytes(b)
            }
        }
    }

    /// The value of type `ty` carried as `raw`; `None` for a type this protocol cannot
    /// carry (64-bit types, unknown values).
    ///
    /// ```
    /// use mavstack_dialects::common::MavParamType;
    /// use mavstack_services::param::{Encoding, Value};
    /// let raw = Encoding::Bytewise.encode(Value::U32(0xFFFF_FFFF)); // a NaN: kept as is
    /// assert_eq!(Encoding::Bytewise.decode(raw, MavParamType::UINT32), Some(Value::U32(0xFFFF_FFFF)));
    /// ```
    #[must_use]
    pub fn decode(self, raw: f32, ty: MavParamType) -> Option<Value> {
        match self {
            Self::CCast => Value::F32(raw).converted_to(ty),
            Self::Bytewise => {
                let b = raw.to_le_bytes();
                Some(match ty {
                    MavParamType::UINT8 => Value::U8(b[0]),
                    MavParamType::INT8 => Value::I8(i8::from_le_bytes([b[0]])),
                    MavParamType::UINT16 => Value::U16(u16::from_le_bytes([b[0], b[1]])),
                    MavParamType::INT16 => Value::I16(i16::from_le_bytes([b[0], b[1]])),
                    MavParamType::UINT32 => Value::U32(u32::from_le_bytes(b)),
                    MavParamType::INT32 => Value::I32(i32::from_le_bytes(b)),
                    MavParamType::REAL32 => Value::F32(raw),
                    _ => return None,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [Value; 9] = [
        Value::U8(200),
        Value::I8(-5),
        Value::U16(60_000),
        Value::I16(-30_000),
        Value::U32(4_000_000_000),
        Value::I32(-2_000_000_000),
        Value::I32(16_777_217),
        Value::F32(1.5),
        Value::F32(f32::NAN),
    ];

    #[test]
    fn bytewise_round_trips_every_type_exactly() {
        for v in ALL {
            let raw = Encoding::Bytewise.encode(v);
            let back = Encoding::Bytewise.decode(raw, v.param_type()).unwrap();
            assert!(back.same_as(v), "{v:?} -> {back:?}");
        }
    }

    #[test]
    fn c_cast_is_exact_to_24_bits() {
        for v in [
            Value::U8(200),
            Value::I16(-30_000),
            Value::I32(16_777_216),
            Value::F32(1.5),
        ] {
            let raw = Encoding::CCast.encode(v);
            assert_eq!(raw as f64, v.as_f64());
            assert!(
                Encoding::CCast
                    .decode(raw, v.param_type())
                    .unwrap()
                    .same_as(v)
            );
        }
        // 2^24 + 1 is not a float: C-cast loses it, bytewise does not.
        let v = Value::I32(16_777_217);
        assert_eq!(
            Encoding::CCast.decode(Encoding::CCast.encode(v), MavParamType::INT32),
            Some(Value::I32(16_777_216))
        );
    }

    #[test]
    fn encodings_chosen_by_autopilot_and_capability() {
        assert_eq!(
            Encoding::for_autopilot(MavAutopilot::ARDUPILOTMEGA),
            Encoding::CCast
        );
        assert_eq!(
            Encoding::for_autopilot(MavAutopilot::PX4),
            Encoding::Bytewise
        );
        assert_eq!(Encoding::from_capabilities(16), Some(Encoding::Bytewise));
        assert_eq!(Encoding::from_capabilities(131_072), Some(Encoding::CCast));
        assert_eq!(Encoding::from_capabilities(8192), None);
    }

    #[test]
    fn sixty_four_bit_types_are_refused() {
        assert_eq!(Encoding::Bytewise.decode(0.0, MavParamType::INT64), None);
        assert_eq!(Value::U8(1).converted_to(MavParamType::REAL64), None);
    }

    #[test]
    fn names_are_sixteen_bytes_at_most() {
        let n = Name::new("ABCDEFGHIJKLMNOP").unwrap();
        assert_eq!(Name::from_field(&n.to_field()), n);
        assert_eq!(Name::new(""), Err(NameError::Invalid));
        assert_eq!(
            Name::new("ABCDEFGHIJKLMNOPQ"),
            Err(NameError::TooLong { len: 17 })
        );
    }
}
