//! # mavstack-codegen
//!
//! MAVLink dialect model → Rust source, as a library with a builder. It is what the build
//! script of `mavstack-dialects` runs over the vendored XML, and what `mavstack codegen`
//! runs over a user's own XML.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!  XML roots ──mavstack-xml──► Dialect per file ──plan──► modules + enum owners
//!                                                              │
//!              quote ◄── messages, open enums, MavMessage ◄────┘
//!                │
//!                └──► prettyplease ──► one `@generated` file per module + an index
//! ```
//!
//! Every definition file becomes one module: its own messages (structs implementing
//! `mavstack_core::Message`), the enums it declares first (open newtypes with one constant
//! per entry; bitmasks keep unknown bits), a `MavMessage` enum over every message of the
//! file's include closure (implementing `mavstack_core::MessageSet`), and `pub use` of the
//! modules of the files it includes. Types are never duplicated: `ardupilotmega` reuses
//! `common::Heartbeat` and adds its `MAV_CMD` entries to `common::MavCmd`.
//!
//! No git, no network and no `rustfmt` binary: formatting is done in-process.
//!
//! ```no_run
//! # fn main() -> Result<(), mavstack_codegen::Error> {
//! mavstack_codegen::Config::new()
//!     .dialect("definitions/my_dialect.xml")
//!     .out_dir("src/dialects")
//!     .generate()?;
//! # Ok(())
//! # }
//! ```
//!
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

mod docs;
mod emit_enum;
mod emit_message;
mod emit_set;
mod names;
mod plan;

use core::fmt::Write as _;
use std::path::{Path, PathBuf};

use proc_macro2::TokenStream;
use quote::quote;

/// Why generation failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A definition file is invalid.
    #[error(transparent)]
    Dialect(#[from] mavstack_xml::Error),
    /// Two definition files cannot be generated side by side.
    #[error("{0}")]
    Conflict(String),
    /// The output cannot be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The generated code did not parse: a bug in the generator.
    #[error("generated code for {module} does not parse ({reason}); please report this")]
    Syntax {
        /// The module.
        module: String,
        /// The parser's message.
        reason: String,
    },
    /// No dialect was given.
    #[error("no dialect given: call Config::dialect at least once")]
    NoDialect,
}

/// How the generated modules are tied together.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Layout {
    /// `mod.rs` declares `pub mod x;` for every `x.rs` beside it: a source tree to commit
    /// and mount with `mod dialects;`.
    #[default]
    Files,
    /// `mod.rs` declares `pub mod x { include!(concat!(env!("OUT_DIR"), "/x.rs")); }`: for a
    /// build script writing to `OUT_DIR`, mounted with
    /// `include!(concat!(env!("OUT_DIR"), "/mod.rs"));`.
    OutDir,
}

/// What the emitters need to know of the configuration.
#[derive(Clone, Debug)]
pub(crate) struct Options {
    core_path: String,
    feature_gates: bool,
    serde: bool,
}

impl Options {
    pub(crate) fn core_path(&self) -> TokenStream {
        // The path is checked to parse when it is set.
        self.core_path
            .parse()
            .unwrap_or_else(|_| quote!(::mavstack_core))
    }

    pub(crate) fn core_path_str(&self) -> &str {
        &self.core_path
    }

    pub(crate) fn serde_derive(&self) -> TokenStream {
        if self.serde {
            quote!(#[cfg_attr(feature = "serde", derive(::serde::Serialize, ::serde::Deserialize))])
        } else {
            TokenStream::new()
        }
    }
}

/// One generated file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GeneratedFile {
    /// File name, e.g. `common.rs` or `mod.rs`.
    pub name: String,
    /// Its contents.
    pub contents: String,
}

/// The generator's configuration: a `&mut Self` builder.
#[derive(Clone, Debug)]
pub struct Config {
    roots: Vec<PathBuf>,
    out_dir: Option<PathBuf>,
    layout: Layout,
    format: bool,
    supplements: bool,
    dispatch: bool,
    options: Options,
}

impl Default for Config {
    fn default() -> Self {
        Self::new()
    }
}

impl Config {
    /// Defaults: `Layout::Files`, formatted output, the PROTOCOL_VERSION supplement on, no
    /// feature gates, no serde, no dispatch by name, core crate at `::mavstack_core`.
    #[must_use]
    pub fn new() -> Self {
        Self {
            roots: Vec::new(),
            out_dir: None,
            layout: Layout::Files,
            format: true,
            supplements: true,
            dispatch: false,
            options: Options {
                core_path: "::mavstack_core".into(),
                feature_gates: false,
                serde: false,
            },
        }
    }

    /// Adds a dialect's root XML file; its includes are generated too.
    pub fn dialect(&mut self, path: impl Into<PathBuf>) -> &mut Self {
        self.roots.push(path.into());
        self
    }

