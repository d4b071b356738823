//! The mission (plan) protocol, in both roles, for mission, fence and rally plans.
//!
//! **Client** ([`MissionClient`]), one transfer at a time:
//! - [`MissionClient::upload`]: MISSION_COUNT, then the vehicle pulls every
//!   MISSION_ITEM_INT with MISSION_REQUEST_INT (MISSION_REQUEST is answered too), and ends
//!   with MISSION_ACK; to a vehicle that takes the next item unasked, a few items go out
//!   ahead of its requests ([`MissionConfig::upload_window`]).
//! - [`MissionClient::download`]: MISSION_REQUEST_LIST → MISSION_COUNT, then the client
//!   pulls item after item (a few at a time from a vehicle that answers any request,
//!   [`MissionConfig::download_window`]) and ends with MISSION_ACK(ACCEPTED).
//! - [`MissionClient::clear`]: MISSION_CLEAR_ALL → MISSION_ACK.
//! - [`MissionClient::set_current`]: MISSION_SET_CURRENT → MISSION_CURRENT with that seq.
//! - [`MissionClient::cancel`] sends MISSION_ACK(OPERATION_CANCELLED) and goes idle.
//!
//! The phases are types consumed by value ([`transfer::Upload`]: `AwaitingRequest` →
//! `AwaitingAck`; [`transfer::Download`]: `AwaitingCount` → `AwaitingItem { seq }`).
//! Every wait resends its last message on timeout ([`MissionConfig`]: 1.5 s, 250 ms while
//! items flow, 5 retries, the digest's recommended values) and then gives up. A MISSION_ACK
//! with an error ends the transfer with [`MissionError::Rejected`]; timeouts are
//! [`MissionError::TimedOut`]. One exception: an upload the vehicle refuses to start as busy
//! (ERROR or DENIED to the count, before any request: another transfer is open) is asked for
//! again every half second for up to [`BUSY_WAIT`].
//!
//! **Server** ([`MissionServer`]) stores the three plans. An upload replaces a plan only
//! when it is complete (atomic); out-of-sequence items are dropped and the expected one is
//! re-requested; a MISSION_ACK(OPERATION_CANCELLED) or a timeout abandons it and leaves the
//! stored plan unchanged. When it asks again for an item that did not come, and when it gives
//! up, is its [`UploadPacing`]: by the measured round trip, or at fixed times as ArduPilot.
//! Downloads are answered statelessly from the stored plan.

use alloc::vec::Vec;
use core::time::Duration;

use mavstack_dialects::common::{
    MavAutopilot, MavFrame, MavMessage, MavMissionResult, MavMissionType, MissionAck,
    MissionItemInt, MissionRequestInt,
};

use crate::Address;
use crate::rtt::Rtt;

/// Items a transfer makes room for before they arrive.
const PREALLOCATED_ITEMS: usize = 64;

/// Timeouts and retries of both roles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MissionConfig {
    /// Time to wait for the first answer (default 1.5 s).
    pub timeout: Duration,
    /// The longest wait for the next item or request while items flow (default 250 ms).
    /// Both roles wait less once they have measured the round trip (`srtt + 4 × rttvar`,
    /// at least 20 ms, RFC 6298's estimator with Karn's rule).
    pub item_timeout: Duration,
    /// Resends before giving up (default 5).
    pub retries: u8,
    /// How the server answers an item it did not ask for.
    pub stray_items: StrayItems,
    /// When the server asks again for an item that did not come, and when it gives an
    /// upload up.
    pub pacing: UploadPacing,
    /// How many items a download asks for ahead of the first one missing (default 1: one
    /// request at a time, as the protocol describes and PX4 requires: it aborts a download
    /// on a request out of turn). A vehicle answering any request as it comes (ArduPilot,
    /// see [`MissionConfig::for_autopilot`]) takes a window: a slow link's round trip is
    /// then paid once per window rather than once per item. At least 1, at most
    /// [`MAX_WINDOW`].
    pub download_window: u16,
    /// How many items an upload sends ahead of the one the vehicle asked for (default 1:
    /// only what it asks for). A vehicle that takes the next item in sequence whether it
    /// asked for it yet or not (ArduPilot and PX4) takes a window: items go out `n` at a
    /// time and the vehicle's requests slide it (go-back-n: on a sign of loss, a request
    /// repeated, ArduPilot's INVALID_SEQUENCE or a timeout, the window is sent again from
    /// the item asked for). At least 1, at most [`MAX_WINDOW`].
    pub upload_window: u16,
    /// Whether the vehicle writes each item of a MISSION upload into its plan as it takes it
    /// (ArduPilot: `MissionItemProtocol_Waypoints.cpp` truncates the plan to the count, then
    /// replaces or appends item by item), so that a vehicle that asked for item `k` holds
    /// the new items before `k` whatever happens next. Default `false`: the vehicle keeps an
    /// upload apart until its last item (PX4; ArduPilot's fences and rally points), and only
    /// reading the whole plan back tells what it holds. See
    /// [`MissionConfig::readback_from`].
    pub stores_in_place: bool,
}

