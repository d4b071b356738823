//! The server side ([`MissionServer`]): the three stored plans, uploads taken whole or not at
//! all, downloads answered from the stored plan.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavFrame, MavMessage, MavMissionResult, MavMissionType, MissionCount, MissionCurrent,
    MissionItem, MissionItemInt,
};

use super::{
    MissionConfig, PREALLOCATED_ITEMS, StrayItems, UploadPacing, ack, as_request, for_me,
    is_global, request_int,
};
use crate::rtt::Rtt;
use crate::{Address, Outgoing, Service};

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
