//! mavlink2rest 1.0.2's REST and WebSocket API on a node, beside the status page (feature
//! `http`; see [`NodeBuilder::http`] and `docs/contracts/web-api.md`).
//!
//! The service is a link of the node, named `web`: a monitor link
//! ([`LinkConfig::monitor`](crate::router::LinkConfig::monitor)), so it sees every frame the
//! router accepts and every broadcast the node sends, and what web clients post enters the
//! router as frames from that link, framed with the header the client gave: the router
//! routes, converts, signs and filters them like any other link's frames, and a vehicle
//! node's own component answers them. What it serves:
//!
//! | path | what |
//! | --- | --- |
//! | `GET /mavlink` | the latest message of each type, by vehicle and component |
//! | `GET /mavlink/{pointer}` | a part of that object (`vehicles/1/components/1/messages/HEARTBEAT`) |
//! | `POST /mavlink` | a `{"header","message"}` object, sent as a frame |
//! | `GET /helper/mavlink?name=NAME` | a template of message NAME |
//! | `GET /ws/mavlink[?filter=REGEX]` | a WebSocket: every frame whose name matches, as `{"header","message"}`; objects sent on it go out as frames |
//! | `GET /info` | what serves the API |
//! | `GET /docs.json` | the OpenAPI document |
//! | the same under `/v1/` | |
//! | `GET /`, `/api/status`, `/api/events` | the status page ([`crate::status`]) |
//!
//! Bounds: each WebSocket client reads from a ring of the newest frames (a client that falls
//! behind loses the oldest, counted, and never holds the node back); at most
//! [`WebOptions::max_clients`] WebSockets and [`WebOptions::max_connections`] connections at
//! once; request bodies up to
//! [`WebOptions::body_limit`]; with [`WebOptions::token`], every request must carry it
//! (`Authorization: Bearer TOKEN`, or `?token=TOKEN` where a browser cannot set a header).
//!
//! [`NodeBuilder::http`]: crate::NodeBuilder::http

mod api;
pub mod json;
mod limit;
mod store;
mod ws;

use core::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use axum::Router;
use axum::extract::ws::Utf8Bytes;
use axum::extract::{DefaultBodyLimit, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use mavstack_core::wire::Frame;
use mavstack_transport::protocol::PeerId;
use mavstack_transport::{ExternalPeer, ExternalSender};
use tokio::net::TcpListener;
use tokio::sync::broadcast;

use self::json::{Header, JsonMapping};
use self::store::Store;
use crate::NodeHandle;

/// How many frames from the node may wait for the service before the newest are dropped
/// (counted as the `web` link's `tx_dropped`).
pub(crate) const LINK_QUEUE: usize = 4096;

/// The web service's settings.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct WebOptions {
    /// A token every request must carry (`Authorization: Bearer TOKEN` or `?token=TOKEN`);
    /// none by default.
    pub token: Option<String>,
    /// WebSocket clients at once (default 64); more are refused with 503.
    pub max_clients: usize,
    /// Open connections at once, WebSockets included (default 128); more wait in the
    /// listener's backlog until one closes.
    pub max_connections: usize,
    /// Frames a WebSocket client may fall behind before it loses the oldest (default 1024).
    pub client_queue: usize,
    /// The largest request body in bytes (default 64 KiB); larger ones get 413.
    pub body_limit: usize,
    /// The dialect whose messages the API reads and writes (default `ardupilotmega`, what
    /// mavlink2rest 1.0.2 speaks).
    pub mapping: Option<Arc<JsonMapping>>,
}

impl Default for WebOptions {
    fn default() -> Self {
        Self {
            token: None,
            max_clients: 64,
            max_connections: 128,
            client_queue: 1024,
            body_limit: 64 * 1024,
            mapping: None,
        }
    }
}

impl WebOptions {
    /// Requires `token` on every request.
    #[must_use]
    pub fn token(mut self, token: impl Into<String>) -> Self {
        self.token = Some(token.into());
        self
    }

    /// The dialect of the API's messages.
    #[must_use]
    pub fn mapping(mut self, mapping: Arc<JsonMapping>) -> Self {
        self.mapping = Some(mapping);
        self
    }
}

/// The built-in `ardupilotmega` mapping, loaded once.
///
/// # Panics
/// If the built-in definitions do not load (they are tested to).
#[must_use]
pub fn default_mapping() -> Arc<JsonMapping> {
    static MAPPING: OnceLock<Arc<JsonMapping>> = OnceLock::new();
    Arc::clone(MAPPING.get_or_init(|| {
        #[allow(clippy::expect_used)]
        let dialect = mavstack_xml::load("ardupilotmega").expect("built-in ardupilotmega loads");
        Arc::new(JsonMapping::new(dialect))
    }))
}

/// A frame for the WebSocket clients: its message's name and its JSON text.
#[derive(Debug)]
pub(crate) struct Outgoing {
    pub(crate) id: u32,
    pub(crate) name: String,
    pub(crate) text: Utf8Bytes,
}

