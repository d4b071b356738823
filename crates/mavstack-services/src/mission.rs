//! The mission (plan) protocol, in both roles, for mission, fence and rally plans.
//!
//! **Client** ([`MissionClient`]), one transfer at a time:
//! - [`MissionClient::upload`]: MISSION_COUNT, then the vehicle pulls every
//!   MISSION_ITEM_INT with MISSION_REQUEST_INT (MISSION_REQUEST is answered too), and ends
//!   with MISSION_ACK.
//! - [`MissionClient::download`]: MISSION_REQUEST_LIST → MISSION_COUNT, then the client
//!   pulls item after item and ends with MISSION_ACK(ACCEPTED).
//! - [`MissionClient::clear`]: MISSION_CLEAR_ALL → MISSION_ACK.
//! - [`MissionClient::set_current`]: MISSION_SET_CURRENT → MISSION_CURRENT with that seq.
//! - [`MissionClient::cancel`] sends MISSION_ACK(OPERATION_CANCELLED) and goes idle.
//!
//! The phases are types consumed by value ([`transfer::Upload`]: `AwaitingRequest` →
//! `AwaitingAck`; [`transfer::Download`]: `AwaitingCount` → `AwaitingItem { seq }`).
//! Every wait resends its last message on timeout ([`MissionConfig`]: 1.5 s, 250 ms while
//! items flow, 5 retries, the digest's recommended values) and then gives up. A MISSION_ACK
//! with an error ends the transfer with [`MissionError::Rejected`]; timeouts are
//! [`MissionError::TimedOut`].
//!
//! **Server** ([`MissionServer`]) stores the three plans. An upload replaces a plan only
//! when it is complete (atomic); out-of-sequence items are dropped and the expected one is
//! re-requested; a MISSION_ACK(OPERATION_CANCELLED) or a timeout abandons it and leaves the
//! stored plan unchanged. When it asks again for an item that did not come, and when it gives
//! up, is its [`UploadPacing`]: by the measured round trip, or at fixed times as ArduPilot.
//! Downloads are answered statelessly from the stored plan.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavFrame, MavMessage, MavMissionResult, MavMissionType, MissionAck, MissionClearAll,
    MissionCount, MissionCurrent, MissionItem, MissionItemInt, MissionRequestInt,
    MissionRequestList, MissionSetCurrent,
};

use crate::rtt::Rtt;
use crate::{Address, Outgoing, Service};

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
pub mod transfer {
    use alloc::vec::Vec;

    use mavstack_core::time::Instant;
    use mavstack_dialects::common::MissionItemInt;

    /// An upload's phase.
    #[derive(Debug)]
    pub enum Upload {
        /// MISSION_COUNT (or the last item) sent; waiting for a request for item `next`.
        AwaitingRequest(AwaitingRequest),
        /// Every item sent; waiting for MISSION_ACK.
        AwaitingAck(AwaitingAck),
    }

    /// Waiting for the vehicle to request an item.
    #[derive(Debug)]
    pub struct AwaitingRequest {
        pub(super) items: Vec<MissionItemInt>,
        /// The last item sent (`None`: only MISSION_COUNT so far).
        pub(super) last: Option<u16>,
        pub(super) attempts: u8,
        pub(super) deadline: Instant,
    }

    /// Waiting for the final MISSION_ACK.
    #[derive(Debug)]
    pub struct AwaitingAck {
        pub(super) items: Vec<MissionItemInt>,
        /// The last item sent (`None`: only MISSION_COUNT so far).
        pub(super) last: Option<u16>,
        pub(super) attempts: u8,
        pub(super) deadline: Instant,
    }

    /// A download's phase.
    #[derive(Debug)]
    pub enum Download {
        /// MISSION_REQUEST_LIST sent.
        AwaitingCount(AwaitingCount),
        /// Items `0..seq` received; item `seq` requested.
        AwaitingItem(AwaitingItem),
    }

    /// Waiting for MISSION_COUNT.
    #[derive(Debug)]
    pub struct AwaitingCount {
        pub(super) attempts: u8,
        pub(super) deadline: Instant,
    }

    /// Waiting for item `seq`.
    #[derive(Debug)]
    pub struct AwaitingItem {
        /// The item requested.
        pub seq: u16,
        pub(super) count: u16,
        pub(super) items: Vec<MissionItemInt>,
        pub(super) attempts: u8,
        pub(super) deadline: Instant,
    }

    impl AwaitingRequest {
        /// How many items the upload has.
        #[must_use]
        pub fn count(&self) -> usize {
            self.items.len()
        }

        /// How many items have gone out (the vehicle asked for them).
        #[must_use]
        pub fn sent(&self) -> usize {
            self.last.map_or(0, |l| usize::from(l) + 1)
        }
    }

    impl AwaitingAck {
        /// How many items the upload has (all sent).
        #[must_use]
        pub fn count(&self) -> usize {
            self.items.len()
        }
    }

    impl AwaitingItem {
        /// How many items the plan has.
        #[must_use]
        pub fn count(&self) -> u16 {
            self.count
        }
    }
}