    /// Where [`Config::generate`] writes (default: `$OUT_DIR`).
    pub fn out_dir(&mut self, dir: impl Into<PathBuf>) -> &mut Self {
        self.out_dir = Some(dir.into());
        self
    }

    /// How modules are tied together.
    pub fn layout(&mut self, layout: Layout) -> &mut Self {
        self.layout = layout;
        self
    }

    /// Whether to run the output through prettyplease (default on). Off saves time in build
    /// scripts whose output nobody reads.
    pub fn format(&mut self, on: bool) -> &mut Self {
        self.format = on;
        self
    }

    /// Whether to merge mavstack's PROTOCOL_VERSION supplement into `common.xml` (default on).
    pub fn supplements(&mut self, on: bool) -> &mut Self {
        self.supplements = on;
        self
    }

    /// Gate every module behind `#[cfg(feature = "<module>")]` and every enum entry added by
    /// another file behind that file's feature (used by `mavstack-dialects`).
    pub fn feature_gates(&mut self, on: bool) -> &mut Self {
        self.options.feature_gates = on;
        self
    }

    /// Give `mod.rs` a dispatch by name (default off): a `DialectVisitor` trait and
    /// `with_dialect(name, visitor)`, which runs the visitor with the `MavMessage` of the
    /// module called `name` (any case), so that a program can pick a dialect at run time and
    /// still use the typed code. With [`Config::feature_gates`], only the modules compiled in
    /// are found. The one list of the generated dialects is then the definition files.
    pub fn dispatch(&mut self, on: bool) -> &mut Self {
        self.dispatch = on;
        self
    }

    /// Emit `#[cfg_attr(feature = "serde", derive(Serialize, Deserialize))]` on every type; the
    /// crate that includes the code needs a `serde` feature, and `mavstack-core`'s.
    pub fn serde(&mut self, on: bool) -> &mut Self {
        self.options.serde = on;
        self
    }

    /// The path generated code uses for `mavstack-core` (default `::mavstack_core`).
    ///
    /// # Errors
    /// `path` is not a Rust path.
    pub fn core_path(&mut self, path: &str) -> Result<&mut Self, Error> {
        syn::parse_str::<syn::Path>(path)
            .map_err(|e| Error::Conflict(format!("core path {path:?} is not a Rust path: {e}")))?;
        self.options.core_path = path.to_owned();
        Ok(self)
    }

    /// Generates every module in memory: one file per definition file, then `mod.rs`.
    ///
    /// # Errors
    /// An invalid definition file, or two files that cannot be generated side by side.
    pub fn render(&self) -> Result<Vec<GeneratedFile>, Error> {
        if self.roots.is_empty() {
            return Err(Error::NoDialect);
        }
        let plan = plan::build(&self.roots, self.supplements)?;
        let mut files = Vec::new();
        for unit in &plan.units {
            let tokens = emit_unit(unit, &plan, &self.options);
            let body = if self.format {
                let file = syn::parse2::<syn::File>(tokens).map_err(|e| Error::Syntax {
                    module: unit.module.clone(),
                    reason: e.to_string(),
                })?;
                prettyplease::unparse(&file)
            } else {
                tokens.to_string()
            };
            let source = unit
                .path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let contents = format!(
                "// @generated by mavstack-codegen from {source}. Do not edit: regenerate instead.\n{body}"
            );
            files.push(GeneratedFile {
                name: format!("{}.rs", unit.module),
                contents,
            });
        }
        files.push(GeneratedFile {
            name: "mod.rs".into(),
            contents: self.index(&plan),
        });
        Ok(files)
    }

    /// Generates and writes every file into the output directory.
    ///
    /// # Errors
    /// As [`Config::render`], or the files cannot be written.
    pub fn generate(&self) -> Result<Vec<PathBuf>, Error> {
        let dir = match &self.out_dir {
            Some(d) => d.clone(),
            None => std::env::var_os("OUT_DIR")
                .map(PathBuf::from)
                .ok_or_else(|| Error::Io {
                    path: PathBuf::from("$OUT_DIR"),
                    source: std::io::Error::new(
                        std::io::ErrorKind::NotFound,
                        "no out_dir set and OUT_DIR is unset",
                    ),
                })?,
        };
        std::fs::create_dir_all(&dir).map_err(|source| Error::Io {
            path: dir.clone(),
            source,
        })?;
        let mut written = Vec::new();
        for f in self.render()? {
            let path = dir.join(&f.name);
            write_if_changed(&path, &f.contents)?;
            written.push(path);
        }
        Ok(written)
    }

