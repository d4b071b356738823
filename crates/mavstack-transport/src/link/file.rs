//! Files: read to their end, or written (raw or tlog).

use std::io;

use mavstack_core::time::Instant;
use mavstack_core::wire::Frame;
use tokio::io::AsyncWriteExt as _;
use tokio::sync::mpsc;

use crate::clock;
use crate::conn::FileFormat;
use crate::connection::{FileMode, Options};
use crate::error::{LinkError, OpenError, Reason};
use crate::protocol::{Framing, PeerAddr, PeerId, PeerInfo};
use crate::tlog;

use super::tasks::Tasks;
use super::{LinkMsg, PeerIds, PeerWriter, WriterQueue, sleep_until};

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
            let mut open = std::fs::OpenOptions::new();
            if options.file_mode == FileMode::Append {
                open.append(true).create(true);
            } else {
                open.write(true).create(true).truncate(true);
            }
            let file = open.open(path).map_err(|e| file_err(&e))?;
            let (wtx, wrx) = mpsc::channel(options.write_queue.max(1));
            tasks.writers.insert(
                id,
                PeerWriter {
                    queue: WriterQueue::Plain(wtx),
                    task: None,
                },
            );
            tasks.initial.push(info);
            let sink = write_file(tokio::fs::File::from_std(file), format, wrx, what, tx);
            tasks.sinks.push(tokio::spawn(sink));
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

/// Writes what is sent to a file: raw, or as tlog records stamped with the transport's clock.
/// Writes out at least once a second; writes everything out when the link closes.
pub(super) async fn write_file(
    mut file: tokio::fs::File,
    format: FileFormat,
    mut rx: mpsc::Receiver<Vec<u8>>,
    what: String,
    link: mpsc::Sender<LinkMsg>,
) -> Result<(), LinkError> {
    let mut buffer = tlog::Buffer::new();
    let fail = |e: &io::Error| LinkError::Write {
        what: what.clone(),
        reason: Reason::from_io(e),
    };
    loop {
        let deadline = buffer.deadline().map(tokio::time::Instant::from_std);
        let flush = tokio::select! {
            data = rx.recv() => match data {
                Some(data) => {
                    append(&mut buffer, format, &data, &what);
                    buffer.due()
                }
                None => break,
            },
            () = sleep_until(deadline), if deadline.is_some() => true,
        };
        if flush && let Err(e) = write_out(&mut file, &mut buffer).await {
            let err = fail(&e);
            let _ = link.send(LinkMsg::Closed(Err(err.clone()))).await;
            return Err(err);
        }
    }
    write_out(&mut file, &mut buffer)
        .await
        .map_err(|e| fail(&e))?;
    file.sync_data().await.map_err(|e| fail(&e))
}

pub(super) fn append(buffer: &mut tlog::Buffer, format: FileFormat, data: &[u8], what: &str) {
    match format {
        FileFormat::Raw => buffer.push_raw(data),
        FileFormat::Tlog => {
            let now = clock::now().as_micros();
            let mut rest = data;
            while !rest.is_empty() {
                let Ok(frame) = Frame::new_checked(rest) else {
                    tracing::warn!(
                        "{what}: {} bytes that are not a frame not logged",
                        rest.len()
                    );
                    return;
                };
                let len = frame.frame_len();
                buffer.push_record(now, &rest[..len]);
                rest = &rest[len..];
            }
        }
    }
}

pub(super) async fn write_out(
    file: &mut tokio::fs::File,
    buffer: &mut tlog::Buffer,
) -> io::Result<()> {
    if buffer.bytes().is_empty() {
        return Ok(());
    }
    file.write_all(buffer.bytes()).await?;
    buffer.clear();
    file.flush().await
}
