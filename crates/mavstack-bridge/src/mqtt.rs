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

use crate::command::{CommandTiming, Commands, Reply};
use crate::outbox::{Lane, Outbox};
use crate::{BridgeSpec, Keys, Topic};

/// Publishes waiting in rumqttc's request queue at most.
const CLIENT_QUEUE: usize = 1024;
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
    let keys = spec.keys.clone();
    let mut options = MqttOptions::new(spec.client_id.clone(), spec.host.clone(), spec.port);
    options.set_keep_alive(Duration::from_secs(5));
    options.set_clean_start(true);
    options.set_last_will(LastWill::new(
        keys.alive(),
        "offline",
        QoS::AtLeastOnce,
        true,
        None,
    ));
    if let Some((user, password)) = &spec.credentials {
        options.set_credentials(user.clone(), password.clone());
    }
    let (client, events) = AsyncClient::new(options, CLIENT_QUEUE);
    let (link, peer) = Link::external(format!("mqtt {}:{}", spec.host, spec.port), LINK_QUEUE);
    let stats = Arc::new(BridgeStats::default());
    let (tx, rx) = mpsc::channel(CLIENT_QUEUE);
    let pump = tokio::spawn(pump(events, tx, Arc::clone(&stats)));
    let task = tokio::spawn(
        Driver {
            client,
            keys,
            dialect,
            peer,
            incoming: rx,
            outbox: Outbox::new(OUTBOX_CONTROL, OUTBOX_KEYS),
            commands: Commands::new(CommandTiming::default()),
            stats: Arc::clone(&stats),
        }
        .run(pump),
    );
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

struct Driver {
    client: AsyncClient,
    keys: Keys,
    dialect: InfoFn,
    peer: ExternalPeer,
    incoming: mpsc::Receiver<FromBroker>,
    outbox: Outbox,
    commands: Commands<ReplyTo>,
    stats: Arc<BridgeStats>,
}

impl Driver {
    async fn run(mut self, pump: JoinHandle<()>) {
        let mut replies = Vec::new();
        let mut resend = Vec::new();
        loop {
            let wake = self.commands.poll_timeout().map(clock::to_tokio);
            let retry = !self.outbox.is_empty();
            tokio::select! {
                frame = self.peer.recv() => {
                    let Some(frame) = frame else { break };
                    self.outgoing(&frame, &mut replies);
                    while let Some(frame) = self.peer.try_recv() {
                        self.outgoing(&frame, &mut replies);
                    }
                }
                msg = self.incoming.recv() => match msg {
                    Some(msg) => self.handle_broker(msg).await,
                    None => break,
                },
                () = sleep_until(wake) => {
                    self.commands.handle_timeout(clock::now(), &mut resend, &mut replies);
                    for frame in resend.drain(..) {
                        self.peer.deliver(frame).await;
                    }
                }
                () = tokio::time::sleep(RETRY), if retry => {}
            }
            for reply in replies.drain(..) {
                self.reply(reply);
            }
            self.drain();
        }
        self.close(pump).await;
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
        let lane = if is_control(id) {
            Lane::Control
        } else {
            Lane::Telemetry
        };
        if !self
            .outbox
            .push(lane, key, frame[..view.frame_len()].to_vec())
        {
            let counter = match lane {
                Lane::Control => &self.stats.dropped_control,
                Lane::Telemetry => &self.stats.dropped_telemetry,
            };
            counter.fetch_add(1, Ordering::Relaxed);
        }
    }

    async fn handle_broker(&mut self, msg: FromBroker) {
        match msg {
            FromBroker::Connected => {
                let subs = [
                    (self.keys.input(), QoS::AtLeastOnce),
                    (self.keys.commands_filter(), QoS::AtLeastOnce),
                ];
                for (topic, qos) in subs {
                    if let Err(e) = self.client.subscribe(topic, qos).await {
                        tracing::warn!("mqtt: subscribing: {e}");
                    }
                }
                if let Err(e) = self
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
                Some(Topic::In) => {
                    self.stats.received.fetch_add(1, Ordering::Relaxed);
                    self.peer.deliver(payload).await;
                }
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
                        Ok(frame) => {
                            self.stats.received.fetch_add(1, Ordering::Relaxed);
                            self.peer.deliver(frame).await;
                        }
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
        self.stats.replies.fetch_add(1, Ordering::Relaxed);
        if let Err(e) = self.client.try_publish_with_properties(
            to.topic.clone(),
            QoS::AtLeastOnce,
            false,
            payload,
            props,
        ) {
            tracing::warn!("mqtt: a command reply could not be queued: {e}");
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
                .try_publish(out.key.clone(), qos, false, out.payload.clone())
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
        self.stats
            .replaced
            .store(self.outbox.replaced(), Ordering::Relaxed);
    }

    /// The link has closed: `offline`, then a clean disconnect (which the broker does not
    /// answer with the last will).
    async fn close(mut self, pump: JoinHandle<()>) {
        self.drain();
        let offline = self
            .client
            .publish(self.keys.alive(), QoS::AtLeastOnce, true, "offline");
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, offline).await;
        // Let the event loop send it (a QoS 1 publish waits for its PUBACK only in the
        // broker's bookkeeping; a short pause before disconnecting is enough on a live
        // connection).
        tokio::time::sleep(Duration::from_millis(100)).await;
        let _ = self.client.disconnect().await;
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, pump).await;
        tracing::debug!(
            "mqtt {}: closed ({} published, {} replaced)",
            self.keys.vid(),
            self.stats.published.load(Ordering::Relaxed),
            self.outbox.replaced()
        );
    }
}

async fn sleep_until(at: Option<tokio::time::Instant>) {
    match at {
        Some(at) => tokio::time::sleep_until(at).await,
        None => core::future::pending().await,
    }
}
