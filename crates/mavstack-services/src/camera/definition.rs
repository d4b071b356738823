//! Camera definition files (the camera protocol's `cam_definition_uri`): the settings a
//! camera offers, their types, defaults, limits and options, and which options rule out
//! which settings or narrow their choices.
//!
//! ```text
//! <mavlinkcamera>
//!   <definition version="3"><model>M</model><vendor>V</vendor></definition>
//!   <parameters>
//!     <parameter name="CAM_MODE" type="uint32" default="1" control="0">
//!       <description>Camera Mode</description>
//!       <updates><update>CAM_ISO</update></updates>
//!       <options>
//!         <option name="Photo" value="0">
//!           <exclusions><exclude>CAM_VIDRES</exclude></exclusions>
//!           <parameterranges>
//!             <parameterrange parameter="CAM_ISO" condition="CAM_EXPMODE=1">
//!               <roption name="100" value="100"/>
//!             </parameterrange>
//!           </parameterranges>
//!         </option>
//!         ...
//! ```
//!
//! [`CameraDefinition::parse`] reads one. The file comes from the camera (over MAVFTP or
//! HTTP), so it is input from outside: the text is bounded ([`MAX_DEFINITION_LEN`], a node
//! count, [`MAX_SETTINGS`] settings of [`MAX_OPTIONS`] options), nothing in it can make the
//! parser panic, and every error names its line and column. Elements the format does not
//! have here (`localization`, vendor additions) are skipped; a reference to a setting the
//! file does not define (in an exclusion, an update or a range) is kept as a warning.

use alloc::collections::BTreeSet;
use alloc::format;
use alloc::string::{String, ToString};
use alloc::vec::Vec;
use core::fmt;

use super::value::{ExtType, ExtValue, NAME_LEN};

/// The longest definition file read (bytes).
pub const MAX_DEFINITION_LEN: usize = 512 * 1024;

/// The most XML nodes read (elements, text, comments).
const MAX_NODES: u32 = 100_000;

/// The most settings in a file.
pub const MAX_SETTINGS: usize = 512;

/// The most options of one setting (and of one range).
pub const MAX_OPTIONS: usize = 1024;

/// A camera's settings, as its definition file describes them.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraDefinition {
    /// The file's version (`<definition version>`), which CAMERA_INFORMATION repeats.
    pub version: u32,
    /// The camera's model.
    pub model: String,
    /// Its vendor.
    pub vendor: String,
    /// Its settings, in the file's order.
    pub settings: Vec<Setting>,
    /// References to settings the file does not define, with where they are.
    pub warnings: Vec<String>,
}

/// One setting (a `<parameter>`).
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// Its name (at most 16 bytes: PARAM_EXT_*'s `param_id`).
    pub name: String,
    /// Its type.
    pub ty: ExtType,
    /// Its value until set.
    pub default: ExtValue,
    /// What it is, for people.
    pub description: String,
    /// The values it takes, when it is a choice.
    pub options: Vec<SettingOption>,
    /// The least value, for a number without options.
    pub min: Option<ExtValue>,
    /// The most.
    pub max: Option<ExtValue>,
    /// The increment.
    pub step: Option<ExtValue>,
    /// Whether a ground station shows a control for it (`control`, default yes).
    pub control: bool,
    /// It cannot be set (`readonly`).
    pub read_only: bool,
    /// It cannot be read (`writeonly`: an action such as a zoom step).
    pub write_only: bool,
    /// The settings to read again after this one changes (`<updates>`).
    pub updates: Vec<String>,
}

/// One of a setting's options.
#[derive(Clone, Debug, PartialEq)]
pub struct SettingOption {
    /// Its name, for people.
    pub name: String,
    /// Its value.
    pub value: ExtValue,
    /// The settings that do not apply while this option is chosen.
    pub exclusions: Vec<String>,
    /// The settings whose choices this option narrows.
    pub ranges: Vec<OptionRange>,
}

/// The options a setting is narrowed to while another setting has a certain option
/// (`<parameterrange>`).
#[derive(Clone, Debug, PartialEq)]
pub struct OptionRange {
    /// The setting narrowed.
    pub parameter: String,
    /// Only while this holds (`NAME=VALUE`), when given.
    pub condition: Option<(String, String)>,
    /// The options left (name and value).
    pub options: Vec<(String, ExtValue)>,
}

