//! Loading a dialect: a root file and its include closure, merged and validated.
//!
//! Includes are resolved relative to the including file. Files are read through a
//! [`Source`]: the file system, or the definitions built into this crate ([`Builtin`]).
//!
//! ## Supplements
//! A supplement is a definition file merged into another file of a given name whenever the
//! dialect does not define the supplement's messages itself. The loaders made by
//! [`Loader::builtin`] and [`Loader::filesystem`] register three, all merged into
//! `common.xml`, so `common` and every dialect that includes it have their messages:
//! mavstack's `extras/protocol_version.xml` (PROTOCOL_VERSION, id 300, dropped from the
//! newest official `common.xml`: the version handshake's reply) and `extras/events.xml` (the
//! events protocol, ids 410–413, and COMPONENT_METADATA, 397, which the official
//! `common.xml` mavstack vendors lacks: PX4 says why it refuses a command in EVENT messages),
//! and `extras/standard_modes.xml` (AVAILABLE_MODES, CURRENT_MODE, AVAILABLE_MODES_MONITOR,
//! ids 435–437, only in the vendored `development.xml`, while the flight stacks send them
//! with the common set: how a vehicle lists its modes).

use std::collections::{HashMap, HashSet};
use std::path::{Component, Path, PathBuf};
use std::sync::Arc;

use crate::builtin;
use crate::error::{Error, ErrorKind, Location};
use crate::layout;
use crate::model::{Dialect, Enum, FileInfo, Message};
use crate::xml::{self, FileDecls};

/// Where definition files come from.
pub trait Source {
    /// The text of the file at `path`.
    ///
    /// # Errors
    /// Any I/O error; the loader reports it with the include that named the file.
    fn read(&self, path: &Path) -> std::io::Result<String>;
}

/// Reads definition files from the file system.
#[derive(Clone, Copy, Debug, Default)]
pub struct FileSystem;

impl Source for FileSystem {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        std::fs::read_to_string(path)
    }
}

/// The definitions vendored into this crate, by their path under `definitions/` (for example
/// `common.xml` or `extras/protocol_version.xml`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Builtin;

impl Source for Builtin {
    fn read(&self, path: &Path) -> std::io::Result<String> {
        let key = path.to_string_lossy();
        builtin::file(&key).map(str::to_owned).ok_or_else(|| {
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no built-in definition file of that name",
            )
        })
    }
}

/// A file merged into every file called `target` of a dialect that lacks its messages.
#[derive(Clone, Debug)]
struct Supplement {
    target: String,
    decls: Arc<FileDecls>,
}

/// Loads dialects through a [`Source`], caching parsed files across loads.
///
/// ```
/// use mavstack_xml::Loader;
/// let common = Loader::builtin().load("common.xml")?;
/// let heartbeat = common.message(0).expect("common defines HEARTBEAT");
/// assert_eq!((heartbeat.name.as_str(), heartbeat.crc_extra), ("HEARTBEAT", 50));
/// assert_eq!(common.message(300).map(|m| m.crc_extra), Some(217));
/// # Ok::<(), mavstack_xml::Error>(())
/// ```
#[derive(Debug)]
pub struct Loader<S> {
    source: S,
    supplements: Vec<Supplement>,
    cache: HashMap<PathBuf, Arc<FileDecls>>,
}

/// The path of mavstack's own PROTOCOL_VERSION definition among the built-in files.
pub const PROTOCOL_VERSION_SUPPLEMENT: &str = "extras/protocol_version.xml";

/// The path of mavstack's own definition of the events protocol (EVENT and its companions,
/// COMPONENT_METADATA) among the built-in files.
pub const EVENTS_SUPPLEMENT: &str = "extras/events.xml";

/// The path of mavstack's own definition of the standard modes protocol's messages
/// (AVAILABLE_MODES, CURRENT_MODE, AVAILABLE_MODES_MONITOR) among the built-in files.
pub const STANDARD_MODES_SUPPLEMENT: &str = "extras/standard_modes.xml";

