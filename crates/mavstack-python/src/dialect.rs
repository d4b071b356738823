//! A dialect as the reader needs it: per message id its CRC_EXTRA and the layout of its
//! fields (XML order, as pymavlink lists them, and wire order), loaded once per name.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use mavstack_core::MessageTable;
use mavstack_xml::PrimitiveType;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::PyString;

/// One field of a message.
#[derive(Debug)]
pub(crate) struct FieldLayout {
    /// Its name.
    pub(crate) name: String,
    /// Its element type.
    pub(crate) primitive: PrimitiveType,
    /// `N` of an array (`char[N]` included); `None` for a scalar.
    pub(crate) array_len: Option<usize>,
    /// Offset in the full payload.
    pub(crate) offset: usize,
    /// The XML's `units`, if any.
    pub(crate) units: Option<String>,
    /// Whether it comes after `<extensions/>`.
    pub(crate) extension: bool,
    /// Whether its XML type is `uint8_t_mavlink_version` (HEARTBEAT's `mavlink_version`).
    pub(crate) mavlink_version: bool,
}

impl FieldLayout {
    /// Elements (1 for a scalar).
    pub(crate) fn count(&self) -> usize {
        self.array_len.unwrap_or(1)
    }

    /// Whether the field is text (`char` or `char[N]`).
    pub(crate) fn is_text(&self) -> bool {
        self.primitive == PrimitiveType::Char
    }
}

/// One message of the dialect.
pub(crate) struct MessageType {
    /// Its id.
    pub(crate) id: u32,
    /// Its name, e.g. `ATTITUDE`.
    pub(crate) name: String,
    /// Length of the full payload, extensions included.
    pub(crate) max_len: usize,
    /// Fields in XML order (pymavlink's `fieldnames`).
    pub(crate) fields: Vec<FieldLayout>,
    /// Field indexes in wire order (pymavlink's `ordered_fieldnames`).
    pub(crate) wire_order: Vec<usize>,
    /// Field index by name.
    by_name: FastMap<String, usize>,
    /// The fields' names as interned Python strings, made at the first look-up.
    interned: PyOnceLock<Box<[Py<PyString>]>>,
}

/// A map keyed by what the dialect defines (never by what the network sends), looked up for
/// every message received: foldhash rather than SipHash.
type FastMap<K, V> = HashMap<K, V, foldhash::fast::FixedState>;

impl core::fmt::Debug for MessageType {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("MessageType")
            .field("id", &self.id)
            .field("name", &self.name)
            .field("fields", &self.fields)
            .finish_non_exhaustive()
    }
}

impl MessageType {
    /// The field called `name`.
    pub(crate) fn field(&self, name: &str) -> Option<&FieldLayout> {
        self.by_name.get(name).map(|&i| &self.fields[i])
    }

    /// The field called `name`: found by identity among the interned field names first (an
    /// attribute name written in Python code is interned), else by its text.
    pub(crate) fn field_named(&self, name: &Bound<'_, PyString>) -> Option<&FieldLayout> {
        let py = name.py();
        let interned = self.interned.get_or_init(py, || {
            self.fields
                .iter()
                .map(|f| PyString::intern(py, &f.name).unbind())
                .collect()
        });
        match interned.iter().position(|n| n.as_ptr() == name.as_ptr()) {
            Some(i) => self.fields.get(i),
            None => self.field(name.to_str().ok()?),
        }
    }
}

/// A loaded dialect.
#[derive(Debug)]
pub(crate) struct Dialect {
    /// The name it was loaded by.
    pub(crate) name: String,
    /// Its messages.
    pub(crate) messages: Vec<Arc<MessageType>>,
    /// The stack's message-entry table of the dialect (what the frame parsers check
    /// checksums with).
    pub(crate) table: MessageTable,
    /// Every enum entry's name and value, and `MAVLINK_MSG_ID_<NAME>` of every message
    /// (pymavlink's module constants).
    pub(crate) constants: Vec<(String, u64)>,
    by_id: FastMap<u32, usize>,
    by_name: HashMap<String, usize>,
}

impl Dialect {
    /// Loads a built-in dialect by name or an XML file by path (once per name).
    pub(crate) fn load(name: &str) -> PyResult<Arc<Self>> {
        static CACHE: OnceLock<Mutex<HashMap<String, Arc<Dialect>>>> = OnceLock::new();
        let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
        let builtin = mavstack_xml::builtin::dialect_names()
            .iter()
            .any(|b| b.eq_ignore_ascii_case(name));
        if builtin && let Some(found) = cache.lock().ok().and_then(|c| c.get(name).cloned()) {
            return Ok(found);
        }
        let loaded = mavstack_xml::load(name)
            .map_err(|e| PyValueError::new_err(format!("dialect {name:?}: {e}")))?;
        let dialect = Arc::new(Self::from_loaded(name, &loaded));
        if builtin && let Ok(mut c) = cache.lock() {
            c.insert(name.to_owned(), Arc::clone(&dialect));
        }
        Ok(dialect)
    }

    fn from_loaded(name: &str, loaded: &mavstack_xml::Dialect) -> Self {
        let mut messages = Vec::with_capacity(loaded.messages.len());
        for m in &loaded.messages {
            let xml = m.fields_in_xml_order();
            let fields: Vec<FieldLayout> = xml
                .iter()
                .map(|f| FieldLayout {
                    name: f.name.clone(),
                    primitive: f.ty.primitive,
                    array_len: f.ty.array_len.map(usize::from),
                    offset: f.offset,
                    units: f.units.clone(),
                    extension: f.extension,
                    mavlink_version: f.ty.mavlink_version,
                })
                .collect();
            let wire_order = m
                .fields
                .iter()
                .filter_map(|w| xml.iter().position(|f| f.name == w.name))
                .collect();
            let by_name = fields
                .iter()
                .enumerate()
                .map(|(i, f)| (f.name.clone(), i))
                .collect();
            messages.push(Arc::new(MessageType {
                id: m.id,
                name: m.name.clone(),
                max_len: m.max_len,
                fields,
                wire_order,
                by_name,
                interned: PyOnceLock::new(),
            }));
        }
        let by_id = messages
            .iter()
            .enumerate()
            .map(|(i, m)| (m.id, i))
            .collect();
        let by_name = messages
            .iter()
            .enumerate()
            .map(|(i, m)| (m.name.clone(), i))
            .collect();
        Self {
            name: name.to_owned(),
            messages,
            table: loaded.message_table(),
            constants: loaded
                .enums
                .iter()
                .flat_map(|e| e.entries.iter().map(|x| (x.name.clone(), x.value)))
                .chain(
                    loaded
                        .messages
                        .iter()
                        .map(|m| (format!("MAVLINK_MSG_ID_{}", m.name), u64::from(m.id))),
                )
                .collect(),
            by_id,
            by_name,
        }
    }

    /// The index of message `id`.
    #[inline]
    pub(crate) fn index_of_id(&self, id: u32) -> Option<usize> {
        self.by_id.get(&id).copied()
    }

    /// The index of the message called `name`.
    pub(crate) fn index_of_name(&self, name: &str) -> Option<usize> {
        self.by_name.get(name).copied()
    }

    /// CRC_EXTRA of message `id`, for the frame parsers.
    #[inline]
    pub(crate) fn crc_extra(&self, id: u32) -> Option<u8> {
        self.table.crc_extra(id)
    }
}
