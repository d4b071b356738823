//! The receive side of the [`Router`]: a link's channel events, routing an accepted frame,
//! and putting it onto each destination link, converted as that link needs.

use alloc::boxed::Box;
use alloc::vec::Vec;

use mavstack_channel::{Event as ChannelEvent, EventRef, ReceivedFrame};
use mavstack_core::message::Message as _;
use mavstack_core::signing;
use mavstack_core::time::Instant;
use mavstack_core::wire::MAX_FRAME_LEN;
use mavstack_dialects::common::{Heartbeat, SetupSigning};

use super::{EVENT_CAPACITY, Event, LinkId, Router};
use crate::config::LocalDelivery;
use crate::convert::{self, Origin, Plan};
use crate::dialect::{is_control, target_of};
use crate::log_readers::{LOG_DATA, LOG_REQUEST_DATA, LOG_REQUEST_END};
use crate::stats::DropReason;

impl Router {
    /// Handles every event of `id`'s channel; returns whether there was any.
    pub(super) fn drain_channel(&mut self, now: Instant, id: LinkId) -> bool {
        let mut any = false;
        // An accepted frame is copied out of the channel (its bytes only) into this one, kept
        // from call to call, and routed from there.
        let mut received = self.received.take();
        while let Some(next) = self.link_mut(id).and_then(|l| l.channel.poll_event_ref()) {
            any = true;
            if let EventRef::Frame(frame) = next {
                let held = match &mut received {
                    Some(held) => {
                        held.as_mut().clone_from(frame);
                        held
                    }
                    None => received.insert(Box::new(frame.clone())),
                };
                self.route(now, id, held);
                continue;
            }
            let Some(event) = self.link_mut(id).and_then(|l| l.channel.poll_event()) else {
                break;
            };
            match event {
                ChannelEvent::Frame(frame) => self.route(now, id, &frame),
                ChannelEvent::Rejected(rejected) => {
                    self.push_event(Event::Rejected { link: id, rejected });
                }
                ChannelEvent::VersionChanged { from, to, cause } => {
                    self.push_event(Event::VersionChanged {
                        link: id,
                        from,
                        to,
                        cause,
                    });
                }
                ChannelEvent::ProtocolVersionRequested {
                    sysid,
                    compid,
                    answer,
                    ..
                } => self.push_event(Event::ProtocolVersionRequested {
                    link: id,
                    from: (sysid, compid),
                    answer,
                }),
                ChannelEvent::Handshake(outcome) => {
                    self.push_event(Event::Handshake { link: id, outcome });
                }
                ChannelEvent::SigningSetup {
                    sysid,
                    compid,
                    setup,
                } => self.push_event(Event::SigningSetup {
                    link: id,
                    from: (sysid, compid),
                    setup,
                }),
                ChannelEvent::PersistTimestamp { timestamp } => {
                    self.push_event(Event::PersistTimestamp {
                        link: id,
                        timestamp,
                    });
                }
                _ => {}
            }
        }
        self.received = received;
        any
    }

    /// Queues what `id`'s channel sends on its own (a vehicle link's handshake answers) as
    /// control traffic of that link.
    pub(super) fn drain_channel_transmits(&mut self, now: Instant, id: LinkId) {
        let Some(l) = self.link_mut(id) else { return };
        if !l.channel.has_transmits() {
            return;
        }
        let mut buf = [0u8; MAX_FRAME_LEN];
        let mut queued = false;
        while let Some(t) = l.channel.poll_transmit(now, &mut buf) {
            if l.queue.push(true, &buf[..t.len], l.config.queue_frames) {
                l.counters.tx_frames += 1;
                l.counters.tx_bytes += t.len as u64;
                queued = true;
            } else {
                l.counters.dropped.count(DropReason::QueueFull);
            }
        }
        if queued && !l.ready {
            l.ready = true;
            self.ready.push_back(id);
        }
    }

    pub(super) fn push_event(&mut self, event: Event) {
        if self.events.len() >= EVENT_CAPACITY {
            self.events_dropped += 1;
        } else {
            self.events.push_back(event);
        }
    }

