//! The driver: the state of a running node and one turn of it (read the ready links, run
//! what is due, forward, carry out a command).

use std::collections::HashMap;

use mavstack_core::Message;
use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_router::{Event, LinkConfig, LinkId, LocalFrames, Router, SendTo};
use mavstack_transport::protocol::Framing;
use mavstack_transport::{Dest, Input, Link, PeerId, PeerInfo, clock};
use tokio::sync::mpsc;

use super::batch::BatchSink;
pub(super) use super::heartbeat::Heartbeat;
use super::log::TrafficLog;
use super::moderation::Moderation;
use super::{Command, Incoming, LinkEvent, NodeError, NodeEvent, NodeReport, Tapped};

/// A link's peers: their router link, framing and address, looked up per input (foldhash
/// instead of SipHash).
pub(super) type PeerLinks = HashMap<PeerId, (LinkId, Framing, String), foldhash::fast::RandomState>;

/// One configured link and the router links of its peers.
pub(super) struct Slot {
    pub(super) io: Link,
    pub(super) template: LinkConfig,
    pub(super) peers: PeerLinks,
    /// Its socket is on the node thread's own poll (`NodeBuilder::own_thread`), not the
    /// runtime's.
    pub(super) polled: bool,
}

pub(super) struct Driver {
    pub(super) router: Router,
    pub(super) slots: Vec<Slot>,
    /// Router link → (slot, peer).
    pub(super) owners: Vec<Option<(usize, PeerId)>>,
    pub(super) commands: mpsc::Receiver<Command>,
    pub(super) log: Option<TrafficLog>,
    pub(super) log_local_only: bool,
    pub(super) started: Instant,
    pub(super) buf: [u8; MAX_FRAME_LEN],
    pub(super) subscribers: Vec<mpsc::Sender<Incoming>>,
    /// Batch subscribers ([`super::NodeHandle::subscribe_batched`]).
    pub(super) batches: Vec<BatchSink>,
    /// The router's local frames of the turn being delivered (kept for its allocation).
    pub(super) local: LocalFrames,
    pub(super) subscriber_drops: u64,
    pub(super) watchers: Vec<mpsc::Sender<NodeEvent>>,
    /// Peer events of the last dispatch, for the watchers.
    pub(super) pending: Vec<NodeEvent>,
    pub(super) taps: Vec<mpsc::Sender<Tapped>>,
    pub(super) heartbeat: Option<Heartbeat>,
    pub(super) moderation: Moderation,
    /// On a thread of its own: that thread's poll and its "waiting, input sparse" flag, for
    /// the batch readers to wait beside it (see `batch`).
    #[cfg(target_os = "linux")]
    pub(super) reader_poll: Option<(
        std::os::fd::OwnedFd,
        std::sync::Arc<core::sync::atomic::AtomicBool>,
    )>,
}

/// What a driver turn leaves to do.
pub(super) enum Turn {
    /// Wait for the next input; `worked`: the turn did something (it found input, a command
    /// or a due timer).
    Go { worked: bool },
    /// Shut down.
    Stop,
}

/// The [`Input`] a slot's link feeds: peers become router links.
pub(super) struct Feed<'a> {
    pub(super) router: &'a mut Router,
    pub(super) slot: usize,
    pub(super) template: &'a LinkConfig,
    pub(super) peers: &'a mut PeerLinks,
    pub(super) owners: &'a mut Vec<Option<(usize, PeerId)>>,
    /// Peer events, when someone watches.
    pub(super) pending: Option<&'a mut Vec<NodeEvent>>,
    /// Inputs (datagrams, stream reads) fed, for [`Moderation`].
    pub(super) inputs: &'a mut u64,
    /// Who gets a copy of every input.
    pub(super) taps: &'a mut Vec<mpsc::Sender<Tapped>>,
}

