//! A loaded dialect as the [`MessageTable`] every layer of the stack takes.

use std::sync::{Mutex, PoisonError};

use mavstack_core::{MessageInfo, MessageTable};

use crate::model::{Dialect, Message};

/// Tables made so far. A table's entries live for the rest of the process (the stack's
/// layers hold `'static` entries), so each distinct set of entries is made once and handed
/// out again for a dialect that produces the same set: loading the same XML twice costs no
/// memory.
static MADE: Mutex<Vec<MessageTable>> = Mutex::new(Vec::new());

/// The ids a table's direct index covers, at most (two bytes each: 128 KiB for a dialect
/// with an id near 65,535, once per process).
const DIRECT_IDS: usize = 1 << 16;

/// The entry of `m`; the layout checks keep lengths and offsets within a payload (255).
fn entry_of(m: &Message, name: &'static str) -> MessageInfo {
    let byte = |n: usize| u8::try_from(n).unwrap_or(u8::MAX);
    MessageInfo {
        id: m.id,
        name,
        crc_extra: m.crc_extra,
        min_len: byte(m.min_len),
        max_len: byte(m.max_len),
        target_system_offset: m.target_system_offset.map(byte),
        target_component_offset: m.target_component_offset.map(byte),
    }
}

/// Whether `info` is the entry of `m`.
fn same(info: &MessageInfo, m: &Message) -> bool {
    *info == entry_of(m, info.name) && info.name == m.name
}

impl Dialect {
    /// The message-entry table of this dialect (id, name, CRC_EXTRA, lengths, target
    /// offsets), for the parser, channel, router and the rest of the stack.
    ///
    /// The entries are kept for the rest of the process and shared: asking again for a
    /// dialect with the same messages returns the table made before.
    ///
    /// ```
    /// let dialect = mavstack_xml::load("common")?;
    /// let table = dialect.message_table();
    /// assert_eq!(table.by_name("COMMAND_ACK").map(|m| (m.id, m.crc_extra)), Some((77, 143)));
    /// assert_eq!(table.len(), dialect.messages.len());
    /// # Ok::<(), mavstack_xml::Error>(())
    /// ```
    #[must_use]
    pub fn message_table(&self) -> MessageTable {
        let mut made = MADE.lock().unwrap_or_else(PoisonError::into_inner);
        let found = made.iter().find(|t| {
            t.len() == self.messages.len()
                && t.entries()
                    .iter()
                    .zip(&self.messages)
                    .all(|(e, m)| same(e, m))
        });
        if let Some(table) = found {
            return *table;
        }
        let entries: Vec<MessageInfo> = self
            .messages
            .iter()
            .map(|m| entry_of(m, Box::leak(m.name.clone().into_boxed_str())))
            .collect();
        let entries: &'static [MessageInfo] = Box::leak(entries.into_boxed_slice());
        // `messages` is sorted by id without repeats (the loader rejects duplicate ids).
        let table = MessageTable::new(entries).unwrap_or_else(|_| MessageTable::empty());
        // An id found with one load rather than a binary search (what the parser and the
        // router do for every frame): an index over the ids below 65,536, made once.
        let covered = entries
            .last()
            .map_or(0, |m| (m.id as usize + 1).min(DIRECT_IDS));
        let mut index = vec![0u16; covered];
        table.direct_index(&mut index);
        let table = table.with_direct_index(Box::leak(index.into_boxed_slice()));
        made.push(table);
        table
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn same_dialect_same_table() {
        let a = crate::load("minimal").unwrap().message_table();
        let b = crate::load("minimal").unwrap().message_table();
        assert!(core::ptr::eq(a.entries(), b.entries()));
        let c = crate::load("common").unwrap().message_table();
        assert_eq!(c.crc_extra(0), Some(50));
        assert!(!core::ptr::eq(a.entries(), c.entries()));
    }

    #[test]
    fn the_direct_index_finds_what_a_search_finds() {
        let t = crate::load("ardupilotmega").unwrap().message_table();
        assert!(
            !format!("{t:?}").contains("direct: 0 }"),
            "an index over the ids: {t:?}"
        );
        for id in (0..70_000).chain([u32::MAX]) {
            let searched = t
                .entries()
                .binary_search_by_key(&id, |m| m.id)
                .ok()
                .map(|i| &t.entries()[i]);
            assert_eq!(t.info(id), searched, "id {id}");
        }
    }
}
