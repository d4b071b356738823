//! The events protocol (libevents) as a ground station reads it: EVENT messages made into
//! text with the metadata their sender publishes.
//!
//! An EVENT (id 410) carries a 32-bit id — the component's id in the metadata in the top
//! 8 bits, the event's sub id below — and up to 40 bytes of arguments. What the event says
//! is in a JSON file the vehicle serves over MAVFTP (PX4: `/etc/extras/all_events.json.xz`,
//! named by the general metadata file that COMPONENT_METADATA points at). PX4 says why it
//! refuses to arm only this way: COMMAND_ACK TEMPORARILY_REJECTED and EVENTs such as
//! "Arming denied: Resolve system health failures first", no STATUSTEXT.
//!
//! [`Catalog`] reads that JSON (objects or arrays at every level, as the format allows) and
//! [`Catalog::decode`] fills an event's message template: `{N}` is argument N (from 1),
//! `{N:.D}` with D decimals, a unit after it (`m`, `m_v`, `m/s`, `m^2`, `C`) is written after
//! the value, enum arguments are their entries' descriptions (bitfields joined with `|`);
//! `<param>NAME</param>` and `<a href="URL">TEXT</a>` become their text, `<profile
//! name="dev">...</profile>` is kept only for the `normal` profile's readers when it names
//! it (`!dev` inverts), other tags go with their content, `\` escapes the next character.
//! Everything shown is made safe for a terminal (control characters become U+FFFD).
//!
//! ```
//! use mavstack::events::Catalog;
//! let json = br#"{"version": 1, "components": {"1": {"namespace": "px4",
//!     "event_groups": {"default": {"name": "default", "events": {"42": {
//!         "name": "low_battery", "message": "Battery at {1:.1}V, {2}",
//!         "arguments": [{"type": "float", "name": "v"}, {"type": "state_t", "name": "s"}]}}}},
//!     "enums": {"state_t": {"type": "uint8_t", "entries": {"2": {"name": "low", "description": "land soon"}}}}}}}"#;
//! let catalog = Catalog::from_json(json)?;
//! let mut args = [0u8; 40];
//! args[..4].copy_from_slice(&14.46f32.to_le_bytes());
//! args[4] = 2;
//! let e = catalog.decode((1 << 24) | 42, &args).expect("known event");
//! assert_eq!((e.name.as_str(), e.text.as_str()), ("low_battery", "Battery at 14.5V, land soon"));
//! # Ok::<(), mavstack::events::EventsError>(())
//! ```

use std::collections::{BTreeMap, HashMap};

use serde_json::Value as Json;

/// Largest metadata file taken once unpacked (PX4's events JSON is about 600 KiB).
pub const MAX_UNPACKED: usize = 16 << 20;

/// `type` of the events entry in a general metadata file's `metadataTypes`
/// (COMP_METADATA_TYPE_EVENTS).
const METADATA_TYPE_EVENTS: u64 = 4;

/// Why event metadata could not be read.
#[derive(Debug, thiserror::Error)]
pub enum EventsError {
    /// Not JSON.
    #[error("event metadata is not JSON: {0}")]
    Json(String),
    /// No format version, or one below 1.
    #[error("event metadata has version {0}; versions from 1 on are known")]
    Version(String),
    /// JSON, but not shaped as the format says.
    #[error("event metadata: {0}")]
    Shape(String),
    /// An xz file that does not unpack.
    #[error("xz: {0}")]
    Xz(String),
    /// Unpacked, it would be larger than [`MAX_UNPACKED`].
    #[error("metadata file larger than {MAX_UNPACKED} bytes once unpacked")]
    TooLarge,
}

/// An argument's type on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BaseType {
    U8,
    I8,
    U16,
    I16,
    U32,
    I32,
    U64,
    I64,
    F32,
}

impl BaseType {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "uint8_t" => Self::U8,
            "int8_t" => Self::I8,
            "uint16_t" => Self::U16,
            "int16_t" => Self::I16,
            "uint32_t" => Self::U32,
            "int32_t" => Self::I32,
            "uint64_t" => Self::U64,
            "int64_t" => Self::I64,
            "float" => Self::F32,
            _ => return None,
        })
    }

    const fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::U64 | Self::I64 => 8,
        }
    }
}

/// An argument's value, read from the arguments bytes.
#[derive(Clone, Copy, Debug)]
enum ArgValue {
    Int(i128),
    Float(f32),
}

