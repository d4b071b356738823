//! Frames the channel hands out: an owned copy of the bytes plus what the channel learned
//! about them.
//!
//! [`OwnedFrame`] holds one frame in a fixed `[u8; 280]` (no heap), so an event can outlive
//! the input buffer it came from. [`ReceivedFrame`] adds the metadata of an accepted frame:
//! when it arrived, whether and how it was authenticated, whether its checksum could be
//! checked, and whether the channel already answered it.

use mavstack_core::message::{Message, MessageSet, UnknownMessage};
use mavstack_core::time::Instant;
use mavstack_core::wire::{self, Frame, MAX_FRAME_LEN, Signature, Version};

use crate::event::ProtocolVersionAnswer;

/// One complete frame, copied out of the input: up to [`MAX_FRAME_LEN`] bytes, no heap.
///
/// ```
/// use mavstack_channel::OwnedFrame;
/// // The protocol digest's golden MAVLink 2 HEARTBEAT.
/// let bytes = [0xfd, 9, 0, 0, 0, 1, 1, 0, 0, 0, 0, 0, 0, 0, 2, 12, 0x51, 4, 3, 0x1b, 0x74];
/// let frame = OwnedFrame::new(&bytes).unwrap();
/// assert_eq!((frame.sysid(), frame.msg_id(), frame.as_bytes().len()), (1, 0, 21));
/// let hb: mavstack_dialects::common::Heartbeat = frame.decode_as().unwrap();
/// assert_eq!(hb.mavlink_version, 3);
/// ```
pub struct OwnedFrame {
    buf: [u8; MAX_FRAME_LEN],
    len: u16,
}

impl OwnedFrame {
    /// Copies the frame at the start of `bytes` (bytes after it are ignored).
    ///
    /// # Errors
    /// [`wire::Error`] if `bytes` does not start with a complete frame.
    pub fn new(bytes: &[u8]) -> Result<Self, wire::Error> {
        let frame = Frame::new_checked(bytes)?;
        let len = frame.frame_len();
        let mut buf = [0u8; MAX_FRAME_LEN];
        buf[..len].copy_from_slice(&bytes[..len]);
        Ok(Self {
            buf,
            // A checked frame is at most MAX_FRAME_LEN (280) bytes long.
            len: u16::try_from(len).unwrap_or(u16::MAX),
        })
    }

    /// A zero-copy view of the frame, with every accessor of [`Frame`].
    #[must_use]
    pub fn view(&self) -> Frame<&[u8]> {
        Frame::new_unchecked(self.as_bytes())
    }

    /// The frame's bytes, exactly as received (signature included).
    #[must_use]
    pub fn as_bytes(&self) -> &[u8] {
        &self.buf[..usize::from(self.len)]
    }

    /// MAVLink 1 or 2.
    #[must_use]
    pub fn version(&self) -> Version {
        self.view().version()
    }

    /// Sequence number.
    #[must_use]
    pub fn seq(&self) -> u8 {
        self.view().seq()
    }

    /// Sender's system id.
    #[must_use]
    pub fn sysid(&self) -> u8 {
        self.view().sysid()
    }

    /// Sender's component id.
    #[must_use]
    pub fn compid(&self) -> u8 {
        self.view().compid()
    }

    /// Message id.
    #[must_use]
    pub fn msg_id(&self) -> u32 {
        self.view().msg_id()
    }

    /// The payload as transmitted (a MAVLink 2 payload may be truncated).
    #[must_use]
    pub fn payload(&self) -> &[u8] {
        let start = self.version().header_len();
        &self.as_bytes()[start..start + self.view().payload_len()]
    }

    /// Whether the frame carries a signature.
    #[must_use]
    pub fn is_signed(&self) -> bool {
        self.view().is_signed()
    }

    /// The signature block, if the frame is signed.
    #[must_use]
    pub fn signature(&self) -> Option<Signature> {
        self.view().signature()
    }

    /// Decodes the payload as a message of dialect `M`.
    ///
    /// # Errors
    /// [`UnknownMessage`] if `M` does not define the frame's message id.
    pub fn decode<M: MessageSet>(&self) -> Result<M, UnknownMessage> {
        M::decode(self.msg_id(), self.payload())
    }

    /// Decodes the payload as message `M`, or `None` if the frame carries another id.
    #[must_use]
    pub fn decode_as<M: Message>(&self) -> Option<M> {
        (self.msg_id() == M::ID).then(|| M::decode(self.payload()))
    }
}

/// `clone_from` copies the frame's bytes only, not the whole buffer: a frame kept for reuse
/// (the channel's event queue, the router's) is overwritten at the cost of the frame's length.
impl Clone for OwnedFrame {
    fn clone(&self) -> Self {
        Self {
            buf: self.buf,
            len: self.len,
        }
    }

    fn clone_from(&mut self, source: &Self) {
        let n = usize::from(source.len);
        self.buf[..n].copy_from_slice(&source.buf[..n]);
        self.len = source.len;
    }
}