/// What is wrong with a definition file.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum DefinitionErrorKind {
    /// Longer than [`MAX_DEFINITION_LEN`].
    TooLong(usize),
    /// Not text (invalid UTF-8).
    NotText,
    /// Not well-formed XML (the XML parser's words).
    Xml(String),
    /// The root element is not `<mavlinkcamera>`.
    NotACameraDefinition(String),
    /// A required element or attribute is missing.
    Missing(&'static str),
    /// A value that cannot be what it is for.
    Invalid {
        /// What it is (an attribute, with its setting).
        what: String,
        /// The value found.
        value: String,
    },
    /// Two settings with one name.
    Duplicate(String),
    /// More settings or options than read.
    TooMany(&'static str),
}

/// A definition file that cannot be read, and where (line and column, from 1).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DefinitionError {
    /// The line.
    pub line: u32,
    /// The column.
    pub column: u32,
    /// What is wrong.
    pub kind: DefinitionErrorKind,
}

impl fmt::Display for DefinitionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "camera definition, line {} column {}: ",
            self.line, self.column
        )?;
        match &self.kind {
            DefinitionErrorKind::TooLong(n) => {
                write!(f, "{n} bytes, more than the {MAX_DEFINITION_LEN} read")
            }
            DefinitionErrorKind::NotText => f.write_str("not UTF-8 text"),
            DefinitionErrorKind::Xml(e) => write!(f, "not well-formed XML: {e}"),
            DefinitionErrorKind::NotACameraDefinition(root) => {
                write!(f, "the root element is <{root}>, not <mavlinkcamera>")
            }
            DefinitionErrorKind::Missing(what) => write!(f, "no {what}"),
            DefinitionErrorKind::Invalid { what, value } => {
                write!(f, "{what} {value:?} is not valid")
            }
            DefinitionErrorKind::Duplicate(name) => write!(f, "parameter {name} is defined twice"),
            DefinitionErrorKind::TooMany(what) => write!(f, "too many {what}"),
        }
    }
}

impl core::error::Error for DefinitionError {}

/// Why a setting's value is refused ([`CameraDefinition::check`]).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SettingError {
    /// The camera has no such setting.
    #[error("the camera has no setting {0}")]
    Unknown(String),
    /// The setting cannot be set.
    #[error("setting {0} is read-only")]
    ReadOnly(String),
    /// The value is not of the setting's type (or not a number for it).
    #[error("{value:?} is not a {ty} value for {name}")]
    WrongType {
        /// The setting.
        name: String,
        /// Its type's name.
        ty: &'static str,
        /// The value given.
        value: String,
    },
    /// Not one of the setting's options (those left by the other settings' choices).
    #[error("{value} is not one of {name}'s options ({allowed})")]
    NotAnOption {
        /// The setting.
        name: String,
        /// The value given.
        value: String,
        /// The options, as `name=value` pairs.
        allowed: String,
    },
    /// Outside the setting's limits.
    #[error("{value} is outside {name}'s range ({min} to {max})")]
    OutOfRange {
        /// The setting.
        name: String,
        /// The value given.
        value: String,
        /// The least.
        min: String,
        /// The most.
        max: String,
    },
    /// Another setting's choice rules this setting out.
    #[error("{name} does not apply while {by} is {option}")]
    Excluded {
        /// The setting.
        name: String,
        /// The setting whose choice excludes it.
        by: String,
        /// That choice's name.
        option: String,
    },
}

/// An error at byte `pos` of `doc`'s text.
fn error_at(
    doc: &roxmltree::Document<'_>,
    pos: usize,
    kind: DefinitionErrorKind,
) -> DefinitionError {
    let p = doc.text_pos_at(pos);
    DefinitionError {
        line: p.row,
        column: p.col,
        kind,
    }
}

/// A reader of one document, with its warnings.
struct Reader<'a, 'input> {
    doc: &'a roxmltree::Document<'input>,
    warnings: Vec<String>,
}

type Node<'a, 'input> = roxmltree::Node<'a, 'input>;

impl<'a, 'input> Reader<'a, 'input> {
    fn err(&self, node: Node<'_, '_>, kind: DefinitionErrorKind) -> DefinitionError {
        error_at(self.doc, node.range().start, kind)
    }