use transfer::{AwaitingAck, AwaitingCount, AwaitingItem, AwaitingRequest, Download, Upload};

#[derive(Debug)]
enum Op {
    Upload(Upload),
    Download(Download),
    Clear {
        attempts: u8,
        deadline: Instant,
    },
    SetCurrent {
        seq: u16,
        attempts: u8,
        deadline: Instant,
    },
}

#[derive(Debug)]
struct Running {
    target: Address,
    mission_type: MavMissionType,
    op: Op,
    /// When the message awaiting an answer was last sent.
    sent: Instant,
    /// Whether it was sent more than once (its answer then says nothing of the RTT).
    resent: bool,
}

/// The client side of the mission protocol.
#[derive(Debug)]
pub struct MissionClient {
    own: Address,
    config: MissionConfig,
    rtt: Rtt,
    running: Option<Running>,
    out: VecDeque<Outgoing>,
    events: VecDeque<MissionEvent>,
}

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

impl MissionClient {
    /// A client sending as `own`.
    #[must_use]
    pub fn new(own: Address, config: MissionConfig) -> Self {
        Self {
            own,
            config,
            rtt: Rtt::default(),
            running: None,
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// Whether a transfer is running.
    #[must_use]
    pub fn is_busy(&self) -> bool {
        self.running.is_some()
    }

    /// The upload's phase, if an upload is running.
    #[must_use]
    pub fn upload_state(&self) -> Option<&Upload> {
        match &self.running {
            Some(Running {
                op: Op::Upload(u), ..
            }) => Some(u),
            _ => None,
        }
    }

    /// The download's phase, if a download is running.
    #[must_use]
    pub fn download_state(&self) -> Option<&Download> {
        match &self.running {
            Some(Running {
                op: Op::Download(d),
                ..
            }) => Some(d),
            _ => None,
        }
    }

    fn start(
        &mut self,
        now: Instant,
        target: Address,
        mission_type: MavMissionType,
        message: MavMessage,
        op: Op,
    ) -> Result<(), MissionBusy> {
        if self.running.is_some() {
            return Err(MissionBusy::Busy);
        }
        self.out.push_back(Outgoing { target, message });
        self.running = Some(Running {
            target,
            mission_type,
            op,
            sent: now,
            resent: false,
        });
        Ok(())
    }

    /// Uploads `items` as the `mission_type` plan of `target` (their `seq`, `target_*` and
    /// `mission_type` are filled in). An empty list clears the plan. Ends with
    /// [`MissionEvent::Uploaded`].
    ///
    /// # Errors
    ///
    /// [`MissionBusy::Busy`] while another transfer runs.
    pub fn upload(
        &mut self,
        now: Instant,
        target: Address,
        mission_type: MavMissionType,
        mut items: Vec<MissionItemInt>,
    ) -> Result<(), MissionBusy> {
        for (i, item) in items.iter_mut().enumerate() {
            item.seq = u16::try_from(i).unwrap_or(u16::MAX);
            item.target_system = target.system;
            item.target_component = target.component;
            item.mission_type = mission_type;
        }
        let count = MavMessage::MissionCount(MissionCount {
            target_system: target.system,
            target_component: target.component,
            count: u16::try_from(items.len()).unwrap_or(u16::MAX),
            mission_type,
        });
        let state = AwaitingRequest {
            items,
            last: None,
            attempts: 1,
            deadline: now + self.config.timeout,
        };
        self.start(
            now,
            target,
            mission_type,
            count,
            Op::Upload(Upload::AwaitingRequest(state)),
        )
    }

    /// Downloads the `mission_type` plan of `target`. Ends with [`MissionEvent::Downloaded`].
    ///
    /// # Errors
    ///
    /// [`MissionBusy::Busy`] while another transfer runs.
    pub fn download(
        &mut self,
        now: Instant,
        target: Address,
        mission_type: MavMissionType,
    ) -> Result<(), MissionBusy> {
        let message = self.request_list(target, mission_type);
        let state = AwaitingCount {
            attempts: 1,
            deadline: now + self.config.timeout,
        };
        self.start(
            now,
            target,
            mission_type,
            message,
            Op::Download(Download::AwaitingCount(state)),
        )
    }

    /// Clears the `mission_type` plan of `target` (`MavMissionType::ALL` for all three).
    /// Ends with [`MissionEvent::Cleared`].
    ///
    /// # Errors
    ///
    /// [`MissionBusy::Busy`] while another transfer runs.
    pub fn clear(
        &mut self,
        now: Instant,
        target: Address,
        mission_type: MavMissionType,
    ) -> Result<(), MissionBusy> {
        let message = clear_all(target, mission_type);
        let deadline = now + self.config.timeout;
        self.start(
            now,
            target,
            mission_type,
            message,
            Op::Clear {
                attempts: 1,
                deadline,
            },
        )
    }

    /// Makes item `seq` of the mission current. Ends with [`MissionEvent::CurrentSet`].
    ///
    /// # Errors
    ///
    /// [`MissionBusy::Busy`] while another transfer runs.
    pub fn set_current(
        &mut self,
        now: Instant,
        target: Address,
        seq: u16,
    ) -> Result<(), MissionBusy> {
        let message = set_current(target, seq);
        let deadline = now + self.config.timeout;
        self.start(
            now,
            target,
            MavMissionType::MISSION,
            message,
            Op::SetCurrent {
                seq,
                attempts: 1,
                deadline,
            },
        )
    }

    /// Cancels the running transfer: tells the target with
    /// MISSION_ACK(OPERATION_CANCELLED) and ends it with [`MissionError::Cancelled`].
    /// Returns whether one was running.
    pub fn cancel(&mut self) -> bool {
        let Some(r) = self.running.take() else {
            return false;
        };
        self.out.push_back(Outgoing {
            target: r.target,
            message: ack(
                r.target,
                r.mission_type,
                MavMissionResult::MAV_MISSION_OPERATION_CANCELLED,
            ),
        });
        self.finish(r, Err(MissionError::Cancelled));
        true
    }

    fn request_list(&self, target: Address, mission_type: MavMissionType) -> MavMessage {
        let _ = self;
        MavMessage::MissionRequestList(MissionRequestList {
            target_system: target.system,
            target_component: target.component,
            mission_type,
        })
    }

    fn finish(&mut self, r: Running, result: Result<Vec<MissionItemInt>, MissionError>) {
        let mission_type = r.mission_type;
        let plain = result.as_ref().map(|_| ()).map_err(|e| *e);
        self.events.push_back(match r.op {
            Op::Upload(_) => MissionEvent::Uploaded {
                mission_type,
                result: plain,
            },
            Op::Download(_) => MissionEvent::Downloaded {
                mission_type,
                result,
            },
            Op::Clear { .. } => MissionEvent::Cleared {
                mission_type,
                result: plain,
            },
            Op::SetCurrent { seq, .. } => MissionEvent::CurrentSet { seq, result: plain },
        });
    }

    fn send(&mut self, target: Address, message: MavMessage) {
        self.out.push_back(Outgoing { target, message });
    }

    /// Advances the running operation with one message; returns the operation (or `None`
    /// when it ended) and whether the message was used.
    fn step(
        &mut self,
        now: Instant,
        mut r: Running,
        message: &MavMessage,
    ) -> (Option<Running>, bool) {
        let target = r.target;
        let ty = r.mission_type;
        // A MISSION_ACK of this plan type ends any operation but set-current.
        if let MavMessage::MissionAck(a) = message
            && for_me(self.own, a.target_system, a.target_component)
            && !matches!(r.op, Op::SetCurrent { .. })
            && (a.mission_type == ty || matches!(r.op, Op::Clear { .. }))
        {
            if matches!(r.op, Op::Upload(_))
                && a.r#type == MavMissionResult::MAV_MISSION_INVALID_SEQUENCE
            {
                // ArduPilot's answer to an item it did not ask for (our resend after its
                // request was lost); the upload goes on. Retries and the timeout still bound
                // it. When it answers so to our resend of item k, it took k and wants k + 1
                // (it accepts only the item after the last it took, and asked for k): send
                // k + 1 now rather than wait for its next request, a second away.
                if let Op::Upload(Upload::AwaitingRequest(s)) = &r.op
                    && s.attempts > 1
                    && let Some(k) = s.last
                    && usize::from(k) + 1 < s.items.len()
                {
                    let wanted = request_int(self.own, ty, k + 1);
                    return self.step(now, r, &wanted);
                }
                return (Some(r), true);
            }
            let done_upload = matches!(r.op, Op::Upload(Upload::AwaitingAck(_)))
                || matches!(&r.op, Op::Upload(Upload::AwaitingRequest(s)) if s.items.is_empty());
            let resent_last = matches!(&r.op, Op::Upload(Upload::AwaitingAck(s)) if s.attempts > 1);
            let result = if a.r#type != MavMissionResult::MAV_MISSION_ACCEPTED && resent_last {
                Err(MissionError::Unconfirmed { result: a.r#type })
            } else if a.r#type != MavMissionResult::MAV_MISSION_ACCEPTED {
                Err(MissionError::Rejected { result: a.r#type })
            } else if matches!(r.op, Op::Clear { .. }) || done_upload {
                Ok(Vec::new())
            } else if matches!(r.op, Op::Upload(_)) {
                // ACCEPTED before every item was requested: take it (ArduPilot-like).
                Ok(Vec::new())
            } else {
                // An ACCEPTED ack in the middle of a download means nothing to us.
                return (Some(r), false);
            };
            self.finish(r, result);
            return (None, true);
        }
        match r.op {
            Op::Upload(state) => {
                let Some((seq, rty)) = as_request(self.own, message) else {
                    r.op = Op::Upload(state);
                    return (Some(r), false);
                };
                let (items, attempts, deadline, last) = match state {
                    Upload::AwaitingRequest(s) => (s.items, s.attempts, s.deadline, s.last),
                    Upload::AwaitingAck(s) => (s.items, s.attempts, s.deadline, s.last),
                };
                let Some(item) = items.get(usize::from(seq)).filter(|_| rty == ty).copied() else {
                    // A request for something we do not have: refuse it and stop.
                    self.send(
                        target,
                        ack(target, ty, MavMissionResult::MAV_MISSION_INVALID_SEQUENCE),
                    );
                    let state = AwaitingRequest {
                        items,
                        last,
                        attempts,
                        deadline,
                    };
                    r.op = Op::Upload(Upload::AwaitingRequest(state));
                    self.finish(
                        r,
                        Err(MissionError::Rejected {
                            result: MavMissionResult::MAV_MISSION_INVALID_SEQUENCE,
                        }),
                    );
                    return (None, true);
                };
                let next = last.map_or(0, |l| l.saturating_add(1));
                if seq < next {
                    // A late copy of a request already answered (the link duplicated or
                    // delayed it), or the vehicle going back: answer it, but it neither
                    // moves the transfer back nor says anything of the round trip.
                    self.send(target, MavMessage::MissionItemInt(item));
                    let state = AwaitingRequest {
                        items,
                        last,
                        attempts,
                        deadline,
                    };
                    r.op = Op::Upload(if usize::from(next) >= state.items.len() {
                        Upload::AwaitingAck(AwaitingAck {
                            items: state.items,
                            last: state.last,
                            attempts: state.attempts,
                            deadline: state.deadline,
                        })
                    } else {
                        Upload::AwaitingRequest(state)
                    });
                    return (Some(r), true);
                }
                if !r.resent {
                    self.rtt.sample(r.sent, now);
                }
                (r.sent, r.resent) = (now, false);
                let last = Some(seq);
                self.send(target, MavMessage::MissionItemInt(item));
                let is_last = usize::from(seq) + 1 == items.len();
                let (attempts, deadline) = (1, now + self.item_wait());
                r.op = Op::Upload(if is_last {
                    Upload::AwaitingAck(AwaitingAck {
                        items,
                        last,
                        attempts,
                        deadline: now + self.config.timeout,
                    })
                } else {
                    Upload::AwaitingRequest(AwaitingRequest {
                        items,
                        last,
                        attempts,
                        deadline,
                    })
                });
                (Some(r), true)
            }
            Op::Download(state) => {
                let (next, used) = self.download_step(now, target, ty, state, message);
                if used {
                    // A count or the awaited item: the answer to what we sent last.
                    if !r.resent {
                        self.rtt.sample(r.sent, now);
                    }
                    (r.sent, r.resent) = (now, false);
                }
                match next {
                    Ok(state) => {
                        r.op = Op::Download(state);
                        (Some(r), used)
                    }
                    Err(items) => {
                        r.op = Op::Download(Download::AwaitingCount(AwaitingCount {
                            attempts: 0,
                            deadline: now,
                        }));
                        self.finish(r, Ok(items));
                        (None, true)
                    }
                }
            }
            Op::SetCurrent { seq, .. } => {
                if let MavMessage::MissionCurrent(c) = message
                    && c.seq == seq
                {
                    self.finish(r, Ok(Vec::new()));
                    return (None, true);
                }
                (Some(r), false)
            }
            Op::Clear { .. } => (Some(r), false),
        }
    }

    /// One download step: `Ok(next state)` or `Err(items)` when complete.
    fn download_step(
        &mut self,
        now: Instant,
        target: Address,
        ty: MavMissionType,
        state: Download,
        message: &MavMessage,
    ) -> (Result<Download, Vec<MissionItemInt>>, bool) {
        match (state, message) {
            (Download::AwaitingCount(_), MavMessage::MissionCount(c))
                if for_me(self.own, c.target_system, c.target_component)
                    && c.mission_type == ty =>
            {
                if c.count == 0 {
                    self.send(
                        target,
                        ack(target, ty, MavMissionResult::MAV_MISSION_ACCEPTED),
                    );
                    return (Err(Vec::new()), true);
                }
                self.send(target, request_int(target, ty, 0));
                let next = AwaitingItem {
                    seq: 0,
                    count: c.count,
                    // Room for the first items only: a count is a claim (any peer may announce
                    // 65,535 items), and the list grows as items really arrive.
                    items: Vec::with_capacity(usize::from(c.count).min(PREALLOCATED_ITEMS)),
                    attempts: 1,
                    deadline: now + self.item_wait(),
                };
                (Ok(Download::AwaitingItem(next)), true)
            }
            (Download::AwaitingItem(mut s), MavMessage::MissionItemInt(item))
                if for_me(self.own, item.target_system, item.target_component)
                    && item.mission_type == ty
                    && item.seq == s.seq =>
            {
                s.items.push(*item);
                if s.seq + 1 >= s.count {
                    self.send(
                        target,
                        ack(target, ty, MavMissionResult::MAV_MISSION_ACCEPTED),
                    );
                    return (Err(s.items), true);
                }
                s.seq += 1;
                s.attempts = 1;
                s.deadline = now + self.item_wait();
                self.send(target, request_int(target, ty, s.seq));
                (Ok(Download::AwaitingItem(s)), true)
            }
            (state, _) => (Ok(state), false),
        }
    }

    /// Feeds one message from `from`. Returns whether the running operation used it.
    pub fn handle(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let Some(r) = self.running.take() else {
            return false;
        };
        if !from.is_reached_by(r.target) {
            self.running = Some(r);
            return false;
        }
        let (next, used) = self.step(now, r, message);
        self.running = next;
        used
    }

    /// The next result, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<MissionEvent> {
        self.events.pop_front()
    }

    /// How long to wait for the next item or request: the measured round trip's timeout,
    /// at most [`MissionConfig::item_timeout`].
    fn item_wait(&self) -> Duration {
        self.rtt.timeout(self.config.item_timeout)
    }

    fn deadline(&self) -> Option<Instant> {
        let r = self.running.as_ref()?;
        Some(match &r.op {
            Op::Upload(Upload::AwaitingRequest(s)) => s.deadline,
            Op::Upload(Upload::AwaitingAck(s)) => s.deadline,
            Op::Download(Download::AwaitingCount(s)) => s.deadline,
            Op::Download(Download::AwaitingItem(s)) => s.deadline,
            Op::Clear { deadline, .. } | Op::SetCurrent { deadline, .. } => *deadline,
        })
    }
}

/// MISSION_COUNT (`last` = `None`) or the item `last` of an upload.
fn upload_message(
    target: Address,
    mission_type: MavMissionType,
    items: &[MissionItemInt],
    last: Option<u16>,
) -> MavMessage {
    match last.and_then(|seq| items.get(usize::from(seq))) {
        Some(item) => MavMessage::MissionItemInt(*item),
        None => MavMessage::MissionCount(MissionCount {
            target_system: target.system,
            target_component: target.component,
            count: u16::try_from(items.len()).unwrap_or(u16::MAX),
            mission_type,
        }),
    }
}

fn clear_all(target: Address, mission_type: MavMissionType) -> MavMessage {
    MavMessage::MissionClearAll(MissionClearAll {
        target_system: target.system,
        target_component: target.component,
        mission_type,
    })
}

fn set_current(target: Address, seq: u16) -> MavMessage {
    MavMessage::MissionSetCurrent(MissionSetCurrent {
        target_system: target.system,
        target_component: target.component,
        seq,
    })
}

impl Service for MissionClient {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        self.handle(now, from, message)
    }

    fn handle_timeout(&mut self, now: Instant) {
        if self.deadline().is_none_or(|d| now < d) {
            return;
        }
        let Some(mut r) = self.running.take() else {
            return;
        };
        let (target, ty) = (r.target, r.mission_type);
        let retries = self.config.retries;
        let wait = Some(self.config.timeout);
        // `None`: an item's wait, the round trip's timeout backing off with each resend.
        let item_wait = None;
        (r.sent, r.resent) = (now, true);
        // (attempts so far, message to resend, wait)
        let (attempts, resend, wait) = match &mut r.op {
            Op::Upload(Upload::AwaitingRequest(s)) => {
                let w = if s.last.is_none() { wait } else { item_wait };
                let m = upload_message(target, ty, &s.items, s.last);
                (&mut s.attempts, m, (&mut s.deadline, w))
            }
            Op::Upload(Upload::AwaitingAck(s)) => {
                let m = upload_message(target, ty, &s.items, s.last);
                (&mut s.attempts, m, (&mut s.deadline, wait))
            }
            Op::Download(Download::AwaitingCount(s)) => (
                &mut s.attempts,
                self.request_list(target, ty),
                (&mut s.deadline, wait),
            ),
            Op::Download(Download::AwaitingItem(s)) => (
                &mut s.attempts,
                request_int(target, ty, s.seq),
                (&mut s.deadline, item_wait),
            ),
            Op::Clear { attempts, deadline } => (attempts, clear_all(target, ty), (deadline, wait)),
            Op::SetCurrent {
                seq,
                attempts,
                deadline,
            } => (attempts, set_current(target, *seq), (deadline, wait)),
        };
        if *attempts > retries {
            let attempts = *attempts;
            self.finish(r, Err(MissionError::TimedOut { attempts }));
            return;
        }
        *attempts += 1;
        let (deadline, w) = wait;
        let item_timeout = self.config.item_timeout;
        *deadline = now + w.unwrap_or_else(|| self.rtt.backoff(item_timeout, *attempts));
        self.out.push_back(Outgoing {
            target,
            message: resend,
        });
        self.running = Some(r);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.deadline()
    }
}

/// What a [`MissionServer`] reports.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum MissionServerEvent {
    /// A plan was replaced by a complete upload, or cleared.
    PlanChanged {
        /// Which plan.
        mission_type: MavMissionType,
        /// How many items it has now.
        count: u16,
    },
    /// An upload was abandoned (cancelled or timed out); the stored plan is unchanged.
    UploadAbandoned {
        /// Which plan.
        mission_type: MavMissionType,
    },
    /// The current mission item changed.
    CurrentChanged {
        /// The new current item.
        seq: u16,
    },
}

#[derive(Debug)]
struct Receiving {
    peer: Address,
    mission_type: MavMissionType,
    count: u16,
    items: Vec<MissionItemInt>,
    attempts: u8,
    deadline: Instant,
    /// When the pending request was sent, and whether more than once.
    sent: Instant,
    resent: bool,
    /// When the last item arrived (or the count): the upload is abandoned after
    /// [`MissionServer::patience`] without one.
    progress_at: Instant,
}

/// The server side of the mission protocol: stores the mission, fence and rally plans.
#[derive(Debug)]
pub struct MissionServer {
    own: Address,
    config: MissionConfig,
    plans: [Vec<MissionItemInt>; 3],
    current: u16,
    receiving: Option<Receiving>,
    /// The round trip of our requests (uploads from ground stations that never resend).
    rtt: Rtt,
    /// The last completed upload (peer, type, count), to re-ACK a resent last item.
    last_upload: Option<(Address, MavMissionType, u16)>,
    out: VecDeque<Outgoing>,
    events: VecDeque<MissionServerEvent>,
}

fn slot(mission_type: MavMissionType) -> Option<usize> {
    match mission_type {
        MavMissionType::MISSION => Some(0),
        MavMissionType::FENCE => Some(1),
        MavMissionType::RALLY => Some(2),
        _ => None,
    }
}

impl MissionServer {
    /// A server for `own` with three empty plans.
    #[must_use]
    pub fn new(own: Address, config: MissionConfig) -> Self {
        Self {
            own,
            config,
            plans: [Vec::new(), Vec::new(), Vec::new()],
            current: 0,
            receiving: None,
            rtt: Rtt::default(),
            last_upload: None,
            out: VecDeque::new(),
            events: VecDeque::new(),
        }
    }

