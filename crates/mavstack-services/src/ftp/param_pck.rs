//! ArduPilot's packed parameter file, `@PARAM/param.pck`: a whole parameter table in one
//! MAVFTP download.
//!
//! The format (ArduPilot's `AP_Filesystem_Param`, read by pymavlink's `ftp_param_decode`),
//! all little-endian:
//!
//! - a 6-byte header: magic `0x671b` ([`MAGIC`]; `0x671c`, [`MAGIC_WITH_DEFAULTS`], when
//!   entries may carry their default), the number of entries in the file, and the number
//!   of parameters the vehicle has (more when the file is a slice, `?start=N&count=C`);
//! - per entry: one byte with the type in its low nibble (1 int8, 2 int16, 3 int32,
//!   4 float) and flags in its high nibble (bit 0: a default value follows the value); one
//!   byte with the number of leading name bytes shared with the previous entry's name in its
//!   low nibble (0–15) and the number of name bytes that follow, minus one, in its high
//!   nibble (so 1–16); those name bytes; the value (1, 2 or 4 bytes), then the default (as
//!   many) when flagged;
//! - zero bytes before an entry are padding (an entry's first byte is never zero): ArduPilot
//!   inserts them so that the entry's last value does not cross a read-block boundary.
//!
//! Uploads (writing the file sets the parameters in it, as ArduPilot does when the client's
//! session closes) use the same layout with three differences, checked by
//! [`decode_upload`] as ArduPilot's parser checks them: the magic is [`MAGIC`], the
//! header's third field holds the file's length in bytes (so an upload is at most
//! [`MAX_UPLOAD`] bytes), and there are neither defaults nor padding. [`encode_upload`]
//! writes one. Names the vehicle does not have are skipped by it.
//!
//! The 64-bit types do not exist in this format, nor do the unsigned ones: [`encode`] writes
//! an unsigned value as the smallest signed type that holds it (so it decodes as that signed
//! type, same number), and refuses a `u32` above `i32::MAX`.

use alloc::vec::Vec;

use crate::param::{Name, Value};

/// The magic of a file without default values.
pub const MAGIC: u16 = 0x671b;
/// The magic of a file whose entries may carry their default value.
pub const MAGIC_WITH_DEFAULTS: u16 = 0x671c;
/// The path of the file on ArduPilot's MAVFTP server (and on `mavstack-sim`'s vehicle).
pub const PATH: &str = "@PARAM/param.pck";
/// The read block [`encode`] pads for by default: the data of one MAVFTP reply.
pub const BLOCK: usize = super::payload::MAX_DATA;

/// The largest upload: its header holds the file's length in 16 bits.
pub const MAX_UPLOAD: usize = u16::MAX as usize;

const HEADER: usize = 6;

/// Why a table cannot be packed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EncodeError {
    /// More than 65,535 entries.
    #[error("{0} parameters: the file holds at most 65535")]
    TooMany(usize),
    /// A value no type of the format holds (a `u32` above `i32::MAX`).
    #[error("parameter {0}: the value does not fit the format's int32")]
    Unrepresentable(Name),
    /// An empty name (a `param_id` of NULs), which the format cannot hold.
    #[error("an empty parameter name")]
    EmptyName,
    /// An upload longer than [`MAX_UPLOAD`] bytes.
    #[error("{0} bytes: an upload holds at most 65535")]
    TooLarge(usize),
}

/// Why bytes are not a packed parameter file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum DecodeError {
    /// Shorter than the 6-byte header.
    #[error("{0} bytes: shorter than the header")]
    TooShort(usize),
    /// Neither [`MAGIC`] nor [`MAGIC_WITH_DEFAULTS`].
    #[error("bad magic {0:#06x}")]
    BadMagic(u16),
    /// The header's entry count is larger than its parameter count.
    #[error("{count} entries of {total} parameters")]
    BadCount {
        /// Entries the header announces.
        count: u16,
        /// Parameters it says the vehicle has.
        total: u16,
    },
    /// An entry cut short at this offset.
    #[error("entry at byte {0} is truncated")]
    Truncated(usize),
    /// An entry's type is not 1–4.
    #[error("entry at byte {offset}: unknown type {ty}")]
    BadType {
        /// The entry's offset.
        offset: usize,
        /// Its type nibble.
        ty: u8,
    },
    /// An entry shares more bytes with the previous name than that name has.
    #[error("entry at byte {0}: shared prefix longer than the previous name")]
    BadPrefix(usize),
    /// An entry's name is longer than 16 bytes, contains a NUL or is not UTF-8.
    #[error("entry at byte {0}: not a parameter name")]
    BadName(usize),
    /// An upload whose length differs from the one its header gives.
    #[error("{found} bytes, the upload's header says {expected}")]
    WrongLength {
        /// Bytes received.
        found: usize,
        /// Bytes announced.
        expected: u16,
    },
    /// An upload with default values (magic [`MAGIC_WITH_DEFAULTS`] or an entry's flag).
    #[error("an upload cannot carry defaults")]
    DefaultsInUpload,
    /// The number of entries differs from the header's.
    #[error("{found} entries, the header says {expected}")]
    WrongCount {
        /// Entries found.
        found: usize,
        /// Entries announced.
        expected: u16,
    },
}

