//! `mavstack dialect list|show` and `mavstack codegen`.

use std::io::{self, Write};
use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Args, Subcommand};
use mavstack_xml::{Dialect, Field, Message, builtin};
use serde_json::{Value, json};

use crate::Failure;

#[derive(Debug, Subcommand)]
pub(crate) enum DialectAction {
    /// The built-in dialects, with their message and enum counts.
    List {
        /// One JSON object per dialect instead of a table.
        #[arg(long)]
        json: bool,
    },
    /// One dialect: every message (id, name, CRC_EXTRA, lengths, fields in wire order) and enum.
    Show {
        /// A built-in dialect name or a path to an XML file.
        dialect: String,
        /// Print one JSON object (the format of `docs/contracts/json-lines.md`).
        #[arg(long)]
        json: bool,
    },
}

#[derive(Debug, Args)]
pub(crate) struct CodegenArgs {
    /// The dialect's root XML file.
    xml: PathBuf,
    /// The directory to write `mod.rs` and one `<file>.rs` per definition file into.
    #[arg(long)]
    out: PathBuf,
    /// Add `#[cfg_attr(feature = "serde", derive(Serialize, Deserialize))]` to every type.
    #[arg(long)]
    serde: bool,
    /// The path generated code uses for the mavstack-core crate.
    #[arg(long, default_value = "::mavstack_core")]
    core_path: String,
}

pub(crate) fn load(name: &str) -> Result<Dialect, Failure> {
    mavstack_xml::load(name).map_err(|e| Failure::Input(e.into()))
}

/// The message table of `name` when it is a dialect compiled into the binary (any case):
/// every built-in dialect is (`mavstack_dialects`, feature `all`).
pub(crate) fn compiled_table(name: &str) -> Option<mavstack_core::MessageTable> {
    struct Table;
    impl mavstack_dialects::DialectVisitor for Table {
        type Output = mavstack_core::MessageTable;
        fn visit<M: mavstack_core::MessageSet>(self) -> Self::Output {
            mavstack_core::MessageTable::of::<M>()
        }
    }
    mavstack_dialects::with_dialect(name, Table)
}

pub(crate) fn run(action: DialectAction) -> Result<(), Failure> {
    let stdout = io::stdout();
    let mut out = io::BufWriter::new(stdout.lock());
    match action {
        DialectAction::List { json } => list(&mut out, json)?,
        DialectAction::Show { dialect, json } => {
            let d = load(&dialect)?;
            if json {
                serde_json::to_writer(&mut out, &dialect_json(&d)).context("writing JSON")?;
                writeln!(out).context("writing output")?;
            } else {
                show(&mut out, &d).context("writing output")?;
            }
        }
    }
    out.flush().context("writing output")?;
    Ok(())
}

fn list(out: &mut impl Write, json: bool) -> Result<(), Failure> {
    if !json {
        writeln!(
            out,
            "{:<20} {:>8} {:>6}  includes",
            "dialect", "messages", "enums"
        )
        .context("writing output")?;
    }
    for name in builtin::dialect_names() {
        let d = load(name)?;
        let includes: Vec<String> = d
            .root()
            .includes
            .iter()
            .map(|p| mavstack_xml::model::file_stem(p))
            .collect();
        if json {
            let line = json!({"name": name, "messages": d.messages.len(), "enums": d.enums.len(), "includes": includes});
            writeln!(out, "{line}").context("writing output")?;
        } else {
            writeln!(
                out,
                "{name:<20} {:>8} {:>6}  {}",
                d.messages.len(),
                d.enums.len(),
                includes.join(", ")
            )
            .context("writing output")?;
        }
    }
    Ok(())
}

fn type_label(f: &Field) -> String {
    match f.ty.array_len {
        Some(n) => format!("{}[{n}]", f.ty.primitive.c_name()),
        None => f.ty.primitive.c_name().to_owned(),
    }
}

