//! Reading one definition file: XML → declarations, each with its position.
//!
//! Nothing is resolved here: includes are only listed, enums may be partial (other files can
//! extend them), and fields are in XML order with no offsets yet.

use std::path::Path;

use roxmltree::{Document, Node};

use crate::error::{Error, ErrorKind, Location};
use crate::model::{Deprecation, Entry, EntryParam, Enum, Field, FieldType, PrimitiveType};

/// The largest message id MAVLink 2 can carry (24 bits).
pub const MAX_MESSAGE_ID: u32 = 0x00FF_FFFF;

/// One file's declarations.
#[derive(Clone, Debug)]
pub(crate) struct FileDecls {
    pub(crate) includes: Vec<(String, Location)>,
    pub(crate) version: Option<u8>,
    pub(crate) dialect: Option<u8>,
    pub(crate) enums: Vec<Enum>,
    pub(crate) messages: Vec<MessageDecl>,
}

/// A message as declared: fields in XML order, no layout yet.
#[derive(Clone, Debug)]
pub(crate) struct MessageDecl {
    pub(crate) id: u32,
    pub(crate) name: String,
    pub(crate) description: String,
    pub(crate) fields: Vec<Field>,
    pub(crate) deprecation: Option<Deprecation>,
    pub(crate) wip: bool,
    pub(crate) location: Location,
}

struct Reader<'a> {
    text: &'a str,
    /// Byte offset of the start of every line, for positions in O(log n).
    line_starts: Vec<usize>,
    path: &'a Path,
}

impl Reader<'_> {
    fn location(&self, node: Node<'_, '_>) -> Location {
        let offset = node.range().start;
        let line = self.line_starts.partition_point(|&s| s <= offset).max(1);
        let start = self.line_starts[line - 1];
        let column = self
            .text
            .get(start..offset)
            .map_or(1, |t| t.chars().count() + 1);
        Location {
            file: self.path.to_path_buf(),
            line: to_u32(line),
            column: to_u32(column),
        }
    }

    fn error(&self, node: Node<'_, '_>, kind: ErrorKind) -> Error {
        Error::new(self.location(node), kind)
    }

    fn required<'n>(
        &self,
        node: Node<'n, '_>,
        element: &'static str,
        attribute: &'static str,
    ) -> Result<&'n str, Error> {
        node.attribute(attribute)
            .ok_or_else(|| self.error(node, ErrorKind::MissingAttribute { element, attribute }))
    }

    fn number(
        &self,
        node: Node<'_, '_>,
        what: String,
        text: &str,
        max: u64,
        range: &'static str,
    ) -> Result<u64, Error> {
        parse_number(text).filter(|&v| v <= max).ok_or_else(|| {
            self.error(
                node,
                ErrorKind::BadNumber {
                    what,
                    value: text.to_owned(),
                    range,
                },
            )
        })
    }
}

/// roxmltree ends its messages with " at LINE:COLUMN", which our location already says.
fn strip_position(message: &str) -> String {
    match message.rsplit_once(" at ") {
        Some((head, tail))
            if tail
                .split(':')
                .all(|p| !p.is_empty() && p.bytes().all(|b| b.is_ascii_digit())) =>
        {
            head.to_owned()
        }
        _ => message.to_owned(),
    }
}

fn to_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

/// Reads a number as MAVLink XML writes them: decimal, `0x` hex, `0b` binary or `2**N`.
fn parse_number(text: &str) -> Option<u64> {
    let t = text.trim();
    if let Some(hex) = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        u64::from_str_radix(hex, 16).ok()
    } else if let Some(bin) = t.strip_prefix("0b").or_else(|| t.strip_prefix("0B")) {
        u64::from_str_radix(bin, 2).ok()
    } else if let Some((base, exp)) = t.split_once("**") {
        let base: u64 = base.trim().parse().ok()?;
        base.checked_pow(exp.trim().parse().ok()?)
    } else {
        t.parse().ok()
    }
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

fn text_of(node: Option<Node<'_, '_>>) -> String {
    node.and_then(|n| n.text())
        .map(normalize_space)
        .unwrap_or_default()
}

