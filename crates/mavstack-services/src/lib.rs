//! Sans-IO MAVLink microservices, in both roles: heartbeat and peer tracking, the command
//! protocol, the parameter and mission protocols, message rates, and TIMESYNC.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! Every service is a state machine that never reads a clock, never sleeps and never touches
//! a socket. It works on *decoded* messages (the `common` dialect's
//! [`MavMessage`]), not bytes, so it sits on top of a
//! link layer such as `mavstack-channel`, whose accepted frames an adapter decodes and
//! hands in, and whose `send` the adapter feeds with what the services emit:
//!
//! ```text
//!              accepted frames (decoded)                       messages to send
//!   channel ──► handle_message(now, from, &MavMessage) ─┐   ┌─► poll_transmit() -> Outgoing { target, message }
//!                                                       ▼   │                         │
//!   driver  ──► handle_timeout(now) ───────────────► [ service ] ──► poll_event()    ▼
//!       ▲                                               │        (results, peers)  channel ──► link
//!       └─────────── sleep until poll_timeout() ◄───────┘
//! ```
//!
//! The contract, the same for every service (and collected in the [`Service`] trait):
//!
//! - [`Service::handle_message`]`(now, from, &msg)` for every decoded message received, with
//!   the sender's [`Address`] (frame header sysid/compid). It returns whether the service
//!   used the message; messages meant for other components are ignored.
//! - [`Service::handle_timeout`]`(now)` when the deadline from
//!   [`Service::poll_timeout`] has passed (calling it early is harmless).
//! - [`Service::poll_transmit`] until `None` after each of the above and after each
//!   request (`send`, `fetch_all`, `set`, ...): every [`Outgoing`] is one message to
//!   send, with the [`Address`] it is for (`Address::BROADCAST` for broadcasts). The
//!   services fill in `target_system`/`target_component` fields themselves.
//! - Each service's `poll_event` (an inherent method, because every service has its own
//!   event type) until `None`: results of requests, peers found and lost, values changed.
//!
//! Time is a [`mavstack_core::time::Instant`] (monotonic microseconds) chosen by the driver.
//! Retries and timeouts follow the reference values collected in `docs/protocol-notes.md`
//! (§6): MAVSDK's 0.5 s command timeout with 3 retries and 3 s after IN_PROGRESS,
//! a 3 s heartbeat timeout, parameter retries ×5.
//!
//! | module | messages | client role | server role |
//! | --- | --- | --- | --- |
//! | [`heartbeat`] | HEARTBEAT | [`heartbeat::Heartbeats`] peer table (new / lost / changed) | the same type emits our own HEARTBEAT |
//! | [`command`] | COMMAND_LONG, COMMAND_INT, COMMAND_ACK | [`command::CommandClient`] | [`command::CommandServer`] |
//! | [`param`] | PARAM_REQUEST_LIST/READ, PARAM_SET, PARAM_VALUE | [`param::ParamClient`] | [`param::ParamServer`] |
//! | [`mission`] | MISSION_COUNT, MISSION_REQUEST_INT, MISSION_ITEM_INT, MISSION_ACK, ... | [`mission::MissionClient`] | [`mission::MissionServer`] |
//! | [`stream`] | SET_MESSAGE_INTERVAL, REQUEST_MESSAGE, MESSAGE_INTERVAL | [`stream::Subscriptions`], [`stream::set_message_interval`], [`stream::request_message`] | [`stream::StreamScheduler`], [`stream::StreamServer`] (a whole service) |
//! | [`ftp`] | FILE_TRANSFER_PROTOCOL | [`ftp::FtpClient`] | [`ftp::FtpServer`] over a [`ftp::Backend`] ([`ftp::MemoryBackend`]) |
//! | [`log_transfer`] | LOG_REQUEST_LIST, LOG_ENTRY, LOG_REQUEST_DATA, LOG_DATA, LOG_ERASE, LOG_REQUEST_END | [`log_transfer::LogClient`] (list, download with gaps asked again, erase) | [`log_transfer::LogServer`] over a [`log_transfer::LogStore`] ([`log_transfer::MemoryLogs`]), paced per tick |
//! | [`plan`] | — | [`plan::to_vehicle`], [`plan::from_vehicle`], [`plan::same`]: a plan file's mission as each autopilot stores it (ArduPilot's home at 0, PX4's none) | — |
//! | [`rtcm`] | GPS_RTCM_DATA | [`rtcm::RtcmSender`] (a message in up to 4 fragments, a sequence id each), [`rtcm::Deframer`] (RTCM3 frames in a byte stream, by their CRC-24Q) | [`rtcm::Reassembler`] |
//! | [`gimbal`] | GIMBAL_MANAGER_*, GIMBAL_DEVICE_*, DO_GIMBAL_MANAGER_PITCHYAW / _CONFIGURE, DO_SET_ROI_LOCATION / _NONE | [`gimbal::GimbalDiscovery`], [`gimbal::GimbalInfo`] (the commands, checked against the manager's limits), [`gimbal::Attitude`] (quaternion → degrees in the frame the flags say) | [`gimbal::GimbalManager`] (a manager for a device its owner drives) |
//! | [`camera`] | CAMERA_*, STORAGE_INFORMATION, VIDEO_STREAM_*, IMAGE_* / VIDEO_* commands, PARAM_EXT_* | [`camera::PhotoCapture`] (a photo to its CAMERA_IMAGE_CAPTURED, a lost one asked for again), [`camera::ParamExtClient`], [`camera::CameraDefinition`] (definition files, bounded, positioned errors) | [`camera::CameraServer`], [`camera::ParamExtServer`] |
//! | [`shell`] | SERIAL_CONTROL | [`shell::ShellClient`] (a session with the SHELL device: 70-byte chunks, polling), [`shell::ShellCommand`] (one command line, its output) | — |
//! | [`statustext`] | STATUSTEXT | [`statustext::Lines`] (chunks put together, text made safe to show) | — |
//! | [`timesync`] | TIMESYNC | [`timesync::Timesync`] (estimates the offset) | the same type answers requests |
//!
//! # Limitations
//!
//! - Parameters: a list fetch addressed to component 0 collects every answering
//!   component's values into one list; fetch per component instead. The server hands the
//!   whole list out at once; pacing it to the link is the driver's job (drain
//!   `poll_transmit` at a rate). The 64-bit parameter types are not carried.
//! - Commands: a second command with the same id to the same target while the first is in
//!   flight is refused ([`command::SendError::AlreadyInFlight`]) rather than queued, and
//!   COMMAND_CANCEL is not sent.
//! - Missions: the server takes uploads of the deprecated float MISSION_ITEM (converted
//!   to MISSION_ITEM_INT) but answers MISSION_REQUEST with MISSION_ITEM_INT; one upload at a time (another peer
//!   gets DENIED); no `opaque_id` (the vendored common.xml version has none); ArduPilot's
//!   "seq 0 is home" is the caller's concern.
//! - TIMESYNC: this dialect's TIMESYNC has no target fields, so answers are matched by
//!   their `ts1`.
//! - Over real links, run these state machines on a `mavstack::Node`:
//!   `mavstack::system::System` drives the client roles for one remote system and
//!   `mavstack::serve::Served` the server roles as the node's own component; every message
//!   is then framed by its link's channel (version, sequence, signature). By hand, decode
//!   each accepted frame with `MavMessage::decode(frame.msg_id(), frame.payload())` and
//!   give each [`Outgoing`] message to the link that frames it.
//!
//! # Features
//!
//! - `std` (default): links the standard library; nothing in the crate needs it. Without it
//!   the crate is `no_std` and needs only `alloc` (for its tables and queues).
//! - `json`: mission plans as JSON ([`mission_json`]; with `std`).
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (the `fuzz_*` entry points and `HEAP_BOUND`).
//!
//! # Example
//!
//! A command client and a server wired by hand:
//!
//! ```
//! use mavstack_core::time::Instant;
//! use mavstack_dialects::common::{CommandLong, MavCmd, MavResult};
//! use mavstack_services::command::{
//!     Command, CommandClient, CommandEvent, CommandHandler, CommandServer, Request, Response,
//! };
//! use mavstack_services::{Address, Service};
//!
//! struct Arm;
//! impl CommandHandler for Arm {
//!     fn handle_command(&mut self, _now: Instant, _request: &Request) -> Response {
//!         Response::done(MavResult::ACCEPTED)
//!     }
//! }
//!
//! let gcs = Address::new(255, 190);
//! let vehicle = Address::new(1, 1);
//! let mut client = CommandClient::new(gcs, Default::default());
//! let mut server = CommandServer::new(vehicle, Default::default(), Arm);
//! let now = Instant::ZERO;
//! let cmd = CommandLong { command: MavCmd::COMPONENT_ARM_DISARM, param1: 1.0, ..Default::default() };
//! let handle = client.send(now, vehicle, Command::Long(cmd)).unwrap();
//! while let Some(out) = client.poll_transmit() {
//!     server.handle_message(now, gcs, &out.message);
//! }
//! while let Some(out) = server.poll_transmit() {
//!     client.handle_message(now, vehicle, &out.message);
//! }
//! match client.poll_event() {
//!     Some(CommandEvent::Finished { handle: h, result: Ok(ack) }) => {
//!         assert_eq!(h, handle);
//!         assert_eq!(ack.result, MavResult::ACCEPTED);
//!     }
//!     other => panic!("{other:?}"),
//! }
//! ```
#![no_std]
#![forbid(unsafe_code)]

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod camera;
pub mod command;
pub mod ftp;
#[cfg(feature = "fuzzing")]
mod fuzzing;
pub mod gimbal;
pub mod heartbeat;
pub mod log_transfer;
pub mod mission;
#[cfg(feature = "json")]
pub mod mission_json;
pub mod param;
pub mod plan;
mod ranges;
pub mod rtcm;
mod rtt;
mod search;
pub mod shell;
pub mod statustext;
pub mod stream;
pub mod timesync;
pub mod wpl;

