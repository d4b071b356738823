//! The message-entry table: what every layer looks up about a message id without decoding
//! the payload.
//!
//! A [`MessageTable`] is a sorted slice of [`MessageInfo`] entries (id, name, CRC_EXTRA,
//! base and full payload lengths, target offsets). A generated dialect gives one with
//! [`MessageTable::of`]; a dialect loaded from XML at run time gives one through
//! `mavstack_xml::Dialect::message_table`. The parser, the channel, the router, the
//! transport's frame protocol, the command line and the Python package all take this one
//! type.
//!
//! ```
//! use mavstack_core::{MessageInfo, MessageTable};
//! static ENTRIES: [MessageInfo; 1] = [MessageInfo {
//!     id: 0,
//!     name: "HEARTBEAT",
//!     crc_extra: 50,
//!     min_len: 9,
//!     max_len: 9,
//!     target_system_offset: None,
//!     target_component_offset: None,
//! }];
//! let table = MessageTable::new(&ENTRIES).expect("sorted by id");
//! assert_eq!(table.crc_extra(0), Some(50));
//! assert_eq!(table.by_name("HEARTBEAT").map(|m| m.id), Some(0));
//! assert_eq!(table.info(1), None);
//! ```

use crate::message::{MessageInfo, MessageSet};
use crate::parse::CrcExtra;

/// The entries of one dialect, sorted by id: a cheap `Copy` handle onto `'static` data.
#[derive(Clone, Copy)]
pub struct MessageTable {
    entries: &'static [MessageInfo],
    /// A generated dialect's own id dispatch (a `match` the compiler makes into a jump
    /// table); `None`: `direct`, then binary search over `entries`.
    find: Option<fn(u32) -> Option<&'static MessageInfo>>,
    /// For a table made at run time ([`MessageTable::with_direct_index`]): by id, for the ids
    /// below its length, 1 + the entry's index, or 0 for an id the dialect does not define.
    direct: &'static [u16],
}

/// The entries given to [`MessageTable::new`] are not sorted by id without repeats.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UnsortedEntries {
    /// The first id that is not greater than the one before it.
    pub id: u32,
}

impl core::fmt::Display for UnsortedEntries {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "message id {} is out of order or repeated in the table",
            self.id
        )
    }
}

impl core::error::Error for UnsortedEntries {}

impl MessageTable {
    /// A table over `entries`, which must be sorted by id with no id twice.
    ///
    /// # Errors
    /// [`UnsortedEntries`] naming the first id out of order.
    pub const fn new(entries: &'static [MessageInfo]) -> Result<Self, UnsortedEntries> {
        let mut i = 1;
        while i < entries.len() {
            if entries[i].id <= entries[i - 1].id {
                return Err(UnsortedEntries { id: entries[i].id });
            }
            i += 1;
        }
        Ok(Self {
            entries,
            find: None,
            direct: &[],
        })
    }

    /// The table with `index` as its direct index: `index[id]` is 1 + the position of
    /// message `id` in the entries, or 0 where no message has that id, for the ids below
    /// `index.len()` (see [`direct_index`](Self::direct_index)); an id is then found with one
    /// load instead of a binary search. An index that does not match the entries (or a
    /// generated dialect's table, which has its own dispatch) leaves the table as it was.
    #[must_use]
    pub fn with_direct_index(self, index: &'static [u16]) -> Self {
        let fits = self.find.is_none()
            && index.iter().enumerate().all(|(id, &i)| {
                i == 0
                    || self
                        .entries
                        .get(usize::from(i) - 1)
                        .is_some_and(|m| m.id as usize == id)
            })
            && self
                .entries
                .iter()
                .enumerate()
                .filter(|(_, m)| (m.id as usize) < index.len())
                .all(|(i, m)| usize::from(index[m.id as usize]) == i + 1);
        if fits {
            Self {
                direct: index,
                ..self
            }
        } else {
            self
        }
    }

    /// Fills `index` (its length: the ids it covers) as
    /// [`with_direct_index`](Self::with_direct_index) wants it for these entries; ids past
    /// `u16::MAX` entries are left to the binary search.
    pub fn direct_index(&self, index: &mut [u16]) {
        index.fill(0);
        for (i, m) in self.entries.iter().enumerate() {
            if let (Some(slot), Ok(i)) = (index.get_mut(m.id as usize), u16::try_from(i + 1)) {
                *slot = i;
            }
        }
    }

