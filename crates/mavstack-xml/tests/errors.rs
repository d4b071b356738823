//! Malformed definitions: every error names the file, line and column of the offending
//! element (its `<`, 1-based, counted in characters) and says what is wrong.
//!
//! One fixture per case under `tests/fixtures/errors/`. The expected strings are the full
//! `Display` output; the positions were checked by hand against the fixtures.

use std::path::{Path, PathBuf};

use mavstack_xml::{Error, ErrorKind, Loader, builtin, load};

/// The folder of the error fixtures, as the loader reports it.
fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/errors")
}

/// `dir()/name`, as a string for expected messages.
fn path(name: &str) -> String {
    dir().join(name).display().to_string()
}

/// Loads a fixture from the file system and returns the error it must produce.
fn load_error(name: &str) -> Error {
    match Loader::filesystem().load(dir().join(name)) {
        Ok(d) => panic!(
            "{name} loaded ({} messages) but should fail",
            d.messages.len()
        ),
        Err(e) => e,
    }
}

/// Checks the displayed error of fixture `name`: `<path of file>:<rest>`.
fn expect_error(name: &str, file: &str, rest: &str) -> ErrorKind {
    let e = load_error(name);
    assert_eq!(e.to_string(), format!("{}:{rest}", path(file)), "{name}");
    assert_eq!(e.location.file, dir().join(file), "{name}");
    *e.kind
}

#[test]
fn message_without_id() {
    let kind = expect_error(
        "message_without_id.xml",
        "message_without_id.xml",
        r#"7:5: <message> is missing the attribute "id""#,
    );
    assert!(matches!(
        kind,
        ErrorKind::MissingAttribute {
            element: "message",
            attribute: "id"
        }
    ));
}

#[test]
fn field_without_type() {
    let kind = expect_error(
        "field_without_type.xml",
        "field_without_type.xml",
        r#"6:7: <field> is missing the attribute "type""#,
    );
    assert!(matches!(
        kind,
        ErrorKind::MissingAttribute {
            element: "field",
            attribute: "type"
        }
    ));
}

#[test]
fn field_without_name() {
    // After <extensions/>, indented one level deeper: column 9.
    let kind = expect_error(
        "field_without_name.xml",
        "field_without_name.xml",
        r#"7:9: <field> is missing the attribute "name""#,
    );
    assert!(matches!(
        kind,
        ErrorKind::MissingAttribute {
            element: "field",
            attribute: "name"
        }
    ));
}

#[test]
fn enum_without_name() {
    let kind = expect_error(
        "enum_without_name.xml",
        "enum_without_name.xml",
        r#"7:5: <enum> is missing the attribute "name""#,
    );
    assert!(matches!(
        kind,
        ErrorKind::MissingAttribute {
            element: "enum",
            attribute: "name"
        }
    ));
}

#[test]
fn entry_without_name() {
    let kind = expect_error(
        "entry_without_name.xml",
        "entry_without_name.xml",
        r#"6:7: <entry> is missing the attribute "name""#,
    );
    assert!(matches!(
        kind,
        ErrorKind::MissingAttribute {
            element: "entry",
            attribute: "name"
        }
    ));
}

#[test]
fn unknown_type() {
    // A comment with a non-ASCII letter precedes the field on its line: the column counts
    // characters (27), not bytes (28).
    let kind = expect_error(
        "unknown_type.xml",
        "unknown_type.xml",
        r#"6:27: field "nine" of message ODD_TYPE: unknown type "uint9_t""#,
    );
    let ErrorKind::UnknownType { message, field, ty } = kind else {
        panic!("{kind:?}")
    };
    assert_eq!(
        (message.as_str(), field.as_str(), ty.as_str()),
        ("ODD_TYPE", "nine", "uint9_t")
    );
}