/// A decoded file.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamFile {
    /// The entries, in file order: name, value, and the default when the file has defaults
    /// ([`MAGIC_WITH_DEFAULTS`]: the value itself for an entry without a default of its own,
    /// as pymavlink reads it).
    pub entries: Vec<(Name, Value, Option<Value>)>,
    /// The number of parameters the vehicle has (the header's third field).
    pub total: u16,
    /// Whether the magic was [`MAGIC_WITH_DEFAULTS`].
    pub with_defaults: bool,
}

impl ParamFile {
    /// The table without defaults.
    #[must_use]
    pub fn table(&self) -> Vec<(Name, Value)> {
        self.entries.iter().map(|&(n, v, _)| (n, v)).collect()
    }
}

/// How [`encode_with`] packs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EncodeOptions {
    /// Write [`MAGIC_WITH_DEFAULTS`] and each entry's default where it differs from the
    /// value.
    pub with_defaults: bool,
    /// The header's parameter count (`None`: the number of entries).
    pub total: Option<u16>,
    /// Pad so that no entry's last value crosses a multiple of this many bytes (from the
    /// file's start), as ArduPilot does for its read size; `0`: no padding.
    pub block: usize,
}

impl Default for EncodeOptions {
    fn default() -> Self {
        Self {
            with_defaults: false,
            total: None,
            block: BLOCK,
        }
    }
}

/// The format's type code and bytes of `v`.
fn packed(name: Name, v: Value) -> Result<(u8, [u8; 4], usize), EncodeError> {
    let i8_ = |x: i8| (1, [x.to_le_bytes()[0], 0, 0, 0], 1);
    let i16_ = |x: i16| {
        let b = x.to_le_bytes();
        (2, [b[0], b[1], 0, 0], 2)
    };
    let i32_ = |x: i32| (3, x.to_le_bytes(), 4);
    Ok(match v {
        Value::I8(x) => i8_(x),
        Value::I16(x) => i16_(x),
        Value::I32(x) => i32_(x),
        Value::F32(x) => (4, x.to_le_bytes(), 4),
        Value::U8(x) => i8::try_from(x).map_or_else(|_| i16_(i16::from(x)), i8_),
        Value::U16(x) => i16::try_from(x).map_or_else(|_| i32_(i32::from(x)), i16_),
        Value::U32(x) => i32_(i32::try_from(x).map_err(|_| EncodeError::Unrepresentable(name))?),
    })
}

/// The value of type code `ty` in `bytes` (as long as the type).
fn unpacked(ty: u8, bytes: &[u8]) -> Option<Value> {
    Some(match (ty, bytes) {
        (1, &[a]) => Value::I8(i8::from_le_bytes([a])),
        (2, &[a, b]) => Value::I16(i16::from_le_bytes([a, b])),
        (3, &[a, b, c, d]) => Value::I32(i32::from_le_bytes([a, b, c, d])),
        (4, &[a, b, c, d]) => Value::F32(f32::from_le_bytes([a, b, c, d])),
        _ => return None,
    })
}

/// Packs `table` (no defaults, padded for [`BLOCK`]-byte reads).
///
/// # Errors
///
/// As [`encode_with`].
///
/// ```
/// use mavstack_services::ftp::param_pck;
/// use mavstack_services::param::{Name, Value};
/// let table = vec![
///     (Name::new("RTL_ALT").unwrap(), Value::I32(1500)),
///     (Name::new("RTL_SPEED").unwrap(), Value::I16(0)),
/// ];
/// let bytes = param_pck::encode(&table).unwrap();
/// assert_eq!(&bytes[..6], &[0x1b, 0x67, 2, 0, 2, 0]);
/// assert_eq!(param_pck::decode(&bytes).unwrap(), table);
/// ```
pub fn encode(table: &[(Name, Value)]) -> Result<Vec<u8>, EncodeError> {
    let entries: Vec<_> = table.iter().map(|&(n, v)| (n, v, None)).collect();
    encode_with(&entries, EncodeOptions::default())
}

