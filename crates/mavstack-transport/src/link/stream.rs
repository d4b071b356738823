//! Stream peers (TCP, serial): their reader and writer tasks, and the supervisor that
//! reopens a stream when it drops.

use core::time::Duration;

use tokio::io::{AsyncRead, AsyncReadExt as _, AsyncWrite, AsyncWriteExt as _};
use tokio::sync::mpsc;

use crate::clock;
use crate::connection::Options;
use crate::error::Reason;
use crate::protocol::{Framing, PeerAddr, PeerId, PeerInfo};
use crate::tlog;

use super::tasks::Tasks;
use super::{LINK_QUEUE, LinkMsg, PeerIds, PeerWriter, READ_CHUNK, WriterQueue};

/// Reads a stream into [`LinkMsg::Data`] until it ends, fails or the link closes. Returns
/// why it ended, if by an error.
pub(super) async fn read_stream<R: AsyncRead + Unpin>(
    mut reader: R,
    peer: PeerId,
    tx: &mpsc::Sender<LinkMsg>,
) -> Option<Reason> {
    loop {
        let mut buf = vec![0u8; READ_CHUNK];
        let n = tokio::select! {
            () = tx.closed() => return None,
            r = reader.read(&mut buf) => match r {
                Ok(0) => return None,
                Ok(n) => n,
                Err(e) => return Some(Reason::from_io(&e)),
            },
        };
        buf.truncate(n);
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes: buf,
        };
        if tx.send(msg).await.is_err() {
            return None;
        }
    }
}

/// Writes what the driver queues for one peer, coalescing queued transmits into one write.
pub(super) async fn write_stream<W: AsyncWrite + Unpin>(
    mut writer: W,
    mut rx: mpsc::Receiver<Vec<u8>>,
    what: String,
) {
    let mut out = Vec::with_capacity(tlog::BUFFER_LEN);
    while let Some(first) = rx.recv().await {
        out.clear();
        out.extend_from_slice(&first);
        while out.len() < tlog::BUFFER_LEN {
            match rx.try_recv() {
                Ok(more) => out.extend_from_slice(&more),
                Err(_) => break,
            }
        }
        if let Err(e) = writer.write_all(&out).await {
            tracing::debug!("{what}: write failed: {e}");
            return;
        }
    }
    let _ = writer.shutdown().await;
}

/// Starts the writer task of a stream peer.
pub(super) fn spawn_writer<W>(writer: W, what: String, queue: usize) -> PeerWriter
where
    W: AsyncWrite + Unpin + Send + 'static,
{
    let (wtx, wrx) = mpsc::channel(queue.max(1));
    PeerWriter {
        queue: WriterQueue::Plain(wtx),
        task: Some(tokio::spawn(write_stream(writer, wrx, what))),
    }
}

/// Reads a stream peer until it ends, then reports it gone. Returns false when the link has
/// closed.
pub(super) async fn read_peer<R: AsyncRead + Unpin>(
    reader: R,
    id: PeerId,
    what: &str,
    tx: &mpsc::Sender<LinkMsg>,
) -> bool {
    match read_stream(reader, id, tx).await {
        Some(reason) => tracing::info!("{what}: {reason}"),
        None => tracing::debug!("{what}: closed"),
    }
    tx.send(LinkMsg::PeerRemoved(id)).await.is_ok()
}

/// A link over one stream that is reopened when it drops (a TCP client connection, a
/// serial port). `first`, when already open, becomes the first peer at once; without it the
/// supervisor starts by reconnecting.
pub(super) fn supervise<S, F, Fut>(
    first: Option<S>,
    addr: PeerAddr,
    what: String,
    ids: PeerIds,
    options: &Options,
    reopen: F,
) -> Tasks
where
    S: AsyncRead + AsyncWrite + Send + 'static,
    F: FnMut() -> Fut + Send + 'static,
    Fut: Future<Output = Result<S, Reason>> + Send + 'static,
{
    let (tx, rx) = mpsc::channel(LINK_QUEUE);
    let mut tasks = Tasks::new(rx);
    let first_id = ids.next();
    let reader = first.map(|stream| {
        let info = PeerInfo {
            id: first_id,
            addr: addr.clone(),
            framing: Framing::Stream,
        };
        let (reader, writer) = tokio::io::split(stream);
        let writer = spawn_writer(writer, what.clone(), options.write_queue);
        tasks.writers.insert(info.id, writer);
        tasks.initial.push(info);
        reader
    });
    let supervisor = Supervisor {
        first_id,
        addr,
        what,
        ids,
        tx,
        options: options.clone(),
    };
    tokio::spawn(supervisor.run(reader, reopen));
    tasks
}

/// Keeps one stream up, reopening it with exponential back-off when it drops.
pub(super) struct Supervisor {
    first_id: PeerId,
    addr: PeerAddr,
    what: String,
    ids: PeerIds,
    tx: mpsc::Sender<LinkMsg>,
    options: Options,
}

impl Supervisor {
    async fn run<S, F, Fut>(self, first: Option<tokio::io::ReadHalf<S>>, mut reopen: F)
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
        F: FnMut() -> Fut,
        Fut: Future<Output = Result<S, Reason>>,
    {
        let min = self.options.reconnect_min.max(Duration::from_millis(1));
        let max = self.options.reconnect_max.max(min);
        let mut reader = first;
        let mut id = self.first_id;
        loop {
            if let Some(r) = reader.take()
                && !read_peer(r, id, &self.what, &self.tx).await
            {
                return;
            }
            let mut delay = min;
            let stream = loop {
                tracing::debug!("{}: reconnecting in {delay:?}", self.what);
                tokio::select! {
                    () = self.tx.closed() => return,
                    () = tokio::time::sleep(delay) => {}
                }
                let attempt = tokio::select! {
                    () = self.tx.closed() => return,
                    r = reopen() => r,
                };
                match attempt {
                    Ok(s) => {
                        tracing::info!("{}: connected again", self.what);
                        break s;
                    }
                    Err(reason) => {
                        tracing::debug!("{}: {reason}", self.what);
                        delay = (delay * 2).min(max);
                    }
                }
            };
            id = self.ids.next();
            let (r, w) = tokio::io::split(stream);
            let writer = spawn_writer(w, self.what.clone(), self.options.write_queue);
            let info = PeerInfo {
                id,
                addr: self.addr.clone(),
                framing: Framing::Stream,
            };
            let added = LinkMsg::PeerAdded {
                info,
                writer: Some(writer),
            };
            if self.tx.send(added).await.is_err() {
                return;
            }
            reader = Some(r);
        }
    }
}
