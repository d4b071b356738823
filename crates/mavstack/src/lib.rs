//! # mavstack
//!
//! The MAVLink stack in one crate: [`Node`], one MAVLink component with any number of
//! links (UDP, TCP, serial), each with its own version and signing
//! ([`LinkSpec`]: a connection string and link options), the router core between them, and
//! one tokio task that owns every socket.
//!
//! A ground station: system 255, MAVLink 2 towards the vehicle, printing its attitude.
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::core::MessageSet as _;
//! use mavstack::dialects::common::MavMessage;
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let gcs = Node::builder()
//!     .identity(255, 190)
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550?version=2", &none)?)
//!     .start()
//!     .await?;
//! let mut frames = gcs.subscribe().await;
//! while let Some(incoming) = frames.recv().await {
//!     let f = incoming.frame.frame.view();
//!     if let Ok(MavMessage::Attitude(a)) = MavMessage::decode(f.msg_id(), f.payload()) {
//!         println!("{}/{} roll {:.2} rad on {}", f.sysid(), f.compid(), a.roll, incoming.link);
//!     }
//! }
//! # Ok(()) }
//! ```
//!
//! [`Node::send`] sends the node's own messages (each link frames them in its version and
//! signs them where it signs); [`NodeBuilder::heartbeat`] announces the node. With the
//! `sim` feature, [`sim`] is the simulated vehicle and `sim_vehicle::SimVehicle` runs it on
//! a node of its own, in-process, for a ground station's tests (the `ground_station`
//! example).
//!
//! A router between a MAVLink 1-only peripheral, a ground station and a signed link:
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
//! The layers are re-exported for direct use: [`core`] (frames, CRC, signing), [`dialects`]
//! (generated messages), [`channel`] (one link's version, handshake and signing), [`router`]
//! (the sans-IO routing core), [`transport`] (connections).
//!
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

pub mod link_spec;
pub mod node;
pub mod router_conf;
#[cfg(feature = "services")]
pub mod serve;
#[cfg(feature = "sim")]
pub mod sim_vehicle;
#[cfg(feature = "services")]
pub mod system;

pub use link_spec::{LinkSpec, LinkSpecError, redacted};
pub use node::{
    EventSubscription, Incoming, LinkEvent, LinkReport, Node, NodeBuilder, NodeError, NodeEvent,
    NodeHandle, NodeReport, RequestError, Subscription,
};

pub use mavstack_channel as channel;
pub use mavstack_core as core;
pub use mavstack_dialects as dialects;
pub use mavstack_router as router;
#[cfg(feature = "services")]
pub use mavstack_services as services;
#[cfg(feature = "sim")]
pub use mavstack_sim as sim;
pub use mavstack_transport as transport;
