//! The Zenoh client of a bridge link. Zenoh's calls complete on the calling thread (a
//! `put` with `Block` waits there for room), so the session lives on threads of its own:
//! one opens it, declares what the link needs and sends the control lane and the command
//! replies (`Block`, priority `InteractiveHigh`); another sends telemetry (`Drop`,
//! priority `Data`: the two never share a priority, zenoh #2584). The bridge hands them
//! work without waiting; what Zenoh delivers comes back through a channel.
//!
//! - Vehicle: a subscriber on `in`, a queryable on `mav/F/V/*/*/@cmd` (each query a
//!   command request: its payload the COMMAND_LONG/INT frame, its replies the ACK frames,
//!   intermediate ones with the attachment `status=in_progress`; a timeout or a refused
//!   request is an error reply, `timeout` or `CODE: text`), and a liveliness token on
//!   `@alive`, which goes when the session does (exit or crash alike).
//! - Ground: subscribers on the vehicles' frames and on their liveliness (with history:
//!   the vehicles already up are heard at once).

use core::sync::atomic::Ordering;
use core::time::Duration;
use std::sync::Arc;

use mavstack_router::MessageTable;
use tokio::sync::oneshot;
use zenoh::Wait as _;
use zenoh::qos::{CongestionControl, Priority};
use zenoh::query::Query;
use zenoh::sample::{Sample, SampleKind};

use crate::driver::{Answer, Bridge, BridgeStats, Broker, Incoming, Interest, start};
use crate::outbox::{Lane, Outgoing};
use crate::{BridgeSpec, OpenError, Transport};

/// Work waiting for each of the session's threads, at most.
const CLIENT_QUEUE: usize = 1024;
/// Longest wait before trying a Zenoh router that is down again.
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// How long closing waits for the session to close.
const CLOSE_TIMEOUT: Duration = Duration::from_secs(2);

/// Opens the Zenoh link `spec` describes (a client of the router at HOST:PORT, or a peer).
pub(crate) fn open(spec: &BridgeSpec, dialect: MessageTable) -> Result<Bridge, OpenError> {
    let config = config(spec).map_err(|reason| OpenError::Zenoh {
        name: spec.name.clone(),
        reason,
    })?;
    let stats = Arc::new(BridgeStats::default());
    let (control, control_rx) = flume::bounded(CLIENT_QUEUE);
    let (telemetry, telemetry_rx) = flume::bounded(CLIENT_QUEUE);
    let (incoming_tx, incoming) = flume::bounded(CLIENT_QUEUE);
    let (done_tx, done) = oneshot::channel();
    let session = SessionThread {
        link: spec.name.clone(),
        config,
        interest: Interest::of(spec),
        control: control_rx,
        telemetry: telemetry_rx,
        incoming: incoming_tx,
        stats: Arc::clone(&stats),
    };
    std::thread::Builder::new()
        .name(format!("zenoh {}", spec.name))
        .spawn(move || {
            session.run();
            let _ = done_tx.send(());
        })
        .map_err(|e| OpenError::Zenoh {
            name: spec.name.clone(),
            reason: format!("starting its thread: {e}"),
        })?;
    let broker = Zenoh {
        link: spec.name.clone(),
        control,
        telemetry,
        incoming,
        done,
    };
    Ok(start(spec, dialect, broker, stats))
}

/// The session's settings: a client of one router (no scouting), or a peer (scouting as
/// Zenoh does by default, listening where `listen` says).
fn config(spec: &BridgeSpec) -> Result<zenoh::Config, String> {
    let mut config = zenoh::Config::default();
    let mut set = |key: &str, value: String| {
        config
            .insert_json5(key, &value)
            .map_err(|e| format!("zenoh setting {key} = {value}: {e}"))
    };
    match spec.transport {
        Transport::ZenohPeer => {
            set("mode", "\"peer\"".into())?;
            if let Some(listen) = &spec.listen {
                set("listen/endpoints", format!("[{listen:?}]"))?;
            }
        }
        _ => {
            let host = if spec.host.contains(':') {
                format!("[{}]", spec.host)
            } else {
                spec.host.clone()
            };
            set("mode", "\"client\"".into())?;
            set(
                "connect/endpoints",
                format!("[\"tcp/{host}:{}\"]", spec.port),
            )?;
            set("scouting/multicast/enabled", "false".into())?;
        }
    }
    Ok(config)
}