fn show(out: &mut impl Write, d: &Dialect) -> io::Result<()> {
    writeln!(
        out,
        "dialect {} (version {}): {} messages, {} enums, from {}",
        d.name,
        d.version.map_or_else(|| "-".to_owned(), |v| v.to_string()),
        d.messages.len(),
        d.enums.len(),
        d.files
            .iter()
            .map(|f| f.stem())
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    for m in &d.messages {
        show_message(out, m)?;
    }
    writeln!(out)?;
    for e in &d.enums {
        let kind = if e.bitmask { "bitmask" } else { "enum" };
        writeln!(out, "{kind} {} ({} entries)", e.name, e.entries.len())?;
        for entry in &e.entries {
            writeln!(out, "  {:>10}  {}", entry.value, entry.name)?;
        }
    }
    Ok(())
}

fn show_message(out: &mut impl Write, m: &Message) -> io::Result<()> {
    writeln!(
        out,
        "\n{:>7} {}  crc_extra={} len={}..{}{}",
        m.id,
        m.name,
        m.crc_extra,
        m.min_len,
        m.max_len,
        if m.deprecation.is_some() {
            "  (deprecated)"
        } else {
            ""
        }
    )?;
    for f in &m.fields {
        let mut notes = Vec::new();
        if f.extension {
            notes.push("extension".to_owned());
        }
        if let Some(e) = &f.enum_name {
            notes.push(format!("enum {e}"));
        }
        if let Some(u) = &f.units {
            notes.push(format!("units {u}"));
        }
        writeln!(
            out,
            "        {:>3}  {:<14} {:<28} {}",
            f.offset,
            type_label(f),
            f.name,
            notes.join(", ")
        )?;
    }
    Ok(())
}

/// The dialect as the JSON object of `docs/contracts/json-lines.md`.
pub(crate) fn dialect_json(d: &Dialect) -> Value {
    let messages: Vec<Value> = d
        .messages
        .iter()
        .map(|m| {
            let fields: Vec<Value> = m
                .fields
                .iter()
                .map(|f| {
                    json!({
                        "name": f.name,
                        "type": f.ty.primitive.c_name(),
                        "array_len": f.ty.array_len,
                        "enum": f.enum_name,
                        "extension": f.extension,
                    })
                })
                .collect();
            json!({
                "id": m.id, "name": m.name, "crc_extra": m.crc_extra,
                "min_len": m.min_len, "max_len": m.max_len, "fields": fields,
            })
        })
        .collect();
    let enums: Vec<Value> = d
        .enums
        .iter()
        .map(|e| {
            let entries: Vec<Value> = e
                .entries
                .iter()
                .map(|x| json!({"name": x.name, "value": x.value}))
                .collect();
            json!({"name": e.name, "bitmask": e.bitmask, "entries": entries})
        })
        .collect();
    json!({"name": d.name, "messages": messages, "enums": enums})
}

pub(crate) fn codegen(args: &CodegenArgs) -> Result<(), Failure> {
    let mut config = mavstack_codegen::Config::new();
    config
        .dialect(&args.xml)
        .out_dir(&args.out)
        .serde(args.serde);
    config
        .core_path(&args.core_path)
        .map_err(|e| Failure::Input(e.into()))?;
    let written = config.generate().map_err(|e| match e {
        mavstack_codegen::Error::Dialect(_) | mavstack_codegen::Error::Conflict(_) => {
            Failure::Input(e.into())
        }
        other => Failure::Other(other.into()),
    })?;
    let mut total = 0u64;
    for path in &written {
        total += std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        println!("{}", path.display());
    }
    eprintln!(
        "wrote {} files, {} bytes; mount them with `mod <name>;` on {}",
        written.len(),
        total,
        args.out.display()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{compiled_table, load};

    /// Every built-in dialect is compiled in under its name, in any case, and its typed
    /// table is the run-time model's.
    #[test]
    fn every_builtin_dialect_is_compiled_in() {
        let names = mavstack_xml::builtin::dialect_names();
        assert!(names.len() >= 19, "{names:?}");
        for name in names {
            let compiled = compiled_table(name).unwrap_or_else(|| panic!("{name} not compiled"));
            let model = load(name)
                .unwrap_or_else(|_| panic!("{name} loads"))
                .message_table();
            assert_eq!(compiled.entries(), model.entries(), "{name}");
            let upper = compiled_table(&name.to_ascii_uppercase()).expect("any case");
            assert_eq!(upper.entries(), compiled.entries(), "{name}");
        }
        assert!(compiled_table("no_such_dialect").is_none());
    }
}
