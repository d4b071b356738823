//! Include resolution and enum merging on a small tree of fixtures (`tests/fixtures/includes/`):
//!
//! ```text
//! root.xml ──► sub/child.xml ──► ../base.xml  (= base.xml)
//!    │                   └─────► grandchild.xml (= sub/grandchild.xml)
//!    └───────► base.xml   (the same file again, by another spelling)
//! ```
//!
//! `COLOR` is declared in base.xml and extended by sub/child.xml and root.xml; some entries have
//! no `value` attribute and take the previous entry's value plus one.
//!
//! `tests/fixtures/supplement/` checks when the PROTOCOL_VERSION supplement goes into a file
//! called `common.xml`.

use std::path::{Path, PathBuf};

use mavstack_xml::{Dialect, Loader};

fn dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/includes")
}

fn load_root() -> Dialect {
    Loader::filesystem()
        .load(dir().join("root.xml"))
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn includes_resolve_relative_to_the_including_file() {
    let d = load_root();
    let (base, child, grandchild, root) = (
        dir().join("base.xml"),
        dir().join("sub/child.xml"),
        dir().join("sub/grandchild.xml"),
        dir().join("root.xml"),
    );
    // Depth first, every file after the files it includes; base.xml once although it is
    // reached as `base.xml` and as `sub/../base.xml`.
    let paths: Vec<&Path> = d.files.iter().map(|f| f.path.as_path()).collect();
    assert_eq!(
        paths,
        [
            base.as_path(),
            grandchild.as_path(),
            child.as_path(),
            root.as_path()
        ]
    );
    assert_eq!(d.files[2].includes, [base.clone(), grandchild.clone()]);
    assert_eq!(d.files[3].includes, [child.clone(), base.clone()]);
    assert_eq!(d.root().path, root);
    assert_eq!(d.name, "root");
    // Each file's own <version> and <dialect>; the root's version is in force.
    let versions: Vec<(Option<u8>, Option<u8>)> =
        d.files.iter().map(|f| (f.version, f.dialect)).collect();
    assert_eq!(
        versions,
        [
            (Some(3), None),
            (None, None),
            (None, None),
            (Some(7), Some(42))
        ]
    );
    assert_eq!(d.version, Some(7));
}

#[test]
fn messages_of_every_file_sorted_by_id() {
    let d = load_root();
    let messages: Vec<(u32, &str, PathBuf)> = d
        .messages
        .iter()
        .map(|m| {
            (
                m.id,
                m.name.as_str(),
                m.file.strip_prefix(dir()).expect("in dir").to_path_buf(),
            )
        })
        .collect();
    assert_eq!(
        messages,
        [
            (10, "BASE_MSG", PathBuf::from("base.xml")),
            (20, "CHILD_MSG", PathBuf::from("sub/child.xml")),
            (21, "GRANDCHILD_MSG", PathBuf::from("sub/grandchild.xml")),
            (30, "ROOT_MSG", PathBuf::from("root.xml")),
        ]
    );
    let grandchild = d.message(21).expect("GRANDCHILD_MSG");
    assert_eq!(
        (grandchild.location.line, grandchild.location.column),
        (4, 5)
    );
    assert_eq!(grandchild.location.file, dir().join("sub/grandchild.xml"));
    // No PROTOCOL_VERSION: the supplement only goes into files called common.xml.
    assert!(d.message(300).is_none());
    let root_msg = d.message(30).expect("ROOT_MSG");
    let fields: Vec<(&str, usize, Option<&str>)> = root_msg
        .fields
        .iter()
        .map(|f| (f.name.as_str(), f.offset, f.enum_name.as_deref()))
        .collect();
    assert_eq!(fields, [("count", 0, None), ("color", 4, Some("COLOR"))]);
}

#[test]
fn enum_extended_by_including_files() {
    let d = load_root();
    let color = d.enum_by_name("COLOR").expect("COLOR");
    assert_eq!(color.file, dir().join("base.xml"));
    assert_eq!((color.location.line, color.location.column), (6, 5));
    // The first declaration with a description gives it.
    assert_eq!(color.description, "Colors, first declared here.");
    let entries: Vec<(&str, u64, PathBuf)> = color
        .entries
        .iter()
        .map(|e| {
            (
                e.name.as_str(),
                e.value,
                e.file.strip_prefix(dir()).expect("in dir").to_path_buf(),
            )
        })
        .collect();
    assert_eq!(
        entries,
        [
            // base.xml: GREEN and BLUE have no value attribute.
            ("COLOR_RED", 1, PathBuf::from("base.xml")),
            ("COLOR_GREEN", 2, PathBuf::from("base.xml")),
            ("COLOR_BLUE", 3, PathBuf::from("base.xml")),
            // sub/child.xml repeats COLOR_GREEN with the same value (kept once, from base.xml),
            // and ORANGE follows YELLOW.
            ("COLOR_YELLOW", 5, PathBuf::from("sub/child.xml")),
            ("COLOR_ORANGE", 6, PathBuf::from("sub/child.xml")),
            // root.xml: BLACK follows WHITE.
            ("COLOR_WHITE", 10, PathBuf::from("root.xml")),
            ("COLOR_BLACK", 11, PathBuf::from("root.xml")),
        ]
    );
    let black = color.entry("COLOR_BLACK").expect("COLOR_BLACK");
    assert_eq!(
        (
            black.location.file.clone(),
            black.location.line,
            black.location.column
        ),
        (dir().join("root.xml"), 12, 7)
    );
}

#[test]
fn the_same_tree_from_an_inner_file() {
    // Loading sub/child.xml directly: its includes still resolve against sub/.
    let d = Loader::filesystem()
        .load(dir().join("sub/child.xml"))
        .unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = d.messages.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["BASE_MSG", "CHILD_MSG", "GRANDCHILD_MSG"]);
    assert_eq!(d.version, Some(3));
    let color = d.enum_by_name("COLOR").expect("COLOR");
    assert_eq!(color.entries.len(), 5);
}