    /// The table of a generated dialect `M` (e.g. `mavstack_dialects::common::MavMessage`).
    #[must_use]
    pub fn of<M: MessageSet>() -> Self {
        Self {
            entries: M::all(),
            find: Some(M::info),
            direct: &[],
        }
    }

    /// A table without entries: every id is unknown.
    #[must_use]
    pub const fn empty() -> Self {
        Self {
            entries: &[],
            find: None,
            direct: &[],
        }
    }

    /// The entry of message `id`, or `None` if the dialect does not define it.
    #[inline]
    #[must_use]
    pub fn info(&self, id: u32) -> Option<&'static MessageInfo> {
        if let Some(find) = self.find {
            return find(id);
        }
        let entries = self.entries;
        if let Some(&i) = self.direct.get(id as usize) {
            return usize::from(i).checked_sub(1).and_then(|i| entries.get(i));
        }
        entries
            .binary_search_by_key(&id, |m| m.id)
            .ok()
            .and_then(|i| entries.get(i))
    }

    /// The CRC_EXTRA of message `id`.
    #[inline]
    #[must_use]
    pub fn crc_extra(&self, id: u32) -> Option<u8> {
        self.info(id).map(|m| m.crc_extra)
    }

    /// The entry of the message called `name` (as in the XML, e.g. `"HEARTBEAT"`).
    #[must_use]
    pub fn by_name(&self, name: &str) -> Option<&'static MessageInfo> {
        self.entries.iter().find(|m| m.name == name)
    }

    /// Every entry, sorted by id.
    #[must_use]
    pub const fn entries(&self) -> &'static [MessageInfo] {
        self.entries
    }

    /// How many messages the table defines.
    #[must_use]
    pub const fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the table defines no message.
    #[must_use]
    pub const fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

impl CrcExtra for MessageTable {
    #[inline]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        Self::crc_extra(self, id)
    }
}

impl core::fmt::Debug for MessageTable {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("MessageTable")
            .field("messages", &self.entries.len())
            .field("generated", &self.find.is_some())
            .field("direct", &self.direct.len())
            .finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn entry(id: u32, name: &'static str, crc_extra: u8) -> MessageInfo {
        MessageInfo {
            id,
            name,
            crc_extra,
            min_len: 1,
            max_len: 2,
            target_system_offset: None,
            target_component_offset: None,
        }
    }

    static SORTED: [MessageInfo; 3] = [entry(0, "A", 1), entry(5, "B", 2), entry(70000, "C", 3)];
    static REPEATED: [MessageInfo; 2] = [entry(5, "A", 1), entry(5, "B", 2)];

    #[test]
    fn finds_by_id_and_name() {
        let t = MessageTable::new(&SORTED).unwrap();
        assert_eq!(t.crc_extra(0), Some(1));
        assert_eq!(t.crc_extra(5), Some(2));
        assert_eq!(t.crc_extra(70000), Some(3));
        assert_eq!(t.crc_extra(4), None);
        assert_eq!(CrcExtra::crc_extra(&t, 5), Some(2));
        assert_eq!(t.by_name("C").map(|m| m.id), Some(70000));
        assert_eq!(t.by_name("c"), None);
        assert_eq!((t.len(), t.is_empty()), (3, false));
        assert!(MessageTable::empty().info(0).is_none());
    }

    #[test]
    fn a_direct_index_finds_what_the_search_finds() {
        static INDEX: [u16; 8] = [1, 0, 0, 0, 0, 2, 0, 0];
        let plain = MessageTable::new(&SORTED).unwrap();
        let mut made = [9u16; 8];
        plain.direct_index(&mut made);
        assert_eq!(made, INDEX);
        let t = plain.with_direct_index(&INDEX);
        assert_eq!(t.direct.len(), 8);
        for id in [0, 1, 4, 5, 6, 7, 8, 69999, 70000, 70001, u32::MAX] {
            assert_eq!(t.info(id), plain.info(id), "id {id}");
        }
        // An index that disagrees with the entries is not taken.
        static WRONG: [u16; 6] = [1, 0, 0, 0, 0, 0];
        assert!(plain.with_direct_index(&WRONG).direct.is_empty());
        static OFF: [u16; 2] = [2, 0];
        assert!(plain.with_direct_index(&OFF).direct.is_empty());
    }

    #[test]
    fn unsorted_entries_are_refused() {
        assert_eq!(
            MessageTable::new(&REPEATED).unwrap_err(),
            UnsortedEntries { id: 5 }
        );
    }
}
