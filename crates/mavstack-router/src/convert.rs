//! Re-framing a frame for a link that carries another framing: MAVLink 2 → 1 (base fields),
//! 1 → 2 (truncated), signature removed, or ready to be signed. The source's sysid, compid
//! and seq are kept; the checksum is recomputed with the message's CRC_EXTRA.

use mavstack_core::message::MessageInfo;
use mavstack_core::wire::{self, Frame, FrameHeader, MAX_FRAME_LEN, Version};

use crate::stats::{Conversions, DropReason, LinkMode};

/// How a frame goes onto a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Plan {
    /// Byte for byte.
    AsIs,
    /// Written again in `version`, with the signed flag when `sign` (the signature is then
    /// appended by the out-link's channel).
    Reframe {
        /// The framing to write.
        version: Version,
        /// Set the signed flag.
        sign: bool,
    },
}

/// What the router knows about a frame's origin.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Origin {
    /// It came from a `trusted` link.
    pub(crate) trusted: bool,
    /// Its signature was verified by the link it came from.
    pub(crate) verified: bool,
}

/// How `frame` goes onto a link in `mode`. `verifies_here` tells whether a signed frame's
/// signature verifies with the out-link's key (asked only on a signed link).
pub(crate) fn plan(
    frame: &Frame<&[u8]>,
    known: bool,
    mode: LinkMode,
    origin: Origin,
    verifies_here: impl FnOnce() -> bool,
) -> Result<Plan, DropReason> {
    let v2 = frame.version() == Version::V2;
    let signed = frame.is_signed();
    let plan = match mode {
        LinkMode::Transparent => Plan::AsIs,
        LinkMode::Mavlink1 if !v2 => Plan::AsIs,
        LinkMode::Mavlink1 => {
            if frame.msg_id() > 255 {
                return Err(DropReason::CannotConvert);
            }
            Plan::Reframe {
                version: Version::V1,
                sign: false,
            }
        }
        LinkMode::Mavlink2 if v2 && !signed => Plan::AsIs,
        LinkMode::Auto if !signed => Plan::AsIs,
        LinkMode::Mavlink2 | LinkMode::Auto => Plan::Reframe {
            version: Version::V2,
            sign: false,
        },
        LinkMode::Signed => {
            if signed && verifies_here() {
                Plan::AsIs
            } else if !(origin.trusted || origin.verified) {
                return Err(DropReason::UntrustedToSigned);
            } else {
                Plan::Reframe {
                    version: Version::V2,
                    sign: true,
                }
            }
        }
    };
    if plan != Plan::AsIs && !known {
        return Err(DropReason::CannotConvert);
    }
    Ok(plan)
}

/// Writes `frame` again in `version` (signed flag set when `sign`) into `out`; returns the
/// length (without a signature: append it with the out-link's channel).
pub(crate) fn reframe(
    frame: &Frame<&[u8]>,
    info: &MessageInfo,
    version: Version,
    sign: bool,
    out: &mut [u8; MAX_FRAME_LEN],
) -> Result<usize, DropReason> {
    let payload = frame.payload();
    let mut info = *info;
    // A newer definition may carry more extension bytes than ours: keep them in MAVLink 2.
    info.max_len = info
        .max_len
        .max(u8::try_from(payload.len()).unwrap_or(u8::MAX));
    let header = FrameHeader {
        version,
        seq: frame.seq(),
        sysid: frame.sysid(),
        compid: frame.compid(),
        signed: sign,
    };
    wire::emit(&header, &info, payload, out).map_err(|_| DropReason::CannotConvert)
}

/// Counts what a re-framing did.
pub(crate) fn count(
    conversions: &mut Conversions,
    from: &Frame<&[u8]>,
    version: Version,
    sign: bool,
) {
    match (from.version(), version) {
        (Version::V2, Version::V1) => conversions.to_mavlink1 += 1,
        (Version::V1, Version::V2) => conversions.to_mavlink2 += 1,
        _ => {}
    }
    if from.is_signed() && !sign {
        conversions.signature_removed += 1;
    }
    if sign {
        conversions.signed += 1;
    }
}