    fn children<'n>(
        node: Node<'n, 'input>,
        tag: &'static str,
    ) -> impl Iterator<Item = Node<'n, 'input>> {
        node.children()
            .filter(move |c| c.is_element() && c.tag_name().name() == tag)
    }

    fn child<'n>(node: Node<'n, 'input>, tag: &'static str) -> Option<Node<'n, 'input>> {
        Self::children(node, tag).next()
    }

    fn text(node: Node<'_, '_>) -> String {
        node.children()
            .filter_map(|c| c.text())
            .collect::<String>()
            .trim()
            .to_string()
    }

    fn invalid(&self, node: Node<'_, '_>, what: String, value: &str) -> DefinitionError {
        self.err(
            node,
            DefinitionErrorKind::Invalid {
                what,
                value: value.chars().take(64).collect(),
            },
        )
    }

    fn value(
        &self,
        node: Node<'_, '_>,
        ty: ExtType,
        what: String,
        text: &str,
    ) -> Result<ExtValue, DefinitionError> {
        ExtValue::parse(ty, text).ok_or_else(|| self.invalid(node, what, text))
    }

    fn flag(
        &self,
        node: Node<'_, '_>,
        attr: &'static str,
        default: bool,
        setting: &str,
    ) -> Result<bool, DefinitionError> {
        match node.attribute(attr) {
            None => Ok(default),
            Some("1" | "true") => Ok(true),
            Some("0" | "false") => Ok(false),
            Some(v) => Err(self.invalid(node, format!("{setting}'s {attr}"), v)),
        }
    }

    fn names<'n>(
        node: Node<'n, 'input>,
        list: &'static str,
        item: &'static str,
    ) -> Vec<(String, usize)> {
        Self::children(node, list)
            .flat_map(|l| Self::children(l, item))
            .map(|n| (Self::text(n), n.range().start))
            .collect()
    }

    fn option_list(
        &self,
        node: Node<'a, 'input>,
        tag: &'static str,
        ty: ExtType,
        setting: &str,
    ) -> Result<Vec<(String, ExtValue, Node<'a, 'input>)>, DefinitionError> {
        let mut out = Vec::new();
        for o in node
            .children()
            .filter(|c| c.is_element() && c.tag_name().name() == tag)
        {
            if out.len() == MAX_OPTIONS {
                return Err(self.err(o, DefinitionErrorKind::TooMany("options")));
            }
            let name = o.attribute("name").unwrap_or_default().to_string();
            let text = o
                .attribute("value")
                .ok_or_else(|| self.err(o, DefinitionErrorKind::Missing("option value")))?;
            let value = self.value(o, ty, format!("{setting}'s option {name:?} value"), text)?;
            out.push((name, value, o));
        }
        Ok(out)
    }

    fn setting(
        &mut self,
        p: Node<'a, 'input>,
    ) -> Result<(Setting, Vec<(String, usize)>), DefinitionError> {
        let name = p
            .attribute("name")
            .ok_or_else(|| self.err(p, DefinitionErrorKind::Missing("parameter name")))?;
        if name.is_empty() || name.len() > NAME_LEN {
            return Err(self.invalid(p, "parameter name (1 to 16 bytes)".to_string(), name));
        }
        let ty_name = p
            .attribute("type")
            .ok_or_else(|| self.err(p, DefinitionErrorKind::Missing("parameter type")))?;
        let ty = ExtType::from_definition(ty_name)
            .ok_or_else(|| self.invalid(p, format!("{name}'s type"), ty_name))?;
        let default_text = p
            .attribute("default")
            .ok_or_else(|| self.err(p, DefinitionErrorKind::Missing("parameter default")))?;
        let default = self.value(p, ty, format!("{name}'s default"), default_text)?;
        let bound = |attr: &'static str| -> Result<Option<ExtValue>, DefinitionError> {
            p.attribute(attr)
                .map(|t| self.value(p, ty, format!("{name}'s {attr}"), t))
                .transpose()
        };
        let (min, max, step) = (bound("min")?, bound("max")?, bound("step")?);
        let mut options = Vec::new();
        let mut references = Vec::new();
        for list in Self::children(p, "options") {
            for (opt_name, value, o) in self.option_list(list, "option", ty, name)? {
                if options.len() == MAX_OPTIONS {
                    return Err(self.err(o, DefinitionErrorKind::TooMany("options")));
                }
                let exclusions = Self::names(o, "exclusions", "exclude");
                let mut ranges = Vec::new();
                for r in Self::children(o, "parameterranges")
                    .flat_map(|l| Self::children(l, "parameterrange"))
                {
                    let parameter = r.attribute("parameter").ok_or_else(|| {
                        self.err(r, DefinitionErrorKind::Missing("parameterrange parameter"))
                    })?;
                    let condition = r.attribute("condition").map(|c| match c.split_once('=') {
                        Some((k, v)) => (k.trim().to_string(), v.trim().to_string()),
                        None => (c.trim().to_string(), String::new()),
                    });
                    references.push((parameter.to_string(), r.range().start));
                    // The range's options are of the setting it narrows, known once every
                    // setting is read: kept as text for now.
                    let mut texts = Vec::new();
                    for ro in Self::children(r, "roption") {
                        if texts.len() == MAX_OPTIONS {
                            return Err(self.err(ro, DefinitionErrorKind::TooMany("options")));
                        }
                        let v = ro.attribute("value").ok_or_else(|| {
                            self.err(ro, DefinitionErrorKind::Missing("roption value"))
                        })?;
                        texts.push((
                            ro.attribute("name").unwrap_or_default().to_string(),
                            ExtValue::Custom(v.chars().take(128).collect()),
                            ro.range().start,
                        ));
                    }
                    ranges.push((parameter.to_string(), condition, texts));
                }
                references.extend(exclusions.iter().cloned());
                options.push(SettingOption {
                    name: opt_name,
                    value,
                    exclusions: exclusions.into_iter().map(|(n, _)| n).collect(),
                    ranges: ranges
                        .into_iter()
                        .map(|(parameter, condition, texts)| OptionRange {
                            parameter,
                            condition,
                            options: texts.into_iter().map(|(n, v, _)| (n, v)).collect(),
                        })
                        .collect(),
                });
            }
        }
        let updates = Self::names(p, "updates", "update");
        references.extend(updates.iter().cloned());
        let setting = Setting {
            name: name.to_string(),
            ty,
            default,
            description: Self::child(p, "description")
                .map(Self::text)
                .unwrap_or_default(),
            options,
            min,
            max,
            step,
            control: self.flag(p, "control", true, name)?,
            read_only: self.flag(p, "readonly", false, name)?,
            write_only: self.flag(p, "writeonly", false, name)?,
            updates: updates.into_iter().map(|(n, _)| n).collect(),
        };
        Ok((setting, references))
    }
}

