//! The default protocol: frames in, frames out, nothing else.
//!
//! [`FrameProtocol`] finds MAVLink frames in what each peer sends (a
//! [`Deframer`] per stream peer; a [`SliceParser`] per datagram, so a frame never spans two
//! datagrams), checks their checksums with the [`MessageTable`] the caller supplies, and reports
//! each as a [`FrameEvent::Frame`] holding an owned copy in a fixed [`FrameBuf`] (no heap
//! allocation per frame). It sends whatever frames it is given. It keeps no sequence numbers,
//! versions or signing state: that is the channel layer's job, which will implement
//! [`Protocol`] itself.
//!
//! The table is a typed dialect's ([`MessageTable::of`]) or one made from XML at run time
//! (`mavstack_xml::Dialect::message_table`).
//!
//! ```
//! use mavstack_core::time::Instant;
//! use mavstack_core::MessageTable;
//! use mavstack_transport::frame::{FrameEvent, FrameProtocol};
//! use mavstack_transport::protocol::{Framing, PeerAddr, PeerId, PeerInfo, Protocol};
//!
//! let heartbeat = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
//! let mut proto = FrameProtocol::new(MessageTable::of::<mavstack_dialects::common::MavMessage>());
//! let peer = PeerInfo { id: PeerId::new(1), addr: PeerAddr::Serial("/dev/ttyS0".into()), framing: Framing::Stream };
//! proto.handle_peer_added(Instant::ZERO, &peer);
//! assert_eq!(proto.poll_event(), Some(FrameEvent::PeerAdded(peer.clone())));
//! proto.handle_input(Instant::from_micros(5), peer.id, &heartbeat[..7]);
//! proto.handle_input(Instant::from_micros(9), peer.id, &heartbeat[7..]);
//! let Some(FrameEvent::Frame(frame)) = proto.poll_event() else { panic!("a frame") };
//! assert_eq!((frame.peer, frame.time, frame.frame.msg_id()), (peer.id, Instant::from_micros(9), 0));
//! assert_eq!(frame.frame.as_bytes(), &heartbeat);
//! assert_eq!(proto.stats().frames, 1);
//! ```

use std::collections::{HashMap, VecDeque};

use mavstack_core::Message;
pub use mavstack_core::MessageTable;
use mavstack_core::parse::{Deframer, Item, SliceParser, Stats as ParseStats};
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, EmitError, Frame, FrameHeader, MAX_FRAME_LEN};

use crate::protocol::{Dest, Framing, PeerId, PeerInfo, Protocol, Transmit};

/// One whole frame, owned, in a fixed 280-byte buffer (the longest frame): no heap.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct FrameBuf {
    bytes: [u8; MAX_FRAME_LEN],
    len: u16,
}

/// Why bytes cannot be a [`FrameBuf`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameBufError {
    /// The bytes do not start with a complete frame.
    #[error("not a frame: {0}")]
    NotAFrame(wire::Error),
    /// The bytes hold more than one frame.
    #[error("{len} bytes given, but the frame is {frame_len} bytes long")]
    TrailingBytes {
        /// Bytes given.
        len: usize,
        /// The frame's length from its header.
        frame_len: usize,
    },
}

impl FrameBuf {
    /// A copy of the one frame in `bytes` (its length must match the frame's header; the
    /// checksum is not checked).
    ///
    /// # Errors
    /// [`FrameBufError`] if `bytes` is not exactly one frame.
    pub fn new(bytes: &[u8]) -> Result<Self, FrameBufError> {
        let frame = Frame::new_checked(bytes).map_err(FrameBufError::NotAFrame)?;
        if frame.frame_len() != bytes.len() {
            return Err(FrameBufError::TrailingBytes {
                len: bytes.len(),
                frame_len: frame.frame_len(),
            });
        }
        Ok(Self::copy(bytes))
    }

    /// A copy of `frame`'s bytes.
    #[must_use]
    pub fn from_frame<T: AsRef<[u8]>>(frame: &Frame<T>) -> Self {
        Self::copy(frame.as_bytes())
    }