impl ArgValue {
    fn read(ty: BaseType, bytes: &[u8]) -> Option<Self> {
        let b = |n: usize| bytes.get(..n);
        Some(match ty {
            BaseType::U8 => Self::Int(b(1)?[0].into()),
            BaseType::I8 => Self::Int(i8::from_le_bytes(b(1)?.try_into().ok()?).into()),
            BaseType::U16 => Self::Int(u16::from_le_bytes(b(2)?.try_into().ok()?).into()),
            BaseType::I16 => Self::Int(i16::from_le_bytes(b(2)?.try_into().ok()?).into()),
            BaseType::U32 => Self::Int(u32::from_le_bytes(b(4)?.try_into().ok()?).into()),
            BaseType::I32 => Self::Int(i32::from_le_bytes(b(4)?.try_into().ok()?).into()),
            BaseType::U64 => Self::Int(u64::from_le_bytes(b(8)?.try_into().ok()?).into()),
            BaseType::I64 => Self::Int(i64::from_le_bytes(b(8)?.try_into().ok()?).into()),
            BaseType::F32 => Self::Float(f32::from_le_bytes(b(4)?.try_into().ok()?)),
        })
    }
}

#[derive(Clone, Debug)]
struct EnumDef {
    ty: BaseType,
    bitfield: bool,
    entries: BTreeMap<u64, String>,
}

#[derive(Clone, Debug)]
struct ArgDef {
    ty: BaseType,
    /// `namespace::name` of its enum.
    enumeration: Option<String>,
}

#[derive(Clone, Debug)]
struct EventDef {
    name: String,
    group: String,
    message: String,
    args: Vec<ArgDef>,
    summary: bool,
}

/// Event definitions by id, from one or more metadata files.
#[derive(Clone, Debug, Default)]
pub struct Catalog {
    events: HashMap<u32, EventDef>,
    enums: HashMap<String, EnumDef>,
}

/// An event made into text.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Decoded {
    /// The event's id.
    pub id: u32,
    /// Its name in the metadata (`commander_arm_denied_resolve_failures`).
    pub name: String,
    /// Its group (`default`, `arming_check`, `health`, `calibration`, ...).
    pub group: String,
    /// The message with its arguments filled in.
    pub text: String,
    /// A summary event (`"type": "summary"`, PX4's arming check summary): bits for a
    /// ground station's health display, not a line for a person (its texts come as events
    /// of their own).
    pub summary: bool,
}

/// The members of a JSON object or array, with their keys (an array's are its indexes).
fn members(v: &Json) -> Vec<(String, &Json)> {
    match v {
        Json::Object(m) => m.iter().map(|(k, v)| (k.clone(), v)).collect(),
        Json::Array(a) => a
            .iter()
            .enumerate()
            .map(|(i, v)| (i.to_string(), v))
            .collect(),
        _ => Vec::new(),
    }
}

fn text_field<'a>(v: &'a Json, key: &str) -> Option<&'a str> {
    v.get(key).and_then(Json::as_str)
}

fn number_of(v: Option<&Json>, key: &str) -> Option<u64> {
    match v {
        Some(Json::Number(n)) => n.as_u64(),
        Some(Json::String(s)) => s.parse().ok(),
        _ => key.parse().ok(),
    }
}

impl Catalog {
    /// Reads a metadata file (JSON, already unpacked: see [`unpack`]).
    ///
    /// Definitions that are not usable (an argument of an unknown type, a missing name) are
    /// left out, as libevents' own parser leaves them; the first definition of an id wins.
    ///
    /// # Errors
    /// Not JSON, not version 1, or no `components`.
    pub fn from_json(bytes: &[u8]) -> Result<Self, EventsError> {
        let root: Json =
            serde_json::from_slice(bytes).map_err(|e| EventsError::Json(e.to_string()))?;
        // Later versions add to the format (2, PX4 1.16's: translation hints), as libevents
        // reads them: any version from 1 on.
        match root.get("version") {
            Some(v) if v.as_u64().is_some_and(|v| v >= 1) => {}
            Some(v) => return Err(EventsError::Version(v.to_string())),
            None => return Err(EventsError::Version("(none)".into())),
        }
        let components = root
            .get("components")
            .ok_or_else(|| EventsError::Shape("no \"components\"".into()))?;
        let mut catalog = Self::default();
        let components = members(components);
        for (_, comp) in &components {
            let Some(ns) = text_field(comp, "namespace") else {
                continue;
            };
            for (key, e) in members(comp.get("enums").unwrap_or(&Json::Null)) {
                let name = text_field(e, "name").map_or(key, str::to_owned);
                let Some(ty) = text_field(e, "type").and_then(BaseType::parse) else {
                    continue;
                };
                let mut entries = BTreeMap::new();
                for (k, entry) in members(e.get("entries").unwrap_or(&Json::Null)) {
                    if let (Some(value), Some(d)) = (
                        number_of(entry.get("value"), &k),
                        text_field(entry, "description").or_else(|| text_field(entry, "name")),
                    ) {
                        entries.insert(value, d.to_owned());
                    }
                }
                let bitfield = e.get("is_bitfield").and_then(Json::as_bool) == Some(true);
                catalog.enums.insert(
                    format!("{ns}::{name}"),
                    EnumDef {
                        ty,
                        bitfield,
                        entries,
                    },
                );
            }
        }
        for (key, comp) in &components {
            let Some(ns) = text_field(comp, "namespace") else {
                continue;
            };
            let Some(component) = number_of(comp.get("component_id"), key) else {
                continue;
            };
            let component = (component & 0xff) as u32;
            for (gkey, group) in members(comp.get("event_groups").unwrap_or(&Json::Null)) {
                let group_name = text_field(group, "name").map_or(gkey, str::to_owned);
                for (ekey, e) in members(group.get("events").unwrap_or(&Json::Null)) {
                    if let Some(def) = catalog.event_def(ns, &group_name, e) {
                        let Some(sub) = number_of(e.get("sub_id"), &ekey) else {
                            continue;
                        };
                        let id = (component << 24) | (sub as u32 & 0x00ff_ffff);
                        catalog.events.entry(id).or_insert(def);
                    }
                }
            }
        }
        Ok(catalog)
    }