/// What the bridge hands the session's threads.
enum Job {
    /// A frame onto a key.
    Put { key: String, payload: Vec<u8> },
    /// A reply to a command request.
    Answer { to: Request, answer: Answer },
}

/// A command request's query: replies go to it; the last copy dropped ends it.
#[derive(Clone)]
pub(crate) struct Request(Query);

impl core::fmt::Debug for Request {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "query on {}", self.0.key_expr())
    }
}

/// The bridge's side: the threads' queues and what Zenoh delivered.
struct Zenoh {
    /// The link's name, for the log.
    link: String,
    control: flume::Sender<Job>,
    telemetry: flume::Sender<Job>,
    incoming: flume::Receiver<Incoming<Request>>,
    done: oneshot::Receiver<()>,
}

impl Broker for Zenoh {
    type ReplyTo = Request;
    const NAME: &'static str = "zenoh";

    fn try_publish(&mut self, out: &Outgoing) -> bool {
        let job = Job::Put {
            key: out.topic().to_owned(),
            payload: out.payload.clone(),
        };
        let queue = match out.lane {
            Lane::Control => &self.control,
            Lane::Telemetry => &self.telemetry,
        };
        queue.try_send(job).is_ok()
    }

    async fn next(&mut self) -> Option<Incoming<Request>> {
        self.incoming.recv_async().await.ok()
    }

    /// The session's thread declared everything when it opened the session.
    async fn connected(&mut self, _: &Interest) {}

    fn answer(&mut self, to: &Request, answer: Answer) {
        let job = Job::Answer {
            to: to.clone(),
            answer,
        };
        if self.control.try_send(job).is_err() {
            tracing::warn!(link = %self.link, "zenoh: a command reply could not be queued");
        }
    }

    /// The threads finish what they hold and close the session; the liveliness token goes
    /// with it (that is `offline`).
    async fn close(self, _alive: Option<String>) {
        let Self {
            control,
            telemetry,
            done,
            ..
        } = self;
        drop((control, telemetry));
        let _ = tokio::time::timeout(CLOSE_TIMEOUT, done).await;
    }
}

/// The thread that owns the session.
struct SessionThread {
    /// The link's name, for the log.
    link: String,
    config: zenoh::Config,
    interest: Interest,
    control: flume::Receiver<Job>,
    telemetry: flume::Receiver<Job>,
    incoming: flume::Sender<Incoming<Request>>,
    stats: Arc<BridgeStats>,
}

impl SessionThread {
    fn run(self) {
        let Some(session) = self.open() else {
            return;
        };
        let declared = match self.declare(&session) {
            Ok(declared) => declared,
            Err(e) => {
                tracing::error!(link = %self.link, "zenoh: declaring the link's keys: {e}");
                return;
            }
        };
        self.stats.connections.fetch_add(1, Ordering::Relaxed);
        if self.incoming.send(Incoming::Connected).is_err() {
            return;
        }
        let telemetry = {
            let (session, jobs) = (session.clone(), self.telemetry.clone());
            let link = self.link.clone();
            std::thread::Builder::new()
                .name("zenoh telemetry".into())
                .spawn(move || serve(&session, &jobs, Lane::Telemetry, &link))
        };
        serve(&session, &self.control, Lane::Control, &self.link);
        if let Ok(t) = telemetry {
            let _ = t.join();
        }
        drop(declared);
        if let Err(e) = session.close().wait() {
            tracing::debug!(link = %self.link, "zenoh: closing the session: {e}");
        }
    }

    /// Opens the session, trying again with back-off while the router is down; `None`
    /// when the bridge closed meanwhile.
    fn open(&self) -> Option<zenoh::Session> {
        let mut backoff = Duration::from_millis(100);
        loop {
            match zenoh::open(self.config.clone()).wait() {
                Ok(session) => return Some(session),
                Err(e) => tracing::warn!(
                    link = %self.link,
                    "zenoh: opening the session: {e}; trying again in {backoff:?}"
                ),
            }
            // Waiting on the control queue notices a close at once.
            match self.control.recv_timeout(backoff) {
                Err(flume::RecvTimeoutError::Disconnected) => return None,
                Ok(_) | Err(flume::RecvTimeoutError::Timeout) => {}
            }
            backoff = (backoff * 2).min(MAX_BACKOFF);
        }
    }