/// Packs `entries` (name, value, default) as `options` say. A default is written (with
/// [`EncodeOptions::with_defaults`]) only where it differs from the value, converted to the
/// value's type.
///
/// # Errors
///
/// [`EncodeError::TooMany`] past 65,535 entries, [`EncodeError::Unrepresentable`] for a
/// `u32` above `i32::MAX`.
pub fn encode_with(
    entries: &[(Name, Value, Option<Value>)],
    options: EncodeOptions,
) -> Result<Vec<u8>, EncodeError> {
    let count = u16::try_from(entries.len()).map_err(|_| EncodeError::TooMany(entries.len()))?;
    let total = options.total.unwrap_or(count).max(count);
    let magic = if options.with_defaults {
        MAGIC_WITH_DEFAULTS
    } else {
        MAGIC
    };
    let mut out = Vec::with_capacity(HEADER + entries.len() * 12);
    out.extend_from_slice(&magic.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&total.to_le_bytes());
    let mut last: &[u8] = &[];
    for (name, value, default) in entries {
        let (ty, bytes, len) = packed(*name, *value)?;
        let default = match default {
            Some(d) if options.with_defaults && !d.same_as(*value) => {
                let (dty, dbytes, _) = packed(*name, *d)?;
                // A default of another type is converted to the value's.
                if dty == ty {
                    Some(dbytes)
                } else {
                    let converted = d.converted_to(unpacked_type(ty)).unwrap_or(*value);
                    Some(packed(*name, converted)?.1)
                }
            }
            _ => None,
        };
        let full = name.as_bytes();
        if full.is_empty() {
            return Err(EncodeError::EmptyName);
        }
        let shared = full.iter().zip(last).take_while(|(a, b)| a == b).count();
        // At least one name byte follows, and the nibble holds at most 15.
        let shared = shared.min(full.len() - 1).min(15);
        let suffix = &full[shared..];
        let record = 2 + suffix.len() + len + if default.is_some() { len } else { 0 };
        if options.block > 0 && len > 1 {
            let end = (out.len() + record) % options.block;
            if end > 0 && end < len {
                out.resize(out.len() + (len - end), 0);
            }
        }
        out.push(ty | (u8::from(default.is_some()) << 4));
        // `shared` ≤ 15 and 1 ≤ suffix.len() ≤ 16.
        out.push(shared as u8 | (((suffix.len() - 1) as u8) << 4));
        out.extend_from_slice(suffix);
        out.extend_from_slice(&bytes[..len]);
        if let Some(d) = default {
            out.extend_from_slice(&d[..len]);
        }
        last = full;
    }
    Ok(out)
}

/// Packs `table` as an upload to [`PATH`]: no defaults, no padding, the file's length in
/// the header's third field. A vehicle converts each value to its parameter's own type;
/// give an int32 parameter an `I32` to keep all its bits.
///
/// # Errors
///
/// As [`encode_with`], and [`EncodeError::TooLarge`] past [`MAX_UPLOAD`] bytes.
///
/// ```
/// use mavstack_services::ftp::param_pck;
/// use mavstack_services::param::{Name, Value};
/// let table = vec![(Name::new("RTL_ALT").unwrap(), Value::I32(2000))];
/// let bytes = param_pck::encode_upload(&table).unwrap();
/// assert_eq!(&bytes[..6], &[0x1b, 0x67, 1, 0, 19, 0]);
/// assert_eq!(param_pck::decode_upload(&bytes).unwrap(), table);
/// ```
pub fn encode_upload(table: &[(Name, Value)]) -> Result<Vec<u8>, EncodeError> {
    let entries: Vec<_> = table.iter().map(|&(n, v)| (n, v, None)).collect();
    let options = EncodeOptions {
        with_defaults: false,
        total: None,
        block: 0,
    };
    let mut bytes = encode_with(&entries, options)?;
    let len = u16::try_from(bytes.len()).map_err(|_| EncodeError::TooLarge(bytes.len()))?;
    bytes[4..HEADER].copy_from_slice(&len.to_le_bytes());
    Ok(bytes)
}

