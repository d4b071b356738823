//! Counting a raw capture file on several threads: the file is cut into parts, each parsed
//! by a thread of its own, and the counts are those of one parse of the whole file.
//!
//! A part after the first starts at an arbitrary byte, maybe inside a frame, so its first
//! items may be wrong: the tail of a frame taken for noise, a false frame inside a payload.
//! The parser keeps no state at the end of an item (the next scan starts afresh there), so two
//! parses that end an item at the same offset go on identically from it. Each part therefore
//! notes the offsets where its items end in a window after its start, with its counts there,
//! and the part before it parses on past its own end until it ends an item at one of those
//! offsets. From there on the later part's counts are right; the earlier part's end and the
//! later part's note at that offset are subtracted. An earlier part that finds no common
//! offset within the window (a window full of noise and false starts) parses on to the end of
//! the file itself, and the later parts' counts are not used: the result is exact either way.

use core::ops::Sub;
use std::fs::File;
use std::io::{self, Seek, SeekFrom};
use std::path::Path;
use std::sync::mpsc;

use mavstack_core::parse::{CrcExtra, Item, Stats};

use super::{CHUNK_LEN, Pieces};

/// The bytes after a part's start in which it notes where its items end.
const WINDOW: u64 = 64 * 1024;
/// The smallest part worth a thread of its own.
const MIN_PART: u64 = 4 << 20;

/// Counts of a parse up to an offset of the file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Mark {
    /// The file offset (the end of an item, or of the file).
    at: u64,
    /// The parser's counts from the part's start (`bytes` unused).
    stats: Stats,
    /// The sum of the caller's tally over the items.
    tally: u64,
}

impl Sub for Mark {
    type Output = Self;

    fn sub(self, from: Self) -> Self {
        Self {
            at: self.at - from.at,
            stats: self.stats - from.stats,
            tally: self.tally - from.tally,
        }
    }
}

/// What one part's thread found.
struct Part {
    /// Where its items end in the window after its start (the start itself first).
    starts: Vec<Mark>,
    /// Where it stopped.
    end: Mark,
    /// It parsed to the end of the file: the later parts' counts are not needed.
    to_eof: bool,
}