impl Input for Feed<'_> {
    fn handle_peer_added(&mut self, _now: Instant, peer: &PeerInfo) {
        match self.router.add_link(self.template.clone()) {
            Ok(id) => {
                tracing::debug!("{}: {} is {id}", self.template.name, peer.addr);
                self.peers
                    .insert(peer.id, (id, peer.framing, peer.addr.to_string()));
                if self.owners.len() <= id.index() {
                    self.owners.resize(id.index() + 1, None);
                }
                self.owners[id.index()] = Some((self.slot, peer.id));
                if let Some(pending) = &mut self.pending {
                    pending.push(NodeEvent {
                        link: self.template.name.clone(),
                        link_id: id,
                        kind: LinkEvent::PeerAdded {
                            peer: peer.addr.to_string(),
                        },
                    });
                }
            }
            Err(e) => tracing::warn!("{}: {e}", self.template.name),
        }
    }

    fn handle_peer_removed(&mut self, _now: Instant, peer: PeerId) {
        if let Some((id, _, addr)) = self.peers.remove(&peer) {
            tracing::debug!("{}: {addr} went away", self.template.name);
            self.router.remove_link(id);
            if let Some(o) = self.owners.get_mut(id.index()) {
                *o = None;
            }
            if let Some(pending) = &mut self.pending {
                pending.push(NodeEvent {
                    link: self.template.name.clone(),
                    link_id: id,
                    kind: LinkEvent::PeerRemoved { peer: addr },
                });
            }
        }
    }

    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]) {
        *self.inputs += 1;
        if let Some(&(id, framing, _)) = self.peers.get(&peer) {
            if !self.taps.is_empty() {
                self.taps.retain(|t| !t.is_closed());
                for t in self.taps.iter() {
                    let _ = t.try_send(Tapped {
                        link_id: id,
                        at: now,
                        bytes: data.to_vec(),
                        datagram: framing == Framing::Datagram,
                    });
                }
            }
            match framing {
                Framing::Datagram => self.router.handle_datagram(now, id, data),
                Framing::Stream => self.router.handle_input(now, id, data),
            }
        }
    }
}

impl Driver {
    pub(super) fn feed(&mut self, i: usize) -> (&mut Link, Feed<'_>) {
        let slot = &mut self.slots[i];
        (
            &mut slot.io,
            Feed {
                router: &mut self.router,
                slot: i,
                template: &slot.template,
                peers: &mut slot.peers,
                owners: &mut self.owners,
                pending: (!self.watchers.is_empty()).then_some(&mut self.pending),
                inputs: &mut self.moderation.inputs,
                taps: &mut self.taps,
            },
        )
    }

    pub(super) fn start_links(&mut self) {
        for i in 0..self.slots.len() {
            let (io, mut feed) = self.feed(i);
            io.start(&mut feed);
        }
    }

    /// Polls every running link and the command queue with `cx`; marks the links that may
    /// have input in `ready` and takes a command. Whether anything was ready, and whether
    /// the runtime's side (the commands, helper-task links) is to be polled again next time
    /// (it had something: a poll that finds something registers no waker). With `runtime` false that
    /// side is only looked at ([`Link::ready_now`]), not polled: the caller knows that the
    /// waker it registered last time has not been woken since.
    pub(super) fn poll_inputs(
        &mut self,
        cx: &mut core::task::Context<'_>,
        ready: &mut [bool],
        command: &mut Option<Option<Command>>,
        runtime: bool,
    ) -> (bool, bool) {
        let mut any = false;
        let mut from_runtime = false;
        for (slot, r) in self.slots.iter_mut().zip(ready.iter_mut()) {
            if slot.io.finished().is_some() {
                continue;
            }
            let input = if runtime {
                slot.io.poll_ready(cx).is_ready()
            } else {
                slot.io.ready_now()
            };
            if input {
                *r = true;
                any = true;
                from_runtime |= !slot.polled;
            }
        }
        if runtime
            && command.is_none()
            && let core::task::Poll::Ready(c) = self.commands.poll_recv(cx)
        {
            *command = Some(c);
            any = true;
        }
        // A command taken (now or on an earlier look of this turn) left the queue unpolled
        // until it answers pending: poll it again next time.
        (any, from_runtime || command.is_some())
    }