    /// Emits a typed message into a new buffer (see [`wire::emit_message`]).
    ///
    /// ```
    /// use mavstack_core::wire::{FrameHeader, Version};
    /// use mavstack_dialects::common::Heartbeat;
    /// use mavstack_transport::frame::FrameBuf;
    /// let header = FrameHeader { version: Version::V2, seq: 0, sysid: 255, compid: 190, signed: false };
    /// let frame = FrameBuf::from_message(&header, &Heartbeat::default()).unwrap();
    /// assert_eq!((frame.msg_id(), frame.sysid(), frame.compid()), (0, 255, 190));
    /// ```
    ///
    /// # Errors
    /// [`EmitError`] as [`wire::emit_message`] (an id over 255 or a signature in MAVLink 1).
    pub fn from_message<M: Message>(header: &FrameHeader, message: &M) -> Result<Self, EmitError> {
        let mut bytes = [0u8; MAX_FRAME_LEN];
        let len = wire::emit_message(header, message, &mut bytes)?;
        Ok(Self {
            bytes,
            len: len_u16(len),
        })
    }

    /// `bytes`, at most [`MAX_FRAME_LEN`] of them (callers pass one parsed frame).
    fn copy(bytes: &[u8]) -> Self {
        let len = bytes.len().min(MAX_FRAME_LEN);
        let mut buf = [0u8; MAX_FRAME_LEN];
        buf[..len].copy_from_slice(&bytes[..len]);
        Self {
            bytes: buf,
            len: len_u16(len),
        }
    }

    /// The frame's bytes.
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..usize::from(self.len)]
    }

    /// A view of the frame.
    #[must_use]
    pub fn frame(&self) -> Frame<&[u8]> {
        Frame::new_unchecked(self.as_bytes())
    }

    /// The message id.
    #[must_use]
    pub fn msg_id(&self) -> u32 {
        self.frame().msg_id()
    }

    /// The sender's system id.
    #[must_use]
    pub fn sysid(&self) -> u8 {
        self.frame().sysid()
    }

    /// The sender's component id.
    #[must_use]
    pub fn compid(&self) -> u8 {
        self.frame().compid()
    }
}

/// Lengths here are at most [`MAX_FRAME_LEN`] (280).
fn len_u16(len: usize) -> u16 {
    u16::try_from(len).unwrap_or(u16::MAX)
}

impl core::fmt::Debug for FrameBuf {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FrameBuf")
            .field("msg_id", &self.msg_id())
            .field("sysid", &self.sysid())
            .field("compid", &self.compid())
            .field("len", &self.len)
            .finish()
    }
}

impl AsRef<[u8]> for FrameBuf {
    fn as_ref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl TryFrom<&[u8]> for FrameBuf {
    type Error = FrameBufError;

    fn try_from(bytes: &[u8]) -> Result<Self, FrameBufError> {
        Self::new(bytes)
    }
}

/// A frame as received.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReceivedFrame {
    /// Who sent it.
    pub peer: PeerId,
    /// When it arrived (the input's time: see [`crate::clock`]; for a tlog, the record's).
    pub time: Instant,
    /// The frame, as on the wire (a signature, if any, is not checked).
    pub frame: FrameBuf,
}

/// What [`FrameProtocol`] reports.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameEvent {
    /// A frame of a known message id with a good checksum.
    Frame(ReceivedFrame),
    /// A frame of a message id the table does not define (checksum unchecked); only with
    /// [`FrameProtocol::keep_unknown`].
    Unknown(ReceivedFrame),
    /// A peer appeared.
    PeerAdded(PeerInfo),
    /// A peer went away.
    PeerRemoved(PeerId),
}

/// What [`FrameProtocol`] can be asked to do.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum FrameCommand {
    /// Send a frame (as it is: sequence number, checksum and signature untouched).
    Send {
        /// Where to.
        dest: Dest,
        /// The frame.
        frame: FrameBuf,
    },
}

impl FrameCommand {
    /// Send `frame` to every peer.
    #[must_use]
    pub fn to_all(frame: FrameBuf) -> Self {
        Self::Send {
            dest: Dest::All,
            frame,
        }
    }
}

