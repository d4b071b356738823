//! Counters of one link.

use mavstack_core::parse;

use crate::event::RejectReason;

/// How many frames were rejected, per reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct RejectionCounts {
    /// [`RejectReason::BadSignature`].
    pub bad_signature: u64,
    /// [`RejectReason::Replayed`].
    pub replayed: u64,
    /// [`RejectReason::TooOld`].
    pub too_old: u64,
    /// [`RejectReason::StreamTableFull`].
    pub stream_table_full: u64,
    /// [`RejectReason::UnsignedNotAllowed`].
    pub unsigned_not_allowed: u64,
    /// [`RejectReason::Mavlink1OnSignedLink`].
    pub mavlink1_on_signed_link: u64,
    /// [`RejectReason::SetupSigningInsecure`].
    pub setup_signing_insecure: u64,
    /// [`RejectReason::SetupSigningMisaddressed`].
    pub setup_signing_misaddressed: u64,
    /// [`RejectReason::SetupSigningNeedsMavlink2`].
    pub setup_signing_needs_mavlink2: u64,
    /// [`RejectReason::SetupSigningHeld`].
    pub setup_signing_held: u64,
}

impl RejectionCounts {
    /// Counts one rejection.
    pub(crate) const fn count(&mut self, reason: RejectReason) {
        let counter = match reason {
            RejectReason::BadSignature => &mut self.bad_signature,
            RejectReason::Replayed { .. } => &mut self.replayed,
            RejectReason::TooOld { .. } => &mut self.too_old,
            RejectReason::StreamTableFull => &mut self.stream_table_full,
            RejectReason::UnsignedNotAllowed => &mut self.unsigned_not_allowed,
            RejectReason::Mavlink1OnSignedLink => &mut self.mavlink1_on_signed_link,
            RejectReason::SetupSigningInsecure => &mut self.setup_signing_insecure,
            RejectReason::SetupSigningMisaddressed => &mut self.setup_signing_misaddressed,
            RejectReason::SetupSigningNeedsMavlink2 => &mut self.setup_signing_needs_mavlink2,
            RejectReason::SetupSigningHeld => &mut self.setup_signing_held,
        };
        *counter += 1;
    }

    /// All rejections.
    #[must_use]
    pub const fn total(&self) -> u64 {
        self.bad_signature
            + self.replayed
            + self.too_old
            + self.stream_table_full
            + self.unsigned_not_allowed
            + self.mavlink1_on_signed_link
            + self.setup_signing_insecure
            + self.setup_signing_misaddressed
            + self.setup_signing_needs_mavlink2
            + self.setup_signing_held
    }
}

/// The statistics of one link: parser counters, accepted and sent frames, rejections and
/// sequence totals (per-source detail: [`crate::Channel::sources`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct LinkStats {
    /// The parser's counters: frames with a good checksum, bytes, bad CRC, unknown ids,
    /// unknown incompatibility flags, skipped bytes.
    pub parser: parse::Stats,
    /// Frames accepted (delivered as [`crate::Event::Frame`] or applied as SETUP_SIGNING).
    pub accepted: u64,
    /// Frames written by `send*` and `poll_transmit`.
    pub sent: u64,
    /// Rejected frames per reason.
    pub rejected: RejectionCounts,
    /// Sum over sources of frames counted by sequence number.
    pub received: u64,
    /// Sum over sources of frames lost (sequence gaps).
    pub lost: u64,
    /// Sum over sources of duplicated frames.
    pub duplicates: u64,
    /// Frames of sources beyond the table's capacity ([`crate::seq::MAX_SOURCES`]).
    pub untracked_frames: u64,
    /// Control frames (COMMAND_ACK, PROTOCOL_VERSION, handshake requests) dropped because
    /// the transmit queue was full ([`crate::channel::TRANSMIT_CAPACITY`]); the requester's
    /// retry gets a new answer.
    pub control_dropped: u64,
}