    /// One turn after a wake-up at `now`: reads the ready links and forwards at once, then
    /// runs what is due and carries out `command` (`Some(None)`: every handle is gone).
    pub(super) fn turn(
        &mut self,
        now: Instant,
        ready: &mut [bool],
        command: Option<Option<Command>>,
        timer: bool,
    ) -> Result<Turn, NodeError> {
        let mut worked = command.is_some() || timer;
        for (i, r) in ready.iter_mut().enumerate() {
            if core::mem::take(r) {
                let (io, mut feed) = self.feed(i);
                worked |= io.dispatch(&mut feed);
            }
        }
        // What the input brought goes out first: the heartbeat, the timers and the events
        // (subscribers, the log) can wait the few microseconds.
        self.flush();
        if let Some(hb) = &mut self.heartbeat
            && hb.due(now)
        {
            self.router.send(
                now,
                SendTo::Target,
                mavstack_dialects::common::Heartbeat::ID,
                &hb.payload,
            );
        }
        if timer {
            self.router.handle_timeout(now);
            for i in 0..self.slots.len() {
                if self.slots[i]
                    .io
                    .next_housekeeping()
                    .is_some_and(|t| now >= t)
                {
                    let (io, mut feed) = self.feed(i);
                    io.housekeeping(&mut feed);
                }
            }
        }
        self.drain_events()?;
        self.flush();
        match command {
            Some(Some(Command::Report(tx))) => {
                let _ = tx.send(self.report(clock::now()));
            }
            Some(Some(Command::Send {
                to,
                msg_id,
                payload,
                done,
            })) => {
                let queued = self.router.send(clock::now(), to, msg_id, &payload);
                self.flush();
                let _ = done.send(queued);
            }
            Some(Some(Command::Subscribe(tx, done))) => {
                self.subscribers.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::SubscribeBatched(sink, done))) => {
                #[cfg(target_os = "linux")]
                if let Some((poll, idle)) = &self.reader_poll {
                    use std::os::fd::AsFd as _;
                    match super::batch::NodeInput::new(poll.as_fd(), idle) {
                        Ok(input) => sink.watch_node(input),
                        // It waits as any other reader: woken by this thread.
                        Err(e) => tracing::debug!("a batch reader cannot watch the poll: {e}"),
                    }
                }
                self.batches.push(sink);
                let _ = done.send(());
            }
            Some(Some(Command::Events(tx, done))) => {
                self.watchers.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::Tap(tx, done))) => {
                self.taps.push(tx);
                let _ = done.send(());
            }
            Some(Some(Command::SendBytes { link, bytes, done })) => {
                let sent = match self.owners.get(link.index()) {
                    Some(Some((slot, peer))) => {
                        let io = &mut self.slots[*slot].io;
                        io.send(Dest::Peer(*peer), &bytes);
                        io.flush();
                        true
                    }
                    _ => false,
                };
                let _ = done.send(sent);
            }
            Some(Some(Command::Handshake {
                link,
                target,
                method,
                encoding,
                done,
            })) => {
                let started =
                    self.router
                        .start_handshake(clock::now(), link, target, method, encoding);
                self.flush();
                let _ = done.send(started);
            }
            Some(Some(Command::SetSigning {
                link,
                signing,
                done,
            })) => {
                let set = self.router.set_signing(clock::now(), link, signing);
                self.drain_events()?;
                let _ = done.send(set);
            }
            Some(Some(Command::SetSigningAll { signing, done })) => {
                // Peers that come later take it from their link's template.
                for slot in &mut self.slots {
                    slot.template.signing.clone_from(&signing);
                }
                let now = clock::now();
                let links: Vec<LinkId> = self.router.links().collect();
                let mut set = Ok(());
                for link in links {
                    if let Err(e) = self.router.set_signing(now, link, signing.clone()) {
                        set = Err(e);
                    }
                }
                self.drain_events()?;
                let _ = done.send(set);
            }
            Some(Some(Command::HoldSetupSigning { held, done })) => {
                self.router.hold_setup_signing(held);
                let _ = done.send(());
            }
            Some(Some(Command::Shutdown) | None) => return Ok(Turn::Stop),
            None => {}
        }
        Ok(Turn::Go { worked })
    }

    /// The error of the first link that failed.
    pub(super) fn failed(&self) -> Option<NodeError> {
        self.slots.iter().find_map(|s| match s.io.finished() {
            Some(Err(e)) => Some(NodeError::Link {
                name: s.template.name.clone(),
                source: e.clone(),
            }),
            _ => None,
        })
    }

    /// Sends what is queued, closes the links, writes out the log; the final report.
    pub(super) async fn finish(
        mut self,
        result: Result<(), NodeError>,
    ) -> Result<NodeReport, NodeError> {
        self.flush();
        for slot in &mut self.slots {
            if let Err(e) = slot.io.shutdown().await {
                tracing::warn!("{}: {e}", slot.template.name);
            }
        }
        let report = self.report(clock::now());
        if let Some(log) = self.log.take() {
            // Writing out and syncing blocks: off the runtime's threads.
            tokio::task::spawn_blocking(move || log.finish())
                .await
                .map_err(|e| NodeError::Stopped(e.to_string()))??;
        }
        result.map(|()| report)
    }

    pub(super) fn next_deadline(&self) -> Option<Instant> {
        let housekeeping = self
            .slots
            .iter()
            .filter_map(|s| s.io.next_housekeeping())
            .min();
        let heartbeat = self.heartbeat.as_ref().map(|h| h.next);
        [self.router.poll_timeout(), housekeeping, heartbeat]
            .into_iter()
            .flatten()
            .min()
    }

    /// Hands the frames for the node (the router's local frames) to the traffic log, the
    /// batch subscribers and the subscribers, each frame copied once per batch and once per
    /// subscriber (none for a batch subscriber alone).
    fn deliver_local(&mut self) {
        let mut local = core::mem::take(&mut self.local);
        self.router.take_local(&mut local);
        if self.log.is_none() && self.subscribers.is_empty() && self.batches.len() == 1 {
            // A batch reader alone (a Python connection): the frames change hands whole.
            self.batches[0].stage_all(&mut local);
            self.local = local;
            return;
        }
        for frame in local.iter() {
            if let Some(log) = &mut self.log {
                let slot = self.owners.get(frame.link.index()).copied().flatten();
                log.push(
                    slot.map(|(s, _)| s),
                    frame.received_at.as_micros(),
                    frame.bytes,
                );
            }
            if self.log_local_only {
                continue;
            }
            for b in &mut self.batches {
                b.push(&frame);
            }
            if self.subscribers.is_empty() {
                continue;
            }
            let Some(received) = frame.to_received() else {
                continue;
            };
            let incoming = Incoming {
                link: self.link_label(frame.link),
                link_id: frame.link,
                frame: received,
            };
            self.subscribers.retain(|s| !s.is_closed());
            for s in &self.subscribers {
                if s.try_send(incoming.clone()).is_err() {
                    self.subscriber_drops += 1;
                }
            }
        }
        self.local = local;
    }

    pub(super) fn drain_events(&mut self) -> Result<(), NodeError> {
        self.deliver_local();
        while let Some(event) = self.router.poll_event() {
            match event {
                Event::VersionChanged {
                    link,
                    from,
                    to,
                    cause,
                } => {
                    tracing::info!("{}: {from} → {to} ({cause})", self.link_label(link));
                    self.tell(link, LinkEvent::VersionChanged { from, to, cause });
                }
                Event::Rejected { link, rejected } => {
                    tracing::debug!("{}: rejected {:?}", self.link_label(link), rejected.reason);
                    self.tell(link, LinkEvent::Rejected(rejected));
                }
                Event::ProtocolVersionRequested { link, from, answer } => {
                    tracing::info!("{}: handshake request: {answer}", self.link_label(link));
                    self.tell(link, LinkEvent::ProtocolVersionRequested { from, answer });
                }
                Event::Handshake { link, outcome } => {
                    tracing::info!(
                        "{}: handshake: {}",
                        self.link_label(link),
                        outcome.result.name()
                    );
                    self.tell(link, LinkEvent::Handshake(outcome));
                }
                Event::SigningSetup { link, from, setup } => {
                    tracing::info!("{}: SETUP_SIGNING applied", self.link_label(link));
                    self.tell(link, LinkEvent::SigningSetup { from, setup });
                }
                _ => {}
            }
        }
        if !self.batches.is_empty() {
            self.batches.retain(BatchSink::is_open);
            for b in &mut self.batches {
                self.subscriber_drops += b.publish();
            }
        }
        let pending = core::mem::take(&mut self.pending);
        for event in pending {
            self.publish(event);
        }
        if let Some(log) = &mut self.log {
            log.send()?;
        }
        Ok(())
    }

    /// Tells the watchers what happened on `link`.
    pub(super) fn tell(&mut self, link: LinkId, kind: LinkEvent) {
        if self.watchers.is_empty() {
            return;
        }
        let event = NodeEvent {
            link: self.link_label(link),
            link_id: link,
            kind,
        };
        self.publish(event);
    }

    pub(super) fn publish(&mut self, event: NodeEvent) {
        self.watchers.retain(|w| !w.is_closed());
        for w in &self.watchers {
            if w.try_send(event.clone()).is_err() {
                self.subscriber_drops += 1;
            }
        }
    }

    pub(super) fn link_label(&self, link: LinkId) -> String {
        self.router
            .link_config(link)
            .map_or_else(|| link.to_string(), |c| c.name.clone())
    }

    /// Writes every queued frame to its link, then sends the batches.
    pub(super) fn flush(&mut self) {
        while let Some(t) = self.router.poll_transmit(&mut self.buf) {
            if let Some(Some((slot, peer))) = self.owners.get(t.link.index()) {
                self.slots[*slot]
                    .io
                    .send(Dest::Peer(*peer), &self.buf[..t.len]);
            }
        }
        for slot in &mut self.slots {
            slot.io.flush();
        }
    }
}
