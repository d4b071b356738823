//! Embeds the vendored definitions (`definitions/*.xml`, and our own `definitions/extras/`) so
//! that every built-in dialect can be loaded without touching the file system.

use core::fmt::Write as _;
use std::path::Path;
use std::{env, fs};

fn xml_files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", dir.display()))
        .filter_map(|entry| entry.ok()?.file_name().into_string().ok())
        .filter(|name| name.ends_with(".xml"))
        .collect();
    names.sort();
    names
}

fn main() {
    let manifest = env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let defs = Path::new(&manifest).join("definitions");
    let defs = defs.canonicalize().unwrap_or(defs);
    let extras = defs.join("extras");
    println!("cargo:rerun-if-changed={}", defs.display());
    println!("cargo:rerun-if-changed={}", extras.display());
    let mut out = String::from(
        "/// The vendored definition files: (path relative to `definitions/`, text).\n",
    );
    out.push_str("pub(crate) static FILES: &[(&str, &str)] = &[\n");
    for (prefix, dir) in [("", &defs), ("extras/", &extras)] {
        for name in xml_files(dir) {
            let path = dir.join(&name);
            println!("cargo:rerun-if-changed={}", path.display());
            writeln!(
                out,
                "    ({:?}, include_str!({:?})),",
                format!("{prefix}{name}"),
                path.display().to_string()
            )
            .expect("writing to a String cannot fail");
        }
    }
    out.push_str("];\n");
    let dest =
        Path::new(&env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("builtin_files.rs");
    fs::write(&dest, out).unwrap_or_else(|e| panic!("cannot write {}: {e}", dest.display()));
}