    fn index(&self, plan: &plan::Plan) -> String {
        let mut out =
            String::from("// @generated by mavstack-codegen. Do not edit: regenerate instead.\n");
        for unit in &plan.units {
            let file = unit
                .path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let messages = unit.dialect.messages.len();
            let _ = writeln!(
                out,
                "\n/// The `{}` dialect, from `{file}` ({messages} messages with its includes).",
                unit.module
            );
            if self.options.feature_gates {
                let _ = writeln!(out, "#[cfg(feature = {:?})]", unit.module);
            }
            out.push_str(
                "#[allow(unused_imports, rustdoc::bare_urls, rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags, \
                 unused_qualifications)]\n",
            );
            match self.layout {
                Layout::Files => {
                    let _ = writeln!(out, "pub mod {};", unit.module);
                }
                Layout::OutDir => {
                    let _ = writeln!(
                        out,
                        "pub mod {m} {{\n    include!(concat!(env!(\"OUT_DIR\"), \"/{m}.rs\"));\n}}",
                        m = unit.module
                    );
                }
            }
        }
        if self.dispatch {
            self.dispatch_by_name(plan, &mut out);
        }
        out
    }

    /// The `DialectVisitor` trait and `with_dialect`, appended to the index.
    fn dispatch_by_name(&self, plan: &plan::Plan, out: &mut String) {
        let core = self.options.core_path_str();
        let _ = write!(
            out,
            "
/// A computation over one dialect's messages, for [`with_dialect`]: the dialect is chosen
/// by name at run time, the computation compiled for each.
pub trait DialectVisitor {{
    /// What the computation gives.
    type Output;
    /// Runs the computation with `M`, the chosen dialect's `MavMessage`.
    fn visit<M: {core}::MessageSet>(self) -> Self::Output;
}}

/// Runs `visitor` with the `MavMessage` of the dialect called `name` (its module's name,
/// in any case), or gives `None` when no such dialect is compiled in.
pub fn with_dialect<V: DialectVisitor>(name: &str, visitor: V) -> Option<V::Output> {{
"
        );
        for unit in &plan.units {
            if self.options.feature_gates {
                let _ = writeln!(out, "    #[cfg(feature = {:?})]", unit.module);
            }
            let _ = writeln!(
                out,
                "    if name.eq_ignore_ascii_case({m:?}) {{\n        return Some(visitor.visit::<{m}::MavMessage>());\n    }}",
                m = unit.module
            );
        }
        if self.options.feature_gates {
            // Without any dialect's feature, nothing above uses them.
            out.push_str("    let _ = (name, visitor);\n");
        }
        out.push_str("    None\n}\n");
    }
}

fn write_if_changed(path: &Path, contents: &str) -> Result<(), Error> {
    if std::fs::read_to_string(path).is_ok_and(|old| old == contents) {
        return Ok(());
    }
    std::fs::write(path, contents).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn emit_unit(unit: &plan::Unit, plan: &plan::Plan, opts: &Options) -> TokenStream {
    let core = opts.core_path();
    // Re-export only the includes no other include already brings (all.xml includes both
    // ardupilotmega.xml and common.xml; ardupilotmega brings common).
    let reached_by_other = |m: &String| {
        unit.includes.iter().filter(|o| *o != m).any(|o| {
            plan.units.iter().find(|u| u.module == *o).is_some_and(|u| {
                u.dialect
                    .files
                    .iter()
                    .any(|f| plan.module_of(&f.path) == Some(m.as_str()))
            })
        })
    };
    let reexports = unit
        .includes
        .iter()
        .filter(|m| !reached_by_other(m))
        .map(|m| {
            let m = names::ident(m);
            quote!(pub use super::#m::*;)
        });
    let own: Vec<_> = unit.own_messages().collect();
    let payload_use = if own.is_empty() {
        TokenStream::new()
    } else {
        quote!(use #core::payload::{get, put};)
    };
    let enums = plan
        .enums
        .values()
        .filter(|e| e.owner == unit.module)
        .map(|e| emit_enum::emit(e, opts));
    let messages = own.iter().map(|m| emit_message::emit(m, unit, plan, opts));
    // Where two enum types share a name (see `plan::EnumKey`), glob re-exports would make the
    // name ambiguous: name the one this dialect uses explicitly.
    let explicit = unit.dialect.enums.iter().filter_map(|e| {
        let owner = unit.enum_owner(&e.name)?;
        let shared = plan.enums.keys().filter(|(n, _)| *n == e.name).count() > 1;
        (shared && owner != unit.module).then(|| {
            let (m, t) = (names::ident(&owner), names::type_name(&e.name));
            quote!(pub use super::#m::#t;)
        })
    });
    let set = emit_set::emit(unit, plan, opts);
    quote! {
        #(#reexports)*
        #(#explicit)*
        #payload_use

        #(#enums)*
        #(#messages)*
        #set
    }
}