/// The raw MAVLink capture at `path` parsed on up to `threads` threads (fewer for a small
/// file: each part has at least 4 MiB; one for what is not a regular file, such as a pipe,
/// which can only be read in order), checksums checked with `lookup`; `tally` is called for
/// every item and its results are summed. Returns the counts and the sum that one parse of the
/// whole file in order would give ([`super::read_items`]), though items are seen out of order
/// and some bytes twice (`tally` must be a pure count).
///
/// # Errors
/// The file cannot be opened or read.
pub fn count_items_split<L, T>(
    path: &Path,
    threads: usize,
    lookup: L,
    tally: T,
) -> io::Result<(Stats, u64)>
where
    L: CrcExtra + Copy + Send,
    T: Fn(Item<'_>) -> u64 + Sync,
{
    let meta = std::fs::metadata(path)?;
    if !meta.is_file() {
        let mut sum = 0;
        let stats = super::read_items(File::open(path)?, lookup, |i| sum += tally(i), |_| {})?;
        return Ok((stats, sum));
    }
    let len = meta.len();
    let parts = usize::try_from(len / MIN_PART)
        .unwrap_or(usize::MAX)
        .clamp(1, threads.max(1));
    split_in(path, len, parts, CHUNK_LEN, WINDOW, lookup, &tally)
}

/// [`count_items_split`] with `parts` parts of a file `len` bytes long, `chunk_len` bytes read
/// at a time and a window of `window` bytes.
fn split_in<L, T>(
    path: &Path,
    len: u64,
    parts: usize,
    chunk_len: usize,
    window: u64,
    lookup: L,
    tally: &T,
) -> io::Result<(Stats, u64)>
where
    L: CrcExtra + Copy + Send,
    T: Fn(Item<'_>) -> u64 + Sync,
{
    let parts = parts.max(1) as u64;
    let starts: Vec<u64> = (0..parts).map(|k| len * k / parts).collect();
    // Part k hands its item ends to part k - 1: the first part has nobody to tell, the last
    // nobody to hear from.
    let (mut senders, mut receivers) = (vec![None], Vec::new());
    for _ in 1..parts {
        let (tx, rx) = mpsc::channel();
        senders.push(Some(tx));
        receivers.push(Some(rx));
    }
    receivers.push(None);
    let results: Vec<io::Result<Part>> = std::thread::scope(|scope| {
        let workers: Vec<_> = starts
            .iter()
            .enumerate()
            .map(|(k, &start)| {
                let job = Job {
                    start,
                    next_start: starts.get(k + 1).copied(),
                    window,
                    chunk_len,
                    publish: senders[k].take(),
                    next: receivers[k].take(),
                };
                scope.spawn(move || job.run(path, lookup, tally))
            })
            .collect();
        workers
            .into_iter()
            .map(|w| {
                w.join()
                    .unwrap_or_else(|_| Err(io::Error::other("a counting thread panicked")))
            })
            .collect()
    });
    let mut total = Mark::default();
    let mut from = 0;
    for part in results {
        let part = part?;
        let Some(&first) = part.starts.iter().find(|m| m.at == from) else {
            // Not reached: an earlier part stops only at an offset this part noted.
            return Err(io::Error::other("parts of the file did not meet"));
        };
        let counted = part.end - first;
        total.at += counted.at;
        total.stats += counted.stats;
        total.tally += counted.tally;
        if part.to_eof {
            break;
        }
        from = part.end.at;
    }
    total.stats.bytes = total.at;
    Ok((total.stats, total.tally))
}

/// One part's work.
struct Job {
    start: u64,
    /// Where the next part starts: from there on, item ends are looked up in its notes.
    next_start: Option<u64>,
    window: u64,
    chunk_len: usize,
    /// Where this part's notes go (to the part before it).
    publish: Option<mpsc::Sender<Vec<Mark>>>,
    /// The next part's notes.
    next: Option<mpsc::Receiver<Vec<Mark>>>,
}

impl Job {
    fn run<L: CrcExtra + Copy, T: Fn(Item<'_>) -> u64>(
        mut self,
        path: &Path,
        lookup: L,
        tally: &T,
    ) -> io::Result<Part> {
        let mut input = File::open(path)?;
        input.seek(SeekFrom::Start(self.start))?;
        let mut pieces = Pieces::new(self.chunk_len);
        // The file offset of the first byte in `pieces`.
        let mut base = self.start;
        let mut done = Mark {
            at: self.start,
            ..Mark::default()
        };
        let mut starts = vec![done];
        let window_end = self.start.saturating_add(self.window);
        // Item ends from here on are looked up in the next part's notes, until its window
        // is passed.
        let mut watch = self.next_start.unwrap_or(u64::MAX);
        let give_up = watch.saturating_add(self.window);
        let mut next_starts: Option<Vec<Mark>> = None;
        loop {
            pieces.fill(&mut input)?;
            let mut parser = pieces.parser(lookup);
            while let Some(item) = parser.next() {
                done.tally += tally(item);
                let at = base + parser.position() as u64;
                if at < watch && (at >= window_end || self.publish.is_none()) {
                    continue;
                }
                let mark = Mark {
                    at,
                    stats: sum(done.stats, *parser.stats()),
                    tally: done.tally,
                };
                if at < window_end {
                    starts.push(mark);
                } else if let Some(to) = self.publish.take() {
                    // The part before may be waiting for these.
                    let _ = to.send(starts.clone());
                }
                if at >= watch {
                    let notes = next_starts.get_or_insert_with(|| {
                        self.next
                            .take()
                            .and_then(|r| r.recv().ok())
                            .unwrap_or_default()
                    });
                    if notes.binary_search_by_key(&at, |m| m.at).is_ok() {
                        return Ok(Part {
                            starts,
                            end: mark,
                            to_eof: false,
                        });
                    }
                    if at >= give_up {
                        watch = u64::MAX;
                    }
                }
            }
            done.stats = sum(done.stats, *parser.stats());
            if pieces.eof {
                if let Some(to) = self.publish.take() {
                    let _ = to.send(starts.clone());
                }
                done.at = base + pieces.filled as u64;
                return Ok(Part {
                    starts,
                    end: done,
                    to_eof: true,
                });
            }
            let keep = parser.position();
            pieces.keep_from(keep);
            base += keep as u64;
        }
    }
}

/// `a` and `b` added, `bytes` left out.
fn sum(mut a: Stats, b: Stats) -> Stats {
    a += b;
    a.bytes = 0;
    a
}

#[cfg(test)]
mod tests;

/// Fuzz body (`fuzz/fuzz_targets/raw_split.rs`). The first three bytes choose the parts (1
/// to 8), the window (0 to 1,020 bytes) and the chunk length; the rest is written to a file
/// and counted in parts. Property: the counts and the tally are those of one parse in order.
///
/// # Panics
/// When the property fails, or the temporary file cannot be written.
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_raw_split(data: &[u8]) {
    let [parts, window, chunk, stream @ ..] = data else {
        return;
    };
    let lookup = |id: u32| match id {
        0 => Some(50u8),
        30 => Some(39),
        33 => Some(104),
        76 => Some(152),
        _ => None,
    };
    let tally = |item: Item<'_>| match item {
        Item::Frame(f) => 1 + u64::from(f.is_signed()) * 1_000,
        Item::Unknown(_) => 1_000_000,
    };
    let mut want = 0;
    let in_order = super::read_items(stream, lookup, |item| want += tally(item), |_| {})
        .unwrap_or_else(|e| panic!("reading a slice: {e}"));
    let path = std::env::temp_dir().join(format!("mavstack-fuzz-split-{}", std::process::id()));
    std::fs::write(&path, stream).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let got = split_in(
        &path,
        stream.len() as u64,
        usize::from(parts % 8) + 1,
        2 * mavstack_core::wire::MAX_FRAME_LEN + usize::from(*chunk) * 37,
        u64::from(*window) * 4,
        lookup,
        &tally,
    );
    let _ = std::fs::remove_file(&path);
    assert_eq!(got.ok(), Some((in_order, want)));
}
