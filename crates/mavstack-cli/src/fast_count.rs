//! `decode --count` for built-in dialects through the generated, typed code: zero-copy
//! parsing, checksum validation, typed decoding of every frame, no allocation per frame.

use std::io::{self, Read};

use mavstack_core::parse::{CrcExtra, Item, Stats};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::{MessageSet, MessageTable};
use mavstack_dialects::{DialectVisitor, with_dialect};
use mavstack_transport::raw::read_items;

/// A dense index over a dialect's [`MessageTable`] for ids below 65536 (0: unknown, else
/// 0x100 | CRC_EXTRA), the rest through the table: one load per frame, inlined into the
/// parser.
struct DenseIndex {
    dense: Vec<u16>,
    table: MessageTable,
}

impl DenseIndex {
    fn new(table: MessageTable) -> Self {
        let mut dense = vec![0u16; 1 << 16];
        for info in table.entries() {
            if let Some(slot) = usize::try_from(info.id).ok().and_then(|i| dense.get_mut(i)) {
                *slot = 0x100 | u16::from(info.crc_extra);
            }
        }
        Self { dense, table }
    }
}

impl CrcExtra for &DenseIndex {
    #[inline(always)]
    fn crc_extra(&self, id: u32) -> Option<u8> {
        match usize::try_from(id).ok().and_then(|i| self.dense.get(i)) {
            Some(&v) => (v != 0).then_some(v.to_le_bytes()[0]),
            None => self.table.crc_extra(id),
        }
    }
}

/// Parses, validates and decodes every frame read from `input` as dialect `M` (through one
/// fixed buffer); returns the parser's counts and the number of frames whose signature does
/// not match `key`.
pub(crate) fn count<M: MessageSet>(
    input: &mut dyn Read,
    key: Option<&SecretKey>,
) -> io::Result<(Stats, u64)> {
    let lookup = DenseIndex::new(MessageTable::of::<M>());
    let mut bad_signature = 0;
    let stats = read_items(
        input,
        &lookup,
        |item| {
            let Item::Frame(frame) = item else { return };
            // Kept where it was decoded (no move of the whole enum out of the `Result`).
            core::hint::black_box(&M::decode(frame.msg_id(), frame.payload()));
            if let Some(k) = key.filter(|_| frame.is_signed())
                && signing::verify(&frame, k).is_err()
            {
                bad_signature += 1;
            }
        },
        |_| {},
    )?;
    Ok((stats, bad_signature))
}

/// [`count`] for the built-in dialect called `name` (any case), or `None` if it is not one.
pub(crate) fn count_builtin(
    name: &str,
    input: &mut dyn Read,
    key: Option<&SecretKey>,
) -> Option<io::Result<(Stats, u64)>> {
    /// [`count`] with the arguments it is called with.
    struct Count<'a> {
        input: &'a mut dyn Read,
        key: Option<&'a SecretKey>,
    }
    impl DialectVisitor for Count<'_> {
        type Output = io::Result<(Stats, u64)>;
        fn visit<M: MessageSet>(self) -> Self::Output {
            count::<M>(self.input, self.key)
        }
    }
    with_dialect(name, Count { input, key })
}
