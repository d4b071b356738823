//! A node's status as JSON and as a live page (feature `http`; see [`NodeBuilder::http`]).
//!
//! One object describes a node: `t_s` (seconds since it started), `links` (per router link:
//! name, peer, version, frames and bytes each way, conversions, drops by reason, sequence
//! loss per source), `routes` (sysid/compid → link, age) and `systems` (each component's
//! latest HEARTBEAT, its `mode` by name when the autopilot's mode table has it, and the link
//! it came on). `mavstack router --stats` prints it. `GET /api/status` returns it with what
//! the web service ([`crate::web`]) adds: `vehicles` (every component whose HEARTBEAT the
//! service saw, the node's own included: its HEARTBEAT's fields, `mode`, `age_s`, `track`,
//! recent `[lat, lon, height above home]` from GLOBAL_POSITION_INT one a second, and
//! `statustext`, the last lines as `severity`, `text`, `unix_s`) and `web` (the service's
//! counters).
//! `GET /api/events` streams that once a second, and the page at `GET /` draws it beside
//! the telemetry it reads from the mavlink2rest API (`GET /mavlink`), rates computed from
//! successive objects.
//!
//! ```
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let node = Node::builder()
//!     .link(LinkSpec::parse("udpin:127.0.0.1:0?name=gcs", &none)?)
//!     .http("127.0.0.1:0".parse()?)
//!     .start()
//!     .await?;
//! let status = mavstack::status::status_json(&node.report().await.unwrap());
//! assert_eq!(status["links"][0]["name"], "gcs");
//! assert!(node.http_addr().is_some());
//! node.shutdown().await?;
//! # Ok(()) }
//! # tokio::runtime::Builder::new_current_thread().enable_all().build().unwrap().block_on(run()).unwrap();
//! ```
//!
//! [`NodeBuilder::http`]: crate::NodeBuilder::http

use core::convert::Infallible;
use core::time::Duration;

use axum::Router;
use axum::extract::State;
use axum::http::header;
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{Html, IntoResponse, Json, Response};
use axum::routing::get;
use futures_util::Stream;
use serde_json::{Map, Value, json};
use std::sync::Arc;

use crate::NodeReport;
use crate::web::Shared;

/// The page: one self-contained HTML file (no external scripts, styles or fonts).
const PAGE: &str = include_str!("status_page.html");

/// How often `/api/events` sends the status.
pub const EVENT_PERIOD: Duration = Duration::from_secs(1);

