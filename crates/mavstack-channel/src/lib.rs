//! # mavstack-channel
//!
//! The `no_std`, sans-IO state of one MAVLink link: which version it sends (MAVLink 1,
//! MAVLink 2 or signed MAVLink 2) and how that is negotiated, the MAVLink 2 handshake in both
//! roles, signing with per-stream replay protection, sequence and loss statistics, and a
//! semi-transparent radio.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! ```text
//!   bytes in ──► handle_input(now, &[u8]) ─► Deframer ─► signing checks ─► version rules
//!                                                          │ rejections      │ handshake
//!                                                          ▼                 ▼
//!   time ─────► handle_timeout(now)                     poll_event() ◄── events queue
//!                   │ retries                                            (fixed size)
//!                   ▼
//!   bytes out ◄─ poll_transmit(now, &mut buf) ◄── control frames (ACK, PROTOCOL_VERSION,
//!            ◄─ send(now, &msg, &mut buf)                          handshake requests)
//!   next wake-up: poll_timeout()
//! ```
//!
//! A [`Channel`] never reads a clock, sleeps, locks, allocates or touches a socket; the
//! caller passes time in as [`Instant`](mavstack_core::time::Instant) (monotonic
//! microseconds) and moves the bytes.
//!
//! ## Driving a channel
//! A transport adapter owns one channel per link and loops:
//!
//! 1. **Bytes arrived** at `now`: feed them with [`Channel::handle_input`], which returns how
//!    many it took; then drain [`Channel::poll_event`] until `None` (this also resumes
//!    processing if the event queue had filled), and feed the rest again if any.
//! 2. **Drain [`Channel::poll_transmit`]** into the link after every input, timeout and send:
//!    the channel's own answers (COMMAND_ACK, PROTOCOL_VERSION) and handshake requests
//!    come out there, each written into a `[u8; 280]` buffer.
//! 3. **Sleep until [`Channel::poll_timeout`]** (or the next input), then call
//!    [`Channel::handle_timeout`] and go to 2.
//! 4. **The application's frames** go out through [`Channel::send`] (typed),
//!    [`Channel::send_raw`] (id, CRC_EXTRA and payload) or [`Channel::send_mavlink2`] (the
//!    handshake-answer exception), each writing into the caller's buffer.
//! 5. **Persist** the signing timestamp whenever [`Event::PersistTimestamp`] arrives.
//!
//! ```
//! use mavstack_channel::{Channel, CommandEncoding, Config, Event, HandshakeMethod,
//!                        HandshakeResult, LinkVersion, Target};
//! use mavstack_core::time::Instant;
//!
//! let mut vehicle = Channel::new(Config::vehicle(1, 1)).unwrap();
//! let mut gcs = Channel::new(Config::ground_station(255, 190)).unwrap();
//! assert_eq!(vehicle.version(), LinkVersion::Mavlink1);
//!
//! let now = Instant::from_secs(1_767_225_600); // 2026-01-01, Unix time
//! gcs.start_handshake(now, Target::new(1, 1), HandshakeMethod::RequestMessage300,
//!                     CommandEncoding::Long).unwrap();
//! let mut buf = [0u8; 280];
//! // Shuttle bytes both ways until both sides are quiet.
//! loop {
//!     let mut moved = false;
//!     while let Some(t) = gcs.poll_transmit(now, &mut buf) {
//!         assert_eq!(vehicle.handle_input(now, &buf[..t.len]), t.len);
//!         moved = true;
//!     }
//!     while let Some(t) = vehicle.poll_transmit(now, &mut buf) {
//!         assert_eq!(gcs.handle_input(now, &buf[..t.len]), t.len);
//!         moved = true;
//!     }
//!     while vehicle.poll_event().is_some() {}
//!     while let Some(event) = gcs.poll_event() {
//!         if let Event::Handshake(outcome) = event {
//!             assert!(matches!(outcome.result, HandshakeResult::ProtocolVersion(v) if v.max_version == 200));
//!         }
//!     }
//!     if !moved { break; }
//! }
//! assert_eq!((vehicle.version(), gcs.version()), (LinkVersion::Mavlink2, LinkVersion::Mavlink2));
//! ```
//!
//! ## The version rules
//! A link sends one framing: MAVLink 1, MAVLink 2 or signed MAVLink 2, and accepts both
//! MAVLink 1 and 2 frames (subject to signing). The version is per link, never global.
//!
//! - **Vehicle** ([`VehicleVersion`]): MAVLink 2 disabled (MAVLink 1 only, the handshake is
//!   refused with a failure COMMAND_ACK in MAVLink 1), start in MAVLink 1 and switch on the
//!   first MAVLink 2 frame accepted, or MAVLink 2 from the start. With signing it sends signed
//!   MAVLink 2 from the first frame. [`Channel::capabilities`] carries
//!   MAV_PROTOCOL_CAPABILITY_MAVLINK2 whenever MAVLink 2 would be accepted.
//! - **Ground station** ([`GroundPolicy`]): MAVLink 2 from the start, or automatic: switch on
//!   the first MAVLink 2 frame, on AUTOPILOT_VERSION with the capability flag, or when the
//!   handshake succeeds; fall back to MAVLink 1 when it is refused or times out.
//! - **The handshake** (see [`handshake`]): the ground station sends MAV_CMD_REQUEST_MESSAGE
//!   (param1 = 300 or another id ≥ 256) or MAV_CMD_REQUEST_PROTOCOL_VERSION, as COMMAND_LONG
//!   or COMMAND_INT, in MAVLink 2 framing; the vehicle answers COMMAND_ACK in its link's
//!   framing and PROTOCOL_VERSION in MAVLink 2 framing, even while its link sends MAVLink 1.
//!   These two frames are the only exceptions to a link's single version.
//!
//! ```text
//!   ground station (automatic)                       vehicle (start MAVLink 1)
//!   link: v1                                         link: v1
//!     │── COMMAND_LONG 512/300 (v2, confirmation 0) ──X lost
//!     │   … 500 ms …
//!     │── COMMAND_LONG 512/300 (v2, confirmation 1) ──►│ first v2 frame: link → v2
//!     │◄─ COMMAND_ACK ACCEPTED (v2) ───────────────────│
//!   first v2 frame: link → v2
//!     │◄─ PROTOCOL_VERSION 200/100/200 (v2) ───────────│
//!   Event::Handshake(ProtocolVersion)
//! ```
//!
//! ## Signing
//! With a [`SigningConfig`], every outgoing frame is signed MAVLink 2 and every incoming
//! frame must be correctly signed with one of the link's keys and fresh for its stream;
//! frames that are not are rejected with a typed [`RejectReason`], counted, and reported as
//! [`Event::Rejected`]. The signature is checked before the replay table is touched. See
//! [`signing`] and the [`manual`] for the threat model.
//!
//! ## Capacities
//! No heap: every table has a fixed size. Keys [`signing::MAX_KEYS`] (4), unsigned ids
//! [`signing::MAX_UNSIGNED_IDS`] (8), signing streams [`signing::MAX_STREAMS`] (32), sources
//! [`seq::MAX_SOURCES`] (32), events [`channel::EVENT_CAPACITY`] (16), control frames
//! [`channel::TRANSMIT_CAPACITY`] (8), radio queue [`radio::RADIO_QUEUE`] (8 per side). What
//! does not fit is counted, never silently lost (see each constant).
//!
//! ## Limitations
//! - The replay table belongs to one channel; the C library shares one across all links to
//!   stop cross-link replay (see the [`manual`]).
//! - Input is a byte stream: a UDP datagram that ends inside a false start (a stray start
//!   marker claiming more bytes than arrive) holds the frames behind it until the next
//!   datagram's bytes resolve it. Nothing is lost, but it is late.
//! - Sequence statistics assume a link that does not reorder (see [`seq`]).
//! - Capacities are fixed at compile time; there is no `alloc` feature for larger tables.
//! - The MAVProxy trick of a ground station copying the vehicle's link id is not done:
//!   configure distinct link ids instead.
//!
//! ## Features
//! - `std` (default): links `std` for host conveniences; nothing in the crate needs it.
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`fuzz_channel`).
//!
//! MSRV: Rust 1.95.
#![no_std]
#![forbid(unsafe_code)]

