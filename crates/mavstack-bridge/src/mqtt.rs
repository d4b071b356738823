//! The MQTT 5 link: rumqttc's event loop on a task of its own, the bridge's logic on
//! another, the router's side a [`Link::external`].
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn std::error::Error>> {
//! use mavstack_bridge::{BridgeSpec, mqtt};
//! use mavstack_router::InfoFn;
//! use mavstack_core::MessageSet as _;
//! let spec = BridgeSpec::parse("mqtt://127.0.0.1:1883?fleet=demo&vid=v1")?;
//! let dialect = InfoFn(|id| mavstack_dialects::common::MavMessage::info(id).copied());
//! let bridge = mqtt::open(&spec, dialect);
//! // Give the link to a node: `NodeBuilder::opened_link(bridge.config, bridge.link)`;
//! // after the node has shut down, `bridge.handle.finish().await` publishes `offline`.
//! # Ok(()) }
//! ```

use core::sync::atomic::{AtomicU64, Ordering};
use core::time::Duration;
use std::sync::Arc;

use mavstack_core::wire::Frame;
use mavstack_router::{InfoFn, LinkConfig, is_control};
use mavstack_transport::{ExternalPeer, Link, clock};
use rumqttc::v5::mqttbytes::QoS;
use rumqttc::v5::mqttbytes::v5::{LastWill, Packet, PublishProperties};
use rumqttc::v5::{AsyncClient, Event, EventLoop, MqttOptions};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use std::collections::HashMap;

use mavstack_transport::PeerId;

use crate::command::{CommandTiming, Commands, Reply};
use crate::keys::{FleetTopic, fleet_topic};
use crate::outbox::{Lane, Outbox};
use crate::remap::{Remapped, SysidMap};
use crate::{BridgeSpec, Keys, Side, Topic};

/// Publishes waiting in rumqttc's request queue at most.
const CLIENT_QUEUE: usize = 1024;
/// QoS 1 publishes in flight (unacknowledged) at most. rumqttc's default, 65,535, sizes a
/// table of that many publishes per client (13 MB); a fleet router holds many clients.
const INFLIGHT: u16 = 256;
/// Frames from the router waiting for the bridge.
const LINK_QUEUE: usize = 4096;
/// Control frames and telemetry keys waiting for a slow broker.
const OUTBOX_CONTROL: usize = 4096;
const OUTBOX_KEYS: usize = 8192;
/// How often a full client queue is tried again.
const RETRY: Duration = Duration::from_millis(2);
/// Longest wait before reconnecting to a broker that is down.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// How long closing waits for `offline` to reach the broker.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(2);

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
    task: JoinHandle<()>,
}

impl BridgeHandle {
    /// Waits until the bridge has closed (the node that had its link has shut down) and
    /// `offline` has been published, at most a couple of seconds.
    pub async fn finish(self) {
        let _ = self.task.await;
    }
}

/// Opens the MQTT link `spec` describes; `dialect` names the messages in the keys. The
/// broker is connected in the background (and reconnected, with back-off, whenever it
/// drops): opening never waits for it.
#[must_use]
pub fn open(spec: &BridgeSpec, dialect: InfoFn) -> Bridge {
    let mut options = MqttOptions::new(spec.client_id.clone(), spec.host.clone(), spec.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_clean_start(true);
    options.set_outgoing_inflight_upper_limit(INFLIGHT);
    // A frame goes when it comes (rumqttc leaves Nagle on: up to 40 ms more per publish).
    let mut network = rumqttc::NetworkOptions::new();
    network.set_tcp_nodelay(true);
    options.set_network_options(network);
    if let Side::Vehicle(keys) = &spec.side {
        options.set_last_will(LastWill::new(
            keys.alive(),
            "offline",
            QoS::AtLeastOnce,
            true,
            None,
        ));
    }
    if let Some((user, password)) = &spec.credentials {
        options.set_credentials(user.clone(), password.clone());
    }
    let (client, events) = AsyncClient::new(options, CLIENT_QUEUE);
    let first = match &spec.side {
        Side::Vehicle(_) => Some(format!("mqtt {}:{}", spec.host, spec.port)),
        Side::Ground(_) => None,
    };
    let (link, peer) = Link::external(first, LINK_QUEUE);
    let stats = Arc::new(BridgeStats::default());
    let (tx, rx) = mpsc::channel(CLIENT_QUEUE);
    let pump = tokio::spawn(pump(events, tx, Arc::clone(&stats)));
    let io = Io {
        client,
        peer,
        incoming: rx,
        outbox: Outbox::new(OUTBOX_CONTROL, OUTBOX_KEYS),
        stats: Arc::clone(&stats),
    };
    let task = match &spec.side {
        Side::Vehicle(keys) => tokio::spawn(
            Driver {
                io,
                keys: keys.clone(),
                dialect,
                commands: Commands::new(CommandTiming::default()),
            }
            .run(pump),
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
            }
            .run(pump),
        ),
    };
    Bridge {
        config: spec.link_config(),
        link,
        handle: BridgeHandle { stats, task },
    }
}