/// [`FrameProtocol`]'s counters, over all peers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct FrameStats {
    /// Bytes received.
    pub bytes: u64,
    /// Frames of known ids with good checksums.
    pub frames: u64,
    /// Candidates rejected for a bad checksum.
    pub bad_crc: u64,
    /// Frames of unknown message ids (reported or not).
    pub unknown_id: u64,
    /// MAVLink 2 candidates with unknown incompatibility flags.
    pub bad_incompat: u64,
    /// Bytes that were part of no frame.
    pub skipped_bytes: u64,
    /// Frames handed to the link for sending.
    pub sent: u64,
    /// Frames to send that did not fit the driver's transmit buffer (never with this crate's
    /// driver, whose buffer holds any frame).
    pub send_dropped: u64,
    /// Inputs from peers the protocol was never told about (a driver bug; counted, ignored).
    pub unknown_peer: u64,
}

impl FrameStats {
    fn add(&mut self, after: &ParseStats, before: &ParseStats) {
        self.bytes += after.bytes - before.bytes;
        self.frames += after.frames - before.frames;
        self.bad_crc += after.bad_crc - before.bad_crc;
        self.unknown_id += after.unknown_id - before.unknown_id;
        self.bad_incompat += after.bad_incompat - before.bad_incompat;
        self.skipped_bytes += after.skipped_bytes - before.skipped_bytes;
    }
}

/// The default protocol: frames from every peer become events; frames to send go out as they
/// are. See the [module docs](self).
pub struct FrameProtocol {
    table: MessageTable,
    keep_unknown: bool,
    peer_events: bool,
    /// Every live peer: a deframer for stream peers, nothing for datagram peers.
    peers: HashMap<PeerId, Option<Box<Deframer>>>,
    events: VecDeque<FrameEvent>,
    outgoing: VecDeque<(Dest, FrameBuf)>,
    stats: FrameStats,
}

impl core::fmt::Debug for FrameProtocol {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("FrameProtocol")
            .field("keep_unknown", &self.keep_unknown)
            .field("peers", &self.peers.len())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl FrameProtocol {
    /// A protocol that checks checksums with `table` and drops frames of unknown ids
    /// (counting them); peer events are on.
    #[must_use]
    pub fn new(table: MessageTable) -> Self {
        Self {
            table,
            keep_unknown: false,
            peer_events: true,
            peers: HashMap::new(),
            events: VecDeque::new(),
            outgoing: VecDeque::new(),
            stats: FrameStats::default(),
        }
    }

    /// Also report frames of unknown message ids, as [`FrameEvent::Unknown`].
    #[must_use]
    pub fn keep_unknown(mut self, keep: bool) -> Self {
        self.keep_unknown = keep;
        self
    }

    /// Report peers appearing and going away ([`FrameEvent::PeerAdded`],
    /// [`FrameEvent::PeerRemoved`]); on by default.
    #[must_use]
    pub fn peer_events(mut self, on: bool) -> Self {
        self.peer_events = on;
        self
    }
}

/// Queues the event for `item`, if it is reported.
fn push(
    events: &mut VecDeque<FrameEvent>,
    keep_unknown: bool,
    item: Item<'_>,
    peer: PeerId,
    time: Instant,
) {
    let (Item::Frame(f) | Item::Unknown(f)) = item;
    let received = ReceivedFrame {
        peer,
        time,
        frame: FrameBuf::from_frame(&f),
    };
    match item {
        Item::Frame(_) => events.push_back(FrameEvent::Frame(received)),
        Item::Unknown(_) if keep_unknown => events.push_back(FrameEvent::Unknown(received)),
        Item::Unknown(_) => {}
    }
}

impl Protocol for FrameProtocol {
    type Command = FrameCommand;
    type Event = FrameEvent;
    type Stats = FrameStats;

    fn handle_peer_added(&mut self, _now: Instant, peer: &PeerInfo) {
        let state = match peer.framing {
            Framing::Stream => Some(Box::new(Deframer::new())),
            Framing::Datagram => None,
        };
        self.peers.insert(peer.id, state);
        if self.peer_events {
            self.events.push_back(FrameEvent::PeerAdded(peer.clone()));
        }
    }

    fn handle_peer_removed(&mut self, now: Instant, peer: PeerId) {
        if let Some(Some(mut deframer)) = self.peers.remove(&peer) {
            // The stream ended: frames still buffered behind a cut one come out now.
            let before = *deframer.stats();
            while let Some(item) = deframer.finish(&self.table) {
                push(&mut self.events, self.keep_unknown, item, peer, now);
            }
            self.stats.add(deframer.stats(), &before);
        }
        if self.peer_events {
            self.events.push_back(FrameEvent::PeerRemoved(peer));
        }
    }