/// What the handlers share.
#[derive(Debug)]
pub(crate) struct Shared {
    pub(crate) node: NodeHandle,
    pub(crate) mapping: Arc<JsonMapping>,
    pub(crate) options: WebOptions,
    pub(crate) store: Mutex<Store>,
    pub(crate) frames: broadcast::Sender<Arc<Outgoing>>,
    /// The link's far end: what clients send goes in here, from the link's first peer.
    pub(crate) input: ExternalSender,
    pub(crate) peer: Option<PeerId>,
    pub(crate) clients: AtomicUsize,
    pub(crate) counters: WebCounters,
    /// The next sequence number of each (system, component) clients send as: like
    /// mavlink2rest, the link numbers the frames itself, whatever `sequence` a client gave.
    pub(crate) sequences: Mutex<HashMap<(u8, u8), u8>>,
}

/// The service's counters, shown in `/api/status` under `web`.
#[derive(Debug, Default)]
pub(crate) struct WebCounters {
    /// Frames the node handed to the service.
    pub(crate) frames: AtomicU64,
    /// Frames WebSocket clients missed by falling behind.
    pub(crate) ws_dropped: AtomicU64,
    /// Messages web clients sent.
    pub(crate) sent: AtomicU64,
    /// Requests refused (bad JSON, unknown message, token, limits).
    pub(crate) refused: AtomicU64,
}

impl Shared {
    /// The counters and client count as JSON.
    pub(crate) fn counters_json(&self) -> serde_json::Value {
        let c = &self.counters;
        serde_json::json!({
            "clients": self.clients.load(Ordering::Relaxed),
            "frames": c.frames.load(Ordering::Relaxed),
            "ws_dropped": c.ws_dropped.load(Ordering::Relaxed),
            "sent": c.sent.load(Ordering::Relaxed),
            "refused": c.refused.load(Ordering::Relaxed),
        })
    }

    /// Hands a client's frame to the node, numbered in the sequence of its sender, and keeps
    /// it as the latest of its type, as mavlink2rest does; false once the node has stopped.
    pub(crate) async fn send(&self, header: Header, mut frame: Vec<u8>) -> bool {
        let Some(first) = self.peer else {
            return false;
        };
        let seq = {
            let mut sequences = self
                .sequences
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            let next = sequences
                .entry((header.system_id, header.component_id))
                .or_insert(0);
            let seq = *next;
            *next = next.wrapping_add(1);
            seq
        };
        let mut view = Frame::new_unchecked(&mut frame[..]);
        let id = view.msg_id();
        let Some(message) = self.mapping.dialect().message(id) else {
            return false;
        };
        view.set_seq(seq);
        view.fill_checksum(message.crc_extra);
        let payload = view.payload().to_vec();
        let name = message.name.clone();
        if !self.input.deliver(first, frame).await {
            return false;
        }
        self.counters.sent.fetch_add(1, Ordering::Relaxed);
        self.lock_store().update(header, &name, id, &payload);
        true
    }

    pub(crate) fn lock_store(&self) -> std::sync::MutexGuard<'_, Store> {
        self.store
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

/// Starts the service for the node behind `handle` on a thread of its own, with a runtime of
/// its own: however busy its clients keep it, the node's runtime (TCP and serial links,
/// handles, subscriptions) never waits for it. It ends when the node stops.
pub(crate) fn spawn(
    listener: TcpListener,
    handle: NodeHandle,
    peer: ExternalPeer,
    options: WebOptions,
) {
    let listener = match listener.into_std() {
        Ok(l) => l,
        Err(e) => {
            tracing::warn!("web service: {e}");
            return;
        }
    };
    let started = std::thread::Builder::new()
        .name("mavstack-web".into())
        .spawn(move || {
            let runtime = match tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
            {
                Ok(rt) => rt,
                Err(e) => {
                    tracing::warn!("web service: runtime: {e}");
                    return;
                }
            };
            runtime.block_on(async move {
                match TcpListener::from_std(listener) {
                    Ok(listener) => {
                        if let Err(e) = serve(listener, handle, peer, options).await {
                            tracing::warn!("web service: {e}");
                        }
                    }
                    Err(e) => tracing::warn!("web service: {e}"),
                }
            });
        });
    if let Err(e) = started {
        tracing::warn!("web service: thread: {e}");
    }
}

/// Serves the page, the status JSON and the API for the node behind `handle` on `listener`
/// until the node stops; `peer` is the far end of the node's `web` link.
///
/// # Errors
/// An error of the listener.
async fn serve(
    listener: TcpListener,
    handle: NodeHandle,
    peer: ExternalPeer,
    options: WebOptions,
) -> std::io::Result<()> {
    let mapping = options.mapping.clone().unwrap_or_else(default_mapping);
    let (frames, _) = broadcast::channel(options.client_queue.max(1));
    let shared = Arc::new(Shared {
        node: handle.clone(),
        mapping,
        options: options.clone(),
        store: Mutex::new(Store::default()),
        frames,
        input: peer.sender(),
        peer: peer.first(),
        clients: AtomicUsize::new(0),
        counters: WebCounters::default(),
        sequences: Mutex::new(HashMap::new()),
    });
    tokio::spawn(read_link(peer, Arc::clone(&shared)));
    let api = api::routes();
    let app = Router::new()
        .merge(crate::status::routes())
        .merge(api.clone())
        .nest("/v1", api)
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&shared),
            guard,
        ))
        .layer(DefaultBodyLimit::max(options.body_limit))
        .with_state(shared);
    if let Ok(addr) = listener.local_addr() {
        tracing::info!("status page and mavlink2rest API on http://{addr}/");
    }
    let stop = handle.clone();
    axum::serve(limit::Limited::new(listener, options.max_connections), app)
        .with_graceful_shutdown(async move { stop.closed().await })
        .await
}

