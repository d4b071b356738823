//! What the channel reports: accepted frames, rejections, version changes, handshake
//! outcomes, signing setup and timestamp persistence.

use mavstack_core::signing::SecretKey;
use mavstack_core::time::Instant;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{MavCmd, MavResult};

use crate::dialect::CommandEncoding;
use crate::frame::ReceivedFrame;
use crate::handshake::HandshakeOutcome;

/// The framing a link sends: one of three, never a mix (the handshake request and answer are
/// the documented exceptions, see the crate docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LinkVersion {
    /// MAVLink 1 frames (`0xFE`).
    Mavlink1,
    /// Unsigned MAVLink 2 frames (`0xFD`).
    Mavlink2,
    /// Signed MAVLink 2 frames.
    SignedMavlink2,
}

impl LinkVersion {
    /// The wire version of the frames.
    #[must_use]
    pub const fn wire(self) -> Version {
        match self {
            Self::Mavlink1 => Version::V1,
            Self::Mavlink2 | Self::SignedMavlink2 => Version::V2,
        }
    }

    /// Whether frames are signed.
    #[must_use]
    pub const fn is_signed(self) -> bool {
        matches!(self, Self::SignedMavlink2)
    }
}

impl core::fmt::Display for LinkVersion {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Mavlink1 => "MAVLink 1",
            Self::Mavlink2 => "MAVLink 2",
            Self::SignedMavlink2 => "signed MAVLink 2",
        })
    }
}

/// Why the link's version changed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum SwitchCause {
    /// A MAVLink 2 frame was accepted on a link that switches on the first one.
    Mavlink2Received,
    /// AUTOPILOT_VERSION arrived with MAV_PROTOCOL_CAPABILITY_MAVLINK2 (ground station,
    /// automatic policy).
    CapabilityFlag,
    /// The handshake succeeded: the answer arrived in MAVLink 2 framing.
    Handshake,
    /// The handshake was refused or went unanswered: back to MAVLink 1.
    HandshakeFallback,
    /// Signing was turned on (SETUP_SIGNING or [`crate::Channel::set_signing`]).
    SigningEnabled,
    /// Signing was turned off.
    SigningDisabled,
}

impl core::fmt::Display for SwitchCause {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Mavlink2Received => "a MAVLink 2 frame arrived",
            Self::CapabilityFlag => "AUTOPILOT_VERSION has the MAVLINK2 capability",
            Self::Handshake => "the handshake was answered in MAVLink 2",
            Self::HandshakeFallback => "the handshake was refused or went unanswered",
            Self::SigningEnabled => "signing turned on",
            Self::SigningDisabled => "signing turned off",
        })
    }
}

/// Why an incoming frame was not accepted. Rejections are events and counters, never errors
/// that end the stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, thiserror::Error)]
#[non_exhaustive]
pub enum RejectReason {
    /// The signature matches none of the link's keys (a forgery or a wrong key). The replay
    /// table and the link's timestamp are left untouched.
    #[error("signature matches none of the link's keys")]
    BadSignature,
    /// The timestamp is not newer than the last one accepted on the frame's stream (equal
    /// counts as a replay).
    #[error(
        "replayed: timestamp {timestamp} is not newer than {last}, the last accepted on its stream"
    )]
    Replayed {
        /// The frame's timestamp.
        timestamp: u64,
        /// The stream's last accepted timestamp.
        last: u64,
    },
    /// The first frame of a new stream is more than a minute behind the link's timestamp.
    #[error(
        "new signing stream at timestamp {timestamp} is more than a minute behind the link's {local}"
    )]
    TooOld {
        /// The frame's timestamp.
        timestamp: u64,
        /// The link's current timestamp.
        local: u64,
    },
    /// A correctly signed frame of a new stream, and the stream table is full.
    #[error("signing stream table full")]
    StreamTableFull,
    /// An unsigned MAVLink 2 frame on a signed link, and its id is not on the allow-list.
    #[error("unsigned frame on a signed link")]
    UnsignedNotAllowed,
    /// A MAVLink 1 frame (which cannot be signed) on a signed link, and its id is not on the
    /// allow-list.
    #[error("MAVLink 1 frame on a signed link")]
    Mavlink1OnSignedLink,
    /// SETUP_SIGNING on a link not marked secure.
    #[error("SETUP_SIGNING on a link not marked secure")]
    SetupSigningInsecure,
    /// SETUP_SIGNING addressed to another system or component, or broadcast.
    #[error("SETUP_SIGNING not addressed to this component")]
    SetupSigningMisaddressed,
    /// SETUP_SIGNING to a vehicle with MAVLink 2 disabled: signing needs MAVLink 2.
    #[error("SETUP_SIGNING on a link with MAVLink 2 disabled")]
    SetupSigningNeedsMavlink2,
    /// SETUP_SIGNING while the vehicle holds it ([`crate::Channel::hold_setup_signing`]:
    /// ArduPilot while armed). The key is not taken.
    #[error("SETUP_SIGNING held by the vehicle")]
    SetupSigningHeld,
}

