//! # mavstack
//!
//! The MAVLink stack in one crate: [`Node`], one MAVLink component with any number of
//! links (UDP, TCP, serial), each with its own version and signing
//! ([`LinkSpec`]: a connection string and link options), the router core between them, and
//! one tokio task that owns every socket. The layers are re-exported for direct use:
//! [`core`] (frames, CRC, signing), [`dialects`] (generated messages), [`channel`] (one
//! link's version, handshake and signing), [`router`] (the sans-IO routing core),
//! [`transport`] (connections).
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn std::error::Error>> {
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! // A router: a MAVLink 1-only peripheral, a ground station, and a signed link.
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
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

pub mod link_spec;
pub mod node;
pub mod router_conf;

pub use link_spec::{LinkSpec, LinkSpecError, redacted};
pub use node::{Incoming, LinkReport, Node, NodeBuilder, NodeError, NodeReport, Subscription};

pub use mavstack_channel as channel;
pub use mavstack_core as core;
pub use mavstack_dialects as dialects;
pub use mavstack_router as router;
pub use mavstack_transport as transport;
