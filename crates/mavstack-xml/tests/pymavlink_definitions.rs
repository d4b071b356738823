//! Every built-in dialect agrees with pymavlink 2.4.50, the package our definitions are copied
//! from: message ids, names, CRC_EXTRA, minimum and maximum payload lengths, fields in wire
//! order (name, element type, array length, extension flag), field offsets, and the offsets of
//! the target system and component.
//!
//! pymavlink's side comes from `scripts/pymavlink_definitions.py`, which reads its generated
//! python modules and its XML parser (and checks that they agree with each other and that
//! pymavlink's XML files are byte-identical to `definitions/`). It runs once for all dialects.
//! The python is `MAVSTACK_PYTHON` (default: the workspace's `.venv/bin/python`, made by
//! `scripts/setup-peers.sh`); without pymavlink the tests fail with instructions.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::OnceLock;

use mavstack_xml::{Dialect, Message, builtin, load};

#[derive(Debug)]
struct PyField {
    name: String,
    ty: String,
    array_len: Option<u8>,
    extension: bool,
}

#[derive(Debug)]
struct PyMessage {
    id: u32,
    name: String,
    crc_extra: u8,
    min_len: usize,
    max_len: usize,
    target_system_offset: Option<usize>,
    target_component_offset: Option<usize>,
    /// The field count the message line announces.
    field_count: usize,
    fields: Vec<PyField>,
}

#[derive(Debug, Default)]
struct PyDialect {
    files: Vec<String>,
    messages: Vec<PyMessage>,
}

#[derive(Debug)]
struct Pymavlink {
    version: String,
    dialects: BTreeMap<String, PyDialect>,
}

fn number<T: core::str::FromStr>(token: Option<&str>, line: &str) -> T {
    token
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("bad number in script output line {line:?}"))
}

fn optional<T: core::str::FromStr>(token: Option<&str>, line: &str) -> Option<T> {
    match token {
        Some("-") => None,
        other => Some(number(other, line)),
    }
}

/// Parses the line format of `scripts/pymavlink_definitions.py`.
fn parse(output: &str) -> Pymavlink {
    let mut version = None;
    let mut dialects = BTreeMap::new();
    let mut current: Option<(String, PyDialect)> = None;
    for line in output.lines() {
        let mut t = line.split_whitespace();
        match t.next() {
            Some("pymavlink") => version = t.next().map(str::to_owned),
            Some("dialect") => {
                assert!(current.is_none(), "dialect without end before {line:?}");
                current = Some((
                    t.next().expect("dialect name").to_owned(),
                    PyDialect::default(),
                ));
            }
            Some("file") => {
                let (_, d) = current.as_mut().expect("file line inside a dialect");
                d.files.push(t.next().expect("file name").to_owned());
            }
            Some("message") => {
                let (_, d) = current.as_mut().expect("message line inside a dialect");
                let id = number(t.next(), line);
                let name = t.next().expect("message name").to_owned();
                let crc_extra = number(t.next(), line);
                let min_len = number(t.next(), line);
                let max_len = number(t.next(), line);
                let field_count = number(t.next(), line);
                let target_system_offset = optional(t.next(), line);
                let target_component_offset = optional(t.next(), line);
                d.messages.push(PyMessage {
                    id,
                    name,
                    crc_extra,
                    min_len,
                    max_len,
                    target_system_offset,
                    target_component_offset,
                    field_count,
                    fields: Vec::new(),
                });
            }
            Some("field") => {
                let (_, d) = current.as_mut().expect("field line inside a dialect");
                let m = d
                    .messages
                    .last_mut()
                    .expect("field line after a message line");
                let name = t.next().expect("field name").to_owned();
                let ty = t.next().expect("field type").to_owned();
                let array_len = optional(t.next(), line);
                let extension = match t.next() {
                    Some("ext") => true,
                    Some("base") => false,
                    _ => panic!("bad extension flag in {line:?}"),
                };
                m.fields.push(PyField {
                    name,
                    ty,
                    array_len,
                    extension,
                });
            }
            Some("end") => {
                let (name, d) = current.take().expect("end line closes a dialect");
                assert_eq!(t.next(), Some(name.as_str()), "end line of {name}");
                let count: usize = number(t.next(), line);
                assert_eq!(count, d.messages.len(), "message count of {name}");
                for m in &d.messages {
                    assert_eq!(
                        m.fields.len(),
                        m.field_count,
                        "field lines of {name}.{}",
                        m.name
                    );
                }
                dialects.insert(name, d);
            }
            _ => panic!("unexpected script output line {line:?}"),
        }
    }
    assert!(current.is_none(), "script output ends inside a dialect");
    Pymavlink {
        version: version.expect("script prints the pymavlink version"),
        dialects,
    }
}