/// A frame the channel did not accept.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Rejected {
    /// Why.
    pub reason: RejectReason,
    /// The frame's version.
    pub version: Version,
    /// Sender's system id (as claimed: the frame is not trusted).
    pub sysid: u8,
    /// Sender's component id (as claimed).
    pub compid: u8,
    /// Message id.
    pub msg_id: u32,
    /// When it arrived.
    pub received_at: Instant,
}

/// How a vehicle answered a request for PROTOCOL_VERSION.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ProtocolVersionAnswer {
    /// COMMAND_ACK ACCEPTED in the link's framing, then PROTOCOL_VERSION in MAVLink 2.
    Accepted,
    /// COMMAND_ACK with this failure result in MAVLink 1 (MAVLink 2 disabled).
    Nacked(MavResult),
    /// Nothing sent: the vehicle is configured without protocol-version support, and the
    /// frame is delivered unanswered for the caller's own command handling.
    Ignored,
}

impl core::fmt::Display for ProtocolVersionAnswer {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Accepted => f.write_str("accepted, PROTOCOL_VERSION sent in MAVLink 2"),
            Self::Nacked(result) => write!(f, "refused with COMMAND_ACK {result:?} in MAVLink 1"),
            Self::Ignored => f.write_str("left to the vehicle's own command handling"),
        }
    }
}

/// What a SETUP_SIGNING did.
#[derive(Clone, Debug)]
pub enum SigningSetup {
    /// Signing is now on with this key (the link's only key from now on) and a timestamp at
    /// least `initial_timestamp`. Store the key if it must survive a restart. A link that did
    /// not sign before gets link id 0, the wall clock of [`crate::WallClock::InstantIsUnix`]
    /// and the default allow-list; call [`crate::Channel::set_signing`] with this key to
    /// choose otherwise.
    Enabled {
        /// The new key.
        key: SecretKey,
        /// The timestamp the sender asked for.
        initial_timestamp: u64,
    },
    /// An all-zero key with timestamp 0: signing is now off.
    Disabled,
}

/// What [`crate::Channel::poll_event_ref`] found next.
#[derive(Clone, Copy, Debug)]
#[non_exhaustive]
pub enum EventRef<'a> {
    /// An accepted frame, lent where the channel keeps it.
    Frame(&'a ReceivedFrame),
    /// Another event: take it with [`crate::Channel::poll_event`].
    Other,
}

/// Everything [`crate::Channel::poll_event`] reports.
#[derive(Clone, Debug)]
#[non_exhaustive]
#[allow(
    clippy::large_enum_variant,
    reason = "no heap: the frame is carried inline, and it is the common variant"
)]
pub enum Event {
    /// An accepted frame.
    Frame(ReceivedFrame),
    /// A frame that was not accepted, and why.
    Rejected(Rejected),
    /// The link's output version changed.
    VersionChanged {
        /// The version before.
        from: LinkVersion,
        /// The version now.
        to: LinkVersion,
        /// Why.
        cause: SwitchCause,
    },
    /// A ground-station handshake ended.
    Handshake(HandshakeOutcome),
    /// A vehicle received a request for PROTOCOL_VERSION addressed to it.
    ProtocolVersionRequested {
        /// Requester's system id.
        sysid: u8,
        /// Requester's component id.
        compid: u8,
        /// MAV_CMD_REQUEST_PROTOCOL_VERSION or MAV_CMD_REQUEST_MESSAGE.
        command: MavCmd,
        /// COMMAND_LONG or COMMAND_INT.
        encoding: CommandEncoding,
        /// What the channel did.
        answer: ProtocolVersionAnswer,
    },
    /// A SETUP_SIGNING on a secure link, addressed to this component, was applied. The
    /// frame itself is not delivered (it carries the key).
    SigningSetup {
        /// Sender's system id.
        sysid: u8,
        /// Sender's component id.
        compid: u8,
        /// What changed.
        setup: SigningSetup,
    },
    /// Store this signing timestamp where it survives a restart, and pass it back as
    /// [`crate::SigningConfig::initial_timestamp`] next time (see [`crate::signing`]).
    PersistTimestamp {
        /// The value to store.
        timestamp: u64,
    },
}
