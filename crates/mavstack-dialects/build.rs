//! Generates every vendored dialect into `OUT_DIR`: one module per definition file, each
//! behind its cargo feature. Reads only the XML inside this crate; no git, no network, no
//! rustfmt.

use std::path::Path;
use std::{env, fs};

fn main() {
    let manifest = env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let defs = Path::new(&manifest).join("definitions");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed={}", defs.display());
    let mut roots: Vec<_> = fs::read_dir(&defs)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", defs.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "xml"))
        .collect();
    roots.sort();
    let mut config = mavstack_codegen::Config::new();
    for root in &roots {
        println!("cargo:rerun-if-changed={}", root.display());
        config.dialect(root);
    }
    println!("cargo:rerun-if-changed={}", defs.join("extras").display());
    // In-process formatting (prettyplease) costs about 3 s of a clean build and makes the
    // generated source readable in compiler messages and on docs.rs (docs/build-times.md).
    config
        .layout(mavstack_codegen::Layout::OutDir)
        .feature_gates(true)
        .dispatch(true)
        .serde(true)
        .format(true);
    if let Err(e) = config.generate() {
        panic!("generating the dialects failed: {e}");
    }
}