impl Loader<Builtin> {
    /// A loader over the built-in definitions, with the PROTOCOL_VERSION, events and
    /// standard modes supplements.
    #[must_use]
    pub fn builtin() -> Self {
        Self::new(Builtin).with_standard_supplements()
    }
}

impl Loader<FileSystem> {
    /// A loader over the file system, with the PROTOCOL_VERSION, events and standard modes
    /// supplements.
    #[must_use]
    pub fn filesystem() -> Self {
        Self::new(FileSystem).with_standard_supplements()
    }
}

impl<S: Source> Loader<S> {
    /// A loader over `source` with no supplements.
    pub fn new(source: S) -> Self {
        Self {
            source,
            supplements: Vec::new(),
            cache: HashMap::new(),
        }
    }

    fn with_standard_supplements(mut self) -> Self {
        for name in [
            PROTOCOL_VERSION_SUPPLEMENT,
            EVENTS_SUPPLEMENT,
            STANDARD_MODES_SUPPLEMENT,
        ] {
            let text = builtin::file(name).unwrap_or_default();
            // The built-in supplements are ours and covered by tests; a parse failure here
            // would be a bug in this crate, so it is dropped rather than failing every load.
            if let Ok(decls) = xml::parse_file(Path::new(name), text) {
                self.supplements.push(Supplement {
                    target: "common.xml".into(),
                    decls: Arc::new(decls),
                });
            }
        }
        self
    }

    /// Merges the definitions in `text` (named `path` in errors) into every file whose name is
    /// `target` (e.g. `common.xml`), unless the dialect defines one of its messages already.
    ///
    /// # Errors
    /// The supplement itself does not parse.
    pub fn supplement(
        &mut self,
        target: &str,
        path: impl Into<PathBuf>,
        text: &str,
    ) -> Result<&mut Self, Error> {
        let path = path.into();
        let decls = xml::parse_file(&path, text)?;
        self.supplements.push(Supplement {
            target: target.to_owned(),
            decls: Arc::new(decls),
        });
        Ok(self)
    }

    /// Removes every supplement, so that only the files themselves are read.
    pub fn without_supplements(&mut self) -> &mut Self {
        self.supplements.clear();
        self
    }

    /// Loads the dialect whose root file is `root`.
    ///
    /// # Errors
    /// The first problem found, positioned at its file, line and column.
    pub fn load(&mut self, root: impl AsRef<Path>) -> Result<Dialect, Error> {
        let root = normalize(root.as_ref());
        let mut order = Vec::new();
        let mut stack = Vec::new();
        self.visit(&root, None, &mut stack, &mut order)?;
        self.merge(&root, &order)
    }

    fn read_decls(
        &mut self,
        path: &Path,
        included_at: Option<&(String, Location)>,
    ) -> Result<Arc<FileDecls>, Error> {
        if let Some(d) = self.cache.get(path) {
            return Ok(Arc::clone(d));
        }
        let text = self.source.read(path).map_err(|e| match included_at {
            Some((name, loc)) => Error::new(
                loc.clone(),
                ErrorKind::MissingInclude {
                    include: name.clone(),
                    path: path.to_path_buf(),
                    reason: e.to_string(),
                },
            ),
            None => Error::new(
                Location {
                    file: path.to_path_buf(),
                    line: 1,
                    column: 1,
                },
                ErrorKind::Read {
                    path: path.to_path_buf(),
                    reason: e.to_string(),
                },
            ),
        })?;
        let decls = Arc::new(xml::parse_file(path, &text)?);
        self.cache.insert(path.to_path_buf(), Arc::clone(&decls));
        Ok(decls)
    }

