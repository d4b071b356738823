//! The MQTT 5 client of a bridge link: rumqttc's event loop on a task of its own (it also
//! reconnects), publishes handed over with `try_publish` so that a slow broker never holds
//! up the bridge, command replies on the request's response topic with its correlation
//! data.
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn std::error::Error>> {
//! use mavstack_bridge::BridgeSpec;
//! use mavstack_router::MessageTable;
//! let spec = BridgeSpec::parse("mqtt://127.0.0.1:1883?fleet=demo&vid=v1")?;
//! let dialect = MessageTable::of::<mavstack_dialects::common::MavMessage>();
//! let bridge = mavstack_bridge::open(&spec, dialect)?;
//! // Give the link to a node: `NodeBuilder::opened_link(bridge.config, bridge.link)`;
//! // after the node has shut down, `bridge.handle.finish().await` publishes `offline`.
//! # Ok(()) }
//! ```

use core::sync::atomic::Ordering;
use core::time::Duration;
use std::sync::Arc;

use mavstack_router::MessageTable;
use rumqttc::v5::mqttbytes::QoS;
use rumqttc::v5::mqttbytes::v5::{LastWill, Packet, PublishProperties};
use rumqttc::v5::{AsyncClient, Event, EventLoop, MqttOptions};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use crate::driver::{Answer, Bridge, BridgeStats, Broker, Incoming, Interest, start};
use crate::outbox::{Lane, Outgoing};
use crate::{BridgeSpec, OpenError, Side};

/// Publishes waiting in rumqttc's request queue at most.
const CLIENT_QUEUE: usize = 1024;
/// QoS 1 publishes in flight (unacknowledged) at most. rumqttc's default, 65,535, sizes a
/// table of that many publishes per client (13 MB); a fleet router holds many clients.
const INFLIGHT: u16 = 256;
/// Longest wait before reconnecting to a broker that is down.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// How long closing waits for `offline` to reach the broker.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(2);

/// Opens the MQTT link `spec` describes; `dialect` names the messages in the keys. The
/// broker is connected in the background (and reconnected, with back-off, whenever it
/// drops): opening never waits for it. `mqtts://` reads its certificate files here.
pub(crate) fn open(spec: &BridgeSpec, dialect: MessageTable) -> Result<Bridge, OpenError> {
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
    #[cfg(feature = "tls")]
    if spec.transport == crate::Transport::Mqtts {
        let connector = tls::connector(spec)?;
        options.set_transport(rumqttc::Transport::tls_with_config(
            rumqttc::TlsConfiguration::NativeConnector(connector),
        ));
    }
    let (client, events) = AsyncClient::new(options, CLIENT_QUEUE);
    let stats = Arc::new(BridgeStats::default());
    let (tx, rx) = mpsc::channel(CLIENT_QUEUE);
    let pump = tokio::spawn(pump(events, tx, Arc::clone(&stats), spec.name.clone()));
    let broker = Mqtt {
        link: spec.name.clone(),
        client,
        incoming: rx,
        pump,
    };
    Ok(start(spec, dialect, broker, stats))
}

/// `mqtts://`: OpenSSL (through native-tls) checks the broker's certificate and name.
#[cfg(feature = "tls")]
mod tls {
    use crate::{BridgeSpec, OpenError};

    /// The TLS connector of `spec`: its CA (or the system's roots), its client certificate.
    pub(super) fn connector(spec: &BridgeSpec) -> Result<native_tls::TlsConnector, OpenError> {
        let err = |option, path: &std::path::Path, reason: String| OpenError::Tls {
            name: spec.name.clone(),
            option,
            path: path.display().to_string(),
            reason,
        };
        let read = |option, path: &std::path::Path| {
            std::fs::read(path).map_err(|e| err(option, path, e.to_string()))
        };
        let mut builder = native_tls::TlsConnector::builder();
        if let Some(ca) = &spec.ca {
            let cert = native_tls::Certificate::from_pem(&read("ca", ca)?)
                .map_err(|e| err("ca", ca, format!("not a PEM certificate: {e}")))?;
            builder.add_root_certificate(cert);
        }
        if let Some((cert, key)) = &spec.client_cert {
            let identity = native_tls::Identity::from_pkcs8(
                &read("client_cert", cert)?,
                &read("client_key", key)?,
            )
            .map_err(|e| {
                err(
                    "client_cert",
                    cert,
                    format!("with client_key: not a PEM certificate and PKCS#8 key: {e}"),
                )
            })?;
            builder.identity(identity);
        }
        builder.build().map_err(|e| {
            err(
                "ca",
                spec.ca.as_deref().unwrap_or("(system roots)".as_ref()),
                e.to_string(),
            )
        })
    }
}

/// Runs rumqttc's event loop (which also reconnects) and hands on what the bridge needs.
/// Alone on its task, so that publishing never waits on the network read and the other way
/// round. A broker that cannot be reached or drops the connection is a warning naming the
/// link, once per attempt (the back-off spaces them, at most [`MAX_BACKOFF`] apart).
async fn pump(
    mut events: EventLoop,
    tx: mpsc::Sender<Incoming<ReplyTo>>,
    stats: Arc<BridgeStats>,
    link: String,
) {
    let mut backoff = Duration::from_millis(100);
    loop {
        match events.poll().await {
            Ok(Event::Incoming(Packet::ConnAck(_))) => {
                backoff = Duration::from_millis(100);
                stats.connections.fetch_add(1, Ordering::Relaxed);
                if tx.send(Incoming::Connected).await.is_err() {
                    return;
                }
            }
            Ok(Event::Incoming(Packet::Publish(p))) => {
                let reply = p.properties.and_then(reply_to);
                let msg = Incoming::Message {
                    topic: String::from_utf8_lossy(&p.topic).into_owned(),
                    payload: p.payload.to_vec(),
                    reply,
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
                tracing::warn!(link = %link, "mqtt: broker connection: {e}; reconnecting in {backoff:?}");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(MAX_BACKOFF);
            }
        }
    }
}

/// The reply address of a request: its response topic and correlation data.
fn reply_to(props: PublishProperties) -> Option<ReplyTo> {
    Some(ReplyTo {
        topic: props.response_topic?,
        correlation: props.correlation_data.map(|b| b.to_vec()),
    })
}

/// Where a command's replies go: the request's response topic and correlation data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ReplyTo {
    topic: String,
    correlation: Option<Vec<u8>>,
}

/// The client, and what its event loop hands on.
struct Mqtt {
    /// The link's name, for the log.
    link: String,
    client: AsyncClient,
    incoming: mpsc::Receiver<Incoming<ReplyTo>>,
    pump: JoinHandle<()>,
}

impl Broker for Mqtt {
    type ReplyTo = ReplyTo;
    const NAME: &'static str = "mqtt";

    fn try_publish(&mut self, out: &Outgoing) -> bool {
        let qos = match out.lane {
            Lane::Control => QoS::AtLeastOnce,
            Lane::Telemetry => QoS::AtMostOnce,
        };
        self.client
            .try_publish(out.topic().to_owned(), qos, false, out.payload.clone())
            .is_ok()
    }

    async fn next(&mut self) -> Option<Incoming<ReplyTo>> {
        self.incoming.recv().await
    }

    async fn connected(&mut self, interest: &Interest) {
        let filters = match interest {
            Interest::Vehicle(keys) => vec![keys.input(), keys.commands_filter()],
            Interest::Ground { fleet, vids } => {
                let wanted: Vec<&str> = if vids.is_empty() {
                    vec!["+"]
                } else {
                    vids.iter().map(String::as_str).collect()
                };
                wanted
                    .iter()
                    .flat_map(|v| {
                        [
                            format!("mav/{fleet}/{v}/+/+/+"),
                            format!("mav/{fleet}/{v}/@alive"),
                        ]
                    })
                    .collect()
            }
        };
        for f in filters {
            if let Err(e) = self.client.subscribe(f.clone(), QoS::AtLeastOnce).await {
                tracing::warn!(link = %self.link, "mqtt: subscribing to {f}: {e}");
            }
        }
        if let Interest::Vehicle(keys) = interest
            && let Err(e) = self
                .client
                .publish(keys.alive(), QoS::AtLeastOnce, true, "online")
                .await
        {
            tracing::warn!(link = %self.link, "mqtt: publishing online: {e}");
        }
    }

    /// A reply at QoS 1 with the request's correlation data; the ACK frame as it came, or
    /// the error's text with the user property `error=CODE` (`status=in_progress` on
    /// intermediate acks).
    fn answer(&mut self, to: &ReplyTo, answer: Answer) {
        let mut props = PublishProperties {
            correlation_data: to.correlation.clone().map(Into::into),
            ..Default::default()
        };
        let (payload, property) = match answer {
            Answer::Ack { frame, last: true } => (frame, None),
            Answer::Ack { frame, last: false } => (frame, Some(("status", "in_progress"))),
            Answer::Error { text, code } => (text, Some(("error", code))),
        };
        if let Some((name, value)) = property {
            props
                .user_properties
                .push((name.to_owned(), value.to_owned()));
        }
        if let Err(e) = self.client.try_publish_with_properties(
            to.topic.clone(),
            QoS::AtLeastOnce,
            false,
            payload,
            props,
        ) {
            tracing::warn!(link = %self.link, "mqtt: a command reply could not be queued: {e}");
        }
    }

    /// `offline` (the vehicle's key), then a clean disconnect (which the broker does not
    /// answer with the last will).
    async fn close(self, alive: Option<String>) {
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
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, self.pump).await;
    }
}