/// The parameters in an uploaded file, checked as ArduPilot checks an upload: magic
/// [`MAGIC`], the length the header gives, every entry whole with its flags clear and no
/// padding, and the announced number of entries. Never panics, whatever the bytes.
///
/// # Errors
///
/// [`DecodeError`], saying which check failed.
pub fn decode_upload(bytes: &[u8]) -> Result<Vec<(Name, Value)>, DecodeError> {
    let Some(header) = bytes.first_chunk::<HEADER>() else {
        return Err(DecodeError::TooShort(bytes.len()));
    };
    let field = |i: usize| u16::from_le_bytes([header[i], header[i + 1]]);
    match field(0) {
        MAGIC => {}
        MAGIC_WITH_DEFAULTS => return Err(DecodeError::DefaultsInUpload),
        m => return Err(DecodeError::BadMagic(m)),
    }
    if usize::from(field(4)) != bytes.len() {
        return Err(DecodeError::WrongLength {
            found: bytes.len(),
            expected: field(4),
        });
    }
    // No padding: a zero where an entry starts reads as an entry of type 0.
    let mut reader = Entries::new(bytes, false, false);
    let mut entries = Vec::new();
    while let Some(entry) = reader.next_entry()? {
        if entry.flags != 0 {
            return Err(DecodeError::DefaultsInUpload);
        }
        entries.push((entry.name, entry.value));
    }
    if entries.len() != usize::from(field(2)) {
        return Err(DecodeError::WrongCount {
            found: entries.len(),
            expected: field(2),
        });
    }
    Ok(entries)
}

/// The MAV_PARAM_TYPE of a type code.
fn unpacked_type(ty: u8) -> mavstack_dialects::common::MavParamType {
    use mavstack_dialects::common::MavParamType;
    match ty {
        1 => MavParamType::INT8,
        2 => MavParamType::INT16,
        3 => MavParamType::INT32,
        _ => MavParamType::REAL32,
    }
}

/// The table in a packed file (defaults dropped).
///
/// # Errors
///
/// As [`decode_file`].
pub fn decode(bytes: &[u8]) -> Result<Vec<(Name, Value)>, DecodeError> {
    decode_file(bytes).map(|f| f.table())
}

/// A packed file, checked as pymavlink checks it: the magic, entry count ≤ parameter count,
/// every entry whole, of a known type, with a shared prefix no longer than the previous
/// name, a name of 1–16 bytes of UTF-8 without NUL, and as many entries as announced.
/// Never panics, whatever the bytes.
///
/// # Errors
///
/// [`DecodeError`], saying which check failed.
pub fn decode_file(bytes: &[u8]) -> Result<ParamFile, DecodeError> {
    let Some(header) = bytes.first_chunk::<HEADER>() else {
        return Err(DecodeError::TooShort(bytes.len()));
    };
    let field = |i: usize| u16::from_le_bytes([header[i], header[i + 1]]);
    let (magic, count, total) = (field(0), field(2), field(4));
    let with_defaults = match magic {
        MAGIC => false,
        MAGIC_WITH_DEFAULTS => true,
        m => return Err(DecodeError::BadMagic(m)),
    };
    if count > total {
        return Err(DecodeError::BadCount { count, total });
    }
    let mut reader = Entries::new(bytes, with_defaults, true);
    let mut entries: Vec<(Name, Value, Option<Value>)> = Vec::new();
    while let Some(e) = reader.next_entry()? {
        let default = e.default.or_else(|| with_defaults.then_some(e.value));
        entries.push((e.name, e.value, default));
    }
    if entries.len() != usize::from(count) {
        return Err(DecodeError::WrongCount {
            found: entries.len(),
            expected: count,
        });
    }
    Ok(ParamFile {
        entries,
        total,
        with_defaults,
    })
}

/// One entry as read.
struct Entry {
    name: Name,
    value: Value,
    /// Its flags nibble (bit 0: a default follows, read only in a file with defaults).
    flags: u8,
    default: Option<Value>,
}

/// Reads the entries after a file's header one at a time, checking each.
struct Entries<'a> {
    file: &'a [u8],
    rest: &'a [u8],
    with_defaults: bool,
    skip_padding: bool,
    last: [u8; 16],
    last_len: usize,
}

impl<'a> Entries<'a> {
    /// The entries of `file` (header included, at least [`HEADER`] bytes long).
    fn new(file: &'a [u8], with_defaults: bool, skip_padding: bool) -> Self {
        Self {
            file,
            rest: file.get(HEADER..).unwrap_or(&[]),
            with_defaults,
            skip_padding,
            last: [0; 16],
            last_len: 0,
        }
    }