    /// The stored plan of `mission_type` (empty for an unknown type).
    #[must_use]
    pub fn plan(&self, mission_type: MavMissionType) -> &[MissionItemInt] {
        slot(mission_type).map_or(&[], |i| &self.plans[i])
    }

    /// Replaces the stored plan of `mission_type` from the vehicle's side (a plan loaded at
    /// start, ArduPilot's home as item 0 after a clear); ground stations see it on their
    /// next download. No [`MissionServerEvent`] is raised: the caller made the change. The
    /// current item goes back to 0 when it is past the new mission's end. Returns false for
    /// a type with no plan (only mission, fence and rally have one).
    pub fn set_plan(&mut self, mission_type: MavMissionType, items: Vec<MissionItemInt>) -> bool {
        let Some(i) = slot(mission_type) else {
            return false;
        };
        self.plans[i] = items;
        if i == 0 && usize::from(self.current) >= self.plans[0].len() {
            self.current = 0;
        }
        true
    }

    /// The current mission item.
    #[must_use]
    pub fn current(&self) -> u16 {
        self.current
    }

    /// Makes item `seq` of the mission current, as a vehicle does when it moves on to the
    /// next item, and broadcasts MISSION_CURRENT. Returns whether `seq` is in the mission.
    pub fn set_current(&mut self, seq: u16) -> bool {
        if usize::from(seq) >= self.plans[0].len() {
            return false;
        }
        self.current = seq;
        let current = self.mission_current();
        self.send(Address::BROADCAST, current);
        true
    }