#[test]
fn array_length_zero_too_long_or_not_a_number() {
    for (name, ty) in [
        ("array_length_zero.xml", "uint8_t[0]"),
        ("array_length_too_long.xml", "uint8_t[256]"),
        ("array_length_not_a_number.xml", "uint8_t[x]"),
    ] {
        let kind = expect_error(
            name,
            name,
            &format!(
                r#"5:7: field "data" of message BAD_ARRAY: bad array length in "{ty}" (must be 1 to 255)"#
            ),
        );
        assert!(
            matches!(&kind, ErrorKind::BadArrayLength { ty: t, .. } if t == ty),
            "{kind:?}"
        );
    }
}

#[test]
fn duplicate_message_id_across_an_include() {
    // The included file comes first, so the root's message is the duplicate.
    let kind = expect_error(
        "duplicate_id_a.xml",
        "duplicate_id_a.xml",
        &format!(
            "8:5: duplicate message id 5: FIVE_A and FIVE_B (defined at {}:4:5)",
            path("duplicate_id_b.xml")
        ),
    );
    let ErrorKind::DuplicateMessageId {
        id,
        name,
        other,
        other_location,
    } = kind
    else {
        panic!("{kind:?}")
    };
    assert_eq!((id, name.as_str(), other.as_str()), (5, "FIVE_A", "FIVE_B"));
    assert_eq!(
        (
            other_location.file,
            other_location.line,
            other_location.column
        ),
        (dir().join("duplicate_id_b.xml"), 4, 5)
    );
}

#[test]
fn duplicate_message_name() {
    let kind = expect_error(
        "duplicate_name.xml",
        "duplicate_name.xml",
        &format!(
            "7:5: duplicate message name TWICE: ids 21 and 20 (defined at {}:4:5)",
            path("duplicate_name.xml")
        ),
    );
    assert!(
        matches!(
            kind,
            ErrorKind::DuplicateMessageName {
                id: 21,
                other_id: 20,
                ..
            }
        ),
        "{kind:?}"
    );
}

#[test]
fn duplicate_field_name() {
    // Positioned at the second field of that name.
    let kind = expect_error(
        "duplicate_field.xml",
        "duplicate_field.xml",
        r#"7:7: message SAME_FIELD: duplicate field "a""#,
    );
    assert!(
        matches!(&kind, ErrorKind::DuplicateField { message, field } if message == "SAME_FIELD" && field == "a")
    );
}

#[test]
fn include_cycle_through_two_files() {
    // Positioned at the include that closes the cycle.
    let (a, b) = (path("cycle_a.xml"), path("cycle_b.xml"));
    let kind = expect_error(
        "cycle_a.xml",
        "cycle_b.xml",
        &format!("4:3: include cycle: {a} -> {b} -> {a}"),
    );
    let ErrorKind::IncludeCycle { chain } = kind else {
        panic!("{kind:?}")
    };
    assert_eq!(chain, [a.clone(), b.clone(), a.clone()]);
    // Entered from the other end, the cycle closes in the other file.
    let kind = expect_error(
        "cycle_b.xml",
        "cycle_a.xml",
        &format!("3:3: include cycle: {b} -> {a} -> {b}"),
    );
    assert!(matches!(kind, ErrorKind::IncludeCycle { .. }));
}

#[test]
fn file_that_includes_itself() {
    let me = path("self_include.xml");
    let kind = expect_error(
        "self_include.xml",
        "self_include.xml",
        &format!("3:5: include cycle: {me} -> {me}"),
    );
    assert!(matches!(&kind, ErrorKind::IncludeCycle { chain } if chain.len() == 2));
}

#[test]
fn missing_include_file() {
    let target = dir().join("nowhere/absent.xml");
    let reason = std::fs::read_to_string(&target)
        .expect_err("the include target must not exist")
        .to_string();
    let kind = expect_error(
        "missing_include.xml",
        "missing_include.xml",
        &format!(
            r#"3:3: include "nowhere/absent.xml" not found: cannot read {}: {reason}"#,
            target.display()
        ),
    );
    let ErrorKind::MissingInclude {
        include, path: p, ..
    } = kind
    else {
        panic!("{kind:?}")
    };
    assert_eq!((include.as_str(), p), ("nowhere/absent.xml", target));
}