/// Collapses runs of white space (XML descriptions are wrapped and indented).
fn normalize_space(text: &str) -> String {
    text.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn deprecation(node: Node<'_, '_>) -> Option<Deprecation> {
    let (dep, superseded) = match child(node, "deprecated") {
        Some(d) => (d, false),
        None => (child(node, "superseded")?, true),
    };
    Some(Deprecation {
        superseded,
        since: dep.attribute("since").unwrap_or_default().to_owned(),
        replaced_by: dep.attribute("replaced_by").unwrap_or_default().to_owned(),
        note: text_of(Some(dep)),
    })
}

/// Parses a field type such as `uint16_t`, `char[16]`, `uint8_t_mavlink_version` or the
/// legacy `array[N]` (an `int8_t` array).
fn parse_type(text: &str) -> Result<FieldType, bool> {
    let (base, array_len) = match text.split_once('[') {
        Some((base, rest)) => {
            let len = rest.strip_suffix(']').ok_or(true)?;
            let len: u8 = len.trim().parse().map_err(|_| true)?;
            if len == 0 {
                return Err(true);
            }
            (base.trim(), Some(len))
        }
        None => (text.trim(), None),
    };
    if base == "uint8_t_mavlink_version" && array_len.is_none() {
        return Ok(FieldType {
            primitive: PrimitiveType::U8,
            array_len,
            mavlink_version: true,
        });
    }
    if base == "array" && array_len.is_some() {
        return Ok(FieldType {
            primitive: PrimitiveType::I8,
            array_len,
            mavlink_version: false,
        });
    }
    let primitive = PrimitiveType::from_c_name(base).ok_or(false)?;
    Ok(FieldType {
        primitive,
        array_len,
        mavlink_version: false,
    })
}

/// Reads one file's text.
pub(crate) fn parse_file(path: &Path, text: &str) -> Result<FileDecls, Error> {
    let doc = Document::parse(text).map_err(|e| {
        let pos = e.pos();
        Error::new(
            Location {
                file: path.to_path_buf(),
                line: pos.row,
                column: pos.col,
            },
            ErrorKind::Xml(strip_position(&e.to_string())),
        )
    })?;
    let line_starts = core::iter::once(0)
        .chain(text.match_indices('\n').map(|(i, _)| i + 1))
        .collect();
    let r = Reader {
        text,
        line_starts,
        path,
    };
    let root = doc.root_element();
    if !root.has_tag_name("mavlink") {
        return Err(r.error(
            root,
            ErrorKind::NotMavlink {
                found: root.tag_name().name().to_owned(),
            },
        ));
    }
    let mut decls = FileDecls {
        includes: Vec::new(),
        version: None,
        dialect: None,
        enums: Vec::new(),
        messages: Vec::new(),
    };
    for node in root.children().filter(Node::is_element) {
        match node.tag_name().name() {
            "include" => {
                let name = node.text().unwrap_or_default().trim().to_owned();
                if name.is_empty() {
                    return Err(r.error(node, ErrorKind::EmptyInclude));
                }
                decls.includes.push((name, r.location(node)));
            }
            "version" => {
                let v = node.text().unwrap_or_default();
                decls.version =
                    Some(r.number(node, "version".into(), v, 255, " from 0 to 255")? as u8);
            }
            "dialect" => {
                let v = node.text().unwrap_or_default();
                decls.dialect =
                    Some(r.number(node, "dialect".into(), v, 255, " from 0 to 255")? as u8);
            }
            "enums" => {
                for e in node.children().filter(|c| c.has_tag_name("enum")) {
                    decls.enums.push(parse_enum(&r, e)?);
                }
            }
            "messages" => {
                for m in node.children().filter(|c| c.has_tag_name("message")) {
                    decls.messages.push(parse_message(&r, m)?);
                }
            }
            _ => {}
        }
    }
    Ok(decls)
}

fn parse_enum(r: &Reader<'_>, node: Node<'_, '_>) -> Result<Enum, Error> {
    let name = r.required(node, "enum", "name")?.to_owned();
    let mut entries: Vec<Entry> = Vec::new();
    // An entry without a value gets one more than the highest value so far (starting from
    // 0, so a first entry without a value is 1), as pymavlink's parser does.
    let mut highest = 0u64;
    for e in node.children().filter(|c| c.has_tag_name("entry")) {
        let entry_name = r.required(e, "entry", "name")?.to_owned();
        let value = match e.attribute("value") {
            Some(v) => r.number(e, format!("value of {entry_name}"), v, u64::MAX, "")?,
            None => highest.saturating_add(1),
        };
        highest = highest.max(value);
        let params = e
            .children()
            .filter(|c| c.has_tag_name("param"))
            .filter_map(|p| {
                let index = p.attribute("index").and_then(|i| i.trim().parse().ok())?;
                Some(EntryParam {
                    index,
                    label: p.attribute("label").map(str::to_owned),
                    units: p.attribute("units").map(str::to_owned),
                    enum_name: p.attribute("enum").map(str::to_owned),
                    description: text_of(Some(p)),
                })
            })
            .collect();
        entries.push(Entry {
            name: entry_name,
            value,
            description: text_of(child(e, "description")),
            deprecation: deprecation(e),
            wip: child(e, "wip").is_some(),
            params,
            file: r.path.to_path_buf(),
            location: r.location(e),
        });
    }
    Ok(Enum {
        name,
        description: text_of(child(node, "description")),
        bitmask: node
            .attribute("bitmask")
            .is_some_and(|b| b.trim() == "true"),
        entries,
        deprecation: deprecation(node),
        file: r.path.to_path_buf(),
        location: r.location(node),
    })
}

fn parse_message(r: &Reader<'_>, node: Node<'_, '_>) -> Result<MessageDecl, Error> {
    let name = r.required(node, "message", "name")?.to_owned();
    let id_text = r.required(node, "message", "id")?;
    let id = r.number(
        node,
        format!("id of message {name}"),
        id_text,
        u64::from(MAX_MESSAGE_ID),
        " from 0 to 16777215",
    )? as u32;
    let mut fields = Vec::new();
    let mut extension = false;
    for f in node.children().filter(Node::is_element) {
        match f.tag_name().name() {
            "extensions" => extension = true,
            "field" => {
                let ty_text = r.required(f, "field", "type")?;
                let field_name = r.required(f, "field", "name")?.to_owned();
                let ty = parse_type(ty_text).map_err(|bad_len| {
                    let (message, field, ty) =
                        (name.clone(), field_name.clone(), ty_text.to_owned());
                    r.error(
                        f,
                        if bad_len {
                            ErrorKind::BadArrayLength { message, field, ty }
                        } else {
                            ErrorKind::UnknownType { message, field, ty }
                        },
                    )
                })?;
                fields.push(Field {
                    name: field_name,
                    ty,
                    offset: 0,
                    extension,
                    enum_name: f.attribute("enum").map(|s| s.trim().to_owned()),
                    display: f.attribute("display").map(str::to_owned),
                    units: f.attribute("units").map(str::to_owned),
                    invalid: f.attribute("invalid").map(str::to_owned),
                    instance: f.attribute("instance").is_some_and(|v| v.trim() == "true"),
                    description: text_of(Some(f)),
                    location: r.location(f),
                });
            }
            _ => {}
        }
    }
    Ok(MessageDecl {
        id,
        name,
        description: text_of(child(node, "description")),
        fields,
        deprecation: deprecation(node),
        wip: child(node, "wip").is_some(),
        location: r.location(node),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_every_spelling() {
        assert_eq!(parse_number("42"), Some(42));
        assert_eq!(parse_number(" 0x10 "), Some(16));
        assert_eq!(parse_number("0b101"), Some(5));
        assert_eq!(parse_number("2**8"), Some(256));
        assert_eq!(parse_number("forty"), None);
        assert_eq!(parse_number("-1"), None);
    }

    #[test]
    fn types() {
        let t = parse_type("char[16]").unwrap();
        assert_eq!((t.primitive, t.array_len), (PrimitiveType::Char, Some(16)));
        let t = parse_type("uint8_t_mavlink_version").unwrap();
        assert!(t.mavlink_version && t.primitive == PrimitiveType::U8);
        let t = parse_type("array[4]").unwrap();
        assert_eq!((t.primitive, t.array_len), (PrimitiveType::I8, Some(4)));
        assert_eq!(parse_type("uint9_t"), Err(false));
        assert_eq!(parse_type("uint8_t[0]"), Err(true));
        assert_eq!(parse_type("uint8_t[256]"), Err(true));
        assert_eq!(parse_type("uint8_t[x]"), Err(true));
    }
}
