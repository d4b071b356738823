//! `WS /ws/mavlink[?filter=REGEX]`: frames out as `{"header","message"}`, objects in.

use core::sync::atomic::Ordering;
use std::collections::HashMap;
use std::sync::Arc;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use regex::Regex;
use tokio::sync::broadcast::error::RecvError;

use super::Shared;

/// A WebSocket client's place among [`WebOptions::max_clients`](super::WebOptions); given
/// back when dropped.
struct Slot(Arc<Shared>);

impl Drop for Slot {
    fn drop(&mut self) {
        self.0.clients.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Opens a client's WebSocket: 400 for a filter that is no regular expression, 503 when
/// [`WebOptions::max_clients`](super::WebOptions) are connected.
pub(crate) async fn upgrade(
    State(shared): State<Arc<Shared>>,
    Query(query): Query<HashMap<String, String>>,
    ws: WebSocketUpgrade,
) -> Response {
    let filter = query.get("filter").map_or(".*", String::as_str);
    let filter = match Regex::new(filter) {
        Ok(re) => re,
        Err(e) => {
            shared.counters.refused.fetch_add(1, Ordering::Relaxed);
            return (StatusCode::BAD_REQUEST, format!("filter: {e}")).into_response();
        }
    };
    if shared.clients.fetch_add(1, Ordering::Relaxed) >= shared.options.max_clients {
        shared.clients.fetch_sub(1, Ordering::Relaxed);
        shared.counters.refused.fetch_add(1, Ordering::Relaxed);
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!(
                "{} WebSocket clients are connected, the most this node serves",
                shared.options.max_clients
            ),
        )
            .into_response();
    }
    let slot = Slot(Arc::clone(&shared));
    ws.max_message_size(shared.options.body_limit)
        .on_upgrade(move |socket| client(socket, shared, filter, slot))
}

/// One client: frames whose name matches `filter` out, objects in, until either side closes
/// or the node stops. The client reads from the shared ring of the newest frames: one that
/// falls behind loses the oldest (counted) and never holds the node or the other clients
/// back.
async fn client(mut socket: WebSocket, shared: Arc<Shared>, filter: Regex, _slot: Slot) {
    let mut frames = shared.frames.subscribe();
    // Whether each message id passes the filter, decided once.
    let mut passes: HashMap<u32, bool> = HashMap::new();
    loop {
        tokio::select! {
            item = frames.recv() => match item {
                Ok(out) => {
                    let wanted = *passes
                        .entry(out.id)
                        .or_insert_with(|| filter.is_match(&out.name));
                    if wanted && socket.send(Message::Text(out.text.clone())).await.is_err() {
                        break;
                    }
                }
                Err(RecvError::Lagged(n)) => {
                    shared.counters.ws_dropped.fetch_add(n, Ordering::Relaxed);
                }
                Err(RecvError::Closed) => break,
            },
            () = shared.node.closed() => break,
            incoming = socket.recv() => match incoming {
                Some(Ok(Message::Text(text))) => {
                    let reply = receive(&shared, text.as_str()).await;
                    if socket.send(Message::Text(reply.into())).await.is_err() {
                        break;
                    }
                }
                Some(Ok(Message::Close(_)) | Err(_)) | None => break,
                Some(Ok(_)) => {}
            },
        }
    }
}

/// An object a client sent: sent as a frame (`Ok(N)`, the frame's length, as mavlink2rest
/// answers) or refused with the reason.
async fn receive(shared: &Shared, text: &str) -> String {
    let parsed = serde_json::from_str::<serde_json::Value>(text)
        .map_err(|e| e.to_string())
        .and_then(|v| shared.mapping.parse_request(&v).map_err(|e| e.to_string()));
    match parsed {
        Ok((header, frame)) => {
            let len = frame.len();
            if shared.send(header, frame).await {
                format!("Ok({len})")
            } else {
                "Could not send: the node has stopped.".to_owned()
            }
        }
        Err(why) => {
            shared.counters.refused.fetch_add(1, Ordering::Relaxed);
            format!("Could not convert input message: {why}")
        }
    }
}
