//! # mavstack-transport
//!
//! MAVLink links for `std` + tokio: UDP, TCP, serial ports and tlog files behind one
//! connection string, with an async handle and a blocking one over the same driver.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!  "udpin:0.0.0.0:14550"            (conn)  ConnSpec::from_str
//!            │
//!            ▼                                   one tokio task per connection
//!  ┌───────────────┐  bytes + PeerId  ┌────────────────────────────┐  P::Event   ┌────────────┐
//!  │ link          │ ───────────────► │ driver                     │ ──────────► │ Connection │
//!  │ udp  tcp      │                  │  handle_input / _command / │  (bounded   │  recv()    │
//!  │ serial  file  │ ◄─────────────── │  _timeout / _peer_*        │   channel)  │  send()    │
//!  └───────────────┘  poll_transmit   │  poll_transmit / _event /  │ ◄────────── │  stats()   │
//!     ▲   helper tasks:               │  _timeout                  │  P::Command │  peers()   │
//!     │   accept, reconnect,          │     ┌──────────────────┐   │             └────────────┘
//!     │   per-peer writers            │     │ P: Protocol      │   │     blocking::Connection:
//!     │                               │     │ (sans-IO, e.g.   │   │     the same, on a runtime
//!   OS sockets, tty, files            │     │  FrameProtocol)  │   │     thread of its own
//!                                     │     └──────────────────┘   │
//!                                     └────────────────────────────┘
//! ```
//!
//! - [`conn`]: connection strings ([`ConnSpec`]), both the `udpin:HOST:PORT` and the
//!   `udp://HOST:PORT` spellings.
//! - [`protocol`]: the [`Protocol`] trait a driver runs (sans-IO: `handle_*` in, `poll_*`
//!   out), peers ([`PeerId`], [`PeerInfo`]) and transmits ([`Transmit`], [`Dest`]).
//! - [`frame`]: [`FrameProtocol`], the default protocol: frames from every peer, checked
//!   with the caller's `MessageTable`, as events; frames to send as commands.
//! - [`Connection`] (async) and [`blocking::Connection`]: open a link, drive a protocol on
//!   it, talk to it.
//! - [`tlog`]: tlog [`tlog::Reader`] and [`tlog::Writer`] for recording and replaying;
//!   [`raw`]: [`raw::read_items`], the reading of a raw capture to its end, and
//!   [`raw::count_items_split`], a capture file counted in parts on several threads.
//! - [`clock`]: the time the driver gives protocols: monotonic, in microseconds since the
//!   Unix epoch.
//!
//! ## Links
//!
//! | spec | peers |
//! | --- | --- |
//! | `udpin` | every address that sends a datagram, until it is quiet for [`Options::peer_timeout`]; each is answered at its own address |
//! | `udpout`, `udpbcast` | the target (never expires); replies from elsewhere become peers too, reachable by `Dest::Peer` |
//! | `tcp` | the server, a new peer after each reconnection (back-off [`Options::reconnect_min`] doubling to [`Options::reconnect_max`]); transmits while disconnected are dropped and counted |
//! | `tcpin` | each accepted client, until it disconnects |
//! | `serial` | the port (reopened with back-off if it goes away) |
//! | `file` | the file: read to its end (then the connection ends), or written ([`Options::file_mode`]) |
//!
//! A UDP datagram is one input ([`protocol::Framing::Datagram`]): frames never span two.
//! TCP, serial and raw files are streams: a frame may be split anywhere. Writes to stream
//! peers go through a bounded queue per peer, so a slow peer never blocks the others; what
//! does not fit is dropped and counted in [`LinkStats::tx_dropped`].
//!
//! ## Example: a ground station's receive loop
//!
//! ```no_run
//! use mavstack_transport::{Connection, frame::{FrameEvent, FrameProtocol, MessageTable}};
//! use mavstack_dialects::common::MavMessage;
//! # #[tokio::main(flavor = "current_thread")]
//! # async fn main() -> Result<(), Box<dyn core::error::Error>> {
//! let spec = "udp://:14550".parse()?;
//! let mut conn = Connection::open(&spec, FrameProtocol::new(MessageTable::of::<MavMessage>())).await?;
//! while let Some(event) = conn.recv().await {
//!     match event {
//!         FrameEvent::Frame(f) => println!("{}: msg {} from {}", f.peer, f.frame.msg_id(), f.frame.sysid()),
//!         FrameEvent::PeerAdded(p) => println!("{} is {}", p.id, p.addr),
//!         _ => {}
//!     }
//! }
//! # Ok(()) }
//! ```
//!
//! ## Guarantees
//! - `#![forbid(unsafe_code)]`; no panics on anything that comes from outside.
//! - No heap allocation per received UDP frame ([`frame::FrameBuf`] is a fixed array);
//!   stream reads allocate one buffer per read, not per frame.
//! - Errors name the thing that failed, in one line: `cannot bind udp 127.0.0.1:14550:
//!   address in use`, `cannot open serial /dev/ttyX: no such file`.
//!
//! ## Features
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`tlog::fuzz_tlog`).
//!
//! MSRV: Rust 1.95.
#![forbid(unsafe_code)]

mod batch;
pub mod blocking;
pub mod clock;
pub mod conn;
mod connection;
mod driver;
pub mod error;
pub mod frame;
mod link;
pub mod protocol;
pub mod raw;
pub mod tlog;
mod udp_io;

pub use conn::{ConnSpec, ConnSpecError, FileFormat};
pub use connection::{Connection, ConnectionStats, FileMode, Options};
pub use error::{LinkError, OpenError, SendError};
pub use frame::{FrameBuf, FrameCommand, FrameEvent, FrameProtocol, ReceivedFrame};
pub use link::{ExternalPeer, ExternalSender, Link, LinkStats};
pub use protocol::{Dest, Input, PeerId, PeerInfo, Protocol, Transmit};
