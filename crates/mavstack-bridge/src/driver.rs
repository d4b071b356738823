//! What every bridge link does, whatever carries it: the vehicle's end (its network onto
//! its keys, frames in, commands run here) and the ground's end (each vehicle a link of the
//! router), over a [`Broker`]: the MQTT or Zenoh client, which only moves bytes.

use core::future::Future;
use core::sync::atomic::{AtomicU64, Ordering};
use core::time::Duration;
use std::collections::HashMap;
use std::sync::Arc;

use mavstack_core::wire::Frame;
use mavstack_router::{LinkConfig, MessageTable, is_control};
use mavstack_transport::{ExternalPeer, Link, PeerId, clock};
use tokio::task::JoinHandle;

use crate::checksum;
use crate::command::{CommandTiming, Commands, Reply, RequestError};
use crate::keys::{FleetTopic, fleet_topic};
use crate::outbox::{Lane, Outbox, Outgoing};
use crate::remap::{Remapped, SysidMap};
use crate::{BridgeSpec, Keys, Side, Topic};

/// Frames from the router waiting for the bridge.
pub(crate) const LINK_QUEUE: usize = 4096;
/// Control frames and telemetry keys waiting for a slow broker.
const OUTBOX_CONTROL: usize = 4096;
const OUTBOX_KEYS: usize = 8192;
/// How often a full client queue is tried again.
const RETRY: Duration = Duration::from_millis(2);
/// How often vehicles refused for `max_vehicles` are warned about, at most.
const REFUSAL_WARN_EVERY: Duration = Duration::from_secs(10);

/// Counters of one bridge link (read while it runs).
#[derive(Debug, Default)]
pub struct BridgeStats {
    /// Frames published.
    pub published: AtomicU64,
    /// Frames from the broker let into the network (`in` and `@cmd`).
    pub received: AtomicU64,
    /// Telemetry frames replaced by a newer one on their key while the broker was slow.
    pub replaced: AtomicU64,
    /// Control frames dropped with the outbox full.
    pub dropped_control: AtomicU64,
    /// Telemetry dropped with the outbox full.
    pub dropped_telemetry: AtomicU64,
    /// Command requests answered (ACKs, errors and timeouts).
    pub replies: AtomicU64,
    /// Connections made to the broker (the first included).
    pub connections: AtomicU64,
    /// Frames dropped because their checksum was wrong: from the broker (`in`, `@cmd`, a
    /// vehicle's keys on the ground side) or towards a vehicle on the ground side.
    pub bad_crc: AtomicU64,
    /// Ground side: messages of vehicles that would have been a link beyond
    /// `max_vehicles`, ignored.
    pub vehicles_refused: AtomicU64,
    /// [`BridgeStats::replaced`] per key.
    pub replaced_by_key: std::sync::Mutex<std::collections::BTreeMap<String, u64>>,
}

impl BridgeStats {
    /// The counters now.
    #[must_use]
    pub fn snapshot(&self) -> BridgeCounters {
        let n = |c: &AtomicU64| c.load(Ordering::Relaxed);
        BridgeCounters {
            published: n(&self.published),
            received: n(&self.received),
            replaced: n(&self.replaced),
            replaced_by_key: self
                .replaced_by_key
                .lock()
                .map(|m| m.clone())
                .unwrap_or_default(),
            dropped_control: n(&self.dropped_control),
            dropped_telemetry: n(&self.dropped_telemetry),
            replies: n(&self.replies),
            connections: n(&self.connections),
            bad_crc: n(&self.bad_crc),
            vehicles_refused: n(&self.vehicles_refused),
        }
    }
}

/// A snapshot of [`BridgeStats`] (the router's `--stats` lines carry one per bridge link).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct BridgeCounters {
    /// Frames published.
    pub published: u64,
    /// Frames from the broker let into the network.
    pub received: u64,
    /// Telemetry frames replaced by a newer one on their key.
    pub replaced: u64,
    /// The same per key.
    pub replaced_by_key: std::collections::BTreeMap<String, u64>,
    /// Control frames dropped with the outbox full.
    pub dropped_control: u64,
    /// Telemetry dropped with the outbox full.
    pub dropped_telemetry: u64,
    /// Command replies published.
    pub replies: u64,
    /// Connections made to the broker.
    pub connections: u64,
    /// Frames dropped because their checksum was wrong.
    pub bad_crc: u64,
    /// Ground side: messages of vehicles beyond `max_vehicles`, ignored.
    pub vehicles_refused: u64,
}