    /// Depth-first walk: every file after the files it includes.
    fn visit(
        &mut self,
        path: &Path,
        included_at: Option<&(String, Location)>,
        stack: &mut Vec<PathBuf>,
        order: &mut Vec<(PathBuf, Arc<FileDecls>)>,
    ) -> Result<(), Error> {
        if let Some(start) = stack.iter().position(|p| p == path) {
            let mut chain: Vec<String> = stack[start..]
                .iter()
                .map(|p| p.display().to_string())
                .collect();
            chain.push(path.display().to_string());
            let loc = included_at.map(|(_, l)| l.clone()).unwrap_or(Location {
                file: path.to_path_buf(),
                line: 1,
                column: 1,
            });
            return Err(Error::new(loc, ErrorKind::IncludeCycle { chain }));
        }
        if order.iter().any(|(p, _)| p == path) {
            return Ok(());
        }
        let decls = self.read_decls(path, included_at)?;
        stack.push(path.to_path_buf());
        let dir = path.parent().unwrap_or(Path::new(""));
        for include in &decls.includes {
            let child = normalize(&dir.join(&include.0));
            self.visit(&child, Some(include), stack, order)?;
        }
        stack.pop();
        order.push((path.to_path_buf(), decls));
        Ok(())
    }

    fn merge(&self, root: &Path, order: &[(PathBuf, Arc<FileDecls>)]) -> Result<Dialect, Error> {
        let defined_ids: HashSet<u32> = order
            .iter()
            .flat_map(|(_, d)| d.messages.iter().map(|m| m.id))
            .collect();
        let defined_names: HashSet<&str> = order
            .iter()
            .flat_map(|(_, d)| d.messages.iter().map(|m| m.name.as_str()))
            .collect();
        let mut merger = Merger::default();
        let mut files = Vec::new();
        for (path, decls) in order {
            merger.add(path, decls)?;
            let file_name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            for s in &self.supplements {
                // A message the dialect defines itself exactly as the supplement does (the
                // vendored development.xml's AVAILABLE_MODES) is no conflict: the
                // supplement's copy comes first and the file's own is taken as the same.
                let lacks_all = s.decls.messages.iter().all(|m| {
                    let defined =
                        defined_ids.contains(&m.id) || defined_names.contains(m.name.as_str());
                    !defined || identical_elsewhere(order, m)
                });
                if s.target == file_name && lacks_all {
                    // The supplement's items belong to the file they are merged into, so that
                    // generated code puts them beside that file's own; locations keep the
                    // supplement's path.
                    merger.add_supplement(path, &s.decls)?;
                }
            }
            let dir = path.parent().unwrap_or(Path::new(""));
            files.push(FileInfo {
                path: path.clone(),
                version: decls.version,
                dialect: decls.dialect,
                includes: decls
                    .includes
                    .iter()
                    .map(|(name, _)| normalize(&dir.join(name)))
                    .collect(),
            });
        }
        let version = files.iter().rev().find_map(|f| f.version);
        let Merger {
            mut messages,
            mut enums,
            enum_index,
            ..
        } = merger;
        for m in &messages {
            for f in &m.fields {
                if let Some(e) = f
                    .enum_name
                    .as_ref()
                    .filter(|e| !enum_index.contains_key(*e))
                {
                    return Err(Error::new(
                        f.location.clone(),
                        ErrorKind::UnknownEnum {
                            message: m.name.clone(),
                            field: f.name.clone(),
                            enum_name: e.clone(),
                        },
                    ));
                }
            }
        }
        messages.sort_by_key(|m| m.id);
        enums.sort_by(|a, b| a.name.cmp(&b.name));
        Ok(Dialect {
            name: crate::model::file_stem(root),
            files,
            version,
            messages,
            enums,
        })
    }
}

/// Whether every definition of `m`'s id or name in `order` is the same message as `m`
/// (name, id, wire layout and CRC_EXTRA).
fn identical_elsewhere(order: &[(PathBuf, Arc<FileDecls>)], m: &xml::MessageDecl) -> bool {
    let Ok(ours) = layout::layout(m.clone(), Path::new("")) else {
        return false;
    };
    order
        .iter()
        .flat_map(|(path, d)| d.messages.iter().map(move |x| (path, x)))
        .filter(|(_, x)| x.id == m.id || x.name == m.name)
        .all(|(path, x)| {
            layout::layout(x.clone(), path).is_ok_and(|theirs| same_message(&ours, &theirs))
        })
}

