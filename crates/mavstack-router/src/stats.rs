//! Counters of one router link.

use mavstack_channel::LinkStats as ChannelStats;

/// Why a frame was not forwarded (reasons about sending, counted on the link the frame
/// would have gone to; `unknown_target` on the link it came from).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum DropReason {
    /// The out-link's framing needs a conversion that cannot be made: an id above 255 for
    /// MAVLink 1, or a message whose CRC_EXTRA the router does not know.
    CannotConvert,
    /// An unsigned frame from a link that is not `trusted` would have to be signed.
    UntrustedToSigned,
    /// A frame addressed to a system the router has not heard.
    UnknownTarget,
    /// An in- or out-filter of the link.
    Filtered,
    /// A rate limit or the byte budget of the out-link.
    RateLimited,
    /// The out-link's queue was full.
    QueueFull,
    /// The same bytes passed within the dedup window.
    Duplicate,
    /// SETUP_SIGNING from a link not marked `secure`, or broadcast: never forwarded.
    SetupSigning,
}

impl DropReason {
    /// Its name in statistics (`cannot_convert`, ...).
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::CannotConvert => "cannot_convert",
            Self::UntrustedToSigned => "untrusted_to_signed",
            Self::UnknownTarget => "unknown_target",
            Self::Filtered => "filtered",
            Self::RateLimited => "rate_limited",
            Self::QueueFull => "queue_full",
            Self::Duplicate => "duplicate",
            Self::SetupSigning => "setup_signing",
        }
    }
}

/// Drops per reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct Drops {
    /// [`DropReason::CannotConvert`].
    pub cannot_convert: u64,
    /// [`DropReason::UntrustedToSigned`].
    pub untrusted_to_signed: u64,
    /// [`DropReason::UnknownTarget`].
    pub unknown_target: u64,
    /// [`DropReason::Filtered`].
    pub filtered: u64,
    /// [`DropReason::RateLimited`].
    pub rate_limited: u64,
    /// [`DropReason::QueueFull`].
    pub queue_full: u64,
    /// [`DropReason::Duplicate`].
    pub duplicate: u64,
    /// [`DropReason::SetupSigning`].
    pub setup_signing: u64,
}

impl Drops {
    pub(crate) const fn count(&mut self, reason: DropReason) {
        let c = match reason {
            DropReason::CannotConvert => &mut self.cannot_convert,
            DropReason::UntrustedToSigned => &mut self.untrusted_to_signed,
            DropReason::UnknownTarget => &mut self.unknown_target,
            DropReason::Filtered => &mut self.filtered,
            DropReason::RateLimited => &mut self.rate_limited,
            DropReason::QueueFull => &mut self.queue_full,
            DropReason::Duplicate => &mut self.duplicate,
            DropReason::SetupSigning => &mut self.setup_signing,
        };
        *c += 1;
    }
}

/// Frames converted on their way onto a link, by kind (one frame may count twice, e.g.
/// MAVLink 1 → signed MAVLink 2 is `to_mavlink2` and `signed`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct Conversions {
    /// MAVLink 2 → MAVLink 1 (base fields).
    pub to_mavlink1: u64,
    /// MAVLink 1 → MAVLink 2 (truncated).
    pub to_mavlink2: u64,
    /// Signature removed for a link without a key.
    pub signature_removed: u64,
    /// Signed with the link's key.
    pub signed: u64,
}

/// The counters of one link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub struct Counters {
    /// Frames accepted from the link.
    pub rx_frames: u64,
    /// Their bytes.
    pub rx_bytes: u64,
    /// Frames queued for the link (forwarded and the router's own).
    pub tx_frames: u64,
    /// Their bytes.
    pub tx_bytes: u64,
    /// Frames that were converted on their way out.
    pub converted: u64,
    /// How they were converted.
    pub conversions: Conversions,
    /// Frames not converted: sent byte for byte.
    pub unchanged: u64,
    /// Drops by reason.
    pub dropped: Drops,
}

/// What a link carries now, as statistics name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LinkMode {
    /// `"1"`: MAVLink 1.
    Mavlink1,
    /// `"2"`: unsigned MAVLink 2.
    Mavlink2,
    /// `"signed"`: signed MAVLink 2.
    Signed,
    /// `"auto"`: an auto link before its peer's first MAVLink 2 frame (frames go out in the
    /// framing they arrived in).
    Auto,
    /// `"transparent"`: a fleet bridge's link, frames byte for byte whatever their framing.
    Transparent,
}

impl LinkMode {
    /// `"1"`, `"2"`, `"signed"`, `"auto"` or `"transparent"`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Mavlink1 => "1",
            Self::Mavlink2 => "2",
            Self::Signed => "signed",
            Self::Auto => "auto",
            Self::Transparent => "transparent",
        }
    }
}

/// A snapshot of one link.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct LinkStatus<'a> {
    /// Its name.
    pub name: &'a str,
    /// What it carries now.
    pub mode: LinkMode,
    /// The router's counters.
    pub counters: Counters,
    /// The link's channel counters: parser (bad CRC, skipped bytes), signing rejections,
    /// sequence loss.
    pub channel: ChannelStats,
    /// Frames waiting to be sent.
    pub queued: usize,
}

impl LinkStatus<'_> {
    /// Every non-zero drop count by reason name: the receiving reasons (`bad_crc`,
    /// `bad_signature`, `replay`, `unsigned`) from the channel, the sending ones from the
    /// router.
    #[must_use]
    pub fn drops(&self) -> [(&'static str, u64); 12] {
        let r = &self.channel.rejected;
        let d = &self.counters.dropped;
        [
            ("bad_crc", self.channel.parser.bad_crc),
            ("bad_signature", r.bad_signature),
            ("replay", r.replayed + r.too_old),
            (
                "unsigned",
                r.unsigned_not_allowed + r.mavlink1_on_signed_link,
            ),
            ("cannot_convert", d.cannot_convert),
            ("untrusted_to_signed", d.untrusted_to_signed),
            ("unknown_target", d.unknown_target),
            ("filtered", d.filtered),
            ("rate_limited", d.rate_limited),
            ("queue_full", d.queue_full),
            ("duplicate", d.duplicate),
            ("setup_signing", d.setup_signing),
        ]
    }
}