    fn event_def(&self, ns: &str, group: &str, e: &Json) -> Option<EventDef> {
        let mut args = Vec::new();
        for (_, a) in members(e.get("arguments").unwrap_or(&Json::Null)) {
            let ty = text_field(a, "type")?;
            args.push(match BaseType::parse(ty) {
                Some(ty) => ArgDef {
                    ty,
                    enumeration: None,
                },
                None => {
                    let key = if ty.contains("::") {
                        ty.to_owned()
                    } else {
                        format!("{ns}::{ty}")
                    };
                    ArgDef {
                        ty: self.enums.get(&key)?.ty,
                        enumeration: Some(key),
                    }
                }
            });
        }
        Some(EventDef {
            name: text_field(e, "name")?.to_owned(),
            group: group.to_owned(),
            message: text_field(e, "message")?.to_owned(),
            args,
            summary: text_field(e, "type") == Some("summary"),
        })
    }

    /// Adds another file's definitions (those of ids already known are kept).
    pub fn extend(&mut self, other: Self) {
        for (k, v) in other.enums {
            self.enums.entry(k).or_insert(v);
        }
        for (k, v) in other.events {
            self.events.entry(k).or_insert(v);
        }
    }

    /// How many events it defines.
    #[must_use]
    pub fn len(&self) -> usize {
        self.events.len()
    }

    /// Whether it defines none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// The event `id` with its `arguments` (EVENT's 40 bytes) as text; `None` for an id the
    /// catalog does not define.
    #[must_use]
    pub fn decode(&self, id: u32, arguments: &[u8]) -> Option<Decoded> {
        let def = self.events.get(&id)?;
        let mut values = Vec::with_capacity(def.args.len());
        let mut at = 0;
        for a in &def.args {
            values.push(arguments.get(at..).and_then(|b| ArgValue::read(a.ty, b)));
            at += a.ty.size();
        }
        let text = fill(&def.message, 0, &|index, decimals, unit| {
            let arg = def.args.get(index)?;
            let value = values.get(index).copied().flatten();
            Some(self.show(arg, value, decimals, unit))
        });
        Some(Decoded {
            id,
            name: safe(&def.name),
            group: safe(&def.group),
            text: safe(text.trim()),
            summary: def.summary,
        })
    }

    fn show(
        &self,
        arg: &ArgDef,
        value: Option<ArgValue>,
        decimals: Option<usize>,
        unit: &str,
    ) -> String {
        let Some(value) = value else {
            return "(unknown)".into();
        };
        if let (Some(key), ArgValue::Int(v)) = (&arg.enumeration, value)
            && let Some(e) = self.enums.get(key)
        {
            let v = v as u64;
            if !e.bitfield {
                return e
                    .entries
                    .get(&v)
                    .cloned()
                    .unwrap_or_else(|| format!("(unknown: {v})"));
            }
            let bits = e.ty.size() * 8;
            let names: Vec<String> = (0..bits)
                .map(|i| 1u64 << i)
                .filter(|bit| v & bit != 0)
                .map(|bit| {
                    e.entries
                        .get(&bit)
                        .cloned()
                        .unwrap_or_else(|| format!("(unknown: {v})"))
                })
                .collect();
            return names.join("|");
        }
        let mut out = match (value, decimals) {
            (ArgValue::Int(v), _) => v.to_string(),
            (ArgValue::Float(f), Some(d)) => format!("{f:.d$}", d = d.min(12)),
            (ArgValue::Float(f), None) => format!("{f}"),
        };
        if !unit.is_empty() {
            out.push(' ');
            out.push_str(if unit == "m_v" { "m" } else { unit });
        }
        out
    }
}