    /// Routes one accepted frame from `src`.
    fn route(&mut self, now: Instant, src: LinkId, received: &ReceivedFrame) {
        let frame = received.frame.view();
        let (sysid, compid, msg_id) = (frame.sysid(), frame.compid(), frame.msg_id());
        let Some(l) = self.link_mut(src) else { return };
        l.counters.rx_frames += 1;
        l.counters.rx_bytes += frame.frame_len() as u64;
        if !l.config.filters_in.passes(msg_id, sysid, compid) {
            l.counters.dropped.count(DropReason::Filtered);
            return;
        }
        let origin = Origin {
            trusted: l.config.trusted,
            verified: received.auth.is_authenticated(),
        };
        let secure = l.config.secure;
        if sysid != 0 && compid != 0 {
            self.routes
                .learn(now, (sysid, compid), src, self.config.route_move_after);
            if msg_id == Heartbeat::ID && received.crc_checked {
                self.systems
                    .heard(now, (sysid, compid), src, frame.payload());
            }
        }
        let info = if received.crc_checked {
            self.dialect.info(msg_id)
        } else {
            None
        };
        let (tsys, tcomp) = target_of(info, frame.payload());
        let duplicate = self
            .dedup
            .as_mut()
            .is_some_and(|d| d.seen(now, frame.as_bytes()));

        let mut dests = core::mem::take(&mut self.scratch);
        dests.clear();
        let own = (self.config.system_id, self.config.component_id);
        let for_us = tsys == 0 || (tsys == own.0 && (tcomp == 0 || tcomp == own.1));
        match msg_id {
            LOG_REQUEST_DATA if tsys != 0 => self.log_readers.asked(now, tsys, src),
            LOG_REQUEST_END if tsys != 0 => self.log_readers.ended(tsys, src),
            _ => {}
        }
        let log_reader = if msg_id == LOG_DATA {
            self.log_readers
                .reader(now, sysid)
                .filter(|&l| l != src && self.link(l).is_some())
        } else {
            None
        };
        // Nothing goes back to its link, nor to another link of its group.
        let group = self.members.get(src.index()).and_then(|m| m.group);
        if let Some(reader) = log_reader {
            // LOG_DATA has no target: it goes to the link reading the log (and monitors).
            dests.push(reader);
            self.add_monitors(&mut dests);
            self.keep_takers(&mut dests, src, group);
        } else if tsys == 0 {
            dests.extend(
                self.members
                    .iter()
                    .enumerate()
                    .filter(|&(i, m)| i != src.index() && m.takes_from(group))
                    .map(|(i, _)| LinkId(u32::try_from(i).unwrap_or(u32::MAX))),
            );
        } else {
            let known = self
                .routes
                .links_to(now, self.config.route_ttl, tsys, tcomp, &mut dests);
            self.add_monitors(&mut dests);
            self.keep_takers(&mut dests, src, group);
            let local = self.config.local != LocalDelivery::None && tsys == own.0;
            if !known
                && !local
                && let Some(l) = self.link_mut(src)
            {
                l.counters.dropped.count(DropReason::UnknownTarget);
            }
        }
        if !self.config.forward {
            dests.clear();
        }
        if msg_id == SetupSigning::ID && (!secure || tsys == 0) {
            // Never broadcast, and only from a link marked secure.
            for &d in &dests {
                if let Some(l) = self.link_mut(d) {
                    l.counters.dropped.count(DropReason::SetupSigning);
                }
            }
            dests.clear();
        }
        if duplicate {
            for &d in &dests {
                if let Some(l) = self.link_mut(d) {
                    l.counters.dropped.count(DropReason::Duplicate);
                }
            }
        } else {
            let control = is_control(msg_id);
            for &d in &dests {
                self.forward(now, d, received, info, origin, control);
            }
            let deliver = match self.config.local {
                LocalDelivery::None => false,
                LocalDelivery::Addressed => for_us,
                LocalDelivery::All => true,
            };
            if deliver && !self.local.push(src, received) {
                self.events_dropped += 1;
            }
        }
        self.scratch = dests;
    }