/// The largest [`MissionConfig::download_window`] and [`MissionConfig::upload_window`]
/// (more is clamped to it).
pub const MAX_WINDOW: u16 = 32;

impl MissionConfig {
    /// This configuration with the windows a vehicle of `autopilot` takes. ArduPilot: 8 for
    /// downloads (every MISSION_REQUEST_INT is answered on its own, no transfer state:
    /// `MissionItemProtocol.cpp`) and 8 for uploads (it takes the item it expects whether it
    /// asked yet or not, and answers another with INVALID_SEQUENCE, the upload left open).
    /// PX4: 1 for downloads (it aborts one on a request out of turn) and 8 for uploads (it
    /// takes the item it expects and ignores others: `mavlink_mission.cpp`). Every other
    /// autopilot: 1 and 1, the protocol as written.
    #[must_use]
    pub fn for_autopilot(self, autopilot: MavAutopilot) -> Self {
        let (download_window, upload_window) = match autopilot {
            MavAutopilot::ARDUPILOTMEGA => (8, 8),
            MavAutopilot::PX4 => (1, 8),
            _ => (1, 1),
        };
        Self {
            download_window,
            upload_window,
            stores_in_place: autopilot == MavAutopilot::ARDUPILOTMEGA,
            ..self
        }
    }

    /// The first item to read back to learn whether an upload of `count` items of
    /// `mission_type`, whose final MISSION_ACK was lost, is what the vehicle holds
    /// ([`MissionError::Unconfirmed`]): the last item where the vehicle stores items in
    /// place (it asked for the last item, so it holds every one before it; the count and the
    /// last item read back tell the rest), else 0, the whole plan.
    #[must_use]
    pub fn readback_from(&self, mission_type: MavMissionType, count: usize) -> u16 {
        if self.stores_in_place && mission_type == MavMissionType::MISSION {
            u16::try_from(count.saturating_sub(1)).unwrap_or(0)
        } else {
            0
        }
    }
}

/// When a [`MissionServer`] asks again for an item that did not come, and when it gives an
/// upload up.
///
/// A ground station that answers every request, the repeated ones too (MAVProxy does), sends
/// an item twice when the server asked again while the first answer was on its way; the
/// server takes the first and finds the copy out of sequence ([`StrayItems`]). How soon it
/// asks again decides how slow a ground station may be before that happens.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UploadPacing {
    /// Ask again after the measured round trip (`srtt + 4 × rttvar`, at least 20 ms, at most
    /// [`MissionConfig::item_timeout`]), backing off to `item_timeout`; give up after
    /// [`MissionServer::patience`] without an item, saying nothing.
    #[default]
    Adaptive,
    /// Ask again `every` after the last request however long the round trip, and give up
    /// `give_up_after` without an item, telling the ground station with MISSION_ACK
    /// MAV_MISSION_OPERATION_CANCELLED. ArduPilot paces its uploads so, with 1 s (plus the
    /// link's stream slow-down, 0 on a network link) and 8 s.
    Fixed {
        /// The time from one request to the next for the same item.
        every: Duration,
        /// The longest an upload goes without an item (or its count) before it is given up.
        give_up_after: Duration,
    },
}

impl UploadPacing {
    /// The wait for an answer to a request sent for the first time.
    fn first_wait(self, rtt: &Rtt, item_timeout: Duration) -> Duration {
        match self {
            Self::Adaptive => rtt.timeout(item_timeout),
            Self::Fixed {
                every,
                give_up_after,
            } => every.min(give_up_after),
        }
    }
}

/// How a [`MissionServer`] answers an item it did not ask for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StrayItems {
    /// During an upload, drop it and ask for the wanted item at once (a copy of the previous
    /// item means the client missed our request); after one, the last item sent again (its
    /// ACK was lost) is acknowledged again.
    #[default]
    Reask,
    /// As ArduPilot: during an upload, MISSION_ACK MAV_MISSION_INVALID_SEQUENCE with the
    /// upload left open (the wanted item is asked for again when the [`UploadPacing`] says;
    /// ArduPilot asks a second after its last request); outside one, MISSION_ACK MAV_MISSION_ERROR, also
    /// to the last item of an upload that ended and whose ACK was lost.
    ArduPilot,
}