/// The profile whose `<profile>` sections are shown.
const PROFILE: &str = "normal";

/// An argument's text by (index from 0, decimals, unit); `None` for no such argument.
type ArgText<'a> = dyn Fn(usize, Option<usize>, &str) -> Option<String> + 'a;

/// Tags inside tags beyond this depth are shown as they are (a template is a stranger's text).
const MAX_DEPTH: usize = 4;

/// Fills `template` (a tag's content at `depth`): `arg(index from 0, decimals, unit)` gives
/// an argument's text, `None` leaving the placeholder as it is.
fn fill(template: &str, depth: usize, arg: &ArgText<'_>) -> String {
    let mut out = String::with_capacity(template.len());
    let mut rest = template;
    while let Some(c) = rest.chars().next() {
        match c {
            '\\' => {
                let mut chars = rest[1..].chars();
                if let Some(next) = chars.next() {
                    out.push(next);
                }
                rest = chars.as_str();
            }
            '<' => match tag(rest).filter(|_| depth < MAX_DEPTH) {
                Some((name, attr, content, after)) => {
                    match name {
                        "param" | "a" => out.push_str(&fill(content, depth + 1, arg)),
                        "profile" => {
                            let wanted = attr.unwrap_or("");
                            let shown = match wanted.strip_prefix('!') {
                                Some(not) => not != PROFILE,
                                None => wanted.is_empty() || wanted == PROFILE,
                            };
                            if shown {
                                out.push_str(&fill(content, depth + 1, arg));
                            }
                        }
                        _ => {}
                    }
                    rest = after;
                }
                None => {
                    out.push('<');
                    rest = &rest[1..];
                }
            },
            '{' => {
                match placeholder(rest).and_then(|(i, d, u, after)| Some((arg(i, d, u)?, after))) {
                    Some((text, after)) => {
                        out.push_str(&text);
                        rest = after;
                    }
                    None => {
                        out.push('{');
                        rest = &rest[1..];
                    }
                }
            }
            _ => {
                out.push(c);
                rest = &rest[c.len_utf8()..];
            }
        }
    }
    out
}

/// `<name attr="value">content</name>` at the start of `s`: (name, value, content, the rest).
fn tag(s: &str) -> Option<(&str, Option<&str>, &str, &str)> {
    let open_end = s.find('>')?;
    let inside = &s[1..open_end];
    let (name, attrs) = inside.split_once(' ').unwrap_or((inside, ""));
    if name.is_empty() || !name.bytes().all(|b| b.is_ascii_lowercase()) {
        return None;
    }
    let attr = attrs
        .split_once("=\"")
        .and_then(|(_, v)| v.split_once('"'))
        .map(|(v, _)| v);
    let body = &s[open_end + 1..];
    let close = format!("</{name}>");
    let end = body.find(&close)?;
    Some((name, attr, &body[..end], &body[end + close.len()..]))
}

/// `{N[:.D][unit]}` at the start of `s`: (N - 1, D, unit, the rest).
fn placeholder(s: &str) -> Option<(usize, Option<usize>, &str, &str)> {
    let end = s.find('}')?;
    let inner = &s[1..end];
    let digits = inner.bytes().take_while(u8::is_ascii_digit).count();
    let index: usize = inner[..digits].parse().ok()?;
    let mut rest = &inner[digits..];
    let mut decimals = None;
    if let Some(r) = rest.strip_prefix(':') {
        rest = r;
        if let Some(r) = rest.strip_prefix('.') {
            let n = r.bytes().take_while(u8::is_ascii_digit).count();
            decimals = r[..n].parse().ok();
            rest = &r[n..];
        }
    }
    Some((index.checked_sub(1)?, decimals, rest, &s[end + 1..]))
}

/// `s` safe to print: control characters become U+FFFD.
fn safe(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { '\u{fffd}' } else { c })
        .collect()
}

/// The first bytes of an xz file.
const XZ_MAGIC: &[u8] = &[0xfd, b'7', b'z', b'X', b'Z', 0];