#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use fuzzing::{HEAP_BOUND, fuzz_services};

use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;

/// A MAVLink system and component id pair: where a message came from or is going to.
///
/// `0` in either part is the broadcast id of that part.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Address {
    /// The system id (`0` = every system).
    pub system: u8,
    /// The component id (`0` = every component).
    pub component: u8,
}

impl Address {
    /// Every component of every system.
    pub const BROADCAST: Self = Self::new(0, 0);

    /// The address `system`/`component`.
    #[must_use]
    pub const fn new(system: u8, component: u8) -> Self {
        Self { system, component }
    }

    /// Whether a message addressed to `target` reaches `self` (a 0 part in `target` matches
    /// any id).
    ///
    /// ```
    /// use mavstack_services::Address;
    /// let me = Address::new(1, 1);
    /// assert!(me.is_reached_by(Address::new(1, 0)));
    /// assert!(me.is_reached_by(Address::BROADCAST));
    /// assert!(!me.is_reached_by(Address::new(2, 1)));
    /// ```
    #[must_use]
    pub const fn is_reached_by(self, target: Self) -> bool {
        (target.system == 0 || target.system == self.system)
            && (target.component == 0 || target.component == self.component)
    }
}

impl core::fmt::Display for Address {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}/{}", self.system, self.component)
    }
}