    fn handle_input(&mut self, now: Instant, peer: PeerId, data: &[u8]) {
        let Some(state) = self.peers.get_mut(&peer) else {
            self.stats.unknown_peer += 1;
            return;
        };
        let (events, keep_unknown) = (&mut self.events, self.keep_unknown);
        match state {
            None => {
                let mut parser = SliceParser::new(data, self.table);
                for item in parser.by_ref() {
                    push(events, keep_unknown, item, peer, now);
                }
                self.stats.add(parser.stats(), &ParseStats::default());
            }
            Some(deframer) => {
                let before = *deframer.stats();
                let mut rest = data;
                loop {
                    let taken = deframer.push(rest);
                    rest = &rest[taken..];
                    while let Some(item) = deframer.next_item(&self.table) {
                        push(events, keep_unknown, item, peer, now);
                    }
                    if rest.is_empty() {
                        break;
                    }
                }
                self.stats.add(deframer.stats(), &before);
            }
        }
    }

    fn handle_command(&mut self, _now: Instant, command: FrameCommand) {
        match command {
            FrameCommand::Send { dest, frame } => self.outgoing.push_back((dest, frame)),
        }
    }

    fn handle_timeout(&mut self, _now: Instant) {}

    fn poll_transmit(&mut self, _now: Instant, buf: &mut [u8]) -> Option<Transmit> {
        while let Some((dest, frame)) = self.outgoing.pop_front() {
            let bytes = frame.as_bytes();
            let Some(out) = buf.get_mut(..bytes.len()) else {
                self.stats.send_dropped += 1;
                continue;
            };
            out.copy_from_slice(bytes);
            self.stats.sent += 1;
            return Some(Transmit {
                dest,
                len: bytes.len(),
            });
        }
        None
    }

    fn poll_event(&mut self) -> Option<FrameEvent> {
        self.events.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        None
    }

