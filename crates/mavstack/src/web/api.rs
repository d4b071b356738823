//! The REST half of the API: `/mavlink`, `/helper/mavlink`, `/info`, `/docs.json`.

use core::sync::atomic::Ordering;
use std::collections::HashMap;
use std::sync::Arc;

use axum::Router;
use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use serde_json::Value as Json;

use super::{Shared, ws};

/// The OpenAPI document of the API.
const OPENAPI: &str = include_str!("openapi.json");

/// The API's routes (served at the root and under `/v1`).
pub(crate) fn routes() -> Router<Arc<Shared>> {
    Router::new()
        .route("/mavlink", get(all).post(post))
        .route("/mavlink/{*path}", get(pointer))
        .route("/helper/mavlink", get(helper))
        .route("/ws/mavlink", get(ws::upgrade))
        .route("/info", get(info))
        .route("/docs.json", get(openapi))
}

fn json_response(status: StatusCode, body: String) -> Response {
    (status, [(header::CONTENT_TYPE, "application/json")], body).into_response()
}

fn pretty(value: &Json) -> String {
    serde_json::to_string_pretty(value).unwrap_or_else(|_| "null".to_owned())
}

async fn all(State(shared): State<Arc<Shared>>) -> Response {
    let value = shared.lock_store().all_json(&shared.mapping);
    json_response(StatusCode::OK, pretty(&value))
}

/// A JSON pointer into `/mavlink`'s object; a message's own path is answered without
/// making the whole object. Not found: 404 with mavlink2rest's `None`.
async fn pointer(State(shared): State<Arc<Shared>>, Path(path): Path<String>) -> Response {
    let parts: Vec<&str> = path.split('/').collect();
    let found = match parts.as_slice() {
        ["vehicles", s, "components", c, "messages", name, rest @ ..] => {
            match (s.parse::<u8>(), c.parse::<u8>()) {
                (Ok(s), Ok(c)) => shared
                    .lock_store()
                    .message_json(&shared.mapping, s, c, name)
                    .and_then(|v| sub(&v, rest)),
                _ => None,
            }
        }
        _ => {
            let all = shared.lock_store().all_json(&shared.mapping);
            all.pointer(&format!("/{}", path.trim_end_matches('/')))
                .cloned()
        }
    };
    match found {
        Some(v) => json_response(StatusCode::OK, pretty(&v)),
        None => json_response(StatusCode::NOT_FOUND, "None".to_owned()),
    }
}

fn sub(value: &Json, rest: &[&str]) -> Option<Json> {
    if rest.is_empty() || rest == [""] {
        return Some(value.clone());
    }
    value.pointer(&format!("/{}", rest.join("/"))).cloned()
}

/// A `{"header","message"}` object (JSON, or JSON5 as mavlink2rest reads it) sent as a
/// frame: 200 and an empty body once the node has it; 400 naming what is wrong and nothing
/// sent.
async fn post(State(shared): State<Arc<Shared>>, body: Bytes) -> Response {
    let refuse = |status: StatusCode, why: String| {
        shared.counters.refused.fetch_add(1, Ordering::Relaxed);
        (status, [(header::CONTENT_TYPE, "text/plain")], why).into_response()
    };
    let Ok(text) = core::str::from_utf8(&body) else {
        return refuse(
            StatusCode::BAD_REQUEST,
            "Failed to parse input as UTF-8 string".to_owned(),
        );
    };
    let value = match serde_json::from_str::<Json>(text) {
        Ok(v) => v,
        Err(strict) => match json5::from_str::<Json>(text) {
            Ok(v) => v,
            Err(_) => {
                return refuse(
                    StatusCode::BAD_REQUEST,
                    format!("Failed to parse message, not valid JSON: {strict}"),
                );
            }
        },
    };
    let (header, frame) = match shared.mapping.parse_request(&value) {
        Ok(parsed) => parsed,
        Err(e) => {
            return refuse(
                StatusCode::BAD_REQUEST,
                format!("Failed to parse message, not a valid MAVLinkMessage: {e}"),
            );
        }
    };
    if shared.send(header, frame).await {
        StatusCode::OK.into_response()
    } else {
        refuse(
            StatusCode::SERVICE_UNAVAILABLE,
            "the node has stopped".to_owned(),
        )
    }
}

async fn helper(
    State(shared): State<Arc<Shared>>,
    Query(query): Query<HashMap<String, String>>,
) -> Response {
    let Some(name) = query.get("name") else {
        return (
            StatusCode::BAD_REQUEST,
            "Query deserialize error: missing field `name`",
        )
            .into_response();
    };
    match shared.mapping.template(name) {
        Some(v) => json_response(StatusCode::OK, pretty(&v)),
        None => json_response(
            StatusCode::NOT_FOUND,
            "\"Invalid message name.\"".to_owned(),
        ),
    }
}

async fn info(State(shared): State<Arc<Shared>>) -> Response {
    let value = serde_json::json!({
        "version": 0,
        "service": {
            "name": "mavstack",
            "version": env!("CARGO_PKG_VERSION"),
            "sha": "",
            "build_date": "",
            "authors": env!("CARGO_PKG_AUTHORS"),
            "dialect": shared.mapping.dialect().name,
        }
    });
    json_response(StatusCode::OK, pretty(&value))
}

async fn openapi() -> Response {
    json_response(StatusCode::OK, OPENAPI.to_owned())
}
