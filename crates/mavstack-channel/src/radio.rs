//! A semi-transparent radio: forwards frames between two sides and injects RADIO_STATUS.
//!
//! SiK-style telemetry radios pass MAVLink through but also speak it: they parse the stream
//! at frame boundaries and insert their own RADIO_STATUS (id 109) frames, from system 51
//! (`'3'`) and component 68 (`'D'`), which pymavlink recognises as the radio. A radio that has
//! seen MAVLink 2 shows that it carries it by sending RADIO_STATUS in MAVLink 2 framing from
//! then on.
//!
//! ```text
//!   ground side (A)                 Radio                      air side (B)
//!   ───────────────►  deframer A ──► queue to B ──────────────►  vehicle
//!   ◄───────────────  queue to A ◄── deframer B ◄──────────────
//!                        ▲
//!                        └─ RADIO_STATUS every `interval` (v1, then v2 once v2 is seen)
//! ```
//!
//! [`Radio`] is sans-IO like [`Channel`](crate::Channel): bytes from a side go into
//! [`handle_input`](Radio::handle_input), the frames to write come out of
//! [`poll_transmit`](Radio::poll_transmit) with the side they go to. Frames are forwarded
//! byte for byte, never re-serialised (so signatures and untrimmed payloads survive); bytes
//! that are not part of any frame are dropped and counted. RADIO_STATUS goes between whole
//! frames, never inside one.

use core::time::Duration;

use mavstack_core::MessageTable;
use mavstack_core::message::{MAX_PAYLOAD_LEN, Message};
use mavstack_core::parse::{self, Deframer, Item};
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, FrameHeader, MAX_FRAME_LEN, Version};
use mavstack_dialects::common::RadioStatus;

use crate::dialect::{common_table, crc_extra_with_builtins};
use crate::frame::OwnedFrame;
use crate::queue::Queue;

/// How many frames wait towards each side.
pub const RADIO_QUEUE: usize = 8;

/// One side of the radio.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Side {
    /// Side A.
    A,
    /// Side B.
    B,
}

impl Side {
    /// The other side.
    #[must_use]
    pub const fn other(self) -> Self {
        match self {
            Self::A => Self::B,
            Self::B => Self::A,
        }
    }

    const fn index(self) -> usize {
        match self {
            Self::A => 0,
            Self::B => 1,
        }
    }
}

/// Where RADIO_STATUS goes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Injection {
    /// Towards the ground side only (what SiK firmware does).
    #[default]
    Ground,
    /// Towards both sides.
    BothSides,
}

/// The radio's setup.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct RadioConfig {
    /// Source system of RADIO_STATUS (51, `'3'`, like SiK).
    pub system_id: u8,
    /// Source component of RADIO_STATUS (68, `'D'`, like SiK).
    pub component_id: u8,
    /// Time between two RADIO_STATUS (default 1 s).
    pub interval: Duration,
    /// Which side the ground station is on (default A).
    pub ground: Side,
    /// Where RADIO_STATUS goes.
    pub injection: Injection,
    /// The radio figures reported: rssi, remrssi, noise, remnoise, fixed. `txbuf` is
    /// replaced by the free room of the queue the status goes into (percent), `rxerrors` by
    /// the bad-checksum count of both sides.
    pub status: RadioStatus,
}

impl Default for RadioConfig {
    fn default() -> Self {
        Self {
            system_id: 51,
            component_id: 68,
            interval: Duration::from_secs(1),
            ground: Side::A,
            injection: Injection::Ground,
            status: RadioStatus {
                rssi: 190,
                remrssi: 185,
                txbuf: 100,
                noise: 45,
                remnoise: 48,
                rxerrors: 0,
                fixed: 0,
            },
        }
    }
}

/// What the radio reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum RadioEvent {
    /// The first MAVLink 2 frame passed: RADIO_STATUS goes out in MAVLink 2 from now on.
    FirstMavlink2 {
        /// The side it came from.
        from: Side,
    },
}

/// A frame written into the caller's buffer: send `buf[..len]` to side `to`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[must_use = "the frame is in the buffer and must be sent"]
pub struct RadioTransmit {
    /// The side to write to.
    pub to: Side,
    /// The frame's length.
    pub len: usize,
    /// Whether it is the radio's own RADIO_STATUS (otherwise a forwarded frame).
    pub injected: bool,
    /// The frame's version.
    pub version: Version,
}