/// An open bridge link: give `config` and `link` to a node, keep `handle`.
#[derive(Debug)]
pub struct Bridge {
    /// The router's settings of the link.
    pub config: LinkConfig,
    /// The router's side.
    pub link: Link,
    /// The running bridge.
    pub handle: BridgeHandle,
}

/// A running bridge: its counters, and the wait for its end.
#[derive(Debug)]
pub struct BridgeHandle {
    /// Its counters.
    pub stats: Arc<BridgeStats>,
    pub(crate) task: JoinHandle<()>,
}

impl BridgeHandle {
    /// Waits until the bridge has closed (the node that had its link has shut down) and
    /// `offline` has been published, at most a couple of seconds.
    pub async fn finish(self) {
        let _ = self.task.await;
    }
}

/// What the broker's client tells the bridge.
#[derive(Debug)]
pub(crate) enum Incoming<R> {
    /// (Re)connected: time to subscribe and say `online`.
    Connected,
    /// A message on `topic`; `reply` is where a request's replies go, when it has one.
    Message {
        topic: String,
        payload: Vec<u8>,
        reply: Option<R>,
    },
}

/// A reply to a command request.
#[derive(Debug)]
pub(crate) enum Answer {
    /// The target's COMMAND_ACK frame; not `last` when it said IN_PROGRESS.
    Ack { frame: Vec<u8>, last: bool },
    /// No ACK, or the request was refused: the text, and its code (`timeout`,
    /// [`RequestError::code`](crate::command::RequestError::code)).
    Error { text: Vec<u8>, code: &'static str },
}

/// What a bridge subscribes to.
#[derive(Clone, Debug)]
pub(crate) enum Interest {
    /// A vehicle's `in` and `@cmd` keys.
    Vehicle(Keys),
    /// The frames and liveliness of the vehicles named (all when empty).
    Ground { fleet: String, vids: Vec<String> },
}

impl Interest {
    pub(crate) fn of(spec: &BridgeSpec) -> Self {
        match &spec.side {
            Side::Vehicle(keys) => Self::Vehicle(keys.clone()),
            Side::Ground(vids) => Self::Ground {
                fleet: spec.fleet.clone(),
                vids: vids.clone(),
            },
        }
    }
}

/// A broker's client as the bridge uses it. Nothing here may wait on the network for
/// long: a slow broker must never hold up the router's links.
pub(crate) trait Broker: Send + Sync + 'static {
    /// Where a request's replies go.
    type ReplyTo: Clone + Send + Sync + core::fmt::Debug + 'static;
    /// `mqtt` or `zenoh`, for logs and peer names.
    const NAME: &'static str;
    /// Hands a publish to the client without waiting: false when its queue is full.
    fn try_publish(&mut self, out: &Outgoing) -> bool;
    /// The next thing the broker says (`None`: the client has gone).
    fn next(&mut self) -> impl Future<Output = Option<Incoming<Self::ReplyTo>>> + Send;
    /// Connected: subscribe to what `interest` names; a vehicle says `online`.
    fn connected(&mut self, interest: &Interest) -> impl Future<Output = ()> + Send;
    /// Sends a reply to a request.
    fn answer(&mut self, to: &Self::ReplyTo, answer: Answer);
    /// The link has closed: what is queued goes, a vehicle (`alive`) says `offline`, then
    /// the client closes, all within a couple of seconds.
    fn close(self, alive: Option<String>) -> impl Future<Output = ()> + Send;
}

