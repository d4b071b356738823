//! The global view the generator works from: every definition file of the requested dialects
//! as one module ("unit"), and for every enum the one module that owns its type.
//!
//! A message is generated once, in the module of the file that defines it. An enum is
//! generated once, in the module of the file that first declares it; files that extend it
//! (as `ardupilotmega.xml` extends `MAV_CMD` of `common.xml`) add their entries to that same
//! type, behind their dialect's feature when feature gates are on. So `common::MavCmd` and
//! the `MavCmd` seen from `ardupilotmega` are one type, and messages of `common` work
//! unchanged in every dialect that includes it.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use mavstack_xml::{Dialect, Entry, Enum, FileSystem, Loader, Message, PrimitiveType};

use crate::Error;
use crate::names::module_name;

/// One definition file and what is generated into its module.
#[derive(Debug)]
pub(crate) struct Unit {
    /// The module name (and cargo feature name, when gated).
    pub(crate) module: String,
    /// The file.
    pub(crate) path: PathBuf,
    /// Modules of the files it includes directly.
    pub(crate) includes: Vec<String>,
    /// The dialect with this file as its root (its whole include closure).
    pub(crate) dialect: Dialect,
}

impl Unit {
    /// The module that owns the type of enum `name` as this file sees it.
    pub(crate) fn enum_owner(&self, name: &str) -> Option<String> {
        let e = self.dialect.enum_by_name(name)?;
        Some(module_name(&mavstack_xml::model::file_stem(&e.file)))
    }

    /// Messages this file defines itself.
    pub(crate) fn own_messages(&self) -> impl Iterator<Item = &Message> {
        self.dialect.messages.iter().filter(|m| m.file == self.path)
    }
}

/// An enum type: (XML name, owning module). One XML enum is one type, except when files
/// that do not include each other declare it (`loweheiser.xml` extends `MAV_CMD` without
/// including `common.xml`): then each such file owns a type of its own.
pub(crate) type EnumKey = (String, String);

/// One enum type and everything that contributes to it.
#[derive(Debug)]
pub(crate) struct EnumPlan {
    /// The first declaration (name, description, flags).
    pub(crate) def: Enum,
    /// The module that owns the type.
    pub(crate) owner: String,
    /// Every entry, with the modules whose files contribute it.
    pub(crate) entries: Vec<(Entry, Vec<String>)>,
    /// The unsigned integer the type wraps: wide enough for every value and every field.
    pub(crate) repr: PrimitiveType,
}

/// Units in dependency order (included files first) and enums by name.
#[derive(Debug)]
pub(crate) struct Plan {
    pub(crate) units: Vec<Unit>,
    pub(crate) enums: BTreeMap<EnumKey, EnumPlan>,
}

impl Plan {
    /// The module of a file path.
    pub(crate) fn module_of(&self, path: &Path) -> Option<&str> {
        self.units
            .iter()
            .find(|u| u.path == path)
            .map(|u| u.module.as_str())
    }
}

fn unsigned_of_size(size: usize) -> PrimitiveType {
    match size {
        0 | 1 => PrimitiveType::U8,
        2 => PrimitiveType::U16,
        3 | 4 => PrimitiveType::U32,
        _ => PrimitiveType::U64,
    }
}

fn value_size(v: u64) -> usize {
    match v {
        0..=0xFF => 1,
        0x100..=0xFFFF => 2,
        0x1_0000..=0xFFFF_FFFF => 4,
        _ => 8,
    }
}

/// Loads every root and every file they include, and assigns enum ownership.
pub(crate) fn build(roots: &[PathBuf], supplements: bool) -> Result<Plan, Error> {
    let mut loader = Loader::filesystem();
    if !supplements {
        loader.without_supplements();
    }
    build_with(&mut loader, roots)
}

