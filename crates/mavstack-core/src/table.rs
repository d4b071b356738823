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
    /// table); `None`: binary search over `entries`.
    find: Option<fn(u32) -> Option<&'static MessageInfo>>,
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
        })
    }

    /// The table of a generated dialect `M` (e.g. `mavstack_dialects::common::MavMessage`).
    #[must_use]
    pub fn of<M: MessageSet>() -> Self {
        Self {
            entries: M::all(),
            find: Some(M::info),
        }
    }

    /// A table without entries: every id is unknown.
    #[must_use]
    pub const fn empty() -> Self {
        Self {
            entries: &[],
            find: None,
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
    fn unsorted_entries_are_refused() {
        assert_eq!(
            MessageTable::new(&REPEATED).unwrap_err(),
            UnsortedEntries { id: 5 }
        );
    }
}