/// One message a service wants sent.
#[derive(Clone, Debug, PartialEq)]
#[must_use]
pub struct Outgoing {
    /// Whom it is for ([`Address::BROADCAST`] for broadcasts). Routing hint only: the
    /// message's own `target_*` fields, if it has them, are already filled in.
    pub target: Address,
    /// The message.
    pub message: MavMessage,
}

/// The sans-IO surface every service offers (see the crate docs for when to call what).
pub trait Service {
    /// Feeds one decoded message received from `from`. Returns whether the service used it.
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool;

    /// Advances timers to `now`: retries, timeouts, periodic sends. Call it when
    /// [`Service::poll_timeout`] has passed; calling it at other times is harmless.
    fn handle_timeout(&mut self, now: Instant);

    /// The next message to send, if any. Call until `None` after every `handle_*` call and
    /// every request.
    #[must_use]
    fn poll_transmit(&mut self) -> Option<Outgoing>;

    /// When [`Service::handle_timeout`] next needs to be called, if ever.
    #[must_use]
    fn poll_timeout(&self) -> Option<Instant>;
}

/// Two services side by side (a parameter server and a mission server, say): every message
/// goes to both, their transmits and timers are merged. Nest pairs for more.
impl<A: Service, B: Service> Service for (A, B) {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let a = self.0.handle_message(now, from, message);
        let b = self.1.handle_message(now, from, message);
        a || b
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.0.handle_timeout(now);
        self.1.handle_timeout(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.0.poll_transmit().or_else(|| self.1.poll_transmit())
    }

    fn poll_timeout(&self) -> Option<Instant> {
        earliest(self.0.poll_timeout(), self.1.poll_timeout())
    }
}

/// The earlier of two optional deadlines.
fn earliest(a: Option<Instant>, b: Option<Instant>) -> Option<Instant> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, None) => a,
        (None, b) => b,
    }
}
