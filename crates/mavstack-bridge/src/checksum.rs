//! The checksum of a frame from the broker, checked before anything is done with it.
//!
//! A bridge rewrites frames (the ground side's sysids) and builds new ones (the command
//! tracker's resends), each with a fresh checksum; a corrupt frame must not come out of that
//! as a valid one. So a frame is checked with its message's CRC_EXTRA first: a wrong
//! checksum drops it (counted as `bad_crc`). A message id the dialect does not know cannot be
//! checked: such a frame may pass as it came, for the router's channel to judge like any
//! link's, but is never rewritten nor resent.
//!
//! ```
//! use mavstack_bridge::checksum::{Checksum, check};
//! use mavstack_core::MessageSet as _;
//! use mavstack_core::wire::{FrameHeader, Version, emit_message};
//! use mavstack_dialects::common::{Heartbeat, MavMessage};
//!
//! let info = |id| MavMessage::info(id).copied();
//! let header = FrameHeader { version: Version::V2, seq: 0, sysid: 1, compid: 1, signed: false };
//! let mut buf = [0u8; 280];
//! let n = emit_message(&header, &Heartbeat::default(), &mut buf).unwrap();
//! assert_eq!(check(&buf[..n], info), Checksum::Good);
//! buf[12] ^= 0x01;
//! assert_eq!(check(&buf[..n], info), Checksum::Bad);
//! assert_eq!(check(&buf[..3], info), Checksum::NotAFrame);
//! ```

use mavstack_core::MessageInfo;
use mavstack_core::wire::Frame;

/// What the checksum of a frame says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Checksum {
    /// Right for its message.
    Good,
    /// Wrong: the frame is corrupt.
    Bad,
    /// Its message id is not in the dialect: it cannot be checked.
    Unknown,
    /// Not a whole MAVLink frame.
    NotAFrame,
}

/// Checks the frame at the start of `bytes` with the CRC_EXTRA `info` gives for its id.
#[must_use]
pub fn check(bytes: &[u8], info: impl Fn(u32) -> Option<MessageInfo>) -> Checksum {
    let Ok(view) = Frame::new_checked(bytes) else {
        return Checksum::NotAFrame;
    };
    match info(view.msg_id()) {
        Some(m) if view.check_crc(m.crc_extra) => Checksum::Good,
        Some(_) => Checksum::Bad,
        None => Checksum::Unknown,
    }
}

/// Whether any frame in `payload` (frames one after the other, as a datagram holds them)
/// has a wrong checksum. From the first bytes that are not a whole frame on, the rest is
/// left to the router's parser, which resyncs and checks checksums itself (it rewrites
/// nothing).
#[must_use]
pub fn any_bad(mut payload: &[u8], info: impl Fn(u32) -> Option<MessageInfo>) -> bool {
    while let Ok(view) = Frame::new_checked(payload) {
        if check(payload, &info) == Checksum::Bad {
            return true;
        }
        payload = &payload[view.frame_len()..];
    }
    false
}
