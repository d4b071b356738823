//! Files: read to their end, or written (raw or tlog).

use std::io;

use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;
use tokio::sync::mpsc;

use crate::clock;
use crate::conn::FileFormat;
use crate::connection::{FileMode, Options};
use crate::error::{LinkError, OpenError, Reason};
use crate::protocol::{Framing, PeerAddr, PeerId, PeerInfo};
use crate::tlog;

use super::tasks::Tasks;
use super::{LinkMsg, PeerIds, PeerWriter, WriterQueue};

pub(super) fn open_file(
    path: &std::path::Path,
    format: FileFormat,
    options: &Options,
    ids: PeerIds,
    tx: mpsc::Sender<LinkMsg>,
    tasks: &mut Tasks,
) -> Result<(), OpenError> {
    let file_err = |e: &io::Error| OpenError::File {
        path: path.display().to_string(),
        reason: Reason::from_io(e),
    };
    let id = ids.next();
    let info = PeerInfo {
        id,
        addr: PeerAddr::File(path.to_path_buf()),
        framing: match (options.file_mode, format) {
            (FileMode::Read, FileFormat::Tlog) => Framing::Datagram,
            _ => Framing::Stream,
        },
    };
    let what = format!("file {}", path.display());
    match options.file_mode {
        FileMode::Read => {
            let file = std::fs::File::open(path).map_err(|e| file_err(&e))?;
            if file.metadata().is_ok_and(|m| m.is_dir()) {
                return Err(OpenError::File {
                    path: path.display().to_string(),
                    reason: Reason::new(io::ErrorKind::IsADirectory, "is a directory"),
                });
            }
            std::thread::Builder::new()
                .name("mavstack-file".into())
                .spawn(move || read_file(file, format, info, what, &tx))
                .map_err(|e| file_err(&e))?;
        }
        FileMode::Write | FileMode::Append => {
            let mode = if options.file_mode == FileMode::Append {
                tlog::OpenMode::Append
            } else {
                tlog::OpenMode::Truncate
            };
            let spool = tlog::Spool::open(path, mode).map_err(|e| file_err(&e))?;
            let sink = FileSink {
                spool,
                format,
                what,
                _open: tx,
            };
            tasks.writers.insert(
                id,
                PeerWriter {
                    queue: WriterQueue::File(Box::new(sink)),
                    task: None,
                },
            );
            tasks.initial.push(info);
        }
    }
    Ok(())
}

/// Reads a file to its end (on its own thread: file reads block) and reports it closed.
pub(super) fn read_file(
    file: std::fs::File,
    format: FileFormat,
    info: PeerInfo,
    what: String,
    tx: &mpsc::Sender<LinkMsg>,
) {
    let id = info.id;
    if tx
        .blocking_send(LinkMsg::PeerAdded { info, writer: None })
        .is_err()
    {
        return;
    }
    let result = match format {
        FileFormat::Raw => read_raw(file, id, tx),
        FileFormat::Tlog => read_tlog(file, id, tx),
    };
    let end = match result {
        Ok(true) => Ok(()),
        Ok(false) => return, // the connection was closed
        Err(e) => Err(LinkError::Read {
            what,
            reason: Reason::from_io(&e),
        }),
    };
    if tx.blocking_send(LinkMsg::PeerRemoved(id)).is_ok() {
        let _ = tx.blocking_send(LinkMsg::Closed(end));
    }
}

/// Ok(false): the link closed before the end.
pub(super) fn read_raw(
    mut file: std::fs::File,
    peer: PeerId,
    tx: &mpsc::Sender<LinkMsg>,
) -> io::Result<bool> {
    use std::io::Read as _;
    loop {
        let mut buf = vec![0u8; tlog::BUFFER_LEN];
        let n = match file.read(&mut buf) {
            Ok(0) => return Ok(true),
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        buf.truncate(n);
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes: buf,
        };
        if tx.blocking_send(msg).is_err() {
            return Ok(false);
        }
    }
}

/// Ok(false): the link closed before the end.
pub(super) fn read_tlog(
    file: std::fs::File,
    peer: PeerId,
    tx: &mpsc::Sender<LinkMsg>,
) -> io::Result<bool> {
    let mut reader = tlog::Reader::new(file);
    loop {
        let mut bytes = Vec::with_capacity(tlog::BUFFER_LEN);
        let mut parts = Vec::with_capacity(256);
        let mut done = false;
        while bytes.len() < tlog::BUFFER_LEN - tlog::MAX_RECORD_LEN {
            match reader.read_record()? {
                Some((ts, frame)) => {
                    bytes.extend_from_slice(frame);
                    parts.push((Instant::from_micros(ts), bytes.len()));
                }
                None => {
                    done = true;
                    break;
                }
            }
        }
        if !parts.is_empty()
            && tx
                .blocking_send(LinkMsg::Records { peer, bytes, parts })
                .is_err()
        {
            return Ok(false);
        }
        if done {
            let skipped = reader.stats().skipped_bytes;
            if skipped > 0 {
                tracing::info!("tlog: skipped {skipped} corrupt bytes");
            }
            return Ok(true);
        }
    }
}

/// A file being written: what is sent goes to its [`tlog::Spool`] (the file's own writer
/// thread; raw, or as tlog records stamped with the transport's clock when sent), written out
/// at least once a second and all of it when the link closes.
#[derive(Debug)]
pub(super) struct FileSink {
    spool: tlog::Spool,
    format: FileFormat,
    what: String,
    /// Keeps the link's queue open while the file is written.
    _open: mpsc::Sender<LinkMsg>,
}

impl FileSink {
    /// Hands `data` to the writer thread; `Ok(false)` when its queue was full (dropped).
    ///
    /// # Errors
    /// The file could not be written.
    pub(super) fn write(&mut self, data: &[u8]) -> Result<bool, LinkError> {
        match self.format {
            FileFormat::Raw => self.spool.push_raw(data),
            FileFormat::Tlog => {
                let now = clock::now().as_micros();
                let mut rest = data;
                while !rest.is_empty() {
                    let Ok(frame) = Frame::new_checked(rest) else {
                        tracing::warn!(
                            "{}: {} bytes that are not a frame not logged",
                            self.what,
                            rest.len()
                        );
                        break;
                    };
                    let (record, more) = rest.split_at(frame.frame_len());
                    self.spool.push_record(now, record);
                    rest = more;
                }
            }
        }
        self.spool.send().map_err(|e| self.fail(&e))
    }

    /// Writes everything out and syncs the file (blocks: the writer thread finishes).
    ///
    /// # Errors
    /// The file could not be written.
    pub(super) fn finish(self) -> Result<(), LinkError> {
        let what = self.what;
        self.spool.finish().map_err(|e| LinkError::Write {
            what,
            reason: Reason::from_io(&e),
        })
    }

    fn fail(&self, e: &io::Error) -> LinkError {
        LinkError::Write {
            what: self.what.clone(),
            reason: Reason::from_io(e),
        }
    }
}
