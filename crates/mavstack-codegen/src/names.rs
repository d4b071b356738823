//! Rust names for MAVLink names.

use heck::{ToSnakeCase, ToUpperCamelCase};
use proc_macro2::{Ident, Span};

/// `HEARTBEAT` → `Heartbeat`, `MAV_TYPE` → `MavType`.
pub(crate) fn type_name(xml_name: &str) -> Ident {
    Ident::new(&xml_name.to_upper_camel_case(), Span::call_site())
}

/// The module of a definition file: its stem in lower case (`uAvionix` → `uavionix`).
pub(crate) fn module_name(stem: &str) -> String {
    stem.to_lowercase().replace(['-', '.', ' '], "_")
}

/// A field name as an identifier: snake case (`ICAO_address` → `icao_address`, `zoomLevel` →
/// `zoom_level`), and keywords become raw identifiers (`type` → `r#type`).
pub(crate) fn field_ident(xml_name: &str) -> Ident {
    let snake = xml_name.to_snake_case();
    let name = snake.as_str();
    const RESERVED: &[&str] = &[
        "as", "async", "await", "break", "const", "continue", "dyn", "else", "enum", "extern",
        "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move",
        "mut", "pub", "ref", "return", "static", "struct", "trait", "true", "type", "unsafe",
        "use", "where", "while", "abstract", "become", "box", "do", "final", "macro", "override",
        "priv", "try", "typeof", "unsized", "virtual", "yield",
    ];
    match name {
        "self" | "Self" | "super" | "crate" | "_" => {
            Ident::new(&format!("{name}_"), Span::call_site())
        }
        n if RESERVED.contains(&n) => Ident::new_raw(n, Span::call_site()),
        n => Ident::new(n, Span::call_site()),
    }
}

/// The constant names of an enum's entries: the enum name prefix is dropped
/// (`MAV_TYPE_QUADROTOR` → `QUADROTOR`) unless that leaves something that is not an
/// identifier or not unique, in which case every entry keeps its full name. Names are upper
/// case (`GOPRO_RESOLUTION_480p` → `480P` would start with a digit, so `GOPRO_RESOLUTION_480P`).
pub(crate) fn entry_names<'a>(
    enum_name: &str,
    entries: impl Iterator<Item = &'a str> + Clone,
) -> Vec<String> {
    let prefix = format!("{enum_name}_");
    let stripped: Vec<String> = entries
        .clone()
        .map(|e| e.strip_prefix(&prefix).unwrap_or(e).to_uppercase())
        .collect();
    let valid = stripped.iter().all(|s| {
        s.chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
    });
    let mut unique = stripped.clone();
    unique.sort();
    unique.dedup();
    if valid && unique.len() == stripped.len() {
        stripped
    } else {
        entries.map(str::to_uppercase).collect()
    }
}

/// An identifier from a name already known to be valid.
pub(crate) fn ident(name: &str) -> Ident {
    Ident::new(name, Span::call_site())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions() {
        assert_eq!(type_name("GPS_RAW_INT").to_string(), "GpsRawInt");
        assert_eq!(module_name("uAvionix"), "uavionix");
        assert_eq!(field_ident("type").to_string(), "r#type");
        assert_eq!(field_ident("self").to_string(), "self_");
        assert_eq!(field_ident("ICAO_address").to_string(), "icao_address");
        assert_eq!(field_ident("zoomLevel").to_string(), "zoom_level");
        assert_eq!(field_ident("Vcc").to_string(), "vcc");
        let names = entry_names(
            "MAV_TYPE",
            ["MAV_TYPE_GENERIC", "MAV_TYPE_QUADROTOR"].into_iter(),
        );
        assert_eq!(names, ["GENERIC", "QUADROTOR"]);
        let names = entry_names(
            "GPS_FIX_TYPE",
            ["GPS_FIX_TYPE_NO_GPS", "GPS_FIX_TYPE_2D_FIX"].into_iter(),
        );
        assert_eq!(names, ["GPS_FIX_TYPE_NO_GPS", "GPS_FIX_TYPE_2D_FIX"]);
    }
}