    /// The next entry, `None` at the end of the file.
    fn next_entry(&mut self) -> Result<Option<Entry>, DecodeError> {
        if self.skip_padding {
            let pad = self.rest.iter().take_while(|&&b| b == 0).count();
            self.rest = &self.rest[pad..];
        }
        let offset = self.file.len() - self.rest.len();
        let [kind, lens, tail @ ..] = self.rest else {
            if self.rest.is_empty() {
                return Ok(None);
            }
            return Err(DecodeError::Truncated(offset));
        };
        let (ty, flags) = (kind & 0x0f, kind >> 4);
        let len = match ty {
            1 => 1,
            2 => 2,
            3 | 4 => 4,
            _ => return Err(DecodeError::BadType { offset, ty }),
        };
        let reads_default = self.with_defaults && flags & 1 != 0;
        let shared = usize::from(lens & 0x0f);
        let suffix_len = usize::from(lens >> 4) + 1;
        let value_len = if reads_default { 2 * len } else { len };
        let Some((suffix, tail)) = tail.split_at_checked(suffix_len) else {
            return Err(DecodeError::Truncated(offset));
        };
        let Some((values, tail)) = tail.split_at_checked(value_len) else {
            return Err(DecodeError::Truncated(offset));
        };
        if shared > self.last_len {
            return Err(DecodeError::BadPrefix(offset));
        }
        let name_len = shared + suffix_len;
        if name_len > 16 {
            return Err(DecodeError::BadName(offset));
        }
        self.last[shared..name_len].copy_from_slice(suffix);
        self.last_len = name_len;
        let text = core::str::from_utf8(&self.last[..name_len])
            .map_err(|_| DecodeError::BadName(offset))?;
        let name = Name::new(text).map_err(|_| DecodeError::BadName(offset))?;
        let value = unpacked(ty, &values[..len]).ok_or(DecodeError::BadType { offset, ty })?;
        let default = if reads_default {
            Some(unpacked(ty, &values[len..]).ok_or(DecodeError::BadType { offset, ty })?)
        } else {
            None
        };
        self.rest = tail;
        Ok(Some(Entry {
            name,
            value,
            flags,
            default,
        }))
    }
}

/// What a request for the packed file asks (the query ArduPilot's server takes:
/// `@PARAM/param.pck?withdefaults=1&start=N&count=C`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Query {
    /// `withdefaults=1`.
    pub with_defaults: bool,
    /// `start=N`: the first parameter's index.
    pub start: u16,
    /// `count=C`: at most this many (`0`: all).
    pub count: u16,
}

impl Query {
    /// The query in `path` if it names the packed file ([`PATH`], normalised, optionally
    /// followed by `?` and `&`-separated `key=value` pairs); unknown keys are ignored, as
    /// ArduPilot does. `None` for another path.
    ///
    /// # Errors
    ///
    /// `Some(Err(()))` for a known key with a bad value (`withdefaults` other than 0 or 1,
    /// `start` or `count` not below 65,535).
    #[must_use]
    pub fn parse(path: &str) -> Option<Result<Self, ()>> {
        let rest = path.strip_prefix(PATH)?;
        let mut q = Self::default();
        let Some(args) = rest.strip_prefix('?') else {
            return rest.is_empty().then_some(Ok(q));
        };
        for pair in args.split('&') {
            let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
            let number = || {
                value
                    .parse::<u16>()
                    .ok()
                    .filter(|&v| v < u16::MAX)
                    .ok_or(())
            };
            let ok = match key {
                "withdefaults" => match value {
                    "0" | "1" => {
                        q.with_defaults = value == "1";
                        Ok(())
                    }
                    _ => Err(()),
                },
                "start" => number().map(|v| q.start = v),
                "count" => number().map(|v| q.count = v),
                _ => Ok(()),
            };
            if ok.is_err() {
                return Some(Err(()));
            }
        }
        Some(Ok(q))
    }