#[test]
fn root_path_is_normalised() {
    // Paths are normalised lexically: `sub/../root.xml` is `root.xml` in the same folder.
    let spelled = dir().join("sub/../root.xml");
    let d = Loader::filesystem()
        .load(&spelled)
        .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(d.root().path, dir().join("root.xml"));
    assert_eq!(d.files.len(), 4);
}

#[test]
fn protocol_version_supplement_only_with_the_standard_loaders() {
    use mavstack_xml::FileSystem;
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/supplement/common.xml");
    let with = Loader::filesystem()
        .load(&path)
        .unwrap_or_else(|e| panic!("{e}"));
    let ids: Vec<(u32, &str)> = with
        .messages
        .iter()
        .map(|m| (m.id, m.name.as_str()))
        .collect();
    assert_eq!(
        ids,
        [
            (1, "ONLY"),
            (300, "PROTOCOL_VERSION"),
            (397, "COMPONENT_METADATA"),
            (410, "EVENT"),
            (411, "CURRENT_EVENT_SEQUENCE"),
            (412, "REQUEST_EVENT"),
            (413, "RESPONSE_EVENT_ERROR"),
            (435, "AVAILABLE_MODES"),
            (436, "CURRENT_MODE"),
            (437, "AVAILABLE_MODES_MONITOR"),
        ]
    );
    let pv = with.message(300).expect("PROTOCOL_VERSION");
    assert_eq!((pv.crc_extra, pv.min_len, pv.max_len), (217, 22, 22));
    assert_eq!(pv.file, path);
    assert!(pv.location.file.ends_with("extras/protocol_version.xml"));

    for without in [
        Loader::new(FileSystem).load(&path),
        Loader::filesystem().without_supplements().load(&path),
    ] {
        let d = without.unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(d.messages.len(), 1);
        assert_eq!(d.messages[0].name, "ONLY");
    }

    // A common.xml that defines message 300 itself keeps its own (and still gets the events
    // protocol, a supplement of its own).
    let own = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/supplement/own_protocol_version/common.xml");
    let d = Loader::filesystem()
        .load(&own)
        .unwrap_or_else(|e| panic!("{e}"));
    let names: Vec<&str> = d
        .messages
        .iter()
        .map(|m| m.name.as_str())
        .filter(|n| !n.contains("EVENT") && *n != "COMPONENT_METADATA" && !n.contains("_MODE"))
        .collect();
    assert_eq!(names, ["MY_VERSION"]);
    assert!(d.message(410).is_some());
}
