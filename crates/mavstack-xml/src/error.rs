//! Errors of the dialect loader, each positioned at the file, line and column it is about.

use std::fmt;
use std::path::PathBuf;

/// A place in a definition file (1-based line and column).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Location {
    /// The file, as it was named to the loader or reached through includes.
    pub file: PathBuf,
    /// Line, from 1.
    pub line: u32,
    /// Column, from 1.
    pub column: u32,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}", self.file.display(), self.line, self.column)
    }
}

/// A dialect that could not be loaded: where, and what is wrong.
///
/// Displays as `FILE:LINE:COLUMN: what is wrong`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{location}: {kind}")]
pub struct Error {
    /// Where the problem is. For a file that cannot be read, the include that names it (or
    /// line 1 of the file itself when it is the root).
    pub location: Location,
    /// What is wrong (boxed: errors are rare, and a small `Result` keeps the happy path lean).
    pub kind: Box<ErrorKind>,
}

impl Error {
    pub(crate) fn new(location: Location, kind: ErrorKind) -> Self {
        Self {
            location,
            kind: Box::new(kind),
        }
    }
}

/// What is wrong with a definition file.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The file is not well-formed XML.
    #[error("malformed XML: {0}")]
    Xml(String),
    /// The file cannot be read.
    #[error("cannot read {path}: {reason}")]
    Read {
        /// The path that was tried.
        path: PathBuf,
        /// Why it failed.
        reason: String,
    },
    /// An included file cannot be read.
    #[error("include {include:?} not found: cannot read {path}: {reason}")]
    MissingInclude {
        /// The name as written in `<include>`.
        include: String,
        /// The path it resolved to.
        path: PathBuf,
        /// Why reading failed.
        reason: String,
    },
    /// An `<include>` element without a file name.
    #[error("<include> names no file")]
    EmptyInclude,
    /// A file includes itself, directly or through others.
    #[error("include cycle: {}", chain.join(" -> "))]
    IncludeCycle {
        /// The files of the cycle, the repeated one first and last.
        chain: Vec<String>,
    },
    /// The root element is not `<mavlink>`.
    #[error("root element is <{found}>, expected <mavlink>")]
    NotMavlink {
        /// The element found instead.
        found: String,
    },
    /// A required attribute is missing.
    #[error("<{element}> is missing the attribute {attribute:?}")]
    MissingAttribute {
        /// The element, e.g. `field`.
        element: &'static str,
        /// The attribute, e.g. `type`.
        attribute: &'static str,
    },
    /// A field has a type MAVLink does not define.
    #[error("field {field:?} of message {message}: unknown type {ty:?}")]
    UnknownType {
        /// The message.
        message: String,
        /// The field.
        field: String,
        /// The type as written.
        ty: String,
    },
    /// An array length that is not a number from 1 to 255.
    #[error("field {field:?} of message {message}: bad array length in {ty:?} (must be 1 to 255)")]
    BadArrayLength {
        /// The message.
        message: String,
        /// The field.
        field: String,
        /// The type as written.
        ty: String,
    },
    /// A number that cannot be read (message id, enum value, version).
    #[error("{what}: {value:?} is not a valid number{range}")]
    BadNumber {
        /// What the number is, e.g. `message id`.
        what: String,
        /// The text as written.
        value: String,
        /// The allowed range, if that was the problem (e.g. ` from 0 to 16777215`).
        range: &'static str,
    },
    /// Two messages with one id.
    #[error("duplicate message id {id}: {name} and {other} (defined at {other_location})")]
    DuplicateMessageId {
        /// The id.
        id: u32,
        /// The message defined here.
        name: String,
        /// The message defined earlier.
        other: String,
        /// Where the earlier one is.
        other_location: Location,
    },
    /// Two messages with one name.
    #[error("duplicate message name {name}: ids {id} and {other_id} (defined at {other_location})")]
    DuplicateMessageName {
        /// The name.
        name: String,
        /// The id of the message defined here.
        id: u32,
        /// The id of the message defined earlier.
        other_id: u32,
        /// Where the earlier one is.
        other_location: Location,
    },
    /// Two fields of one message with one name.
    #[error("message {message}: duplicate field {field:?}")]
    DuplicateField {
        /// The message.
        message: String,
        /// The field.
        field: String,
    },
    /// Two entries of one enum with one name but different values.
    #[error(
        "enum {enum_name}: entry {entry} has value {value} here and {other_value} at {other_location}"
    )]
    ConflictingEntry {
        /// The enum.
        enum_name: String,
        /// The entry.
        entry: String,
        /// The value here.
        value: u64,
        /// The value given earlier.
        other_value: u64,
        /// Where the earlier one is.
        other_location: Location,
    },
    /// A field names an enum the dialect does not define.
    #[error("field {field:?} of message {message}: unknown enum {enum_name}")]
    UnknownEnum {
        /// The message.
        message: String,
        /// The field.
        field: String,
        /// The enum named.
        enum_name: String,
    },
    /// A payload longer than a frame can carry.
    #[error("message {message}: payload of {len} bytes is over the 255-byte limit")]
    PayloadTooLarge {
        /// The message.
        message: String,
        /// Its full payload length.
        len: usize,
    },
    /// A message with more fields than MAVLink allows.
    #[error("message {message}: {count} fields, more than the 64 MAVLink allows")]
    TooManyFields {
        /// The message.
        message: String,
        /// How many fields it has.
        count: usize,
    },
    /// A message without fields.
    #[error("message {message} has no fields")]
    NoFields {
        /// The message.
        message: String,
    },
    /// A built-in dialect name that does not exist.
    #[error("unknown dialect {name:?} (known: {known})")]
    UnknownDialect {
        /// The name asked for.
        name: String,
        /// The built-in names, comma-separated.
        known: String,
    },
}