/// Equal frames have the same bytes (what the buffer holds past them does not count).
impl PartialEq for OwnedFrame {
    fn eq(&self, other: &Self) -> bool {
        self.as_bytes() == other.as_bytes()
    }
}

impl Eq for OwnedFrame {}

impl core::fmt::Debug for OwnedFrame {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("OwnedFrame")
            .field("version", &self.version().number())
            .field("seq", &self.seq())
            .field("sysid", &self.sysid())
            .field("compid", &self.compid())
            .field("msg_id", &self.msg_id())
            .field("len", &self.len)
            .field("signed", &self.is_signed())
            .finish()
    }
}

/// How a received frame was authenticated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Authentication {
    /// The link does not sign and the frame is unsigned.
    Unsigned,
    /// The link signs; the frame is unsigned (or MAVLink 1) and was let in because its message
    /// id is on the allow-list (e.g. a radio's RADIO_STATUS). Not authenticated.
    AllowedUnsigned,
    /// The signature matched one of the link's keys and the timestamp was fresh for its
    /// stream.
    Verified {
        /// The sender's link id.
        link_id: u8,
        /// The signing timestamp (10 µs units since 2015-01-01 UTC).
        timestamp: u64,
        /// Which of the link's keys matched (0 = the primary key).
        key_index: u8,
    },
    /// The frame is signed but the link has no keys: the signature was **not** checked, so
    /// the frame is not authenticated (parsed OK is not authenticated).
    NotChecked {
        /// The sender's link id.
        link_id: u8,
        /// The signing timestamp it claims.
        timestamp: u64,
    },
}

impl Authentication {
    /// Whether a key holder produced the frame (a verified signature).
    #[must_use]
    pub const fn is_authenticated(&self) -> bool {
        matches!(self, Self::Verified { .. })
    }
}

/// A frame the channel accepted, with what it knows about it.
#[derive(Debug, PartialEq, Eq)]
pub struct ReceivedFrame {
    /// The frame, exactly as received.
    pub frame: OwnedFrame,
    /// When it was handed to [`crate::Channel::handle_input`].
    pub received_at: Instant,
    /// Signature status.
    pub auth: Authentication,
    /// `false` for a message id the channel's dialect does not define: its checksum could not
    /// be checked (it is delivered so that it can be forwarded or logged).
    pub crc_checked: bool,
    /// The channel answered the frame itself (a protocol-version request on a vehicle): the
    /// caller's command handling must not acknowledge it again.
    pub answered: bool,
    /// On a vehicle, `Some` when the frame is a request for PROTOCOL_VERSION addressed to it
    /// (MAV_CMD_REQUEST_PROTOCOL_VERSION, or MAV_CMD_REQUEST_MESSAGE with param1 = 300), with
    /// what the channel did. [`ProtocolVersionAnswer::Ignored`] means the vehicle is
    /// configured without protocol-version support: the caller's command handling should
    /// stay silent too, as such a target does.
    pub protocol_version_request: Option<ProtocolVersionAnswer>,
}

/// `clone_from` copies the frame's bytes only (see [`OwnedFrame`]'s `Clone`).
impl Clone for ReceivedFrame {
    fn clone(&self) -> Self {
        Self {
            frame: self.frame.clone(),
            received_at: self.received_at,
            auth: self.auth,
            crc_checked: self.crc_checked,
            answered: self.answered,
            protocol_version_request: self.protocol_version_request,
        }
    }

    fn clone_from(&mut self, source: &Self) {
        self.frame.clone_from(&source.frame);
        self.received_at = source.received_at;
        self.auth = source.auth;
        self.crc_checked = source.crc_checked;
        self.answered = source.answered;
        self.protocol_version_request = source.protocol_version_request;
    }
}

impl ReceivedFrame {
    /// MAVLink 1 or 2.
    #[must_use]
    pub fn version(&self) -> Version {
        self.frame.version()
    }

    /// Whether the frame carries a signature (verified or not: see [`ReceivedFrame::auth`]).
    #[must_use]
    pub fn is_signed(&self) -> bool {
        self.frame.is_signed()
    }

    /// The sender's link id, for a signed frame.
    #[must_use]
    pub fn link_id(&self) -> Option<u8> {
        self.frame.signature().map(|s| s.link_id)
    }

    /// Message id.
    #[must_use]
    pub fn msg_id(&self) -> u32 {
        self.frame.msg_id()
    }

    /// Sender's system id.
    #[must_use]
    pub fn sysid(&self) -> u8 {
        self.frame.sysid()
    }

    /// Sender's component id.
    #[must_use]
    pub fn compid(&self) -> u8 {
        self.frame.compid()
    }

    /// Decodes the payload as a message of dialect `M`; see [`OwnedFrame::decode`].
    ///
    /// # Errors
    /// [`UnknownMessage`] if `M` does not define the frame's message id.
    pub fn decode<M: MessageSet>(&self) -> Result<M, UnknownMessage> {
        self.frame.decode()
    }

    /// Decodes the payload as message `M`, or `None` if the frame carries another id.
    #[must_use]
    pub fn decode_as<M: Message>(&self) -> Option<M> {
        self.frame.decode_as()
    }
}
