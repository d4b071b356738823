//! The driver's side of the links run by helper tasks (TCP, serial, files, external).

use core::task::{Context, Poll};
use std::collections::HashMap;

use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::clock;
use crate::error::LinkError;
use crate::protocol::{Dest, Input, PeerId, PeerInfo};

use super::{BATCH, LinkMsg, LinkStats, PeerTable, PeerWriter, Queued};

#[derive(Debug)]
pub(super) struct Tasks {
    pub(super) rx: mpsc::Receiver<LinkMsg>,
    pub(super) pending: Option<LinkMsg>,
    pub(super) writers: HashMap<PeerId, PeerWriter>,
    /// File writers, awaited when the link closes so that nothing buffered is lost.
    pub(super) sinks: Vec<JoinHandle<Result<(), LinkError>>>,
    /// Peers known when the link opened, announced by [`Link::start`].
    pub(super) initial: Vec<PeerInfo>,
    /// A writer that failed (a file that cannot be written): the link ends with it.
    pub(super) failed: Option<Box<LinkError>>,
}

impl Tasks {
    pub(super) fn new(rx: mpsc::Receiver<LinkMsg>) -> Self {
        Self {
            rx,
            pending: None,
            writers: HashMap::new(),
            sinks: Vec::new(),
            initial: Vec::new(),
            failed: None,
        }
    }

    pub(super) fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<()> {
        if self.pending.is_some() || self.failed.is_some() {
            return Poll::Ready(());
        }
        self.rx.poll_recv(cx).map(|msg| {
            self.pending = Some(msg.unwrap_or(LinkMsg::Closed(Ok(()))));
        })
    }

    pub(super) fn dispatch<I: Input>(
        &mut self,
        proto: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> Option<Result<(), LinkError>> {
        if let Some(e) = self.failed.take() {
            return Some(Err(*e));
        }
        let mut next = self.pending.take();
        for _ in 0..BATCH {
            let Some(msg) = next.take() else { break };
            if let Some(end) = self.apply(msg, proto, stats, table) {
                return Some(end);
            }
            next = self.rx.try_recv().ok();
        }
        None
    }

    pub(super) fn apply<I: Input>(
        &mut self,
        msg: LinkMsg,
        proto: &mut I,
        stats: &mut LinkStats,
        table: &PeerTable,
    ) -> Option<Result<(), LinkError>> {
        match msg {
            LinkMsg::Data { peer, time, bytes } => {
                stats.rx_chunks += 1;
                stats.rx_bytes += bytes.len() as u64;
                proto.handle_input(time, peer, &bytes);
            }
            LinkMsg::Records { peer, bytes, parts } => {
                let mut from = 0;
                for (time, end) in parts {
                    let Some(part) = bytes.get(from..end) else {
                        break;
                    };
                    stats.rx_chunks += 1;
                    stats.rx_bytes += part.len() as u64;
                    proto.handle_input(time, peer, part);
                    from = end;
                }
            }
            LinkMsg::PeerAdded { info, writer } => {
                tracing::debug!("{} appeared as {}", info.addr, info.id);
                if let Some(w) = writer {
                    self.writers.insert(info.id, w);
                }
                table.add(info.clone());
                stats.peers_added += 1;
                proto.handle_peer_added(clock::now(), &info);
            }
            LinkMsg::PeerRemoved(id) => {
                tracing::debug!("{id} went away");
                self.writers.remove(&id);
                table.remove(id);
                stats.peers_removed += 1;
                proto.handle_peer_removed(clock::now(), id);
            }
            LinkMsg::Closed(end) => return Some(end),
        }
        None
    }

    pub(super) fn transmit(&mut self, dest: Dest, data: &[u8], stats: &mut LinkStats) {
        let failed = &mut self.failed;
        let mut send = |writer: &mut PeerWriter| match writer.queue.try_send(data) {
            Queued::Yes => {
                stats.tx_chunks += 1;
                stats.tx_bytes += data.len() as u64;
            }
            Queued::Full => stats.tx_dropped += 1,
            Queued::Failed(e) => {
                stats.tx_errors += 1;
                failed.get_or_insert(Box::new(e));
            }
        };
        match dest {
            Dest::Peer(id) => match self.writers.get_mut(&id) {
                Some(w) => send(w),
                None => stats.tx_dropped += 1,
            },
            Dest::All | Dest::AllExcept(_) => {
                let mut sent = false;
                for (&id, w) in &mut self.writers {
                    if dest != Dest::AllExcept(id) {
                        send(w);
                        sent = true;
                    }
                }
                if !sent {
                    stats.tx_dropped += 1;
                }
            }
        }
    }
}