    /// How long an upload may go without an item before it is abandoned: with
    /// [`UploadPacing::Adaptive`] `timeout × (retries + 1)`, 9 s by default; with
    /// [`UploadPacing::Fixed`] its `give_up_after` (ArduPilot: 8 s). Ground stations such as
    /// MAVProxy never resend an item, so the server's re-requests are all that moves a lossy
    /// upload on.
    #[must_use]
    pub fn patience(&self) -> Duration {
        match self.config.pacing {
            UploadPacing::Adaptive => self.config.timeout * (u32::from(self.config.retries) + 1),
            UploadPacing::Fixed { give_up_after, .. } => give_up_after,
        }
    }

    /// Whether an upload is in progress.
    #[must_use]
    pub fn is_receiving(&self) -> bool {
        self.receiving.is_some()
    }

    /// The next event, if any. Call until `None` after every `handle_*` call.
    #[must_use]
    pub fn poll_event(&mut self) -> Option<MissionServerEvent> {
        self.events.pop_front()
    }

    fn send(&mut self, target: Address, message: MavMessage) {
        self.out.push_back(Outgoing { target, message });
    }

    fn count_of(&self, mission_type: MavMissionType) -> u16 {
        u16::try_from(self.plan(mission_type).len()).unwrap_or(u16::MAX)
    }