    /// Subscribers, queryable and liveliness token, kept for as long as the link is up.
    fn declare(&self, session: &zenoh::Session) -> zenoh::Result<Declared> {
        let mut declared = Declared::default();
        let frames = {
            let tx = self.incoming.clone();
            move |sample: Sample| {
                let _ = tx.send(Incoming::Message {
                    topic: sample.key_expr().as_str().to_owned(),
                    payload: sample.payload().to_bytes().into_owned(),
                    reply: None,
                });
            }
        };
        match &self.interest {
            Interest::Vehicle(keys) => {
                declared.subscribers.push(
                    session
                        .declare_subscriber(keys.input())
                        .callback(frames)
                        .wait()?,
                );
                let tx = self.incoming.clone();
                declared.queryable = Some(
                    session
                        .declare_queryable(keys.commands_filter().replace('+', "*"))
                        .callback(move |query: Query| {
                            let topic = query.key_expr().as_str().to_owned();
                            let payload = query
                                .payload()
                                .map(|p| p.to_bytes().into_owned())
                                .unwrap_or_default();
                            let _ = tx.send(Incoming::Message {
                                topic,
                                payload,
                                reply: Some(Request(query)),
                            });
                        })
                        .wait()?,
                );
                declared.token = Some(session.liveliness().declare_token(keys.alive()).wait()?);
            }
            Interest::Ground { fleet, vids } => {
                let wanted: Vec<&str> = if vids.is_empty() {
                    vec!["*"]
                } else {
                    vids.iter().map(String::as_str).collect()
                };
                for v in wanted {
                    declared.subscribers.push(
                        session
                            .declare_subscriber(format!("mav/{fleet}/{v}/*/*/*"))
                            .callback(frames.clone())
                            .wait()?,
                    );
                    let tx = self.incoming.clone();
                    declared.subscribers.push(
                        session
                            .liveliness()
                            .declare_subscriber(format!("mav/{fleet}/{v}/@alive"))
                            .history(true)
                            .callback(move |sample: Sample| {
                                let state: &[u8] = match sample.kind() {
                                    SampleKind::Put => b"online",
                                    SampleKind::Delete => b"offline",
                                };
                                let _ = tx.send(Incoming::Message {
                                    topic: sample.key_expr().as_str().to_owned(),
                                    payload: state.to_vec(),
                                    reply: None,
                                });
                            })
                            .wait()?,
                    );
                }
            }
        }
        Ok(declared)
    }
}

/// What a link declared (undeclared when dropped).
#[derive(Default)]
struct Declared {
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    queryable: Option<zenoh::query::Queryable<()>>,
    token: Option<zenoh::liveliness::LivelinessToken>,
}

/// Sends the jobs of one lane until the bridge closes its queue. A put or reply that fails
/// is a warning naming `link` (a telemetry put dropped under congestion is not a failure).
fn serve(session: &zenoh::Session, jobs: &flume::Receiver<Job>, lane: Lane, link: &str) {
    let (congestion, priority) = match lane {
        Lane::Control => (CongestionControl::Block, Priority::InteractiveHigh),
        Lane::Telemetry => (CongestionControl::Drop, Priority::Data),
    };
    while let Ok(job) = jobs.recv() {
        let sent = match job {
            Job::Put { key, payload } => session
                .put(key, payload)
                .congestion_control(congestion)
                .priority(priority)
                .wait(),
            Job::Answer { to, answer } => reply(&to.0, answer),
        };
        if let Err(e) = sent {
            tracing::warn!(link = %link, "zenoh: sending on the {lane:?} lane: {e}");
        }
    }
}

/// A reply to a command request: the ACK frame (the attachment `status=in_progress` on an
/// intermediate one), or an error reply (`timeout`, `CODE: text`).
fn reply(query: &Query, answer: Answer) -> zenoh::Result<()> {
    match answer {
        Answer::Ack { frame, last } => {
            // A reply travels with the query's own priority and congestion control.
            let reply = query.reply(query.key_expr().clone(), frame);
            if last {
                reply.wait()
            } else {
                reply.attachment("status=in_progress").wait()
            }
        }
        Answer::Error { text, code } => {
            let text = String::from_utf8_lossy(&text);
            let payload = if text == code {
                code.to_owned()
            } else {
                format!("{code}: {text}")
            };
            query.reply_err(payload).wait()
        }
    }
}
