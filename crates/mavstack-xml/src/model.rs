//! The validated model of a dialect: what the XML says, resolved across includes, with the
//! wire layout computed.

use std::path::PathBuf;

use crate::error::Location;

/// The element type of a field on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PrimitiveType {
    /// `uint8_t` (also `uint8_t_mavlink_version`).
    U8,
    /// `int8_t`.
    I8,
    /// `uint16_t`.
    U16,
    /// `int16_t`.
    I16,
    /// `uint32_t`.
    U32,
    /// `int32_t`.
    I32,
    /// `uint64_t`.
    U64,
    /// `int64_t`.
    I64,
    /// `float`.
    F32,
    /// `double`.
    F64,
    /// `char`: one byte of text.
    Char,
}

impl PrimitiveType {
    /// Every primitive type.
    pub const ALL: [Self; 11] = [
        Self::U8,
        Self::I8,
        Self::U16,
        Self::I16,
        Self::U32,
        Self::I32,
        Self::U64,
        Self::I64,
        Self::F32,
        Self::F64,
        Self::Char,
    ];

    /// Size of one element in bytes.
    #[must_use]
    pub const fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 | Self::Char => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::U64 | Self::I64 | Self::F64 => 8,
        }
    }

    /// The XML (C) name, e.g. `"uint16_t"`.
    #[must_use]
    pub const fn c_name(self) -> &'static str {
        match self {
            Self::U8 => "uint8_t",
            Self::I8 => "int8_t",
            Self::U16 => "uint16_t",
            Self::I16 => "int16_t",
            Self::U32 => "uint32_t",
            Self::I32 => "int32_t",
            Self::U64 => "uint64_t",
            Self::I64 => "int64_t",
            Self::F32 => "float",
            Self::F64 => "double",
            Self::Char => "char",
        }
    }

    /// The type for an XML (C) name, e.g. `"uint16_t"`.
    #[must_use]
    pub fn from_c_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.c_name() == name)
    }

    /// The Rust type that holds one element, e.g. `"u16"` (`char` is `"u8"`).
    #[must_use]
    pub const fn rust_name(self) -> &'static str {
        match self {
            Self::U8 | Self::Char => "u8",
            Self::I8 => "i8",
            Self::U16 => "u16",
            Self::I16 => "i16",
            Self::U32 => "u32",
            Self::I32 => "i32",
            Self::U64 => "u64",
            Self::I64 => "i64",
            Self::F32 => "f32",
            Self::F64 => "f64",
        }
    }

    /// Whether the type is a signed integer.
    #[must_use]
    pub const fn is_signed_int(self) -> bool {
        matches!(self, Self::I8 | Self::I16 | Self::I32 | Self::I64)
    }

    /// Whether the type is `float` or `double`.
    #[must_use]
    pub const fn is_float(self) -> bool {
        matches!(self, Self::F32 | Self::F64)
    }
}

/// A field's type: an element type, and an array length for arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FieldType {
    /// The element type.
    pub primitive: PrimitiveType,
    /// The array length (1 to 255), or `None` for a scalar.
    pub array_len: Option<u8>,
    /// Whether the XML type was `uint8_t_mavlink_version` (HEARTBEAT.mavlink_version): a
    /// `uint8_t` whose value the library fills in with the dialect's version.
    pub mavlink_version: bool,
}

impl FieldType {
    /// Size on the wire in bytes.
    #[must_use]
    pub fn wire_size(&self) -> usize {
        self.primitive.size() * usize::from(self.array_len.unwrap_or(1))
    }
}

/// Why an item should not be used any more.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Deprecation {
    /// `true` for `<superseded>` (still valid, a better item exists), `false` for `<deprecated>`.
    pub superseded: bool,
    /// The `since` attribute, e.g. `"2019-10"`.
    pub since: String,
    /// The `replaced_by` attribute.
    pub replaced_by: String,
    /// The element's text.
    pub note: String,
}

/// One field of a message.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Name, e.g. `"custom_mode"`.
    pub name: String,
    /// Type.
    pub ty: FieldType,
    /// Offset in the full (untruncated) payload.
    pub offset: usize,
    /// Whether the field comes after `<extensions/>` (MAVLink 2 only, not in CRC_EXTRA).
    pub extension: bool,
    /// The enum the values come from, if any.
    pub enum_name: Option<String>,
    /// `display` attribute (`"bitmask"` marks a bitmask without a named enum).
    pub display: Option<String>,
    /// Units, e.g. `"cm"`.
    pub units: Option<String>,
    /// `invalid` attribute: the value that means "not set".
    pub invalid: Option<String>,
    /// `instance` attribute: the field tells instances of the message apart.
    pub instance: bool,
    /// Description text.
    pub description: String,
    /// Where the field is defined.
    pub location: Location,
}