    fn on_count(&mut self, now: Instant, from: Address, c: &MissionCount) {
        let ty = c.mission_type;
        let Some(i) = slot(ty) else {
            self.send(
                from,
                ack(from, ty, MavMissionResult::MAV_MISSION_UNSUPPORTED),
            );
            return;
        };
        if let Some(r) = &self.receiving {
            if r.peer == from && r.mission_type == ty && r.count == c.count && r.items.is_empty() {
                // A resent count: ask for the first item again.
                self.send(from, request_int(from, ty, 0));
                return;
            }
            if r.peer != from {
                self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_DENIED));
                return;
            }
        }
        if c.count == 0 {
            self.receiving = None;
            self.plans[i].clear();
            self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_ACCEPTED));
            self.events.push_back(MissionServerEvent::PlanChanged {
                mission_type: ty,
                count: 0,
            });
            return;
        }
        self.receiving = Some(Receiving {
            peer: from,
            mission_type: ty,
            count: c.count,
            // Room for the first items only: a count is a claim (any peer may announce
            // 65,535 items), and the list grows as items really arrive.
            items: Vec::with_capacity(usize::from(c.count).min(PREALLOCATED_ITEMS)),
            attempts: 1,
            deadline: now
                + self
                    .config
                    .pacing
                    .first_wait(&self.rtt, self.config.item_timeout),
            sent: now,
            resent: false,
            progress_at: now,
        });
        self.send(from, request_int(from, ty, 0));
    }

    fn on_item(&mut self, now: Instant, from: Address, item: &MissionItemInt) {
        let ty = item.mission_type;
        let Some(r) = self
            .receiving
            .as_mut()
            .filter(|r| r.peer == from && r.mission_type == ty)
        else {
            if self.config.stray_items == StrayItems::ArduPilot {
                self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_ERROR));
                return;
            }
            // The last item resent after a lost final ACK: ACK again.
            if self.last_upload == Some((from, ty, item.seq.saturating_add(1))) {
                self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_ACCEPTED));
            }
            return;
        };
        let expected = u16::try_from(r.items.len()).unwrap_or(u16::MAX);
        if item.seq != expected {
            // Out of sequence: drop it and ask for the expected one. After a gap that is
            // the only way forward; after a copy of the previous item it is the client
            // resending because our request was lost (a copy the link made gets a second
            // request, whose answer we drop in turn).
            if self.config.stray_items == StrayItems::ArduPilot {
                let invalid = MavMissionResult::MAV_MISSION_INVALID_SEQUENCE;
                self.send(from, ack(from, ty, invalid));
            } else if item.seq > expected || item.seq.saturating_add(1) == expected {
                (r.sent, r.resent) = (now, true);
                self.send(from, request_int(from, ty, expected));
            }
            return;
        }
        r.items.push(*item);
        if !r.resent {
            self.rtt.sample(r.sent, now);
        }
        r.attempts = 1;
        r.deadline = now
            + self
                .config
                .pacing
                .first_wait(&self.rtt, self.config.item_timeout);
        (r.sent, r.resent) = (now, false);
        r.progress_at = now;
        if r.items.len() < usize::from(r.count) {
            self.send(from, request_int(from, ty, expected + 1));
            return;
        }
        let Some(done) = self.receiving.take() else {
            return;
        };
        let count = done.count;
        if let Some(i) = slot(ty) {
            self.plans[i] = done.items;
        }
        if ty == MavMissionType::MISSION && self.current >= count {
            self.current = 0;
        }
        self.last_upload = Some((from, ty, count));
        self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_ACCEPTED));
        self.events.push_back(MissionServerEvent::PlanChanged {
            mission_type: ty,
            count,
        });
    }

    fn on_request(&mut self, from: Address, seq: u16, ty: MavMissionType) {
        match self.plan(ty).get(usize::from(seq)).copied() {
            Some(mut item) => {
                item.target_system = from.system;
                item.target_component = from.component;
                item.seq = seq;
                item.mission_type = ty;
                self.send(from, MavMessage::MissionItemInt(item));
            }
            None => {
                let result = if slot(ty).is_some() {
                    MavMissionResult::MAV_MISSION_INVALID_SEQUENCE
                } else {
                    MavMissionResult::MAV_MISSION_UNSUPPORTED
                };
                self.send(from, ack(from, ty, result));
            }
        }
    }

    fn mission_current(&self) -> MavMessage {
        MavMessage::MissionCurrent(MissionCurrent {
            seq: self.current,
            total: self.count_of(MavMissionType::MISSION),
            ..MissionCurrent::default()
        })
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

/// The MISSION_ITEM_INT equivalent of a float MISSION_ITEM: latitude and longitude of
/// global frames scaled to degE7, local coordinates to metres × 10⁴ (as the protocol's INT
/// frames carry them).
fn item_int_of(item: &MissionItem) -> MissionItemInt {
    let global = is_global(item.frame);
    let scale = |v: f32| {
        let v = f64::from(v) * if global { 1e7 } else { 1e4 };
        // Saturating: NaN becomes 0, out-of-range values clamp.
        v as i32
    };
    let frame = match item.frame {
        MavFrame::GLOBAL => MavFrame::GLOBAL_INT,
        MavFrame::GLOBAL_RELATIVE_ALT => MavFrame::GLOBAL_RELATIVE_ALT_INT,
        MavFrame::GLOBAL_TERRAIN_ALT => MavFrame::GLOBAL_TERRAIN_ALT_INT,
        f => f,
    };
    MissionItemInt {
        target_system: item.target_system,
        target_component: item.target_component,
        seq: item.seq,
        frame,
        command: item.command,
        current: item.current,
        autocontinue: item.autocontinue,
        param1: item.param1,
        param2: item.param2,
        param3: item.param3,
        param4: item.param4,
        x: scale(item.x),
        y: scale(item.y),
        z: item.z,
        mission_type: item.mission_type,
    }
}

impl Service for MissionServer {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let own = self.own;
        match message {
            MavMessage::MissionCount(c) if for_me(own, c.target_system, c.target_component) => {
                self.on_count(now, from, c);
            }
            MavMessage::MissionItemInt(item)
                if for_me(own, item.target_system, item.target_component) =>
            {
                self.on_item(now, from, item);
            }
            MavMessage::MissionItem(item)
                if for_me(own, item.target_system, item.target_component) =>
            {
                // Older ground stations answer MISSION_REQUEST_INT with the float item.
                self.on_item(now, from, &item_int_of(item));
            }
            MavMessage::MissionRequestList(m)
                if for_me(own, m.target_system, m.target_component) =>
            {
                let ty = m.mission_type;
                let message = if slot(ty).is_some() {
                    MavMessage::MissionCount(MissionCount {
                        target_system: from.system,
                        target_component: from.component,
                        count: self.count_of(ty),
                        mission_type: ty,
                    })
                } else {
                    ack(from, ty, MavMissionResult::MAV_MISSION_UNSUPPORTED)
                };
                self.send(from, message);
            }
            MavMessage::MissionClearAll(m) if for_me(own, m.target_system, m.target_component) => {
                let ty = m.mission_type;
                let cleared: &[MavMissionType] = match ty {
                    MavMissionType::ALL => &[
                        MavMissionType::MISSION,
                        MavMissionType::FENCE,
                        MavMissionType::RALLY,
                    ],
                    _ if slot(ty).is_some() => &[ty],
                    _ => &[],
                };
                if cleared.is_empty() {
                    self.send(
                        from,
                        ack(from, ty, MavMissionResult::MAV_MISSION_UNSUPPORTED),
                    );
                    return true;
                }
                for &t in cleared {
                    if let Some(i) = slot(t) {
                        self.plans[i].clear();
                    }
                    self.events.push_back(MissionServerEvent::PlanChanged {
                        mission_type: t,
                        count: 0,
                    });
                }
                if cleared.contains(&MavMissionType::MISSION) {
                    self.current = 0;
                }
                self.send(from, ack(from, ty, MavMissionResult::MAV_MISSION_ACCEPTED));
            }
            MavMessage::MissionSetCurrent(m)
                if for_me(own, m.target_system, m.target_component) =>
            {
                if usize::from(m.seq) < self.plans[0].len() && m.seq != self.current {
                    self.current = m.seq;
                    self.events
                        .push_back(MissionServerEvent::CurrentChanged { seq: m.seq });
                }
                let current = self.mission_current();
                self.send(Address::BROADCAST, current);
            }
            MavMessage::MissionAck(a) if for_me(own, a.target_system, a.target_component) => {
                if a.r#type != MavMissionResult::MAV_MISSION_ACCEPTED
                    && let Some(r) = self.receiving.take_if(|r| r.peer == from)
                {
                    self.events.push_back(MissionServerEvent::UploadAbandoned {
                        mission_type: r.mission_type,
                    });
                }
            }
            m => {
                let Some((seq, ty)) = as_request(own, m) else {
                    return false;
                };
                self.on_request(from, seq, ty);
            }
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        let retries = self.config.retries;
        let patience = self.patience();
        let pacing = self.config.pacing;
        let Some(r) = self.receiving.as_mut().filter(|r| now >= r.deadline) else {
            return;
        };
        let quiet = now.saturating_duration_since(r.progress_at) >= patience;
        let give_up = match pacing {
            UploadPacing::Adaptive => r.attempts > retries && quiet,
            UploadPacing::Fixed { .. } => quiet,
        };
        if give_up {
            let (peer, ty) = (r.peer, r.mission_type);
            self.receiving = None;
            if let UploadPacing::Fixed { .. } = pacing {
                let cancelled = MavMissionResult::MAV_MISSION_OPERATION_CANCELLED;
                self.send(peer, ack(peer, ty, cancelled));
            }
            self.events
                .push_back(MissionServerEvent::UploadAbandoned { mission_type: ty });
            return;
        }
        r.attempts = r.attempts.saturating_add(1);
        r.deadline = match pacing {
            UploadPacing::Adaptive => {
                let wait = self.rtt.backoff(self.config.item_timeout, r.attempts);
                (now + wait)
                    .min(r.progress_at + patience)
                    .max(now + Rtt::FLOOR)
            }
            UploadPacing::Fixed { every, .. } => (now + every).min(r.progress_at + patience),
        };
        (r.sent, r.resent) = (now, true);
        let (peer, ty) = (r.peer, r.mission_type);
        let seq = u16::try_from(r.items.len()).unwrap_or(u16::MAX);
        self.send(peer, request_int(peer, ty, seq));
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.receiving.as_ref().map(|r| r.deadline)
    }
}