/// Every frame the node hands the `web` link: kept, and sent to the WebSocket clients.
async fn read_link(mut peer: ExternalPeer, shared: Arc<Shared>) {
    while let Some((_, bytes)) = peer.recv().await {
        shared.counters.frames.fetch_add(1, Ordering::Relaxed);
        let Ok(frame) = Frame::new_checked(&bytes[..]) else {
            continue;
        };
        let Some(message) = shared.mapping.dialect().message(frame.msg_id()) else {
            continue;
        };
        let header = Header {
            system_id: frame.sysid(),
            component_id: frame.compid(),
            sequence: frame.seq(),
        };
        shared
            .lock_store()
            .update(header, &message.name, frame.msg_id(), frame.payload());
        if shared.frames.receiver_count() > 0
            && let Some(body) = shared.mapping.message_json(frame.msg_id(), frame.payload())
        {
            let text = json::request_json(header, body).to_string();
            let _ = shared.frames.send(Arc::new(Outgoing {
                id: frame.msg_id(),
                name: message.name.clone(),
                text: text.into(),
            }));
        }
    }
}

/// Refuses a request without the token (when one is set) or a browser's write from
/// another origin (a page elsewhere cannot post to a vehicle through the operator's
/// browser).
async fn guard(State(shared): State<Arc<Shared>>, request: Request, next: Next) -> Response {
    let headers = request.headers();
    let with_token = match &shared.options.token {
        Some(token) => {
            if !token_given(headers, request.uri().query(), token) {
                shared.counters.refused.fetch_add(1, Ordering::Relaxed);
                return (
                    StatusCode::UNAUTHORIZED,
                    [(header::WWW_AUTHENTICATE, "Bearer")],
                    "a token is required: Authorization: Bearer TOKEN or ?token=TOKEN",
                )
                    .into_response();
            }
            true
        }
        None => false,
    };
    let writes =
        request.method() == axum::http::Method::POST || headers.contains_key(header::UPGRADE);
    if writes && !with_token && cross_origin(headers) {
        shared.counters.refused.fetch_add(1, Ordering::Relaxed);
        return (
            StatusCode::FORBIDDEN,
            "a page from another origin cannot send (serve it from this address, or use a token)",
        )
            .into_response();
    }
    next.run(request).await
}

fn token_given(headers: &HeaderMap, query: Option<&str>, token: &str) -> bool {
    let bearer = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    let in_query = query.and_then(|q| {
        q.split('&')
            .find_map(|pair| pair.strip_prefix("token="))
            .map(percent_decode)
    });
    bearer.is_some_and(|b| same(b.as_bytes(), token.as_bytes()))
        || in_query.is_some_and(|q| same(q.as_bytes(), token.as_bytes()))
}

/// Compares without stopping at the first difference.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        match bytes[i] {
            b'%' if i + 2 < bytes.len() => match (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push(u8::try_from(h * 16 + l).unwrap_or(0));
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A browser's request whose `Origin` is not the address it was sent to.
fn cross_origin(headers: &HeaderMap) -> bool {
    let Some(origin) = headers.get(header::ORIGIN).and_then(|v| v.to_str().ok()) else {
        return false;
    };
    let host = headers
        .get(header::HOST)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let origin_host = origin
        .split_once("://")
        .map_or(origin, |(_, rest)| rest)
        .trim_end_matches('/');
    !origin_host.eq_ignore_ascii_case(host)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_are_read_from_header_or_query() {
        let mut h = HeaderMap::new();
        assert!(!token_given(&h, None, "s3cret"));
        assert!(token_given(&h, Some("filter=.*&token=s3cret"), "s3cret"));
        assert!(token_given(&h, Some("token=a%2Fb"), "a/b"));
        assert!(!token_given(&h, Some("token=s3cre"), "s3cret"));
        h.insert(header::AUTHORIZATION, "Bearer s3cret".parse().unwrap());
        assert!(token_given(&h, None, "s3cret"));
    }

    #[test]
    fn origins_are_compared_with_the_host() {
        let mut h = HeaderMap::new();
        assert!(!cross_origin(&h));
        h.insert(header::HOST, "127.0.0.1:8088".parse().unwrap());
        h.insert(header::ORIGIN, "http://127.0.0.1:8088".parse().unwrap());
        assert!(!cross_origin(&h));
        h.insert(header::ORIGIN, "https://evil.example".parse().unwrap());
        assert!(cross_origin(&h));
    }
}