/// What the event loop's task tells the bridge.
#[derive(Debug)]
enum FromBroker {
    Connected,
    Publish {
        topic: String,
        payload: Vec<u8>,
        properties: Option<PublishProperties>,
    },
}

/// Runs rumqttc's event loop (which also reconnects) and hands on what the bridge needs.
/// Alone on its task, so that publishing never waits on the network read and the other way
/// round.
async fn pump(mut events: EventLoop, tx: mpsc::Sender<FromBroker>, stats: Arc<BridgeStats>) {
    let mut backoff = Duration::from_millis(100);
    loop {
        match events.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                backoff = Duration::from_millis(100);
                stats.connections.fetch_add(1, Ordering::Relaxed);
                if tx.send(FromBroker::Connected).await.is_err() {
                    return;
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let msg = FromBroker::Publish {
                    topic: String::from_utf8_lossy(&p.topic).into_owned(),
                    payload: p.payload.to_vec(),
                    properties: p.properties,
                };
                if tx.send(msg).await.is_err() {
                    return;
                }
            }
            Ok(Event::Outgoing(rumqttc::Outgoing::Disconnect)) => return,
            Ok(_) => {}
            Err(e) => {
                if tx.is_closed() {
                    return;
                }
                tracing::info!("mqtt: {e}; reconnecting in {backoff:?}");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(MAX_BACKOFF);
            }
        }
    }
}

/// Where a command's replies go: the request's response topic and correlation data.
#[derive(Clone, Debug, PartialEq, Eq)]
struct ReplyTo {
    topic: String,
    correlation: Option<Vec<u8>>,
}

/// What both ends share: the client, the link's far end, the broker's messages, the outbox.
struct Io {
    client: AsyncClient,
    peer: ExternalPeer,
    incoming: mpsc::Receiver<FromBroker>,
    outbox: Outbox,
    stats: Arc<BridgeStats>,
}

impl Io {
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
            let qos = match out.lane {
                Lane::Control => QoS::AtLeastOnce,
                Lane::Telemetry => QoS::AtMostOnce,
            };
            match self
                .client
                .try_publish(out.topic().to_owned(), qos, false, out.payload.clone())
            {
                Ok(()) => {
                    self.stats.published.fetch_add(1, Ordering::Relaxed);
                }
                Err(_) => {
                    self.outbox.unpop(out);
                    break;
                }
            }
        }
        let replaced = self.outbox.replaced();
        if self.stats.replaced.swap(replaced, Ordering::Relaxed) != replaced
            && let Ok(mut by_key) = self.stats.replaced_by_key.lock()
        {
            by_key.clone_from(self.outbox.replaced_by_key());
        }
    }

    async fn subscribe(&self, filters: &[String]) {
        for f in filters {
            if let Err(e) = self.client.subscribe(f.clone(), QoS::AtLeastOnce).await {
                tracing::warn!("mqtt: subscribing to {f}: {e}");
            }
        }
    }

    /// The link has closed: what waits goes, `alive` (the vehicle's key) says `offline`,
    /// then a clean disconnect (which the broker does not answer with the last will).
    async fn close(mut self, pump: JoinHandle<()>, alive: Option<String>) {
        self.drain();
        if let Some(alive) = alive {
            let offline = self
                .client
                .publish(alive, QoS::AtLeastOnce, true, "offline");
            let _ = tokio::time::timeout(CLOSE_TIMEOUT, offline).await;
        }
        // Let the event loop write what is queued before the DISCONNECT.
        tokio::time::sleep(Duration::from_millis(100)).await;
        // Bounded too: with the broker down the client's queue may be full.
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, self.client.disconnect()).await;
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, pump).await;
        tracing::debug!(
            "mqtt: closed ({} published, {} replaced)",
            self.stats.published.load(Ordering::Relaxed),
            self.outbox.replaced()
        );
    }
}

/// The vehicle's end: its network onto its keys, frames in, commands run here.
struct Driver {
    io: Io,
    keys: Keys,
    dialect: InfoFn,
    commands: Commands<ReplyTo>,
}