impl Default for MissionConfig {
    fn default() -> Self {
        Self {
            timeout: Duration::from_millis(1500),
            item_timeout: Duration::from_millis(250),
            retries: 5,
            stray_items: StrayItems::Reask,
            pacing: UploadPacing::Adaptive,
            download_window: 1,
            upload_window: 1,
            stores_in_place: false,
        }
    }
}

/// How a transfer failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MissionError {
    /// No answer after every retry.
    #[error("no answer after {attempts} attempts")]
    TimedOut {
        /// How many times the last message was sent.
        attempts: u8,
    },
    /// The other side ended the transfer with this MAV_MISSION_RESULT.
    #[error("ended by the other side with {result:?}")]
    Rejected {
        /// The result.
        result: MavMissionResult,
    },
    /// Cancelled with [`MissionClient::cancel`].
    #[error("cancelled")]
    Cancelled,
    /// Every item was sent, the final MISSION_ACK did not come, and the vehicle refused the
    /// last item sent again with this result: ArduPilot answers MAV_MISSION_ERROR to an item
    /// when no upload is open, which is also what it does once the upload has ended and its
    /// ACCEPTED was lost. Whether the plan was stored is unknown: read it back to tell
    /// (`System::upload_mission` does).
    #[error("the final MISSION_ACK was lost and the resent last item got {result:?}")]
    Unconfirmed {
        /// The result the resent item got.
        result: MavMissionResult,
    },
}

/// Why a transfer was not started.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MissionBusy {
    /// Another transfer is running; cancel it or wait for it.
    #[error("a mission transfer is already running")]
    Busy,
}

/// What a [`MissionClient`] reports: the end of each operation.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum MissionEvent {
    /// An upload ended.
    Uploaded {
        /// Which plan.
        mission_type: MavMissionType,
        /// Accepted, or why not.
        result: Result<(), MissionError>,
    },
    /// A download ended.
    Downloaded {
        /// Which plan.
        mission_type: MavMissionType,
        /// The items, or why not.
        result: Result<Vec<MissionItemInt>, MissionError>,
    },
    /// A clear ended.
    Cleared {
        /// Which plan.
        mission_type: MavMissionType,
        /// Accepted, or why not.
        result: Result<(), MissionError>,
    },
    /// A set-current ended.
    CurrentSet {
        /// The seq asked for.
        seq: u16,
        /// Confirmed by MISSION_CURRENT, or why not.
        result: Result<(), MissionError>,
    },
}

/// The client's transfer states, as types.
pub mod transfer;

mod client;
mod server;

pub use client::{BUSY_WAIT, MissionClient};
pub use server::{MissionServer, MissionServerEvent};

fn ack(target: Address, mission_type: MavMissionType, result: MavMissionResult) -> MavMessage {
    MavMessage::MissionAck(MissionAck {
        target_system: target.system,
        target_component: target.component,
        r#type: result,
        mission_type,
    })
}

fn request_int(target: Address, mission_type: MavMissionType, seq: u16) -> MavMessage {
    MavMessage::MissionRequestInt(MissionRequestInt {
        target_system: target.system,
        target_component: target.component,
        seq,
        mission_type,
    })
}

/// Whether a message's `target_*` fields address `own` (0 = anyone).
fn for_me(own: Address, system: u8, component: u8) -> bool {
    own.is_reached_by(Address::new(system, component))
}

/// A request for item `seq` of type `mission_type`, from MISSION_REQUEST_INT or the
/// deprecated MISSION_REQUEST.
fn as_request(own: Address, m: &MavMessage) -> Option<(u16, MavMissionType)> {
    match m {
        MavMessage::MissionRequestInt(r) if for_me(own, r.target_system, r.target_component) => {
            Some((r.seq, r.mission_type))
        }
        MavMessage::MissionRequest(r) if for_me(own, r.target_system, r.target_component) => {
            Some((r.seq, r.mission_type))
        }
        _ => None,
    }
}

/// Whether `frame` gives latitude and longitude (the global frames, float or INT): their
/// x and y are degrees (degE7 in MISSION_ITEM_INT), other frames' are metres.
///
/// ```
/// use mavstack_dialects::common::MavFrame;
/// use mavstack_services::mission::is_global;
/// assert!(is_global(MavFrame::GLOBAL_RELATIVE_ALT_INT));
/// assert!(!is_global(MavFrame::LOCAL_NED));
/// ```
#[must_use]
pub fn is_global(frame: MavFrame) -> bool {
    matches!(
        frame,
        MavFrame::GLOBAL
            | MavFrame::GLOBAL_RELATIVE_ALT
            | MavFrame::GLOBAL_TERRAIN_ALT
            | MavFrame::GLOBAL_INT
            | MavFrame::GLOBAL_RELATIVE_ALT_INT
            | MavFrame::GLOBAL_TERRAIN_ALT_INT
    )
}
