//! Links whose peers are code of the caller's (a fleet bridge's broker connection).

use std::sync::Arc;

use tokio::sync::mpsc;

use crate::clock;
use crate::protocol::{Framing, PeerAddr, PeerId, PeerInfo};

use super::tasks::Tasks;
use super::{
    Kind, LINK_QUEUE, Link, LinkMsg, LinkStats, PeerIds, PeerTable, PeerWriter, WriterQueue,
};

/// The far end of a [`Link::external`]: the code that carries its frames.
#[derive(Debug)]
pub struct ExternalPeer {
    ids: PeerIds,
    first: Option<PeerId>,
    input: mpsc::Sender<LinkMsg>,
    output_tx: mpsc::Sender<(PeerId, Vec<u8>)>,
    output: mpsc::Receiver<(PeerId, Vec<u8>)>,
}

/// A cloneable handle that hands frames to a [`Link::external`] (what
/// [`ExternalPeer::deliver`] does), for code that reads the link's output in another task.
#[derive(Clone, Debug)]
pub struct ExternalSender {
    input: mpsc::Sender<LinkMsg>,
}

impl ExternalSender {
    /// Hands `bytes` (whole frames) to the link as one datagram from `peer`, waiting while
    /// the link's queue is full. False once the link has closed.
    pub async fn deliver(&self, peer: PeerId, bytes: Vec<u8>) -> bool {
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes,
        };
        self.input.send(msg).await.is_ok()
    }
}

impl ExternalPeer {
    /// A handle that delivers frames to the link while this end is busy receiving.
    #[must_use]
    pub fn sender(&self) -> ExternalSender {
        ExternalSender {
            input: self.input.clone(),
        }
    }

    /// The peer the link started with, if it did.
    #[must_use]
    pub const fn first(&self) -> Option<PeerId> {
        self.first
    }

    /// Hands `bytes` (whole frames) to the link as one datagram from `peer`, waiting while
    /// the link's queue is full. False once the link has closed.
    pub async fn deliver(&self, peer: PeerId, bytes: Vec<u8>) -> bool {
        let msg = LinkMsg::Data {
            peer,
            time: clock::now(),
            bytes,
        };
        self.input.send(msg).await.is_ok()
    }

    /// A new peer named `what` (a router link of its own); `None` once the link has closed.
    pub async fn add_peer(&self, what: impl Into<String>) -> Option<PeerId> {
        let id = self.ids.next();
        let info = PeerInfo {
            id,
            addr: PeerAddr::External(what.into()),
            framing: Framing::Datagram,
        };
        let writer = PeerWriter {
            queue: WriterQueue::Tagged(id, self.output_tx.clone()),
            task: None,
        };
        let msg = LinkMsg::PeerAdded {
            info,
            writer: Some(writer),
        };
        self.input.send(msg).await.ok().map(|()| id)
    }

    /// `peer` went away (its router link goes with it).
    pub async fn remove_peer(&self, peer: PeerId) {
        let _ = self.input.send(LinkMsg::PeerRemoved(peer)).await;
    }

    /// The next frame the link sends, and to which peer; `None` once the link has closed
    /// (and what it sent before has been taken).
    pub async fn recv(&mut self) -> Option<(PeerId, Vec<u8>)> {
        // This end keeps a sender for the peers it adds, so the queue alone never ends:
        // the link's end is its input queue closing.
        tokio::select! {
            biased;
            frame = self.output.recv() => frame,
            () = self.input.closed() => self.output.try_recv().ok(),
        }
    }

    /// A frame the link has sent, if one is waiting.
    pub fn try_recv(&mut self) -> Option<(PeerId, Vec<u8>)> {
        self.output.try_recv().ok()
    }
}

impl Link {
    /// A link whose peers are code of the caller's (a fleet bridge's broker connection):
    /// what the link sends to them comes out of [`ExternalPeer::recv`], one frame each,
    /// tagged with the peer; what [`ExternalPeer::deliver`] is given comes in as a datagram
    /// from a peer. The link starts with one peer named `first` when given (known before the
    /// link starts, so nothing sent right away is lost); more come and go with
    /// [`ExternalPeer::add_peer`] and [`ExternalPeer::remove_peer`] (each a router link of
    /// its own). The link ends when the [`ExternalPeer`] is dropped.
    ///
    /// `queue` bounds the frames waiting for the caller (more are dropped and counted as
    /// [`LinkStats::tx_dropped`], like a full writer queue).
    #[must_use]
    pub fn external(first: Option<String>, queue: usize) -> (Self, ExternalPeer) {
        let ids = PeerIds::default();
        let (tx, rx) = mpsc::channel(LINK_QUEUE);
        let (wtx, wrx) = mpsc::channel(queue.max(1));
        let mut tasks = Tasks::new(rx);
        let first = first.map(|what| {
            let id = ids.next();
            tasks.writers.insert(
                id,
                PeerWriter {
                    queue: WriterQueue::Tagged(id, wtx.clone()),
                    task: None,
                },
            );
            tasks.initial.push(PeerInfo {
                id,
                addr: PeerAddr::External(what),
                framing: Framing::Datagram,
            });
            id
        });
        let link = Self {
            kind: Kind::Tasks(tasks),
            stats: LinkStats::default(),
            peers: Arc::new(PeerTable::default()),
            finished: None,
            local_addr: None,
        };
        (
            link,
            ExternalPeer {
                ids,
                first,
                input: tx,
                output_tx: wtx,
                output: wrx,
            },
        )
    }
}