    /// Adds every monitor link (a vehicle's fleet bridge link), which gets every frame,
    /// targeted or not.
    fn add_monitors(&self, dests: &mut Vec<LinkId>) {
        for (i, m) in self.members.iter().enumerate() {
            if m.live && m.monitor {
                let id = LinkId(u32::try_from(i).unwrap_or(u32::MAX));
                if !dests.contains(&id) {
                    dests.push(id);
                }
            }
        }
    }

    /// Keeps the destinations a frame from `src` (of `group`) may go to.
    fn keep_takers(&self, dests: &mut Vec<LinkId>, src: LinkId, group: Option<u32>) {
        dests.retain(|&l| {
            l != src
                && self
                    .members
                    .get(l.index())
                    .is_some_and(|m| m.takes_from(group))
        });
    }

    /// Puts one frame onto link `dst`, converted as its framing needs.
    fn forward(
        &mut self,
        now: Instant,
        dst: LinkId,
        received: &ReceivedFrame,
        info: Option<&mavstack_core::MessageInfo>,
        origin: Origin,
        control: bool,
    ) {
        let frame = received.frame.view();
        let Some(out) = self.link_mut(dst) else {
            return;
        };
        let (sysid, compid, msg_id) = (frame.sysid(), frame.compid(), frame.msg_id());
        if !out.config.filters_out.passes(msg_id, sysid, compid) {
            return out.counters.dropped.count(DropReason::Filtered);
        }
        if !control && !out.limiter.allow_message(now, sysid, compid, msg_id) {
            return out.counters.dropped.count(DropReason::RateLimited);
        }
        let mode = out.mode();
        let channel = &out.channel;
        let verifies_here = || {
            channel
                .signing()
                .is_some_and(|s| signing::verify(&frame, s.primary_key()).is_ok())
        };
        let plan = match convert::plan(&frame, info.is_some(), mode, origin, verifies_here) {
            Ok(plan) => plan,
            Err(reason) => return out.counters.dropped.count(reason),
        };
        // Set up only for a conversion: a frame that goes as it is is not copied here.
        let mut buf;
        let bytes: &[u8] = match (plan, info) {
            (Plan::AsIs, _) => frame.as_bytes(),
            (Plan::Reframe { version, sign }, Some(info)) => {
                buf = [0u8; MAX_FRAME_LEN];
                let len = match convert::reframe(&frame, info, version, sign, &mut buf) {
                    Ok(len) => len,
                    Err(reason) => return out.counters.dropped.count(reason),
                };
                let signature = if sign {
                    mavstack_core::wire::SIGNATURE_LEN
                } else {
                    0
                };
                if !out.limiter.spend(now, len + signature, control) {
                    return out.counters.dropped.count(DropReason::RateLimited);
                }
                let len = if sign {
                    match out.channel.sign_frame(now, &mut buf, len) {
                        Some(len) => len,
                        None => return out.counters.dropped.count(DropReason::CannotConvert),
                    }
                } else {
                    len
                };
                convert::count(&mut out.counters.conversions, &frame, version, sign);
                out.counters.converted += 1;
                &buf[..len]
            }
            (Plan::Reframe { .. }, None) => {
                return out.counters.dropped.count(DropReason::CannotConvert);
            }
        };
        if plan == Plan::AsIs && !out.limiter.spend(now, bytes.len(), control) {
            return out.counters.dropped.count(DropReason::RateLimited);
        }
        if !out.queue.push(control, bytes, out.config.queue_frames) {
            return out.counters.dropped.count(DropReason::QueueFull);
        }
        if plan == Plan::AsIs {
            out.counters.unchanged += 1;
        }
        out.counters.tx_frames += 1;
        out.counters.tx_bytes += bytes.len() as u64;
        if !out.ready {
            out.ready = true;
            self.ready.push_back(dst);
        }
    }
}