fn build_with(loader: &mut Loader<FileSystem>, roots: &[PathBuf]) -> Result<Plan, Error> {
    // Every file reached, in dependency order.
    let mut files: Vec<PathBuf> = Vec::new();
    for root in roots {
        let dialect = loader.load(root)?;
        for f in &dialect.files {
            if !files.contains(&f.path) {
                files.push(f.path.clone());
            }
        }
    }
    let mut modules: HashMap<PathBuf, String> = HashMap::new();
    for path in &files {
        let module = module_name(&mavstack_xml::model::file_stem(path));
        if let Some((other, _)) = modules.iter().find(|(_, m)| **m == module) {
            return Err(Error::Conflict(format!(
                "{} and {} would both become module `{module}`",
                other.display(),
                path.display()
            )));
        }
        modules.insert(path.clone(), module);
    }
    let mut units = Vec::new();
    for path in &files {
        let dialect = loader.load(path)?;
        let includes = dialect
            .root()
            .includes
            .iter()
            .filter_map(|p| modules.get(p).cloned())
            .collect();
        units.push(Unit {
            module: modules[path].clone(),
            path: path.clone(),
            includes,
            dialect,
        });
    }
    let enums = plan_enums(&units)?;
    let plan = Plan { units, enums };
    check_field_names(&plan)?;
    Ok(plan)
}

fn plan_enums(units: &[Unit]) -> Result<BTreeMap<EnumKey, EnumPlan>, Error> {
    let module_of = |path: &Path| {
        units
            .iter()
            .find(|u| u.path == path)
            .map(|u| u.module.clone())
            .unwrap_or_default()
    };
    let mut plans: BTreeMap<EnumKey, EnumPlan> = BTreeMap::new();
    for unit in units {
        for e in &unit.dialect.enums {
            let owner = module_of(&e.file);
            let key = (e.name.clone(), owner.clone());
            let plan = plans.entry(key).or_insert_with(|| EnumPlan {
                def: e.clone(),
                owner,
                entries: Vec::new(),
                repr: PrimitiveType::U8,
            });
            plan.def.bitmask |= e.bitmask;
            for entry in &e.entries {
                let contributor = module_of(&entry.file);
                match plan.entries.iter_mut().find(|(x, _)| x.name == entry.name) {
                    Some((x, _)) if x.value != entry.value => {
                        return Err(Error::Conflict(format!(
                            "enum {}: entry {} is {} at {} but {} at {}",
                            e.name, entry.name, x.value, x.location, entry.value, entry.location
                        )));
                    }
                    Some((_, by)) => {
                        if !by.contains(&contributor) {
                            by.push(contributor);
                        }
                    }
                    None => plan.entries.push((entry.clone(), vec![contributor])),
                }
            }
        }
    }
    for ((name, owner), plan) in &mut plans {
        let mut size = plan
            .entries
            .iter()
            .map(|(e, _)| value_size(e.value))
            .max()
            .unwrap_or(1);
        for unit in units {
            for m in unit.own_messages() {
                for f in &m.fields {
                    if f.enum_name.as_ref() == Some(name)
                        && f.ty.array_len.is_none()
                        && unit.enum_owner(name).as_deref() == Some(owner.as_str())
                    {
                        size = size.max(f.ty.primitive.size());
                    }
                }
            }
        }
        plan.repr = unsigned_of_size(size);
    }
    Ok(plans)
}

/// Rejects messages whose field names collide once converted to Rust (`fooBar` and
/// `foo_bar`).
pub(crate) fn check_field_names(plan: &Plan) -> Result<(), Error> {
    for unit in &plan.units {
        for m in unit.own_messages() {
            let mut seen: Vec<String> = Vec::new();
            for f in &m.fields {
                let ident = crate::names::field_ident(&f.name).to_string();
                if seen.contains(&ident) {
                    return Err(Error::Conflict(format!(
                        "{}: message {}: two fields become `{ident}` in Rust",
                        f.location, m.name
                    )));
                }
                seen.push(ident);
            }
        }
    }
    Ok(())
}
