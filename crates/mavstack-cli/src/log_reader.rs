//! Reading a log file frame by frame, for the `log` commands: a tlog (a timestamp before each
//! frame) or a raw stream, chosen by the file name, with a progress bar on a terminal.

use std::io::{self, BufReader};
use std::path::Path;

use anyhow::Context as _;
use mavstack_core::parse::Item;
use mavstack_core::wire::Frame;
use mavstack_transport::{raw, tlog};
use mavstack_xml::Dialect;

use crate::Failure;
use crate::progress::Progress;

pub(crate) use mavstack_core::tlog::is_tlog_path as is_tlog;

/// One frame of a log.
pub(crate) struct LogFrame<'a> {
    /// Its record's timestamp (µs since the Unix epoch) in a tlog; none in a raw stream.
    pub(crate) ts_us: Option<u64>,
    /// The frame, checksum verified when the dialect knows its id.
    pub(crate) frame: Frame<&'a [u8]>,
    /// Whether the dialect knows its message id.
    pub(crate) known: bool,
}

/// What reading a whole log found besides the frames.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ReadCounts {
    /// Frames returned.
    pub(crate) frames: u64,
    /// Candidate frames rejected for a bad checksum.
    pub(crate) bad_frames: u64,
    /// Bytes that were part of no frame.
    pub(crate) skipped_bytes: u64,
    /// Bytes read.
    pub(crate) bytes: u64,
}

/// Calls `each` for every frame of the log at `path`, in file order, with a progress bar
/// labelled `what` on a terminal.
pub(crate) fn read_log(
    path: &Path,
    dialect: &Dialect,
    what: &str,
    mut each: impl FnMut(&LogFrame<'_>),
) -> Result<ReadCounts, Failure> {
    let cannot = |e: io::Error| {
        Failure::Input(anyhow::Error::new(e).context(format!("cannot read {}", path.display())))
    };
    let table = dialect.message_table();
    let mut counts = ReadCounts::default();
    if is_tlog(path) {
        let file = std::fs::File::open(path).map_err(cannot)?;
        let total = file.metadata().map_or(0, |m| m.len());
        let mut progress = Progress::new(what, total);
        let mut reader = tlog::Reader::new(BufReader::with_capacity(
            1 << 16,
            file.try_clone().map_err(cannot)?,
        ))
        .with_crc_extra(table)
        .indexed_as_pymavlink_opens(&file)
        .map_err(cannot)?;
        while let Some((ts, bytes)) = reader
            .read_record()
            .with_context(|| format!("reading {}", path.display()))?
        {
            let frame = Frame::new_unchecked(bytes);
            let known = table.info(frame.msg_id()).is_some();
            each(&LogFrame {
                ts_us: Some(ts),
                frame,
                known,
            });
            counts.frames += 1;
            if counts.frames % 4096 == 0 {
                progress.set(reader.stats().bytes);
            }
        }
        let stats = reader.stats();
        counts.bad_frames = stats.bad_crc;
        counts.skipped_bytes = stats.skipped_bytes;
        counts.bytes = stats.bytes;
        progress.finish();
    } else {
        let mut file = std::fs::File::open(path).map_err(cannot)?;
        let total = file.metadata().map_or(0, |m| m.len());
        let mut progress = Progress::new(what, total);
        let mut frames = 0;
        let stats = raw::read_items(
            &mut file,
            table,
            |item| {
                let (frame, known) = match item {
                    Item::Frame(f) => (f, true),
                    Item::Unknown(f) => (f, false),
                };
                each(&LogFrame {
                    ts_us: None,
                    frame,
                    known,
                });
                frames += 1;
            },
            |at| progress.set(at),
        )
        .map_err(cannot)?;
        counts.frames = frames;
        counts.bad_frames = stats.bad_crc;
        counts.skipped_bytes = stats.skipped_bytes;
        counts.bytes = stats.bytes;
        progress.finish();
    }
    Ok(counts)
}