/// Starts the bridge's task over `broker` for `spec`; `stats` are the link's counters
/// (the client counts its connections there).
pub(crate) fn start<B: Broker>(
    spec: &BridgeSpec,
    dialect: MessageTable,
    broker: B,
    stats: Arc<BridgeStats>,
) -> Bridge {
    let first = match &spec.side {
        Side::Vehicle(_) => Some(format!("{} {}:{}", B::NAME, spec.host, spec.port)),
        Side::Ground(_) => None,
    };
    let (link, peer) = Link::external(first, LINK_QUEUE);
    let io = Io {
        broker,
        peer,
        outbox: Outbox::new(OUTBOX_CONTROL, OUTBOX_KEYS),
        stats: Arc::clone(&stats),
        interest: Interest::of(spec),
    };
    let task = match &spec.side {
        Side::Vehicle(keys) => tokio::spawn(
            Vehicle {
                io,
                keys: keys.clone(),
                dialect,
                commands: Commands::new(CommandTiming::default()),
            }
            .run(),
        ),
        Side::Ground(vids) => tokio::spawn(
            Ground {
                io,
                fleet: spec.fleet.clone(),
                vids: vids.clone(),
                dialect,
                vehicles: HashMap::new(),
                by_peer: HashMap::new(),
                sysids: SysidMap::default(),
                name: spec.name.clone(),
                max_vehicles: spec.max_vehicles,
                refusals: Refusals::default(),
            }
            .run(),
        ),
    };
    Bridge {
        config: spec.link_config(),
        link,
        handle: BridgeHandle { stats, task },
    }
}

/// What both ends share: the client, the link's far end, the outbox.
struct Io<B> {
    broker: B,
    peer: ExternalPeer,
    outbox: Outbox,
    stats: Arc<BridgeStats>,
    interest: Interest,
}