/// A metadata file as JSON bytes: unpacked when it is xz (as PX4 serves them), as it is
/// otherwise.
///
/// # Errors
/// A damaged xz file, or one larger than [`MAX_UNPACKED`] once unpacked.
pub fn unpack(bytes: &[u8]) -> Result<Vec<u8>, EventsError> {
    if !bytes.starts_with(XZ_MAGIC) {
        return Ok(bytes.to_vec());
    }
    check_footer(bytes)?;
    let mut out = Bounded(Vec::new());
    let mut input = bytes;
    // lzma-rs 0.3.0 adds 1 to the Backward Size of the footer it reads after the index
    // unchecked: a panic in builds with overflow checks when a damaged file puts 0xFFFFFFFF
    // there (found by the `events` fuzz target; `check_footer` refuses it at the file's end,
    // not after an index placed earlier). Its panics are this file's failure, not ours.
    let decoded = std::panic::catch_unwind(core::panic::AssertUnwindSafe(|| {
        lzma_rs::xz_decompress(&mut input, &mut out)
    }))
    .map_err(|_| EventsError::Xz("the xz decoder failed on this file".into()))?;
    match decoded {
        Ok(()) => Ok(out.0),
        Err(lzma_rs::error::Error::IoError(e)) if e.kind() == std::io::ErrorKind::FileTooLarge => {
            Err(EventsError::TooLarge)
        }
        Err(e) => Err(EventsError::Xz(e.to_string())),
    }
}

/// An xz file's Stream Footer, read from the end where the format puts it (CRC32, Backward
/// Size, Stream Flags, `YZ`): one missing, or a Backward Size that points before the file's
/// start, is refused before the decoder runs.
fn check_footer(bytes: &[u8]) -> Result<(), EventsError> {
    const HEADER_AND_FOOTER: u64 = 24;
    let damaged = || EventsError::Xz("no valid stream footer at the end".into());
    let at = bytes.len().checked_sub(12).ok_or_else(damaged)?;
    let footer = &bytes[at..];
    let mut backward = [0u8; 4];
    backward.copy_from_slice(&footer[4..8]);
    let index_len = (u64::from(u32::from_le_bytes(backward)) + 1) * 4;
    if &footer[10..] != b"YZ" || index_len + HEADER_AND_FOOTER > bytes.len() as u64 {
        return Err(damaged());
    }
    Ok(())
}

/// A writer that refuses to grow past [`MAX_UNPACKED`].
struct Bounded(Vec<u8>);

impl std::io::Write for Bounded {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.0.len() + buf.len() > MAX_UNPACKED {
            return Err(std::io::ErrorKind::FileTooLarge.into());
        }
        self.0.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The URI of the events file named by a general metadata file (COMPONENT_METADATA's
/// `uri`, unpacked): the `metadataTypes` entry of type 4; `None` when it names none.
///
/// # Errors
/// Not JSON.
pub fn events_uri(general: &[u8]) -> Result<Option<String>, EventsError> {
    let root: Json =
        serde_json::from_slice(general).map_err(|e| EventsError::Json(e.to_string()))?;
    Ok(members(root.get("metadataTypes").unwrap_or(&Json::Null))
        .into_iter()
        .find(|(_, t)| t.get("type").and_then(Json::as_u64) == Some(METADATA_TYPE_EVENTS))
        .and_then(|(_, t)| text_field(t, "uri").map(str::to_owned)))
}

/// The MAVFTP path of an `mftp://` URI (`mftp://etc/extras/x.json.xz`, or with a component
/// `mftp://[;comp=1]etc/...`): `/etc/extras/x.json.xz`; `None` for other schemes (http
/// metadata is not fetched).
#[must_use]
pub fn ftp_path(uri: &str) -> Option<String> {
    let rest = uri.strip_prefix("mftp://")?;
    let rest = match rest.strip_prefix('[') {
        Some(r) => r.split_once(']')?.1,
        None => rest,
    };
    if rest.is_empty() {
        return None;
    }
    Some(if rest.starts_with('/') {
        rest.to_owned()
    } else {
        format!("/{rest}")
    })
}

/// EVENT's external log level (the low 4 bits of `log_levels`) by name.
#[must_use]
pub fn level_name(log_levels: u8) -> &'static str {
    match log_levels & 0x0f {
        0 => "emergency",
        1 => "alert",
        2 => "critical",
        3 => "error",
        4 => "warning",
        5 => "notice",
        6 => "info",
        7 => "debug",
        8 => "protocol",
        _ => "disabled",
    }
}

#[cfg(feature = "fuzzing")]
mod fuzzing;
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use fuzzing::fuzz_events;

#[cfg(test)]
mod tests;
