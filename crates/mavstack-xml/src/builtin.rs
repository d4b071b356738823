//! The definitions vendored with mavstack (see `definitions/PROVENANCE.md`).

include!(concat!(env!("OUT_DIR"), "/builtin_files.rs"));

/// The text of a built-in definition file, by its path under `definitions/`.
#[must_use]
pub fn file(path: &str) -> Option<&'static str> {
    FILES
        .iter()
        .find(|(name, _)| *name == path)
        .map(|(_, text)| *text)
}

/// The names of the built-in dialects (every official file, by stem), sorted.
#[must_use]
pub fn dialect_names() -> Vec<&'static str> {
    let mut names: Vec<&'static str> = FILES
        .iter()
        .filter(|(name, _)| !name.contains('/'))
        .filter_map(|(name, _)| name.strip_suffix(".xml"))
        .collect();
    names.sort_unstable();
    names
}