fn tenths(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

/// The status object of `report` (see the [module docs](self)).
#[must_use]
pub fn status_json(report: &NodeReport) -> Value {
    let pairs = |list: &[(&'static str, u64)]| -> Map<String, Value> {
        list.iter()
            .map(|(k, v)| ((*k).to_owned(), json!(v)))
            .collect()
    };
    let links: Vec<Value> = report
        .links
        .iter()
        .map(|l| {
            let sources: Vec<Value> = l
                .sources
                .iter()
                .map(|(sysid, compid, received, lost)| {
                    json!({"sysid": sysid, "compid": compid, "received": received, "lost": lost})
                })
                .collect();
            json!({
                "name": l.name,
                "peer": l.peer,
                "version": l.version,
                "rx_frames": l.rx_frames,
                "tx_frames": l.tx_frames,
                "rx_bytes": l.rx_bytes,
                "tx_bytes": l.tx_bytes,
                "converted": l.converted,
                "conversions": pairs(&l.conversions),
                "dropped": pairs(&l.dropped),
                "seq_lost": l.seq_lost,
                "sources": sources,
            })
        })
        .collect();
    let routes: Vec<Value> = report
        .routes
        .iter()
        .map(|(sysid, compid, link, peer, age)| {
            json!({"sysid": sysid, "compid": compid, "link": link, "peer": peer,
                   "age_s": tenths(*age)})
        })
        .collect();
    let systems: Vec<Value> = report
        .systems
        .iter()
        .map(|s| {
            let h = &s.heartbeat;
            json!({
                "sysid": h.sysid,
                "compid": h.compid,
                "type": h.mav_type,
                "autopilot": h.autopilot,
                "armed": h.armed(),
                "base_mode": h.base_mode,
                "custom_mode": h.custom_mode,
                "mode": mode_name(h.autopilot, h.mav_type, h.custom_mode),
                "system_status": h.system_status,
                "link": s.link,
                "peer": s.peer,
                "age_s": tenths(s.age_ms as f64 / 1000.0),
            })
        })
        .collect();
    json!({
        "t_s": tenths(report.t_s),
        "links": links,
        "routes": routes,
        "systems": systems,
    })
}

/// The status object with what the web service adds: `vehicles` and `web`.
fn full_json(report: &NodeReport, shared: &Shared) -> Value {
    let mut value = status_json(report);
    let store = shared.lock_store();
    let vehicles: Vec<Value> = store
        .heartbeats()
        .into_iter()
        .map(|(sysid, compid, h, age_s)| {
            let track: Vec<Value> = store
                .track(sysid, compid)
                .into_iter()
                .map(|(lat, lon, height)| json!([lat, lon, tenths(height)]))
                .collect();
            let texts: Vec<Value> = store
                .texts(sysid, compid)
                .into_iter()
                .map(|t| json!({"severity": t.severity, "text": t.text, "unix_s": t.unix_s}))
                .collect();
            json!({
                "sysid": sysid,
                "compid": compid,
                "type": h.r#type.0,
                "autopilot": h.autopilot.0,
                "armed": h.base_mode.0 & 0x80 != 0,
                "custom_mode": h.custom_mode,
                "mode": mode_name(h.autopilot.0, h.r#type.0, h.custom_mode),
                "system_status": h.system_status.0,
                "age_s": tenths(age_s),
                "track": track,
                "statustext": texts,
            })
        })
        .collect();
    drop(store);
    if let Value::Object(map) = &mut value {
        map.insert("vehicles".into(), Value::Array(vehicles));
        map.insert("web".into(), shared.counters_json());
    }
    value
}

/// The name of a HEARTBEAT's `custom_mode` in its autopilot's mode table, if it has one.
fn mode_name(autopilot: u8, mav_type: u8, custom_mode: u32) -> Option<&'static str> {
    use mavstack_dialects::common::{MavAutopilot, MavType};
    let flavour = crate::modes::Flavour::of(MavAutopilot(autopilot), MavType(mav_type))?;
    crate::modes::name_of(flavour, custom_mode)
}

/// The page, `/api/status` and `/api/events`, for the web service's router.
pub(crate) fn routes() -> Router<Arc<Shared>> {
    Router::new()
        .route("/", get(page))
        .route("/api/status", get(status))
        .route("/api/events", get(events))
}

async fn page() -> Response {
    (
        [(header::CACHE_CONTROL, "no-store")],
        Html(PAGE).into_response(),
    )
        .into_response()
}

async fn status(State(shared): State<Arc<Shared>>) -> Response {
    match shared.node.report().await {
        Some(report) => Json(full_json(&report, &shared)).into_response(),
        None => (
            axum::http::StatusCode::SERVICE_UNAVAILABLE,
            "the node has stopped",
        )
            .into_response(),
    }
}

async fn events(
    State(shared): State<Arc<Shared>>,
) -> Sse<impl Stream<Item = Result<Event, Infallible>>> {
    let ticks = tokio::time::interval(EVENT_PERIOD);
    let stream = futures_util::stream::unfold((shared, ticks), |(shared, mut ticks)| async move {
        ticks.tick().await;
        let report = shared.node.report().await?;
        let event = Event::default().data(full_json(&report, &shared).to_string());
        Some((Ok(event), (shared, ticks)))
    });
    Sse::new(stream).keep_alive(KeepAlive::default())
}