#[test]
fn missing_root_file() {
    let target = dir().join("does_not_exist.xml");
    let reason = std::fs::read_to_string(&target)
        .expect_err("must not exist")
        .to_string();
    let kind = expect_error(
        "does_not_exist.xml",
        "does_not_exist.xml",
        &format!("1:1: cannot read {}: {reason}", target.display()),
    );
    assert!(matches!(kind, ErrorKind::Read { .. }));
}

#[test]
fn payload_over_255_bytes() {
    // FITS (exactly 255 bytes) comes first and loads; TOO_LARGE is 250 + 6 extension bytes.
    let kind = expect_error(
        "payload_too_large.xml",
        "payload_too_large.xml",
        "7:5: message TOO_LARGE: payload of 256 bytes is over the 255-byte limit",
    );
    assert!(matches!(kind, ErrorKind::PayloadTooLarge { len: 256, .. }));
}

#[test]
fn more_than_64_fields() {
    let kind = expect_error(
        "too_many_fields.xml",
        "too_many_fields.xml",
        "4:5: message MANY_FIELDS: 65 fields, more than the 64 MAVLink allows",
    );
    assert!(matches!(kind, ErrorKind::TooManyFields { count: 65, .. }));
}

#[test]
fn exactly_64_fields_load() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/valid/sixty_four_fields.xml");
    let d = Loader::filesystem()
        .load(&path)
        .expect("64 fields are allowed");
    let m = d.message(12).expect("SIXTY_FOUR_FIELDS");
    assert_eq!((m.fields.len(), m.min_len, m.max_len), (64, 64, 64));
    assert_eq!(
        (
            m.fields[0].name.as_str(),
            m.fields[63].name.as_str(),
            m.fields[63].offset
        ),
        ("f1", "f64", 63)
    );
}

#[test]
fn message_with_no_fields() {
    let kind = expect_error(
        "no_fields.xml",
        "no_fields.xml",
        "4:5: message EMPTY has no fields",
    );
    assert!(matches!(&kind, ErrorKind::NoFields { message } if message == "EMPTY"));
}

#[test]
fn message_id_over_24_bits() {
    // LARGEST (16777215) comes first and is accepted.
    let kind = expect_error(
        "message_id_too_large.xml",
        "message_id_too_large.xml",
        r#"7:5: id of message TOO_LARGE_ID: "16777216" is not a valid number from 0 to 16777215"#,
    );
    assert!(matches!(&kind, ErrorKind::BadNumber { value, .. } if value == "16777216"));
}

#[test]
fn message_id_not_a_number() {
    let kind = expect_error(
        "message_id_not_a_number.xml",
        "message_id_not_a_number.xml",
        r#"4:5: id of message LETTERS: "abc" is not a valid number from 0 to 16777215"#,
    );
    assert!(
        matches!(&kind, ErrorKind::BadNumber { what, value, .. } if what == "id of message LETTERS" && value == "abc")
    );
}

#[test]
fn entry_value_not_a_number() {
    // Hex, binary and `2**N` values before it are fine.
    let kind = expect_error(
        "entry_value_not_a_number.xml",
        "entry_value_not_a_number.xml",
        r#"8:7: value of SPEED_FAST: "fast" is not a valid number"#,
    );
    assert!(matches!(&kind, ErrorKind::BadNumber { range: "", .. }));
}

#[test]
fn version_over_255() {
    let kind = expect_error(
        "version_too_large.xml",
        "version_too_large.xml",
        r#"3:3: version: "256" is not a valid number from 0 to 255"#,
    );
    assert!(matches!(
        kind,
        ErrorKind::BadNumber {
            range: " from 0 to 255",
            ..
        }
    ));
}

