//! The client side ([`MissionClient`]): one upload, download, clear or set-current at a time,
//! each wait resent on timeout.

use alloc::collections::VecDeque;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    MavMessage, MavMissionResult, MavMissionType, MissionClearAll, MissionCount, MissionItemInt,
    MissionRequestList, MissionSetCurrent,
};

use super::transfer::{
    AwaitingAck, AwaitingCount, AwaitingItem, AwaitingRequest, Download, Upload,
};
use super::{
    MAX_WINDOW, MissionBusy, MissionConfig, MissionError, MissionEvent, PREALLOCATED_ITEMS, ack,
    as_request, for_me, request_int,
};
use crate::rtt::Rtt;
use crate::{Address, Outgoing, Service};

/// How long an upload the vehicle refuses to start as busy is asked for again: longer than
/// PX4 keeps another transfer open without news (5 s) and ArduPilot another ground station's
/// upload (8 s).
pub const BUSY_WAIT: Duration = Duration::from_secs(10);
/// The pause before asking a busy vehicle again.
const BUSY_PAUSE: Duration = Duration::from_millis(500);

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
        let state = AwaitingRequest::new(items, None, 1, now + self.config.timeout);
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
        self.download_from(now, target, mission_type, 0)
    }

    /// Downloads the items of the `mission_type` plan of `target` from `first` on (none when
    /// the plan has `first` items or fewer: the vehicle's count decides). Ends with
    /// [`MissionEvent::Downloaded`], whose items carry their numbers.
    ///
    /// # Errors
    ///
    /// [`MissionBusy::Busy`] while another transfer runs.
    pub fn download_from(
        &mut self,
        now: Instant,
        target: Address,
        mission_type: MavMissionType,
        first: u16,
    ) -> Result<(), MissionBusy> {
        let message = self.request_list(target, mission_type);
        let state = AwaitingCount {
            first,
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
                && self.upload_window() > 1
            {
                // ArduPilot refused an item of the window: one before it was lost. The
                // window again from the item it asked for, once for that item.
                if let Op::Upload(Upload::AwaitingRequest(s)) = &mut r.op
                    && let Some(h) = s.last
                    && s.went_back != Some(h)
                {
                    s.went_back = Some(h);
                    s.send_next = h;
                    self.send_window(target, s);
                }
                return (Some(r), true);
            }
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
            if let Op::Upload(Upload::AwaitingRequest(s)) = &mut r.op
                && s.last.is_none()
                && s.sent_ever == 0
                && !s.items.is_empty()
                && matches!(
                    a.r#type,
                    MavMissionResult::MAV_MISSION_ERROR | MavMissionResult::MAV_MISSION_DENIED
                )
            {
                // A refusal to start: PX4 answers ERROR while a transfer is open (a download
                // on this link, any transfer on another) until it ends or 5 s pass without
                // news; ArduPilot DENIED while another ground station uploads. The count goes
                // again after a pause, until BUSY_WAIT has passed since the first refusal.
                let until = *s.busy_until.get_or_insert(now + BUSY_WAIT);
                if now < until {
                    s.attempts = 0;
                    s.deadline = now + BUSY_PAUSE.min(until.saturating_duration_since(now));
                    return (Some(r), true);
                }
            }
            let done_upload = matches!(r.op, Op::Upload(Upload::AwaitingAck(_)))
                || matches!(&r.op, Op::Upload(Upload::AwaitingRequest(s)) if s.items.is_empty());
            // A refusal after the last item went out again may be the answer of a vehicle
            // that had the whole plan and whose ACK was lost. With a window, once every item
            // has gone out, so may be a refusal of any: a copy of an item (resent, or doubled
            // by the link) that came after the vehicle had the plan.
            let windowed = self.upload_window() > 1;
            let resent_last = matches!(&r.op, Op::Upload(Upload::AwaitingAck(s)) if s.attempts > 1 || windowed)
                || matches!(&r.op, Op::Upload(Upload::AwaitingRequest(s))
                    if windowed && usize::from(s.sent_ever) >= s.items.len());
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
                let state = match state {
                    Upload::AwaitingRequest(s)
                        if self.upload_window() > 1
                            && rty == ty
                            && usize::from(seq) < s.items.len() =>
                    {
                        if s.last.is_none() {
                            // The first request answers the count: a round trip.
                            if !r.resent {
                                self.rtt.sample(r.sent, now);
                            }
                            (r.sent, r.resent) = (now, false);
                        }
                        r.op = Op::Upload(self.windowed_request(now, target, s, seq));
                        return (Some(r), true);
                    }
                    other => other,
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
                    let state = AwaitingRequest::new(items, last, attempts, deadline);
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
                    let state = AwaitingRequest::new(items, last, attempts, deadline);
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
                    // The final ACK gets the first answer's wait: each resend of the last item
                    // draws a refusal from ArduPilot once the upload is over, and one still
                    // on its way would end the read-back that the first starts.
                    Upload::AwaitingAck(AwaitingAck {
                        items,
                        last,
                        attempts,
                        deadline: now + self.config.timeout,
                    })
                } else {
                    Upload::AwaitingRequest(AwaitingRequest::new(items, last, attempts, deadline))
                });
                (Some(r), true)
            }
            Op::Download(state) => {
                let counted = matches!(state, Download::AwaitingCount(_));
                let (next, used) = self.download_step(now, target, ty, state, message);
                if used && (counted || self.window() == 1) {
                    // A count or the awaited item: the answer to what we sent last (with a
                    // window, an item answers a request sent some items ago: only the
                    // count times a round trip).
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
                            first: 0,
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
            (Download::AwaitingCount(w), MavMessage::MissionCount(c))
                if for_me(self.own, c.target_system, c.target_component)
                    && c.mission_type == ty =>
            {
                if c.count <= w.first {
                    self.send(
                        target,
                        ack(target, ty, MavMissionResult::MAV_MISSION_ACCEPTED),
                    );
                    return (Err(Vec::new()), true);
                }
                let mut next = AwaitingItem {
                    seq: w.first,
                    count: c.count,
                    // Room for the first items only: a count is a claim (any peer may announce
                    // 65,535 items), and the list grows as items really arrive.
                    items: Vec::with_capacity(
                        usize::from(c.count - w.first).min(PREALLOCATED_ITEMS),
                    ),
                    ahead: Vec::new(),
                    next: w.first,
                    asked_again: w.first,
                    attempts: 1,
                    deadline: now + self.item_wait(),
                };
                self.request_window(target, ty, &mut next);
                (Ok(Download::AwaitingItem(next)), true)
            }
            (Download::AwaitingItem(mut s), MavMessage::MissionItemInt(item))
                if for_me(self.own, item.target_system, item.target_component)
                    && item.mission_type == ty
                    && (s.seq..s.next).contains(&item.seq)
                    && !s.ahead.iter().any(|a| a.seq == item.seq) =>
            {
                if item.seq == s.seq {
                    s.items.push(*item);
                    s.seq += 1;
                    // The items that came ahead of it and follow on now.
                    while let Some(i) = s.ahead.iter().position(|a| a.seq == s.seq) {
                        s.items.push(s.ahead.swap_remove(i));
                        s.seq += 1;
                    }
                } else {
                    s.ahead.push(*item);
                    // Asked for before it, the items still missing were lost on the way.
                    for seq in s.seq.max(s.asked_again)..item.seq {
                        if !s.ahead.iter().any(|a| a.seq == seq) {
                            self.send(target, request_int(target, ty, seq));
                        }
                    }
                    s.asked_again = s.asked_again.max(item.seq);
                }
                if s.seq >= s.count {
                    self.send(
                        target,
                        ack(target, ty, MavMissionResult::MAV_MISSION_ACCEPTED),
                    );
                    return (Err(s.items), true);
                }
                s.attempts = 1;
                s.deadline = now + self.item_wait();
                self.request_window(target, ty, &mut s);
                (Ok(Download::AwaitingItem(s)), true)
            }
            (state, _) => (Ok(state), false),
        }
    }

    /// The download window: how many items are asked for ahead of the first missing one.
    fn window(&self) -> u16 {
        self.config.download_window.clamp(1, MAX_WINDOW)
    }

    /// The upload window: how many items go out from the one the vehicle asked for.
    fn upload_window(&self) -> u16 {
        self.config.upload_window.clamp(1, MAX_WINDOW)
    }

    /// A windowed upload's answer to a request for item `seq` (of the plan).
    fn windowed_request(
        &mut self,
        now: Instant,
        target: Address,
        mut s: AwaitingRequest,
        seq: u16,
    ) -> Upload {
        match s.last {
            // A late copy of an older request: the vehicle has moved on.
            Some(h) if seq < h => return Upload::AwaitingRequest(s),
            // Asked again: what went out from `h` on did not arrive (once for `h`: the
            // copies of one loss make one resend; a timeout goes back again).
            Some(h) if seq == h => {
                if s.went_back != Some(h) {
                    s.went_back = Some(h);
                    s.send_next = h;
                }
            }
            // Progress: the vehicle holds every item before `seq`.
            _ => {
                s.last = Some(seq);
                s.attempts = 1;
                s.deadline = now + self.item_wait();
                s.send_next = s.send_next.max(seq);
            }
        }
        self.send_window(target, &mut s);
        if s.last.is_some_and(|h| usize::from(h) + 1 >= s.items.len()) {
            // The last item asked for (and sent): the ACK is next.
            return Upload::AwaitingAck(AwaitingAck {
                items: s.items,
                last: s.last,
                attempts: 1,
                deadline: now + self.config.timeout,
            });
        }
        Upload::AwaitingRequest(s)
    }

    /// Where an upload's window ends (the first item past it): `upload_window` items from
    /// the last the vehicle asked for, at most the plan's end.
    fn window_end(&self, s: &AwaitingRequest) -> u16 {
        let len = u16::try_from(s.items.len()).unwrap_or(u16::MAX);
        s.last
            .unwrap_or(0)
            .saturating_add(self.upload_window())
            .min(len)
    }

    /// Sends the items of the window not sent since it last went back, in order.
    fn send_window(&mut self, target: Address, s: &mut AwaitingRequest) {
        let end = self.window_end(s);
        while s.send_next < end {
            if let Some(item) = s.items.get(usize::from(s.send_next)) {
                self.send(target, MavMessage::MissionItemInt(*item));
            }
            s.send_next += 1;
        }
        s.sent_ever = s.sent_ever.max(s.send_next);
    }

    /// Requests the items not asked for yet up to the window's end.
    fn request_window(&mut self, target: Address, ty: MavMissionType, s: &mut AwaitingItem) {
        let end = s.seq.saturating_add(self.window()).min(s.count);
        while s.next < end {
            self.send(target, request_int(target, ty, s.next));
            s.next += 1;
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
        // What goes out after the resend (a download window's missing items), in order.
        let mut then = Vec::new();
        // An upload window goes out again after the resend.
        let mut go_back = false;
        let window = self.upload_window();
        // (attempts so far, message to resend, wait)
        let (attempts, resend, wait) = match &mut r.op {
            Op::Upload(Upload::AwaitingRequest(s)) => {
                let w = if s.last.is_none() { wait } else { item_wait };
                let m = upload_message(target, ty, &s.items, s.last);
                if window > 1
                    && let Some(h) = s.last
                {
                    // Go back: the window again from the item asked for (`m`), the rest of
                    // it sent after `m` (`send_window` below).
                    s.went_back = Some(h);
                    s.send_next = h + 1;
                    go_back = true;
                }
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
            Op::Download(Download::AwaitingItem(s)) => {
                // Every item of the window still missing is asked for again.
                then.extend(
                    (s.seq + 1..s.next)
                        .filter(|seq| !s.ahead.iter().any(|a| a.seq == *seq))
                        .map(|seq| request_int(target, ty, seq)),
                );
                (
                    &mut s.attempts,
                    request_int(target, ty, s.seq),
                    (&mut s.deadline, item_wait),
                )
            }
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
        self.out
            .extend(then.into_iter().map(|message| Outgoing { target, message }));
        if go_back && let Op::Upload(Upload::AwaitingRequest(s)) = &mut r.op {
            self.send_window(target, s);
        }
        self.running = Some(r);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.out.pop_front()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.deadline()
    }
}
