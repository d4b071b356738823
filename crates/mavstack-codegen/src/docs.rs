//! Documentation text for generated items, from the XML descriptions.

use mavstack_xml::{Deprecation, Entry, Enum, Field, Message};
use proc_macro2::TokenStream;
use quote::quote;

/// `#[doc = "..."]` attributes, one per line of `text`.
pub(crate) fn doc_attrs(text: &str) -> TokenStream {
    let lines = text.lines().map(|l| format!(" {l}"));
    quote!(#(#[doc = #lines])*)
}

/// Escapes text so rustdoc shows it as written (MAVLink descriptions contain `[`, `<`, `_`).
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '[' | ']' | '*' | '_' | '`' | '<' | '>' | '#' | '\\' => {
                out.push('\\');
                out.push(c);
            }
            _ => out.push(c),
        }
    }
    out
}

fn deprecation_note(d: Option<&Deprecation>) -> String {
    match d {
        None => String::new(),
        Some(d) => {
            let word = if d.superseded {
                "Superseded"
            } else {
                "Deprecated"
            };
            let mut s = format!("\n\n**{word}** since {}", escape(&d.since));
            if !d.replaced_by.is_empty() {
                s.push_str(&format!(", replaced by `{}`", d.replaced_by));
            }
            if !d.note.is_empty() {
                s.push_str(&format!(": {}", escape(&d.note)));
            }
            s
        }
    }
}

fn file_name(path: &std::path::Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}

pub(crate) fn message_doc(m: &Message) -> String {
    let mut s = format!("`{}` (id {}).", m.name, m.id);
    if !m.description.is_empty() {
        s.push_str(&format!("\n\n{}", escape(&m.description)));
    }
    s.push_str(&format!(
        "\n\nCRC_EXTRA {}, payload {} bytes ({} without extensions); defined in `{}`.",
        m.crc_extra,
        m.max_len,
        m.min_len,
        file_name(&m.file)
    ));
    if m.wip {
        s.push_str("\n\n**Work in progress**: the definition may still change.");
    }
    s.push_str(&deprecation_note(m.deprecation.as_ref()));
    s
}

pub(crate) fn field_doc(f: &Field) -> String {
    let mut s = if f.description.is_empty() {
        format!("`{}`.", f.name)
    } else {
        escape(&f.description)
    };
    let mut facts = Vec::new();
    if let Some(u) = &f.units {
        facts.push(format!("units: {}", escape(u)));
    }
    if let Some(e) = &f.enum_name {
        facts.push(format!("values: `{e}`"));
    }
    if let Some(i) = &f.invalid {
        facts.push(format!("invalid (not set): `{i}`"));
    }
    if f.ty.mavlink_version {
        facts.push("filled in with the dialect's version by default".to_owned());
    }
    if f.extension {
        facts.push("extension field (MAVLink 2 only; zero when absent)".to_owned());
    }
    if !facts.is_empty() {
        if !s.is_empty() {
            s.push_str("\n\n");
        }
        s.push_str(&format!("({}.)", facts.join("; ")));
    }
    s
}

pub(crate) fn enum_doc(e: &Enum) -> String {
    let kind = if e.bitmask { "Bitmask" } else { "Enum" };
    let mut s = format!("{kind} `{}`.", e.name);
    if !e.description.is_empty() {
        s.push_str(&format!("\n\n{}", escape(&e.description)));
    }
    s.push_str(
        "\n\nOpen: any value of the underlying integer is valid, and values this dialect does not name survive \
         decoding and encoding unchanged.",
    );
    s.push_str(&deprecation_note(e.deprecation.as_ref()));
    s
}

pub(crate) fn entry_doc(e: &Entry) -> String {
    let mut s = format!("`{}` = {}.", e.name, e.value);
    if !e.description.is_empty() {
        s.push_str(&format!(" {}", escape(&e.description)));
    }
    for p in &e.params {
        let label = p.label.as_deref().unwrap_or("");
        let units = p
            .units
            .as_deref()
            .map(|u| format!(" [{}]", escape(u)))
            .unwrap_or_default();
        s.push_str(&format!(
            "\n- param{} {}{}: {}",
            p.index,
            escape(label),
            units,
            escape(&p.description)
        ));
    }
    if e.wip {
        s.push_str("\n\n**Work in progress**.");
    }
    s.push_str(&deprecation_note(e.deprecation.as_ref()));
    s
}