/// One message.
#[derive(Clone, Debug, PartialEq)]
pub struct Message {
    /// Id (24 bits).
    pub id: u32,
    /// Name, e.g. `"HEARTBEAT"`.
    pub name: String,
    /// Description text.
    pub description: String,
    /// Fields in wire order: base fields sorted by element size (stable), then extensions in
    /// XML order.
    pub fields: Vec<Field>,
    /// CRC_EXTRA seed.
    pub crc_extra: u8,
    /// Payload length of the base fields.
    pub min_len: usize,
    /// Payload length with extensions.
    pub max_len: usize,
    /// Offset of `target_system` (MANUAL_CONTROL: `target`), if the message has that field.
    pub target_system_offset: Option<usize>,
    /// Offset of `target_component`, if the message has that field.
    pub target_component_offset: Option<usize>,
    /// Deprecation or supersession, if any.
    pub deprecation: Option<Deprecation>,
    /// Work in progress (`<wip/>`).
    pub wip: bool,
    /// The file that defines the message.
    pub file: PathBuf,
    /// Where the message is defined.
    pub location: Location,
}

impl Message {
    /// The field called `name`.
    #[must_use]
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.name == name)
    }

    /// The fields in XML order (as generated code and most tools list them).
    #[must_use]
    pub fn fields_in_xml_order(&self) -> Vec<&Field> {
        let mut fields: Vec<&Field> = self.fields.iter().collect();
        fields.sort_by_key(|f| (f.location.line, f.location.column));
        fields
    }
}

/// A parameter description of an enum entry (MAV_CMD params).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EntryParam {
    /// Index, 1 to 7.
    pub index: u8,
    /// `label` attribute.
    pub label: Option<String>,
    /// `units` attribute.
    pub units: Option<String>,
    /// `enum` attribute.
    pub enum_name: Option<String>,
    /// Description text.
    pub description: String,
}

/// One entry of an enum.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// Name, e.g. `"MAV_TYPE_QUADROTOR"`.
    pub name: String,
    /// Value.
    pub value: u64,
    /// Description text.
    pub description: String,
    /// Deprecation or supersession, if any.
    pub deprecation: Option<Deprecation>,
    /// Work in progress.
    pub wip: bool,
    /// Parameter descriptions (MAV_CMD entries).
    pub params: Vec<EntryParam>,
    /// The file that contributes the entry (it may extend an enum of an included file).
    pub file: PathBuf,
    /// Where the entry is defined.
    pub location: Location,
}

/// One enum, with the entries of every file of the dialect that declares it.
#[derive(Clone, Debug, PartialEq)]
pub struct Enum {
    /// Name, e.g. `"MAV_TYPE"`.
    pub name: String,
    /// Description text (of the first declaration that has one).
    pub description: String,
    /// Whether values are bit flags.
    pub bitmask: bool,
    /// Entries, in declaration order across files (included files first).
    pub entries: Vec<Entry>,
    /// Deprecation or supersession, if any.
    pub deprecation: Option<Deprecation>,
    /// The file with the first declaration.
    pub file: PathBuf,
    /// Where the first declaration is.
    pub location: Location,
}

impl Enum {
    /// The entry called `name`.
    #[must_use]
    pub fn entry(&self, name: &str) -> Option<&Entry> {
        self.entries.iter().find(|e| e.name == name)
    }
}

/// One file of a dialect's include closure.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FileInfo {
    /// The path as resolved by the loader.
    pub path: PathBuf,
    /// The file's `<version>`, if any.
    pub version: Option<u8>,
    /// The file's `<dialect>` number, if any.
    pub dialect: Option<u8>,
    /// The paths of the files it includes directly.
    pub includes: Vec<PathBuf>,
}

impl FileInfo {
    /// The file name without directory and `.xml` suffix, e.g. `"common"`.
    #[must_use]
    pub fn stem(&self) -> String {
        file_stem(&self.path)
    }
}

/// The file name of `path` without directory and `.xml` suffix.
#[must_use]
pub fn file_stem(path: &std::path::Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// A resolved dialect: a root file with everything it includes, merged and validated.
#[derive(Clone, Debug, PartialEq)]
pub struct Dialect {
    /// The root file's stem, e.g. `"ardupilotmega"`.
    pub name: String,
    /// Every file of the closure, included files before the files that include them; the
    /// root is last.
    pub files: Vec<FileInfo>,
    /// The `<version>` in force: the root's, else the nearest included file's.
    pub version: Option<u8>,
    /// Messages, sorted by id.
    pub messages: Vec<Message>,
    /// Enums, sorted by name.
    pub enums: Vec<Enum>,
}

impl Dialect {
    /// The message with id `id`.
    #[must_use]
    pub fn message(&self, id: u32) -> Option<&Message> {
        self.messages
            .binary_search_by_key(&id, |m| m.id)
            .ok()
            .map(|i| &self.messages[i])
    }

    /// The message called `name`.
    #[must_use]
    pub fn message_by_name(&self, name: &str) -> Option<&Message> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The enum called `name`.
    #[must_use]
    pub fn enum_by_name(&self, name: &str) -> Option<&Enum> {
        self.enums
            .binary_search_by(|e| e.name.as_str().cmp(name))
            .ok()
            .map(|i| &self.enums[i])
    }

    /// The root file.
    #[must_use]
    pub fn root(&self) -> &FileInfo {
        // A dialect always has its root file: the loader builds `files` from it.
        &self.files[self.files.len() - 1]
    }
}