impl<B: Broker> Io<B> {
    /// Queues a publish of `frame` on `topic` (latest-wins by `key` for telemetry).
    fn queue(&mut self, frame: &[u8], msg_id: u32, key: String, topic: Option<String>) {
        let lane = if is_control(msg_id) {
            Lane::Control
        } else {
            Lane::Telemetry
        };
        if !self.outbox.push(lane, key, topic, frame.to_vec()) {
            let counter = match lane {
                Lane::Control => &self.stats.dropped_control,
                Lane::Telemetry => &self.stats.dropped_telemetry,
            };
            counter.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Hands what waits to the client until its queue is full.
    fn drain(&mut self) {
        while let Some(out) = self.outbox.pop() {
            if self.broker.try_publish(&out) {
                self.stats.published.fetch_add(1, Ordering::Relaxed);
            } else {
                self.outbox.unpop(out);
                break;
            }
        }
        let replaced = self.outbox.replaced();
        if self.stats.replaced.swap(replaced, Ordering::Relaxed) != replaced
            && let Ok(mut by_key) = self.stats.replaced_by_key.lock()
        {
            by_key.clone_from(self.outbox.replaced_by_key());
        }
    }

    async fn close(mut self, alive: Option<String>) {
        self.drain();
        let (published, replaced) = (
            self.stats.published.load(Ordering::Relaxed),
            self.outbox.replaced(),
        );
        self.broker.close(alive).await;
        tracing::debug!(
            "{}: closed ({published} published, {replaced} replaced)",
            B::NAME
        );
    }
}

/// The vehicle's end: its network onto its keys, frames in, commands run here.
struct Vehicle<B: Broker> {
    io: Io<B>,
    keys: Keys,
    dialect: MessageTable,
    commands: Commands<B::ReplyTo>,
}

impl<B: Broker> Vehicle<B> {
    async fn run(mut self) {
        let mut replies = Vec::new();
        let mut resend = Vec::new();
        loop {
            let wake = self.commands.poll_timeout().map(clock::to_tokio);
            let retry = !self.io.outbox.is_empty();
            tokio::select! {
                frame = self.io.peer.recv() => {
                    let Some((_, frame)) = frame else { break };
                    self.outgoing(&frame, &mut replies);
                    while let Some((_, frame)) = self.io.peer.try_recv() {
                        self.outgoing(&frame, &mut replies);
                    }
                }
                msg = self.io.broker.next() => match msg {
                    Some(msg) => self.handle_broker(msg).await,
                    None => break,
                },
                () = sleep_until(wake) => {
                    self.commands.handle_timeout(clock::now(), &mut resend, &mut replies);
                    for frame in resend.drain(..) {
                        self.deliver(frame).await;
                    }
                }
                () = tokio::time::sleep(RETRY), if retry => {}
            }
            for reply in replies.drain(..) {
                self.reply(reply);
            }
            self.io.drain();
        }
        let alive = self.keys.alive();
        self.io.close(Some(alive)).await;
    }

    async fn deliver(&self, frame: Vec<u8>) {
        if let Some(first) = self.io.peer.first() {
            self.io.stats.received.fetch_add(1, Ordering::Relaxed);
            self.io.peer.deliver(first, frame).await;
        }
    }

    /// A frame the router sends to the broker.
    fn outgoing(&mut self, frame: &[u8], replies: &mut Vec<Reply<B::ReplyTo>>) {
        let Ok(view) = Frame::new_checked(frame) else {
            return;
        };
        self.commands.handle_frame(clock::now(), frame, replies);
        let id = view.msg_id();
        let name = self.dialect.info(id).map(|i| i.name);
        let key = self.keys.message(view.sysid(), view.compid(), name, id);
        self.io.queue(&frame[..view.frame_len()], id, key, None);
    }

    async fn handle_broker(&mut self, msg: Incoming<B::ReplyTo>) {
        match msg {
            Incoming::Connected => self.io.broker.connected(&self.io.interest).await,
            Incoming::Message {
                topic,
                payload,
                reply,
            } => match self.keys.parse(&topic) {
                Some(Topic::In) => {
                    if checksum::any_bad(&payload, |id| self.dialect.info(id).copied()) {
                        self.io.stats.bad_crc.fetch_add(1, Ordering::Relaxed);
                        tracing::debug!("{}: a corrupt frame on {topic} dropped", B::NAME);
                        return;
                    }
                    self.deliver(payload).await;
                }
                Some(Topic::Command { sysid, compid }) => {
                    let Some(to) = reply else {
                        tracing::debug!("{}: a command request with no reply address", B::NAME);
                        return;
                    };
                    match self.commands.handle_request(
                        clock::now(),
                        (sysid, compid),
                        &payload,
                        to.clone(),
                    ) {
                        Ok(frame) => self.deliver(frame).await,
                        Err(e) => {
                            if e == RequestError::BadCrc {
                                self.io.stats.bad_crc.fetch_add(1, Ordering::Relaxed);
                            }
                            self.answer(
                                &to,
                                Answer::Error {
                                    text: e.to_string().into_bytes(),
                                    code: e.code(),
                                },
                            );
                        }
                    }
                }
                None => {}
            },
        }
    }

    fn reply(&mut self, reply: Reply<B::ReplyTo>) {
        match reply {
            Reply::Ack { to, frame, last } => self.answer(&to, Answer::Ack { frame, last }),
            Reply::Timeout { to } => self.answer(
                &to,
                Answer::Error {
                    text: b"timeout".to_vec(),
                    code: "timeout",
                },
            ),
        }
    }

    fn answer(&mut self, to: &B::ReplyTo, answer: Answer) {
        self.io.stats.replies.fetch_add(1, Ordering::Relaxed);
        self.io.broker.answer(to, answer);
    }
}

/// The ground's end: each vehicle heard (or named) a peer of the link, so a router link of
/// its own; what the router sends a vehicle goes to its `in` key.
struct Ground<B> {
    io: Io<B>,
    fleet: String,
    /// The vehicles wanted (all when empty).
    vids: Vec<String>,
    dialect: MessageTable,
    vehicles: HashMap<String, PeerId>,
    by_peer: HashMap<PeerId, Keys>,
    /// Vehicles that share a sysid get distinct ones here.
    sysids: SysidMap,
    /// The link's name, for logs.
    name: String,
    /// Vehicles that may be links at once.
    max_vehicles: usize,
    refusals: Refusals,
}

/// Vehicles refused for `max_vehicles` since the last warning.
#[derive(Debug, Default)]
struct Refusals {
    since_warning: u64,
    last_warning: Option<tokio::time::Instant>,
}

impl<B: Broker> Ground<B> {
    async fn run(mut self) {
        loop {
            let retry = !self.io.outbox.is_empty();
            tokio::select! {
                frame = self.io.peer.recv() => {
                    let Some((peer, frame)) = frame else { break };
                    self.outgoing(peer, &frame);
                    while let Some((peer, frame)) = self.io.peer.try_recv() {
                        self.outgoing(peer, &frame);
                    }
                }
                msg = self.io.broker.next() => match msg {
                    Some(msg) => self.handle_broker(msg).await,
                    None => break,
                },
                () = tokio::time::sleep(RETRY), if retry => {}
            }
            self.io.drain();
        }
        self.io.close(None).await;
    }

    /// A frame from a local ground station for vehicle `peer`: onto its `in` key
    /// (latest-wins per source and message for telemetry, in order for control).
    fn outgoing(&mut self, peer: PeerId, frame: &[u8]) {
        let (Some(keys), Ok(view)) = (self.by_peer.get(&peer), Frame::new_checked(frame)) else {
            return;
        };
        let id = view.msg_id();
        let topic = keys.input();
        let key = format!("{topic}/{}/{}/{id}", view.sysid(), view.compid());
        let frame = &frame[..view.frame_len()];
        match self
            .sysids
            .to_vehicle(keys.vid(), frame, |id| self.dialect.info(id).copied())
        {
            Remapped::Same => self.io.queue(frame, id, key, Some(topic)),
            Remapped::Rewritten(f) => self.io.queue(&f, id, key, Some(topic)),
            Remapped::Dropped => {}
            Remapped::Corrupt => {
                self.io.stats.bad_crc.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    async fn handle_broker(&mut self, msg: Incoming<B::ReplyTo>) {
        match msg {
            Incoming::Connected => self.io.broker.connected(&self.io.interest).await,
            Incoming::Message { topic, payload, .. } => match fleet_topic(&self.fleet, &topic) {
                Some(FleetTopic::Frame { vid }) => {
                    if let Some(peer) = self.vehicle(vid).await {
                        let frame = match self
                            .sysids
                            .from_vehicle(vid, &payload, |id| self.dialect.info(id).copied())
                        {
                            Remapped::Same => payload,
                            Remapped::Rewritten(f) => f,
                            Remapped::Dropped => return,
                            Remapped::Corrupt => {
                                self.io.stats.bad_crc.fetch_add(1, Ordering::Relaxed);
                                tracing::debug!("{}: a corrupt frame on {topic} dropped", B::NAME);
                                return;
                            }
                        };
                        self.io.stats.received.fetch_add(1, Ordering::Relaxed);
                        self.io.peer.deliver(peer, frame).await;
                    }
                }
                Some(FleetTopic::Alive { vid }) => {
                    if payload == b"offline" {
                        if let Some(peer) = self.vehicles.remove(vid) {
                            self.by_peer.remove(&peer);
                            self.io.peer.remove_peer(peer).await;
                            tracing::info!("{}: vehicle {vid} went offline", B::NAME);
                        }
                    } else {
                        let _ = self.vehicle(vid).await;
                    }
                }
                None => {}
            },
        }
    }

    /// The peer of vehicle `vid`, added when first heard.
    async fn vehicle(&mut self, vid: &str) -> Option<PeerId> {
        if let Some(&peer) = self.vehicles.get(vid) {
            return Some(peer);
        }
        if !self.vids.is_empty() && !self.vids.iter().any(|v| v == vid) {
            return None;
        }
        let keys = Keys::new(&self.fleet, vid).ok()?;
        if self.vehicles.len() >= self.max_vehicles {
            self.refuse(vid);
            return None;
        }
        let peer = self
            .io
            .peer
            .add_peer(format!("{} {}/{vid}", B::NAME, self.fleet))
            .await?;
        tracing::info!("{}: vehicle {vid} is {peer}", B::NAME);
        self.vehicles.insert(vid.to_owned(), peer);
        self.by_peer.insert(peer, keys);
        Some(peer)
    }
}

impl<B> Ground<B> {
    /// Vehicle `vid` would be one link too many: counted, and warned about once per
    /// [`REFUSAL_WARN_EVERY`].
    fn refuse(&mut self, vid: &str) {
        self.io
            .stats
            .vehicles_refused
            .fetch_add(1, Ordering::Relaxed);
        let r = &mut self.refusals;
        r.since_warning += 1;
        let now = tokio::time::Instant::now();
        if r.last_warning
            .is_none_or(|at| now.duration_since(at) >= REFUSAL_WARN_EVERY)
        {
            tracing::warn!(
                "link \"{}\": {} vehicles are links already (max_vehicles); {} messages of \
                 further vehicles ignored (this one from {vid}); a vehicle that goes offline \
                 frees its place",
                self.name,
                self.vehicles.len(),
                r.since_warning,
            );
            r.since_warning = 0;
            r.last_warning = Some(now);
        }
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => core::future::pending().await,
    }
}