/// Whether two messages are the same on the wire.
fn same_message(a: &Message, b: &Message) -> bool {
    a.id == b.id
        && a.name == b.name
        && a.crc_extra == b.crc_extra
        && a.min_len == b.min_len
        && a.max_len == b.max_len
}

#[derive(Default)]
struct Merger {
    /// Ids of the messages a supplement added: the same message defined again by a file is
    /// taken as that one.
    supplied: HashSet<u32>,
    messages: Vec<Message>,
    enums: Vec<Enum>,
    by_id: HashMap<u32, usize>,
    by_name: HashMap<String, usize>,
    enum_index: HashMap<String, usize>,
}

impl Merger {
    /// Adds `decls` as declarations of the file `owner`.
    fn add(&mut self, owner: &Path, decls: &FileDecls) -> Result<(), Error> {
        for e in &decls.enums {
            self.add_enum(owner, e)?;
        }
        for m in &decls.messages {
            let message = layout::layout(m.clone(), owner)?;
            if let Some(&i) = self.by_id.get(&message.id) {
                let other = &self.messages[i];
                if self.supplied.contains(&message.id) && same_message(other, &message) {
                    continue;
                }
                return Err(Error::new(
                    message.location.clone(),
                    ErrorKind::DuplicateMessageId {
                        id: message.id,
                        name: message.name.clone(),
                        other: other.name.clone(),
                        other_location: other.location.clone(),
                    },
                ));
            }
            if let Some(&i) = self.by_name.get(&message.name) {
                let other = &self.messages[i];
                return Err(Error::new(
                    message.location.clone(),
                    ErrorKind::DuplicateMessageName {
                        name: message.name.clone(),
                        id: message.id,
                        other_id: other.id,
                        other_location: other.location.clone(),
                    },
                ));
            }
            self.by_id.insert(message.id, self.messages.len());
            self.by_name
                .insert(message.name.clone(), self.messages.len());
            self.messages.push(message);
        }
        Ok(())
    }

    /// Adds a supplement's `decls` as declarations of the file `owner`.
    fn add_supplement(&mut self, owner: &Path, decls: &FileDecls) -> Result<(), Error> {
        self.add(owner, decls)?;
        self.supplied.extend(decls.messages.iter().map(|m| m.id));
        Ok(())
    }

    fn add_enum(&mut self, owner: &Path, decl: &Enum) -> Result<(), Error> {
        let i = match self.enum_index.get(&decl.name) {
            Some(&i) => i,
            None => {
                // The first declaration: an empty enum that its entries are merged into, so
                // entries repeated within one file are checked like those across files.
                let mut e = decl.clone();
                e.file = owner.to_path_buf();
                e.entries.clear();
                self.enum_index.insert(e.name.clone(), self.enums.len());
                self.enums.push(e);
                self.enums.len() - 1
            }
        };
        let target = &mut self.enums[i];
        target.bitmask |= decl.bitmask;
        if target.description.is_empty() {
            target.description.clone_from(&decl.description);
        }
        for entry in &decl.entries {
            if let Some(existing) = target.entries.iter().find(|x| x.name == entry.name) {
                if existing.value != entry.value {
                    return Err(Error::new(
                        entry.location.clone(),
                        ErrorKind::ConflictingEntry {
                            enum_name: decl.name.clone(),
                            entry: entry.name.clone(),
                            value: entry.value,
                            other_value: existing.value,
                            other_location: existing.location.clone(),
                        },
                    ));
                }
                continue;
            }
            let mut entry = entry.clone();
            entry.file = owner.to_path_buf();
            target.entries.push(entry);
        }
        Ok(())
    }
}

/// Lexical normalisation: drops `.` components and folds `dir/..`, so that one file reached
/// through different spellings is one file.
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}