/// pymavlink's view of every dialect it ships, computed once per test run.
fn pymavlink() -> &'static Pymavlink {
    static CELL: OnceLock<Pymavlink> = OnceLock::new();
    CELL.get_or_init(|| {
        let script = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../scripts/pymavlink_definitions.py"
        );
        let definitions = concat!(env!("CARGO_MANIFEST_DIR"), "/definitions");
        parse(&support::run_python(&[
            script,
            "--definitions",
            definitions,
            "--all",
        ]))
    })
}

/// Size of one element of a pymavlink type string.
fn element_size(ty: &str) -> usize {
    match ty {
        "char" | "int8_t" | "uint8_t" => 1,
        "int16_t" | "uint16_t" => 2,
        "int32_t" | "uint32_t" | "float" => 4,
        "int64_t" | "uint64_t" | "double" => 8,
        other => panic!("pymavlink type {other:?}"),
    }
}

/// Every difference between our message and pymavlink's, as readable lines.
fn compare_message(dialect: &str, ours: &Message, theirs: &PyMessage, problems: &mut Vec<String>) {
    let at = format!("{dialect}: {} (id {})", theirs.name, theirs.id);
    let mut check = |what: &str, ours: String, theirs: String| {
        if ours != theirs {
            problems.push(format!("{at}: {what}: ours {ours}, pymavlink {theirs}"));
        }
    };
    check("name", ours.name.clone(), theirs.name.clone());
    check(
        "CRC_EXTRA",
        ours.crc_extra.to_string(),
        theirs.crc_extra.to_string(),
    );
    check(
        "min_len",
        ours.min_len.to_string(),
        theirs.min_len.to_string(),
    );
    check(
        "max_len",
        ours.max_len.to_string(),
        theirs.max_len.to_string(),
    );
    check(
        "field count",
        ours.fields.len().to_string(),
        theirs.fields.len().to_string(),
    );
    let mut offset = 0;
    for (i, (f, p)) in ours.fields.iter().zip(&theirs.fields).enumerate() {
        check(
            &format!("wire field {i} name"),
            f.name.clone(),
            p.name.clone(),
        );
        check(
            &format!("{} type", p.name),
            f.ty.primitive.c_name().to_owned(),
            p.ty.clone(),
        );
        check(
            &format!("{} array length", p.name),
            format!("{:?}", f.ty.array_len),
            format!("{:?}", p.array_len),
        );
        check(
            &format!("{} extension", p.name),
            f.extension.to_string(),
            p.extension.to_string(),
        );
        check(
            &format!("{} offset", p.name),
            f.offset.to_string(),
            offset.to_string(),
        );
        offset += element_size(&p.ty) * usize::from(p.array_len.unwrap_or(1));
    }
    check(
        "target_system offset",
        format!("{:?}", ours.target_system_offset),
        format!("{:?}", theirs.target_system_offset),
    );
    check(
        "target_component offset",
        format!("{:?}", ours.target_component_offset),
        format!("{:?}", theirs.target_component_offset),
    );
}