#[cfg(feature = "std")]
extern crate std;

pub mod channel;
pub mod config;
pub mod dialect;
pub mod event;
pub mod frame;
pub mod handshake;
pub mod manual;
mod queue;
pub mod radio;
pub mod seq;
pub mod signing;
pub mod stats;

pub use channel::{Channel, HandshakeError, SendError, Transmit};
pub use config::{Config, ConfigError, GroundPolicy, Role, VehiclePolicy, VehicleVersion};
pub use dialect::CommandEncoding;
pub use event::{
    Event, EventRef, LinkVersion, ProtocolVersionAnswer, RejectReason, Rejected, SigningSetup,
    SwitchCause,
};
pub use frame::{Authentication, OwnedFrame, ReceivedFrame};
pub use handshake::{
    FallbackReason, Handshake, HandshakeConfig, HandshakeMethod, HandshakeOutcome,
    HandshakeRequest, HandshakeResult, Target,
};
pub use mavstack_core::MessageTable;
pub use radio::{Radio, RadioConfig, RadioEvent, RadioStats, RadioTransmit, Side};
pub use seq::SourceStats;
pub use signing::{CapacityError, SigningConfig, SigningStream, WallClock};
pub use stats::{LinkStats, RejectionCounts};

/// Fuzzing entry point for channel input: a signing vehicle, an automatic ground station
/// running a handshake, and a radio each take `data` in pieces the data itself chooses, with
/// time advancing, and everything they emit is drained. Each channel has a twin drained through
/// [`Channel::poll_event_ref`]: both must give the same events, frames byte for byte. Never
/// panics, unless a state machine stops taking input after its queues were drained or a twin
/// differs (bugs).
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub fn fuzz_channel(data: &[u8]) {
    use mavstack_core::signing::SecretKey;
    use mavstack_core::time::Instant;
    use mavstack_core::wire::MAX_FRAME_LEN;

    /// The next event of `ch` by value, and of `twin` through `poll_event_ref`: the same
    /// (frames byte for byte). Whether there was one.
    fn next_same(ch: &mut Channel, twin: &mut Channel) -> bool {
        let a = ch.poll_event();
        let b = match twin.poll_event_ref() {
            Some(EventRef::Frame(f)) => Some(Event::Frame(f.clone())),
            Some(EventRef::Other) => {
                let e = twin.poll_event();
                assert!(
                    !matches!(e, None | Some(Event::Frame(_))),
                    "poll_event_ref announced another event: {e:?}"
                );
                e
            }
            None => None,
        };
        match (&a, &b) {
            (Some(Event::Frame(x)), Some(Event::Frame(y))) => assert_eq!(x, y),
            (x, y) => assert_eq!(
                x.as_ref().map(core::mem::discriminant),
                y.as_ref().map(core::mem::discriminant),
                "{x:?} against {y:?}"
            ),
        }
        a.is_some()
    }

    /// Feeds `data` to `ch` and its twin, drained by value and by reference.
    fn feed(ch: &mut Channel, twin: &mut Channel, now: Instant, data: &[u8]) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut rest = data;
        while !rest.is_empty() {
            let n = ch.handle_input(now, rest);
            assert_eq!(n, twin.handle_input(now, rest), "the twin took as much");
            rest = &rest[n..];
            let mut drained = false;
            while next_same(ch, twin) {
                drained = true;
            }
            while ch.poll_transmit(now, &mut buf).is_some() {}
            while twin.poll_transmit(now, &mut buf).is_some() {}
            assert!(
                n > 0 || drained,
                "channel took no input with its queues empty"
            );
        }
        while next_same(ch, twin) {}
        while ch.poll_transmit(now, &mut buf).is_some() {}
        while twin.poll_transmit(now, &mut buf).is_some() {}
    }

    let mut vehicle_config = Config::vehicle(1, 1);
    vehicle_config.secure = true;
    vehicle_config.signing = Some(SigningConfig::new(SecretKey::new([0x42; 32]), 1));
    let (Ok(mut vehicle), Ok(mut vehicle_twin)) = (
        Channel::new(vehicle_config.clone()),
        Channel::new(vehicle_config),
    ) else {
        return;
    };
    let gcs_config = Config::ground_station(255, 190);
    let (Ok(mut gcs), Ok(mut gcs_twin)) =
        (Channel::new(gcs_config.clone()), Channel::new(gcs_config))
    else {
        return;
    };
    let mut radio = Radio::new(RadioConfig::default());
    let mut now = Instant::from_secs(1_767_225_600);
    for g in [&mut gcs, &mut gcs_twin] {
        let _ = g.start_handshake(
            now,
            Target::new(0, 0),
            HandshakeMethod::RequestMessage300,
            CommandEncoding::Int,
        );
    }
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut rest = data;
    while let Some((&control, tail)) = rest.split_first() {
        let (piece, after) = tail.split_at(usize::from(control & 0x3f).min(tail.len()));
        rest = after;
        now += core::time::Duration::from_millis(u64::from(control >> 6) * 300);
        feed(&mut vehicle, &mut vehicle_twin, now, piece);
        feed(&mut gcs, &mut gcs_twin, now, piece);
        let side = if control & 1 == 0 { Side::A } else { Side::B };
        let mut left = piece;
        while !left.is_empty() {
            let n = radio.handle_input(now, side, left);
            left = &left[n..];
            let mut drained = false;
            while radio.poll_transmit(now, &mut buf).is_some() {
                drained = true;
            }
            assert!(
                n > 0 || drained,
                "radio took no input with its queues empty"
            );
        }
        for ch in [&mut vehicle, &mut vehicle_twin, &mut gcs, &mut gcs_twin] {
            ch.handle_timeout(now);
        }
        radio.handle_timeout(now);
        feed(&mut vehicle, &mut vehicle_twin, now, &[]);
        feed(&mut gcs, &mut gcs_twin, now, &[]);
        for ch in [&mut vehicle, &mut vehicle_twin, &mut gcs, &mut gcs_twin] {
            while ch.poll_transmit(now, &mut buf).is_some() {}
        }
        while radio.poll_transmit(now, &mut buf).is_some() {}
        while radio.poll_event().is_some() {}
        let _ = (
            vehicle.stats(),
            gcs.stats(),
            radio.stats(),
            gcs.poll_timeout(),
        );
    }
}