impl CameraDefinition {
    /// Reads a definition file.
    ///
    /// # Errors
    /// [`DefinitionError`] with the line and column of what is wrong: not UTF-8, too long,
    /// not XML, not `<mavlinkcamera>`, a setting without a name, type or default, a type it
    /// does not know, a value (default, limit, option) that is not of the setting's type, a
    /// name used twice, more than [`MAX_SETTINGS`] settings.
    pub fn parse(bytes: &[u8]) -> Result<Self, DefinitionError> {
        let at_start = |kind| DefinitionError {
            line: 1,
            column: 1,
            kind,
        };
        if bytes.len() > MAX_DEFINITION_LEN {
            return Err(at_start(DefinitionErrorKind::TooLong(bytes.len())));
        }
        let text =
            core::str::from_utf8(bytes).map_err(|_| at_start(DefinitionErrorKind::NotText))?;
        let options = roxmltree::ParsingOptions {
            allow_dtd: false,
            nodes_limit: MAX_NODES,
        };
        let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| {
            let p = e.pos();
            DefinitionError {
                line: p.row,
                column: p.col,
                kind: DefinitionErrorKind::Xml(e.to_string()),
            }
        })?;
        let mut reader = Reader {
            doc: &doc,
            warnings: Vec::new(),
        };
        let root = doc.root_element();
        if root.tag_name().name() != "mavlinkcamera" {
            let name = root.tag_name().name().chars().take(64).collect();
            return Err(reader.err(root, DefinitionErrorKind::NotACameraDefinition(name)));
        }
        let definition = Reader::child(root, "definition")
            .ok_or_else(|| reader.err(root, DefinitionErrorKind::Missing("<definition>")))?;
        let version = match definition.attribute("version") {
            Some(v) => v
                .trim()
                .parse::<u32>()
                .map_err(|_| reader.invalid(definition, "definition version".to_string(), v))?,
            None => 0,
        };
        let model = Reader::child(definition, "model")
            .map(Reader::text)
            .unwrap_or_default();
        let vendor = Reader::child(definition, "vendor")
            .map(Reader::text)
            .unwrap_or_default();
        let mut settings: Vec<Setting> = Vec::new();
        let mut references = Vec::new();
        let mut ranges_at = Vec::new();
        for p in Reader::children(root, "parameters").flat_map(|l| Reader::children(l, "parameter"))
        {
            if settings.len() == MAX_SETTINGS {
                return Err(reader.err(p, DefinitionErrorKind::TooMany("parameters")));
            }
            let (setting, refs) = reader.setting(p)?;
            if settings.iter().any(|s| s.name == setting.name) {
                return Err(reader.err(p, DefinitionErrorKind::Duplicate(setting.name)));
            }
            ranges_at.push(p.range().start);
            settings.push(setting);
            references.extend(refs);
        }
        // Range options as values of the setting they narrow.
        for i in 0..settings.len() {
            for o in 0..settings[i].options.len() {
                for r in 0..settings[i].options[o].ranges.len() {
                    let parameter = settings[i].options[o].ranges[r].parameter.clone();
                    let Some(ty) = settings.iter().find(|s| s.name == parameter).map(|s| s.ty)
                    else {
                        continue;
                    };
                    let range = &mut settings[i].options[o].ranges[r];
                    for (name, v) in &mut range.options {
                        let text = v.to_string();
                        *v = ExtValue::parse(ty, &text).ok_or_else(|| {
                            let what = format!("{parameter}'s range option {name:?} value");
                            error_at(
                                &doc,
                                ranges_at[i],
                                DefinitionErrorKind::Invalid {
                                    what,
                                    value: text.clone(),
                                },
                            )
                        })?;
                    }
                }
            }
        }
        for (name, pos) in references {
            if !settings.iter().any(|s| s.name == name) {
                let p = doc.text_pos_at(pos);
                reader.warnings.push(format!(
                    "line {} column {}: no parameter {name:?}",
                    p.row, p.col
                ));
            }
        }
        Ok(Self {
            version,
            model,
            vendor,
            settings,
            warnings: reader.warnings,
        })
    }

    /// The setting called `name`.
    #[must_use]
    pub fn setting(&self, name: &str) -> Option<&Setting> {
        self.settings.iter().find(|s| s.name == name)
    }

    /// The settings that do not apply with the values `current` gives (each setting's
    /// chosen option's exclusions).
    #[must_use]
    pub fn excluded(&self, current: &dyn Fn(&str) -> Option<ExtValue>) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        for s in &self.settings {
            let value = current(&s.name).unwrap_or_else(|| s.default.clone());
            if let Some(o) = s.options.iter().find(|o| o.value == value) {
                out.extend(o.exclusions.iter().cloned());
            }
        }
        out
    }

    /// The options `name` has with the values `current` gives: its own, or those another
    /// setting's chosen option narrows them to (where that range's condition holds).
    #[must_use]
    pub fn options_of(
        &self,
        name: &str,
        current: &dyn Fn(&str) -> Option<ExtValue>,
    ) -> Vec<(String, ExtValue)> {
        let Some(setting) = self.setting(name) else {
            return Vec::new();
        };
        let value_of = |n: &str| current(n).or_else(|| self.setting(n).map(|s| s.default.clone()));
        for s in &self.settings {
            let Some(v) = value_of(&s.name) else { continue };
            let Some(o) = s.options.iter().find(|o| o.value == v) else {
                continue;
            };
            for r in o.ranges.iter().filter(|r| r.parameter == name) {
                let holds = r.condition.as_ref().is_none_or(|(k, want)| {
                    value_of(k).is_some_and(|v| {
                        v.to_string() == *want || {
                            self.setting(k)
                                .and_then(|ks| ExtValue::parse(ks.ty, want))
                                .is_some_and(|w| w == v)
                        }
                    })
                });
                if holds {
                    return r.options.clone();
                }
            }
        }
        setting
            .options
            .iter()
            .map(|o| (o.name.clone(), o.value.clone()))
            .collect()
    }

    /// `text` as a value of setting `name`: one of its options by name (any case), or a
    /// value of its type.
    ///
    /// # Errors
    /// [`SettingError::Unknown`], [`SettingError::WrongType`].
    pub fn value_of(&self, name: &str, text: &str) -> Result<ExtValue, SettingError> {
        let s = self
            .setting(name)
            .ok_or_else(|| SettingError::Unknown(name.to_string()))?;
        if let Some(o) = s
            .options
            .iter()
            .find(|o| o.name.eq_ignore_ascii_case(text.trim()))
        {
            return Ok(o.value.clone());
        }
        ExtValue::parse(s.ty, text).ok_or_else(|| SettingError::WrongType {
            name: name.to_string(),
            ty: s.ty.name(),
            value: text.to_string(),
        })
    }

    /// Whether `value` may be given to setting `name` with the values `current` gives: a
    /// setting it has, not read-only, not excluded by another's choice, of its type, one
    /// of its options (as narrowed), within its limits.
    ///
    /// # Errors
    /// The [`SettingError`] that says why not.
    pub fn check(
        &self,
        name: &str,
        value: &ExtValue,
        current: &dyn Fn(&str) -> Option<ExtValue>,
    ) -> Result<(), SettingError> {
        let s = self
            .setting(name)
            .ok_or_else(|| SettingError::Unknown(name.to_string()))?;
        if s.read_only {
            return Err(SettingError::ReadOnly(name.to_string()));
        }
        if value.ty() != s.ty {
            return Err(SettingError::WrongType {
                name: name.to_string(),
                ty: s.ty.name(),
                value: value.to_string(),
            });
        }
        for other in &self.settings {
            let v = current(&other.name).unwrap_or_else(|| other.default.clone());
            if let Some(o) = other.options.iter().find(|o| o.value == v)
                && o.exclusions.iter().any(|e| e == name)
            {
                return Err(SettingError::Excluded {
                    name: name.to_string(),
                    by: other.name.clone(),
                    option: o.name.clone(),
                });
            }
        }
        let options = self.options_of(name, current);
        if !options.is_empty() && !options.iter().any(|(_, v)| v == value) {
            let allowed = options
                .iter()
                .map(|(n, v)| format!("{n}={v}"))
                .collect::<Vec<_>>()
                .join(", ");
            return Err(SettingError::NotAnOption {
                name: name.to_string(),
                value: value.to_string(),
                allowed,
            });
        }
        if let Some(v) = value.as_f64() {
            let below = s
                .min
                .as_ref()
                .and_then(ExtValue::as_f64)
                .is_some_and(|m| v < m);
            let above = s
                .max
                .as_ref()
                .and_then(ExtValue::as_f64)
                .is_some_and(|m| v > m);
            if below || above {
                let show = |b: &Option<ExtValue>| {
                    b.as_ref()
                        .map_or_else(|| "-".to_string(), ToString::to_string)
                };
                return Err(SettingError::OutOfRange {
                    name: name.to_string(),
                    value: value.to_string(),
                    min: show(&s.min),
                    max: show(&s.max),
                });
            }
        }
        Ok(())
    }
}