/// The radio's counters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct RadioStats {
    /// Frames forwarded towards A and towards B.
    pub forwarded: [u64; 2],
    /// RADIO_STATUS frames written.
    pub injected: u64,
    /// The parser counters of the bytes from A and from B.
    pub parser: [parse::Stats; 2],
}

/// Per-side state: what came from the side, what goes to it.
#[derive(Clone, Debug)]
struct SideState {
    /// Bytes that came from this side.
    deframer: Deframer,
    /// Whether the deframer may hold frames not yet queued.
    input_pending: bool,
    /// Frames going to this side.
    queue: Queue<OwnedFrame, RADIO_QUEUE>,
    /// A RADIO_STATUS is due to this side.
    inject_due: bool,
}

impl SideState {
    fn new() -> Self {
        Self {
            deframer: Deframer::new(),
            input_pending: false,
            queue: Queue::new(),
            inject_due: false,
        }
    }
}

/// A semi-transparent radio between sides A and B (see the module docs).
///
/// ```
/// use mavstack_channel::radio::{Radio, RadioConfig, Side};
/// use mavstack_core::time::Instant;
/// let mut radio = Radio::new(RadioConfig::default());
/// let mut buf = [0u8; 280];
/// radio.handle_timeout(Instant::ZERO); // the first RADIO_STATUS goes out at once
/// let t = radio.poll_transmit(Instant::ZERO, &mut buf).unwrap();
/// assert!(t.injected && t.to == Side::A);
/// assert_eq!(&buf[..6], &[0xfe, 9, 0, 51, 68, 109]); // MAVLink 1 until v2 is seen
/// let hb = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// assert_eq!(radio.handle_input(Instant::ZERO, Side::B, &hb), hb.len());
/// let t = radio.poll_transmit(Instant::ZERO, &mut buf).unwrap();
/// assert_eq!((t.to, &buf[..t.len]), (Side::A, &hb[..]));
/// ```
#[derive(Clone, Debug)]
pub struct Radio {
    config: RadioConfig,
    table: MessageTable,
    sides: [SideState; 2],
    next_inject: Instant,
    mavlink2: bool,
    first_v2_from: Option<Side>,
    seq: u8,
    turn: Side,
    stats: RadioStats,
}

impl Radio {
    /// A radio that checks frames with the `common` dialect (frames of unknown ids are
    /// forwarded too).
    #[must_use]
    pub fn new(config: RadioConfig) -> Self {
        Self::with_table(config, common_table())
    }

    /// A radio that takes CRC_EXTRA from `table` (the messages the radio reads itself are
    /// always known).
    #[must_use]
    pub fn with_table(config: RadioConfig, table: MessageTable) -> Self {
        Self {
            config,
            table,
            sides: [SideState::new(), SideState::new()],
            next_inject: Instant::ZERO,
            mavlink2: false,
            first_v2_from: None,
            seq: 0,
            turn: Side::A,
            stats: RadioStats::default(),
        }
    }

    /// Feeds bytes that arrived from side `from` and returns how many were taken. Fewer than
    /// `data.len()` are taken only when the queue towards the other side is full: drain
    /// [`poll_transmit`](Self::poll_transmit) and call again with the rest.
    #[must_use = "bytes not taken must be fed again after draining poll_transmit"]
    pub fn handle_input(&mut self, now: Instant, from: Side, data: &[u8]) -> usize {
        let _ = now;
        let mut taken = 0;
        loop {
            if !self.forward_buffered(from) || taken == data.len() {
                return taken;
            }
            let side = &mut self.sides[from.index()];
            let n = side.deframer.push(&data[taken..]);
            if n == 0 {
                return taken;
            }
            taken += n;
            side.input_pending = true;
        }
    }

    /// Lets time pass: at each interval a RADIO_STATUS becomes due (the first one at the
    /// first call).
    pub fn handle_timeout(&mut self, now: Instant) {
        if now < self.next_inject {
            return;
        }
        self.next_inject = now + self.config.interval;
        let ground = self.config.ground;
        self.sides[ground.index()].inject_due = true;
        if self.config.injection == Injection::BothSides {
            self.sides[ground.other().index()].inject_due = true;
        }
    }

    /// When to call [`handle_timeout`](Self::handle_timeout) next.
    #[must_use]
    pub const fn poll_timeout(&self) -> Option<Instant> {
        Some(self.next_inject)
    }

