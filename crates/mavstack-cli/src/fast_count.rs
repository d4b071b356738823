//! `decode --count` for built-in dialects through the generated, typed code: zero-copy
//! parsing, checksum validation, typed decoding of every frame, no allocation per frame; a
//! file is parsed in parts on every processor.

use core::num::NonZero;
use std::io::{self, Read};
use std::path::Path;

use mavstack_core::parse::{CrcExtra, Item, Stats};
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::{MessageSet, MessageTable};
use mavstack_dialects::{DialectVisitor, with_dialect};
use mavstack_transport::raw::{count_items_split, read_items};

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

/// Where `decode --count` reads: a stream in order, or a file parsed in parts on this many
/// threads (`None`: one per processor; a pipe in order; the counts are those of one parse
/// in order).
pub(crate) enum Source<'a> {
    Stream(&'a mut dyn Read),
    File(&'a Path, Option<usize>),
}

/// Parses, validates and decodes every frame of `source` as dialect `M` (through fixed
/// buffers); returns the parser's counts and the number of frames whose signature does not
/// match `key`.
pub(crate) fn count<M: MessageSet>(
    source: Source<'_>,
    key: Option<&SecretKey>,
) -> io::Result<(Stats, u64)> {
    let lookup = DenseIndex::new(MessageTable::of::<M>());
    // 1 for a frame whose signature does not match `key`.
    let bad_signature = |item: Item<'_>| {
        let Item::Frame(frame) = item else { return 0 };
        // Kept where it was decoded (no move of the whole enum out of the `Result`).
        core::hint::black_box(&M::decode(frame.msg_id(), frame.payload()));
        u64::from(
            key.filter(|_| frame.is_signed())
                .is_some_and(|k| signing::verify(&frame, k).is_err()),
        )
    };
    match source {
        Source::Stream(input) => {
            let mut bad = 0;
            let stats = read_items(input, &lookup, |item| bad += bad_signature(item), |_| {})?;
            Ok((stats, bad))
        }
        Source::File(path, threads) => {
            let threads = threads
                .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, NonZero::get));
            count_items_split(path, threads, &lookup, bad_signature)
        }
    }
}

/// [`count`] for the built-in dialect called `name` (any case), or `None` if it is not one.
pub(crate) fn count_builtin<'a>(
    name: &str,
    source: Source<'a>,
    key: Option<&'a SecretKey>,
) -> Option<io::Result<(Stats, u64)>> {
    /// [`count`] with the arguments it is called with.
    struct Count<'a> {
        source: Source<'a>,
        key: Option<&'a SecretKey>,
    }
    impl DialectVisitor for Count<'_> {
        type Output = io::Result<(Stats, u64)>;
        fn visit<M: MessageSet>(self) -> Self::Output {
            count::<M>(self.source, self.key)
        }
    }
    with_dialect(name, Count { source, key })
}