/// The property the `camera_definition` fuzz target checks: any bytes either read as a
/// definition whose settings are all well-formed (names of 1 to 16 bytes, a default of
/// the setting's type, options of its type, at most the bounds) or give an error with a
/// line and column within the text; and checking each setting's default and options
/// against the definition never panics.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_camera_definition(data: &[u8]) {
    match CameraDefinition::parse(data) {
        Ok(d) => {
            assert!(d.settings.len() <= MAX_SETTINGS);
            for s in &d.settings {
                assert!(!s.name.is_empty() && s.name.len() <= NAME_LEN);
                assert_eq!(s.default.ty(), s.ty);
                assert!(s.options.len() <= MAX_OPTIONS);
                assert!(s.options.iter().all(|o| o.value.ty() == s.ty));
                let none = |_: &str| None;
                let _ = d.check(&s.name, &s.default, &none);
                for o in &s.options {
                    let _ = d.check(&s.name, &o.value, &none);
                    let _ = d.value_of(&s.name, &o.name);
                }
                let _ = d.excluded(&none);
            }
        }
        Err(e) => {
            assert!(e.line >= 1 && e.column >= 1);
            let lines = data.iter().filter(|&&b| b == b'\n').count() + 1;
            assert!(e.line as usize <= lines, "{e} in {lines} lines");
            let _ = e.to_string();
        }
    }
}

#[cfg(test)]
mod tests;
