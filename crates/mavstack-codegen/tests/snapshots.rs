//! One small fixture XML per concern, its generated code snapshotted with insta. Review a
//! changed snapshot with `cargo insta review` (or set `INSTA_UPDATE=always` and read the diff).

use std::path::{Path, PathBuf};

use mavstack_codegen::Config;

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// Generated files of `config`, one after the other.
fn render(config: &Config) -> String {
    let files = config.render().expect("generates");
    let mut out = String::new();
    for f in files {
        out.push_str(&format!("==> {} <==\n{}\n", f.name, f.contents));
    }
    out
}

fn snapshot(name: &str, xml: &str) {
    let text = render(Config::new().dialect(fixture(xml)));
    insta::assert_snapshot!(name, text);
}

#[test]
fn every_type_and_the_wire_order() {
    snapshot("types", "types.xml");
}

#[test]
fn extensions_follow_in_xml_order() {
    snapshot("extensions", "extensions.xml");
}

#[test]
fn open_enums_bitmasks_and_widths() {
    snapshot("enums", "enums.xml");
}

#[test]
fn keywords_and_camel_case_field_names() {
    snapshot("names", "names.xml");
}

#[test]
fn docs_deprecation_and_wip() {
    snapshot("docs", "docs.xml");
}

#[test]
fn included_files_share_types_and_gate_added_entries() {
    let text = render(
        Config::new()
            .dialect(fixture("includes/child.xml"))
            .feature_gates(true)
            .serde(true),
    );
    insta::assert_snapshot!("includes_gated", text);
}

/// `mod.rs` with the dispatch by name: one gated branch per module, valid Rust.
#[test]
fn dispatch_by_name_covers_every_module() {
    let files = Config::new()
        .dialect(fixture("includes/child.xml"))
        .feature_gates(true)
        .dispatch(true)
        .render()
        .expect("generates");
    let index = files.iter().find(|f| f.name == "mod.rs").expect("index");
    syn::parse_file(&index.contents).expect("parses");
    insta::assert_snapshot!("dispatch_gated", index.contents);
    let plain = Config::new()
        .dialect(fixture("includes/child.xml"))
        .render()
        .expect("generates");
    let index = plain.iter().find(|f| f.name == "mod.rs").expect("index");
    assert!(!index.contents.contains("with_dialect"), "off by default");
}

#[test]
fn out_dir_layout_and_unformatted_output() {
    let files = Config::new()
        .dialect(fixture("names.xml"))
        .layout(mavstack_codegen::Layout::OutDir)
        .format(false)
        .render()
        .expect("generates");
    let index = files.iter().find(|f| f.name == "mod.rs").expect("index");
    assert!(
        index
            .contents
            .contains(r#"include!(concat!(env!("OUT_DIR"), "/names.rs"));"#),
        "{}",
        index.contents
    );
    let module = files.iter().find(|f| f.name == "names.rs").expect("module");
    assert!(module.contents.contains("pub struct OddNames"));
    // Unformatted output is still valid Rust.
    let body = module
        .contents
        .split_once('\n')
        .map(|(_, b)| b)
        .unwrap_or_default();
    syn::parse_file(body).expect("parses");
}

#[test]
fn errors_are_reported() {
    assert!(matches!(
        Config::new().render(),
        Err(mavstack_codegen::Error::NoDialect)
    ));
    let err = Config::new()
        .dialect(fixture("missing.xml"))
        .render()
        .expect_err("no such file");
    assert!(
        err.to_string().contains("missing.xml:1:1: cannot read"),
        "{err}"
    );
    assert!(Config::new().core_path("not a path").is_err());
}