/// Compares one dialect; returns the messages we have and pymavlink lacks.
fn compare_dialect(
    name: &str,
    ours: &Dialect,
    theirs: &PyDialect,
    problems: &mut Vec<String>,
) -> Vec<(u32, String)> {
    let our_files: BTreeSet<String> = ours
        .files
        .iter()
        .map(|f| {
            f.path
                .file_name()
                .expect("file name")
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let their_files: BTreeSet<String> = theirs.files.iter().cloned().collect();
    if our_files != their_files {
        problems.push(format!(
            "{name}: include closure: ours {our_files:?}, pymavlink {their_files:?}"
        ));
    }
    for p in &theirs.messages {
        match ours.message(p.id) {
            Some(m) => compare_message(name, m, p, problems),
            None => problems.push(format!("{name}: we lack {} (id {})", p.name, p.id)),
        }
    }
    let their_ids: BTreeSet<u32> = theirs.messages.iter().map(|m| m.id).collect();
    ours.messages
        .iter()
        .filter(|m| !their_ids.contains(&m.id))
        .map(|m| (m.id, m.name.clone()))
        .collect()
}

#[test]
fn pymavlink_is_the_version_the_definitions_come_from() {
    let provenance = include_str!("../definitions/PROVENANCE.md");
    let vendored = provenance
        .split("pymavlink==")
        .nth(1)
        .and_then(|rest| {
            rest.split(|c: char| !(c.is_ascii_digit() || c == '.'))
                .next()
        })
        .expect("PROVENANCE.md names pymavlink==VERSION");
    assert_eq!(vendored, "2.4.50");
    assert_eq!(
        pymavlink().version,
        vendored,
        "the python at {} has another pymavlink than the one definitions/ was copied from",
        support::python()
    );
}

#[test]
fn pymavlink_ships_exactly_our_builtin_dialects() {
    let ours: Vec<&str> = builtin::dialect_names();
    let theirs: Vec<&str> = pymavlink().dialects.keys().map(String::as_str).collect();
    assert_eq!(ours, theirs);
}

#[test]
fn every_builtin_dialect_matches_pymavlink() {
    let py = pymavlink();
    let mut problems = Vec::new();
    let mut compared = 0;
    for name in builtin::dialect_names() {
        let ours = load(name).unwrap_or_else(|e| panic!("{name}: {e}"));
        let theirs = py
            .dialects
            .get(name)
            .unwrap_or_else(|| panic!("pymavlink has no dialect {name}"));
        let extra = compare_dialect(name, &ours, theirs, &mut problems);
        // Our only additions: the PROTOCOL_VERSION, events and standard modes supplements,
        // in every dialect with common.xml (the standard modes' messages only where the
        // dialect lacks development.xml, which defines them the same way).
        let includes = |file: &str| ours.files.iter().any(|f| f.path.ends_with(file));
        let mut expected: Vec<(u32, String)> = Vec::new();
        if includes("common.xml") {
            expected.extend(
                [
                    (300, "PROTOCOL_VERSION"),
                    (397, "COMPONENT_METADATA"),
                    (410, "EVENT"),
                    (411, "CURRENT_EVENT_SEQUENCE"),
                    (412, "REQUEST_EVENT"),
                    (413, "RESPONSE_EVENT_ERROR"),
                ]
                .map(|(id, name)| (id, name.to_owned())),
            );
            if !includes("development.xml") {
                expected.extend(
                    [
                        (435, "AVAILABLE_MODES"),
                        (436, "CURRENT_MODE"),
                        (437, "AVAILABLE_MODES_MONITOR"),
                    ]
                    .map(|(id, name)| (id, name.to_owned())),
                );
            }
        }
        if extra != expected {
            problems.push(format!(
                "{name}: messages pymavlink lacks: {extra:?}, expected {expected:?}"
            ));
        }
        compared += theirs.messages.len();
    }
    assert!(
        problems.is_empty(),
        "{} differences from pymavlink:\n{}",
        problems.len(),
        problems.join("\n")
    );
    // All 19 dialects together: a sanity floor so that an empty script output cannot pass.
    assert!(compared > 3000, "only {compared} messages compared");
}

#[test]
fn manual_control_target_is_the_target_system() {
    // MANUAL_CONTROL (id 69) has `target` instead of `target_system`; pymavlink (and the C
    // library's routing table) take it as the target system, and so do we.
    let theirs = pymavlink().dialects["common"]
        .messages
        .iter()
        .find(|m| m.name == "MANUAL_CONTROL")
        .expect("in common");
    let ours = load("common").expect("loads");
    let ours = ours.message_by_name("MANUAL_CONTROL").expect("in common");
    let target = ours.field("target").expect("MANUAL_CONTROL.target");
    assert_eq!(theirs.target_system_offset, Some(target.offset));
    assert_eq!(theirs.target_system_offset, Some(10));
    assert_eq!(ours.target_system_offset, Some(10));
}

#[test]
fn comparison_notices_a_difference() {
    // The comparison itself can fail: a message with one field changed is reported.
    let py = pymavlink();
    let common = load("common").expect("loads");
    let theirs = py.dialects["common"]
        .messages
        .iter()
        .find(|m| m.id == 0)
        .expect("HEARTBEAT");
    let mut ours = common.message(0).expect("HEARTBEAT").clone();
    let mut problems = Vec::new();
    compare_message("common", &ours, theirs, &mut problems);
    assert!(problems.is_empty(), "{problems:?}");
    ours.fields[1].extension = true;
    ours.crc_extra ^= 1;
    compare_message("common", &ours, theirs, &mut problems);
    assert_eq!(
        problems,
        [
            "common: HEARTBEAT (id 0): CRC_EXTRA: ours 51, pymavlink 50",
            "common: HEARTBEAT (id 0): type extension: ours true, pymavlink false",
        ]
    );
}