    /// The next frame to write, and the side it goes to, or `None`. Call after every
    /// `handle_*` until it returns `None`. Sides take turns.
    #[must_use]
    pub fn poll_transmit(
        &mut self,
        now: Instant,
        buf: &mut [u8; MAX_FRAME_LEN],
    ) -> Option<RadioTransmit> {
        let _ = now;
        for _ in 0..2 {
            let to = self.turn;
            self.turn = to.other();
            if let Some(t) = self.transmit_to(to, buf) {
                return Some(t);
            }
        }
        None
    }

    /// The next event, or `None`.
    #[must_use]
    pub const fn poll_event(&mut self) -> Option<RadioEvent> {
        match self.first_v2_from.take() {
            Some(from) => Some(RadioEvent::FirstMavlink2 { from }),
            None => None,
        }
    }

    /// Whether a MAVLink 2 frame has passed.
    #[must_use]
    pub const fn mavlink2_seen(&self) -> bool {
        self.mavlink2
    }

    /// The counters.
    #[must_use]
    pub fn stats(&self) -> RadioStats {
        let mut stats = self.stats;
        stats.parser = [
            *self.sides[0].deframer.stats(),
            *self.sides[1].deframer.stats(),
        ];
        stats
    }

    /// The setup; change `status` to simulate a better or worse link.
    pub const fn config_mut(&mut self) -> &mut RadioConfig {
        &mut self.config
    }

    fn transmit_to(&mut self, to: Side, buf: &mut [u8; MAX_FRAME_LEN]) -> Option<RadioTransmit> {
        if self.sides[to.index()].inject_due {
            self.sides[to.index()].inject_due = false;
            if let Some(t) = self.write_status(to, buf) {
                return Some(t);
            }
        }
        let frame = self.sides[to.index()].queue.pop()?;
        let bytes = frame.as_bytes();
        buf[..bytes.len()].copy_from_slice(bytes);
        self.stats.forwarded[to.index()] += 1;
        // Room was made: frames still buffered from the other side can move up.
        if self.sides[to.other().index()].input_pending {
            self.forward_buffered(to.other());
        }
        Some(RadioTransmit {
            to,
            len: bytes.len(),
            injected: false,
            version: frame.version(),
        })
    }

    fn write_status(&mut self, to: Side, buf: &mut [u8; MAX_FRAME_LEN]) -> Option<RadioTransmit> {
        let errors =
            self.sides[0].deframer.stats().bad_crc + self.sides[1].deframer.stats().bad_crc;
        let free = self.sides[to.index()].queue.free();
        let status = RadioStatus {
            rxerrors: u16::try_from(errors).unwrap_or(u16::MAX),
            txbuf: u8::try_from(free * 100 / RADIO_QUEUE).unwrap_or(100),
            ..self.config.status
        };
        let version = if self.mavlink2 {
            Version::V2
        } else {
            Version::V1
        };
        let header = FrameHeader {
            version,
            seq: self.seq,
            sysid: self.config.system_id,
            compid: self.config.component_id,
            signed: false,
        };
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let n = status.encode(&mut payload);
        let len = wire::emit(&header, &RadioStatus::INFO, &payload[..n], buf).ok()?;
        self.seq = self.seq.wrapping_add(1);
        self.stats.injected += 1;
        Some(RadioTransmit {
            to,
            len,
            injected: true,
            version,
        })
    }

    /// Moves frames that came from `from` into the queue towards the other side while it
    /// has room. Returns whether every complete frame has moved.
    fn forward_buffered(&mut self, from: Side) -> bool {
        let [a, b] = &mut self.sides;
        let (src, dst) = match from {
            Side::A => (a, b),
            Side::B => (b, a),
        };
        let table = self.table;
        let lookup = |id: u32| crc_extra_with_builtins(&table, id);
        loop {
            if dst.queue.free() == 0 {
                return false;
            }
            let Some(item) = src.deframer.next_item(&lookup) else {
                src.input_pending = false;
                return true;
            };
            let (Item::Frame(view) | Item::Unknown(view)) = item;
            let Ok(frame) = OwnedFrame::new(view.as_bytes()) else {
                continue;
            };
            if frame.version() == Version::V2 && !self.mavlink2 {
                self.mavlink2 = true;
                self.first_v2_from = Some(from);
            }
            let _ = dst.queue.push(frame);
        }
    }
}