impl Driver {
    async fn run(mut self, pump: JoinHandle<()>) {
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
                msg = self.io.incoming.recv() => match msg {
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
        self.io.close(pump, Some(alive)).await;
    }

    async fn deliver(&self, frame: Vec<u8>) {
        if let Some(first) = self.io.peer.first() {
            self.io.stats.received.fetch_add(1, Ordering::Relaxed);
            self.io.peer.deliver(first, frame).await;
        }
    }

    /// A frame the router sends to the broker.
    fn outgoing(&mut self, frame: &[u8], replies: &mut Vec<Reply<ReplyTo>>) {
        let Ok(view) = Frame::new_checked(frame) else {
            return;
        };
        self.commands.handle_frame(clock::now(), frame, replies);
        let id = view.msg_id();
        let name = (self.dialect.0)(id).map(|i| i.name);
        let key = self.keys.message(view.sysid(), view.compid(), name, id);
        self.io.queue(&frame[..view.frame_len()], id, key, None);
    }

    async fn handle_broker(&mut self, msg: FromBroker) {
        match msg {
            FromBroker::Connected => {
                let filters = [self.keys.input(), self.keys.commands_filter()];
                self.io.subscribe(&filters).await;
                if let Err(e) = self
                    .io
                    .client
                    .publish(self.keys.alive(), QoS::AtLeastOnce, true, "online")
                    .await
                {
                    tracing::warn!("mqtt: publishing online: {e}");
                }
            }
            FromBroker::Publish {
                topic,
                payload,
                properties,
            } => match self.keys.parse(&topic) {
                Some(Topic::In) => self.deliver(payload).await,
                Some(Topic::Command { sysid, compid }) => {
                    let props = properties.unwrap_or_default();
                    let Some(topic) = props.response_topic else {
                        tracing::debug!("mqtt: a command request without a response topic");
                        return;
                    };
                    let to = ReplyTo {
                        topic,
                        correlation: props.correlation_data.map(|b| b.to_vec()),
                    };
                    match self.commands.handle_request(
                        clock::now(),
                        (sysid, compid),
                        &payload,
                        to.clone(),
                    ) {
                        Ok(frame) => self.deliver(frame).await,
                        Err(e) => self.answer(&to, e.to_string().into_bytes(), e.code(), true),
                    }
                }
                None => {}
            },
        }
    }

    fn reply(&mut self, reply: Reply<ReplyTo>) {
        match reply {
            Reply::Ack { to, frame, last } => {
                let status = if last { "" } else { "in_progress" };
                self.answer(&to, frame, status, false);
            }
            Reply::Timeout { to } => self.answer(&to, b"timeout".to_vec(), "timeout", true),
        }
    }

    /// Publishes a reply (QoS 1, with the request's correlation data). `code` goes in a
    /// user property: `error=code` for errors, `status=code` for intermediate acks.
    fn answer(&mut self, to: &ReplyTo, payload: Vec<u8>, code: &str, error: bool) {
        let mut props = PublishProperties {
            correlation_data: to.correlation.clone().map(Into::into),
            ..Default::default()
        };
        if !code.is_empty() {
            let name = if error { "error" } else { "status" };
            props
                .user_properties
                .push((name.to_owned(), code.to_owned()));
        }
        self.io.stats.replies.fetch_add(1, Ordering::Relaxed);
        if let Err(e) = self.io.client.try_publish_with_properties(
            to.topic.clone(),
            QoS::AtLeastOnce,
            false,
            payload,
            props,
        ) {
            tracing::warn!("mqtt: a command reply could not be queued: {e}");
        }
    }
}

/// The ground's end: each vehicle heard (or named) a peer of the link, so a router link of
/// its own; what the router sends a vehicle goes to its `in` key.
struct Ground {
    io: Io,
    fleet: String,
    /// The vehicles wanted (all when empty).
    vids: Vec<String>,
    dialect: InfoFn,
    vehicles: HashMap<String, PeerId>,
    by_peer: HashMap<PeerId, Keys>,
    /// Vehicles that share a sysid get distinct ones here.
    sysids: SysidMap,
}

impl Ground {
    async fn run(mut self, pump: JoinHandle<()>) {
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
                msg = self.io.incoming.recv() => match msg {
                    Some(msg) => self.handle_broker(msg).await,
                    None => break,
                },
                () = tokio::time::sleep(RETRY), if retry => {}
            }
            self.io.drain();
        }
        self.io.close(pump, None).await;
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
        match self.sysids.to_vehicle(keys.vid(), frame, self.dialect.0) {
            Remapped::Same => self.io.queue(frame, id, key, Some(topic)),
            Remapped::Rewritten(f) => self.io.queue(&f, id, key, Some(topic)),
            Remapped::Dropped => {}
        }
    }

    async fn handle_broker(&mut self, msg: FromBroker) {
        match msg {
            FromBroker::Connected => {
                let wanted: Vec<&str> = if self.vids.is_empty() {
                    vec!["+"]
                } else {
                    self.vids.iter().map(String::as_str).collect()
                };
                let mut filters = Vec::new();
                for v in wanted {
                    filters.push(format!("mav/{}/{v}/+/+/+", self.fleet));
                    filters.push(format!("mav/{}/{v}/@alive", self.fleet));
                }
                self.io.subscribe(&filters).await;
            }
            FromBroker::Publish { topic, payload, .. } => match fleet_topic(&self.fleet, &topic) {
                Some(FleetTopic::Frame { vid }) => {
                    if let Some(peer) = self.vehicle(vid).await {
                        let frame = match self.sysids.from_vehicle(vid, &payload, self.dialect.0) {
                            Remapped::Same => payload,
                            Remapped::Rewritten(f) => f,
                            Remapped::Dropped => return,
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
                            tracing::info!("mqtt: vehicle {vid} went offline");
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
        let peer = self
            .io
            .peer
            .add_peer(format!("mqtt {}/{vid}", self.fleet))
            .await?;
        tracing::info!("mqtt: vehicle {vid} is {peer}");
        self.vehicles.insert(vid.to_owned(), peer);
        self.by_peer.insert(peer, keys);
        Some(peer)
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => core::future::pending().await,
    }
}