    fn stats(&self) -> FrameStats {
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::PeerAddr;

    const HEARTBEAT: [u8; 21] = [
        0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74,
    ];

    fn table() -> MessageTable {
        MessageTable::of::<mavstack_dialects::common::MavMessage>()
    }

    fn unknown_frame() -> [u8; 13] {
        // id 0x123456, len 1, checksum arbitrary.
        [0xfd, 1, 0, 0, 0, 7, 8, 0x56, 0x34, 0x12, 0xaa, 0x11, 0x22]
    }

    fn peer(n: u32, framing: Framing) -> PeerInfo {
        PeerInfo {
            id: PeerId::new(n),
            addr: PeerAddr::Udp(([127, 0, 0, 1], 1000 + n as u16).into()),
            framing,
        }
    }

    fn drain(p: &mut FrameProtocol) -> Vec<FrameEvent> {
        core::iter::from_fn(|| p.poll_event()).collect()
    }

    #[test]
    fn datagrams_never_join() {
        let mut p = FrameProtocol::new(table()).peer_events(false);
        let a = peer(1, Framing::Datagram);
        p.handle_peer_added(Instant::ZERO, &a);
        // A frame cut across two datagrams is two pieces of noise.
        p.handle_input(Instant::ZERO, a.id, &HEARTBEAT[..10]);
        p.handle_input(Instant::ZERO, a.id, &HEARTBEAT[10..]);
        assert!(drain(&mut p).is_empty());
        let mut two = HEARTBEAT.to_vec();
        two.extend_from_slice(&HEARTBEAT);
        p.handle_input(Instant::from_micros(3), a.id, &two);
        let events = drain(&mut p);
        assert_eq!(events.len(), 2);
        let stats = p.stats();
        assert_eq!(
            (stats.frames, stats.bytes, stats.skipped_bytes),
            (2, 63, 21)
        );
    }

    #[test]
    fn streams_are_per_peer() {
        let mut p = FrameProtocol::new(table());
        let (a, b) = (peer(1, Framing::Stream), peer(2, Framing::Stream));
        p.handle_peer_added(Instant::ZERO, &a);
        p.handle_peer_added(Instant::ZERO, &b);
        // Interleaved halves from two peers do not mix.
        p.handle_input(Instant::ZERO, a.id, &HEARTBEAT[..5]);
        p.handle_input(Instant::ZERO, b.id, &HEARTBEAT[..12]);
        p.handle_input(Instant::ZERO, a.id, &HEARTBEAT[5..]);
        p.handle_input(Instant::ZERO, b.id, &HEARTBEAT[12..]);
        let events = drain(&mut p);
        let peers: Vec<_> = events
            .iter()
            .filter_map(|e| match e {
                FrameEvent::Frame(f) => Some(f.peer),
                _ => None,
            })
            .collect();
        assert_eq!(peers, [a.id, b.id]);
        assert!(matches!(events[0], FrameEvent::PeerAdded(ref i) if i.id == a.id));
        p.handle_peer_removed(Instant::ZERO, a.id);
        assert_eq!(drain(&mut p), [FrameEvent::PeerRemoved(a.id)]);
        p.handle_input(Instant::ZERO, a.id, &HEARTBEAT);
        assert_eq!(p.stats().unknown_peer, 1);
    }

    #[test]
    fn unknown_ids_only_when_asked() {
        let mut two = unknown_frame().to_vec();
        two.extend_from_slice(&HEARTBEAT);
        for keep in [false, true] {
            let mut p = FrameProtocol::new(table())
                .keep_unknown(keep)
                .peer_events(false);
            let d = peer(1, Framing::Datagram);
            let s = peer(2, Framing::Stream);
            p.handle_peer_added(Instant::ZERO, &d);
            p.handle_peer_added(Instant::ZERO, &s);
            p.handle_input(Instant::ZERO, d.id, &two);
            p.handle_input(Instant::ZERO, s.id, &two);
            let unknown = drain(&mut p)
                .iter()
                .filter(|e| matches!(e, FrameEvent::Unknown(f) if f.frame.msg_id() == 0x12_3456))
                .count();
            assert_eq!(unknown, if keep { 2 } else { 0 });
            assert_eq!(p.stats().unknown_id, 2);
        }
    }

    #[test]
    fn stream_end_flushes_the_deframer() {
        // An unknown-id frame at the very end of a stream waits for the next byte; the end of
        // the stream decides it.
        let mut p = FrameProtocol::new(table())
            .keep_unknown(true)
            .peer_events(false);
        let s = peer(1, Framing::Stream);
        p.handle_peer_added(Instant::ZERO, &s);
        p.handle_input(Instant::ZERO, s.id, &unknown_frame());
        assert!(drain(&mut p).is_empty());
        p.handle_peer_removed(Instant::from_micros(7), s.id);
        assert!(matches!(
            drain(&mut p)[..],
            [FrameEvent::Unknown(ReceivedFrame { time, .. })] if time == Instant::from_micros(7)
        ));
    }

    #[test]
    fn sends_what_it_is_given() {
        let mut p = FrameProtocol::new(table());
        let frame = FrameBuf::new(&HEARTBEAT).unwrap();
        p.handle_command(Instant::ZERO, FrameCommand::to_all(frame));
        let mut small = [0u8; 4];
        let mut buf = [0u8; 300];
        assert_eq!(p.poll_transmit(Instant::ZERO, &mut small), None);
        p.handle_command(Instant::ZERO, FrameCommand::to_all(frame));
        let t = p.poll_transmit(Instant::ZERO, &mut buf).unwrap();
        assert_eq!((t.dest, &buf[..t.len]), (Dest::All, &HEARTBEAT[..]));
        assert_eq!(p.poll_transmit(Instant::ZERO, &mut buf), None);
        assert_eq!((p.stats().sent, p.stats().send_dropped), (1, 1));
    }

    #[test]
    fn frame_buf_checks_its_input() {
        assert!(FrameBuf::new(&HEARTBEAT).is_ok());
        assert_eq!(
            FrameBuf::new(&HEARTBEAT[..20]),
            Err(FrameBufError::NotAFrame(wire::Error::Truncated {
                needed: 21,
                available: 20
            }))
        );
        let mut long = HEARTBEAT.to_vec();
        long.push(0);
        assert_eq!(
            FrameBuf::try_from(&long[..]),
            Err(FrameBufError::TrailingBytes {
                len: 22,
                frame_len: 21
            })
        );
        let f = FrameBuf::new(&HEARTBEAT).unwrap();
        assert_eq!((f.sysid(), f.compid(), f.msg_id()), (1, 1, 0));
        assert_eq!(f.as_ref(), &HEARTBEAT);
    }
}
