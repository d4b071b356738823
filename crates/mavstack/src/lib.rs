//! # mavstack
//!
//! The MAVLink stack in one crate. A [`Node`] is one MAVLink component (a system and
//! component id) with any number of links — UDP, TCP, serial — each with its own version and
//! signing ([`LinkSpec`]: a connection string and link options), the router core between
//! them, and one driver that owns every socket: a tokio task, or a thread of its own for a
//! process whose main work is the node ([`NodeBuilder::own_thread`]). On a node:
//!
//! - [`system::System`] is a remote system as a ground station sees it: its parameters,
//!   missions, commands and telemetry (feature `services`);
//! - [`serve::Served`] runs your own component's services — a parameter table, a mission
//!   store, command handlers, telemetry streamed at the rates ground stations ask for — for
//!   vehicles, companion computers and peripherals;
//! - [`sim_vehicle::SimVehicle`] is a simulated ArduPilot or PX4 vehicle, in-process, for a
//!   ground station's tests (feature `sim`), and [`radio::RadioBridge`] a semi-transparent
//!   radio to put between them.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ## A ground station
//!
//! [`system::System::connect`] opens a ground station's link (system 255, a GCS HEARTBEAT
//! every second, the MAVLink 2 handshake when the vehicle still speaks MAVLink 1) and finds
//! the first autopilot heard; its handles then give its parameters, a mission, its
//! attitude as it streams, and flying it (the `ground_station`, `mission_upload` and
//! `offboard` examples run this against the simulated vehicle):
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use core::time::Duration;
//! use mavstack::dialects::common::{Attitude, MavMissionType};
//! use mavstack::services::wpl;
//! use mavstack::system::{System, Wanted};
//! use mavstack::LinkSpec;
//! let spec = LinkSpec::parse("udpin:0.0.0.0:14550", &|_| None)?;
//! let session = System::connect(spec, Wanted::AnyAutopilot, Duration::from_secs(10)).await?;
//! let vehicle = session.system();
//! let table = vehicle.params().get_all().await?;
//! println!("{} parameters from {}", table.len(), vehicle.target());
//! let plan = wpl::parse(&std::fs::read_to_string("survey.waypoints")?)?;
//! vehicle.mission().upload_plan(MavMissionType::MISSION, &plan, |_, _| {}).await?;
//! vehicle.action().arm().await?;
//! vehicle.action().takeoff(10.0, |_| {}).await?;
//! let mut attitude = vehicle.telemetry().subscribe::<Attitude>().await;
//! while let Some(a) = attitude.recv().await {
//!     println!("roll {:.2} rad", a.message.roll);
//! }
//! # Ok(()) }
//! ```
//!
//! Every operation runs the `mavstack-services` state machine for it (retries, timeouts,
//! IN_PROGRESS) and ends when its future resolves; dropping the future cancels it.
//! [`system::Discovery`] reports systems appearing, changing and lost; [`Node::subscribe`]
//! gives every frame for the node, [`NodeHandle::events`] what happens on its links.
//!
//! ## A vehicle or a companion computer
//!
//! Links in the vehicle role answer the handshake and SETUP_SIGNING themselves, each by its
//! own rules; your component's services run with [`serve::Served`]:
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::router::{LinkRole, ProtocolVersionSupport};
//! use mavstack::serve::Served;
//! use mavstack::services::Address;
//! use mavstack::services::param::{Encoding, Name, ParamServer, Value};
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let node = Node::builder()
//!     .identity(1, 100) // a camera
//!     .role(LinkRole::Vehicle { protocol_version: ProtocolVersionSupport::Answer })
//!     .link(LinkSpec::parse("serial:/dev/ttyAMA0:921600?name=fc", &none)?)
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550?name=gcs", &none)?)
//!     .start()
//!     .await?;
//! let mut params = ParamServer::new(Address::new(1, 100), Encoding::Bytewise);
//! params.insert(Name::new("CAM_EXPOSURE")?, Value::F32(0.01))?;
//! let served = Served::start(&node.handle(), params).await;
//! # Ok(()) }
//! ```
//!
//! ## Several links, each its own version
//!
//! A router between a MAVLink 1-only peripheral, a ground station and a signed link: frames
//! are forwarded by the MAVLink routing rules and converted where the links differ (the
//! `companion` example; `mavstack router` on the command line):
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let node = Node::builder()
//!     .link(LinkSpec::parse("serial:/dev/ttyS1:57600?version=1&name=legacy", &none)?)
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550?name=gcs", &none)?)
//!     .link(LinkSpec::parse(&format!("tcpin:0.0.0.0:5760?key={}", "00".repeat(32)), &none)?)
//!     .start()
//!     .await?;
//! let report = node.report().await;
//! node.shutdown().await?;
//! # Ok(()) }
//! ```
//!
//! ## The layers
//!
//! Re-exported for direct use: [`core`] (frames, CRC, signing), [`dialects`] (generated
//! messages), [`channel`] (one link's version, handshake and signing), [`router`] (the
//! sans-IO routing core), [`transport`] (connections), [`services`] (the microservices'
//! state machines), [`sim`] (the vehicle model).
//!
//! ## Features
//! - `services`: remote systems' services ([`system`]), our own ([`serve`]), event metadata,
//!   probing a link for its systems and their MAVLink versions ([`probe`]).
//! - `sim`: the simulated vehicle ([`sim_vehicle`], [`sim`]) and `conform` (implies `services`).
//! - `http`: a live status page and JSON for a node (`status`).
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (the `fuzz_*` entry points; enables `mavstack-router`'s too).
//!
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

#[cfg(feature = "sim")]
pub mod conform;
#[cfg(feature = "services")]
pub mod events;
pub mod link_spec;
#[cfg(feature = "services")]
pub mod modes;
pub mod node;
#[cfg(target_os = "linux")]
mod own_thread;
#[cfg(feature = "services")]
pub mod probe;
pub mod radio;
pub mod router_conf;
#[cfg(feature = "services")]
pub mod serve;
#[cfg(feature = "sim")]
pub mod sim_camera;
#[cfg(feature = "sim")]
pub mod sim_vehicle;
#[cfg(feature = "http")]
pub mod status;
#[cfg(feature = "services")]
pub mod system;
#[cfg(feature = "http")]
pub mod web;

pub use link_spec::{LinkSpec, LinkSpecError, redacted};
pub use node::{
    BATCH_DEPTH, BatchFrame, BatchSubscription, BatchWait, EventSubscription, FrameBatch, Incoming,
    InputModeration, LinkEvent, LinkReport, Node, NodeBuilder, NodeError, NodeEvent, NodeHandle,
    NodeReport, RequestError, Subscription, SystemReport, TapSubscription, Tapped,
};

/// A message's name in the common dialect (`"HEARTBEAT"`), or `"message N"` for an id it
/// does not define: for logs and reports.
///
/// ```
/// assert_eq!(mavstack::message_name(0), "HEARTBEAT");
/// assert_eq!(mavstack::message_name(60_000), "message 60000");
/// ```
#[must_use]
pub fn message_name(id: u32) -> String {
    use mavstack_core::MessageSet as _;
    mavstack_dialects::common::MavMessage::info(id)
        .map_or_else(|| format!("message {id}"), |m| m.name.to_owned())
}

/// An error and its sources, joined by `: ` (`cannot read x.tlog: Is a directory (os
/// error 21)`): how an error with its cause chain is shown on one line. A source the line
/// already ends with is not repeated: some errors print their source in their own message
/// too (`link "x": cannot bind ...` over the bind error).
///
/// ```
/// let e = std::io::Error::other("inner");
/// assert_eq!(mavstack::error_chain(&e), "inner");
/// let spec = mavstack::LinkSpec::parse("udpin:0.0.0.0:99999", &|_| None).unwrap_err();
/// let line = mavstack::error_chain(&spec);
/// assert_eq!(line, spec.to_string(), "its cause is already in its message");
/// ```
#[must_use]
pub fn error_chain(e: &dyn ::core::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let more = s.to_string();
        if text != more && !text.ends_with(&format!(": {more}")) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = s.source();
    }
    text
}

pub use mavstack_channel as channel;
pub use mavstack_core as core;
pub use mavstack_dialects as dialects;
pub use mavstack_router as router;
#[cfg(feature = "services")]
pub use mavstack_services as services;
#[cfg(feature = "sim")]
pub use mavstack_sim as sim;
pub use mavstack_transport as transport;