    /// The file this query asks of `table` (entries: name, value, default): the slice it
    /// selects, the header's total the whole table's size.
    ///
    /// # Errors
    ///
    /// As [`encode_with`]; [`EncodeError::TooMany`] also for a `start` past the table (as
    /// ArduPilot, which refuses the read).
    pub fn encode(self, table: &[(Name, Value, Option<Value>)]) -> Result<Vec<u8>, EncodeError> {
        let total = u16::try_from(table.len()).map_err(|_| EncodeError::TooMany(table.len()))?;
        let start = usize::from(self.start);
        if start >= table.len() && start > 0 {
            return Err(EncodeError::TooMany(start));
        }
        let rest = &table[start.min(table.len())..];
        let slice = match self.count {
            0 => rest,
            c => &rest[..rest.len().min(usize::from(c))],
        };
        encode_with(
            slice,
            EncodeOptions {
                with_defaults: self.with_defaults,
                total: Some(total),
                block: BLOCK,
            },
        )
    }
}

/// How many uploads a [`TableFile`] keeps until its owner takes them.
const UPLOADS_KEPT: usize = 4;

/// A parameter table served as [`PATH`] by an [`Overlay`](super::Overlay): a
/// [`Provider`](super::overlay::Provider) packing the table as it is when a client opens the
/// file (with the [`Query`] in the path), each entry's default the value it had when the
/// table was made. Listings show `@PARAM` in the root and `param.pck` in it.
///
/// A client may also write [`PATH`] (at most [`MAX_UPLOAD`] bytes) to set parameters, as
/// on ArduPilot: each upload, checked by [`decode_upload`] when the session closes, waits in
/// [`take_upload`](Self::take_upload) for the owner to apply it (the last few are kept).
#[derive(Clone, Debug, Default)]
pub struct TableFile {
    entries: Vec<(Name, Value, Option<Value>)>,
    uploads: alloc::collections::VecDeque<Result<Vec<(Name, Value)>, DecodeError>>,
}

impl TableFile {
    /// `table`, whose values are also the defaults.
    #[must_use]
    pub fn new(table: &[(Name, Value)]) -> Self {
        Self {
            entries: table.iter().map(|&(n, v)| (n, v, Some(v))).collect(),
            uploads: alloc::collections::VecDeque::new(),
        }
    }

    /// The oldest upload not taken yet: the parameters it sets, or why it was refused.
    pub fn take_upload(&mut self) -> Option<Result<Vec<(Name, Value)>, DecodeError>> {
        self.uploads.pop_front()
    }

    /// Sets a parameter's value (its default stays); `false` if the table has no such name.
    pub fn set(&mut self, name: Name, value: Value) -> bool {
        match self.entries.iter_mut().find(|e| e.0 == name) {
            Some(e) => {
                e.1 = value;
                true
            }
            None => false,
        }
    }

    /// The entries: name, value, default.
    #[must_use]
    pub fn entries(&self) -> &[(Name, Value, Option<Value>)] {
        &self.entries
    }
}

impl super::overlay::Provider for TableFile {
    fn provides(&self, path: &str) -> bool {
        Query::parse(path).is_some()
    }

    fn contents(&mut self, path: &str) -> Result<Vec<u8>, super::BackendError> {
        match Query::parse(path) {
            Some(Ok(q)) => q
                .encode(&self.entries)
                .map_err(|_| super::BackendError::Fail),
            Some(Err(())) => Err(super::BackendError::Fail),
            None => Err(super::BackendError::NotFound),
        }
    }

    /// As ArduPilot: 12 bytes a parameter (its estimate, to spare a scan of the table), or
    /// the real length where that is more; the read ends at the real end.
    fn announced_size(&self, _path: &str, contents: &[u8]) -> u64 {
        let estimate = self.entries.len().saturating_mul(12);
        u64::try_from(estimate.max(contents.len())).unwrap_or(u64::MAX)
    }

    fn upload_limit(&self, path: &str) -> Option<usize> {
        (path == PATH).then_some(MAX_UPLOAD)
    }

    fn upload(&mut self, _path: &str, contents: Vec<u8>) {
        if self.uploads.len() == UPLOADS_KEPT {
            self.uploads.pop_front();
        }
        self.uploads.push_back(decode_upload(&contents));
    }

    fn entries(&mut self, dir: &str) -> Vec<super::DirEntry> {
        let (parent, file) = PATH.split_once('/').unwrap_or(("", PATH));
        if dir.is_empty() {
            alloc::vec![super::overlay::dir_entry(parent)]
        } else if dir == parent {
            let size = Query::default()
                .encode(&self.entries)
                .map_or(0, |b| b.len());
            alloc::vec![super::overlay::file_entry(file, size)]
        } else {
            Vec::new()
        }
    }
}

#[cfg(test)]
mod tests;