#[test]
fn conflicting_enum_entry_across_an_include() {
    let kind = expect_error(
        "conflicting_entry_a.xml",
        "conflicting_entry_a.xml",
        &format!(
            "7:7: enum SHAPE: entry SHAPE_SQUARE has value 3 here and 2 at {}:6:7",
            path("conflicting_entry_b.xml")
        ),
    );
    assert!(
        matches!(
            kind,
            ErrorKind::ConflictingEntry {
                value: 3,
                other_value: 2,
                ..
            }
        ),
        "{kind:?}"
    );
}

#[test]
fn unclosed_tag() {
    // <message> on line 4 is never closed; the parser notices at `</messages>` (line 6).
    let kind = expect_error(
        "unclosed_tag.xml",
        "unclosed_tag.xml",
        "6:3: malformed XML: expected 'message' tag, not 'messages'",
    );
    assert!(matches!(kind, ErrorKind::Xml(_)));
}

#[test]
fn root_element_is_not_mavlink() {
    let kind = expect_error(
        "not_mavlink.xml",
        "not_mavlink.xml",
        "3:3: root element is <definitions>, expected <mavlink>",
    );
    assert!(matches!(&kind, ErrorKind::NotMavlink { found } if found == "definitions"));
}

#[test]
fn unknown_builtin_dialect_name() {
    assert!(!Path::new("nosuchdialect").exists());
    let e = load("nosuchdialect").expect_err("no such dialect");
    let known = builtin::dialect_names().join(", ");
    assert!(
        known.starts_with("ASLUAV, AVSSUAS, all, ardupilotmega, common,"),
        "{known}"
    );
    assert_eq!(
        e.to_string(),
        format!(r#"nosuchdialect:1:1: unknown dialect "nosuchdialect" (known: {known})"#)
    );
    assert!(matches!(&*e.kind, ErrorKind::UnknownDialect { name, .. } if name == "nosuchdialect"));
}

#[test]
fn unknown_xml_path() {
    // A name ending in .xml is taken as a path, even if it does not exist.
    let e = load("nosuchdialect.xml").expect_err("no such file");
    let reason = std::fs::read_to_string("nosuchdialect.xml")
        .expect_err("must not exist")
        .to_string();
    assert_eq!(
        e.to_string(),
        format!("nosuchdialect.xml:1:1: cannot read nosuchdialect.xml: {reason}")
    );
    assert!(matches!(*e.kind, ErrorKind::Read { .. }));
}

#[test]
fn unknown_builtin_file() {
    let e = Loader::builtin()
        .load("nosuchdialect.xml")
        .expect_err("not built in");
    assert_eq!(
        e.to_string(),
        "nosuchdialect.xml:1:1: cannot read nosuchdialect.xml: no built-in definition file of that name"
    );
    assert!(matches!(*e.kind, ErrorKind::Read { .. }));
}

#[test]
fn conflicting_enum_entry_within_one_file() {
    let kind = expect_error(
        "conflicting_entry_same_file.xml",
        "conflicting_entry_same_file.xml",
        &format!(
            "6:7: enum SHAPE: entry SHAPE_CIRCLE has value 2 here and 1 at {}:5:7",
            path("conflicting_entry_same_file.xml")
        ),
    );
    assert!(
        matches!(
            kind,
            ErrorKind::ConflictingEntry {
                value: 2,
                other_value: 1,
                ..
            }
        ),
        "{kind:?}"
    );
}

#[test]
fn field_naming_an_undefined_enum() {
    let kind = expect_error(
        "unknown_enum.xml",
        "unknown_enum.xml",
        r#"6:7: field "shape" of message PAINT: unknown enum SHAPE"#,
    );
    assert!(matches!(kind, ErrorKind::UnknownEnum { .. }), "{kind:?}");
}

#[test]
fn include_without_a_file_name() {
    let kind = expect_error(
        "empty_include.xml",
        "empty_include.xml",
        "3:3: <include> names no file",
    );
    assert_eq!(kind, ErrorKind::EmptyInclude);
}
