//! `listen --rate NAME:HZ,...`: asking the vehicle heard on the link for telemetry rates, as
//! a plain state machine fed with the frames seen and the time.
//!
//! Flight stacks stream little or nothing until asked (ArduPilot on a fresh link). Once the
//! first autopilot's HEARTBEAT is seen, each wanted message is asked for with
//! MAV_CMD_SET_MESSAGE_INTERVAL (sent twice, half a second apart, unless its COMMAND_ACK came);
//! where the vehicle refuses it, or accepts it and the message still does not come within
//! three of its intervals (at least 1.5 s), REQUEST_DATA_STREAM is sent once for the group
//! that carries it (ArduPilot before 4.0 and some links), as `System::request_rate` does.
//!
//! A vehicle that restarts forgets the rates it was asked for (ArduPilot then streams nothing
//! again): a message that came and then stays away for five of its intervals (at least 3 s)
//! while the vehicle's HEARTBEAT still comes is asked for anew, the same way.

use core::time::Duration;
use std::time::Instant;

use mavstack_core::Message as _;
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit_message};
use mavstack_dialects::common::{
    CommandAck, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavMessage, MavResult,
};
use mavstack_services::Address;
use mavstack_services::stream::{data_stream_of, request_data_stream};
use mavstack_transport::frame::FrameBuf;

/// Our ids on the link (a ground station's).
const OWN: (u8, u8) = (255, 190);

#[derive(Debug)]
struct Wanted {
    id: u32,
    hz: f32,
    asked: Option<Instant>,
    sends: u8,
    acked: Option<bool>,
    arrived: bool,
    fell_back: bool,
    /// When it last came.
    last: Option<Instant>,
}

impl Wanted {
    const fn new(id: u32, hz: f32) -> Self {
        Self {
            id,
            hz,
            asked: None,
            sends: 0,
            acked: None,
            arrived: false,
            fell_back: false,
            last: None,
        }
    }
}

/// The rates asked for, and what became of them.
#[derive(Debug)]
pub(crate) struct RateRequests {
    wanted: Vec<Wanted>,
    target: Option<(u8, u8)>,
    /// The target's last HEARTBEAT.
    target_heard: Option<Instant>,
    seq: u8,
}

impl RateRequests {
    /// Rates to ask for: (message id, Hz).
    pub(crate) fn new(rates: &[(u32, f32)]) -> Self {
        Self {
            wanted: rates.iter().map(|&(id, hz)| Wanted::new(id, hz)).collect(),
            target: None,
            target_heard: None,
            seq: 0,
        }
    }

    /// Takes one frame seen on the link; returns frames to send.
    pub(crate) fn on_frame(
        &mut self,
        now: Instant,
        sysid: u8,
        compid: u8,
        msg_id: u32,
        payload: &[u8],
    ) -> Vec<FrameBuf> {
        if self.wanted.is_empty() || (sysid, compid) == OWN {
            return Vec::new();
        }
        if self.target.is_none() && msg_id == Heartbeat::ID {
            let hb = Heartbeat::decode(payload);
            if hb.autopilot != MavAutopilot::INVALID {
                self.target = Some((sysid, compid));
                return self.on_tick(now);
            }
        }
        let Some(target) = self.target else {
            return Vec::new();
        };
        if sysid != target.0 {
            return Vec::new();
        }
        if msg_id == Heartbeat::ID && compid == target.1 {
            self.target_heard = Some(now);
        }
        if msg_id == CommandAck::ID {
            let ack = CommandAck::decode(payload);
            if ack.command == MavCmd::SET_MESSAGE_INTERVAL {
                // The ACK does not say which message: the oldest one waiting takes it.
                if let Some(w) = self
                    .wanted
                    .iter_mut()
                    .find(|w| w.asked.is_some() && w.acked.is_none())
                {
                    w.acked = Some(ack.result == MavResult::ACCEPTED);
                }
            }
        }
        for w in &mut self.wanted {
            if w.id == msg_id && w.asked.is_some() {
                w.arrived = true;
                w.last = Some(now);
            }
        }
        Vec::new()
    }

    /// Takes the time; returns frames to send (first requests, resends, fallbacks).
    pub(crate) fn on_tick(&mut self, now: Instant) -> Vec<FrameBuf> {
        let Some(target) = self.target else {
            return Vec::new();
        };
        let mut out = Vec::new();
        let mut seq = self.seq;
        let heard = self.target_heard;
        for w in &mut self.wanted {
            let interval = Duration::from_secs_f32(1.0 / w.hz);
            // It came, then stopped while the vehicle lives on (restarted): ask anew.
            if let Some(last) = w.last {
                let silent = now.saturating_duration_since(last)
                    >= (interval * 5).max(Duration::from_secs(3));
                if silent && heard.is_some_and(|h| h > last) {
                    *w = Wanted::new(w.id, w.hz);
                }
            }
            let resend_due = w.asked.is_none_or(|t| {
                w.sends < 2 && w.acked.is_none() && now >= t + Duration::from_millis(500)
            });
            if resend_due && !w.arrived {
                let command = CommandLong {
                    target_system: target.0,
                    target_component: target.1,
                    command: MavCmd::SET_MESSAGE_INTERVAL,
                    confirmation: w.sends,
                    param1: w.id as f32,
                    param2: interval.as_micros() as f32,
                    ..CommandLong::default()
                };
                out.extend(frame(&mut seq, &MavMessage::CommandLong(command)));
                w.asked.get_or_insert(now);
                w.sends += 1;
                continue;
            }
            let Some(asked) = w.asked else { continue };
            let waited = now.saturating_duration_since(asked)
                >= (interval * 3).max(Duration::from_millis(1500));
            let refused = w.acked == Some(false);
            if !w.arrived && !w.fell_back && (refused || waited) {
                w.fell_back = true;
                if let Some(group) = data_stream_of(w.id) {
                    let r = request_data_stream(Address::new(target.0, target.1), group, w.hz);
                    out.extend(frame(&mut seq, &MavMessage::RequestDataStream(r)));
                }
            }
        }
        self.seq = seq;
        out
    }
}

/// One of our frames, MAVLink 2.
fn frame(seq: &mut u8, message: &MavMessage) -> Option<FrameBuf> {
    let header = FrameHeader {
        version: Version::V2,
        seq: *seq,
        sysid: OWN.0,
        compid: OWN.1,
        signed: false,
    };
    *seq = seq.wrapping_add(1);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let n = match message {
        MavMessage::CommandLong(m) => emit_message(&header, m, &mut buf),
        MavMessage::RequestDataStream(m) => emit_message(&header, m, &mut buf),
        _ => return None,
    }
    .ok()?;
    FrameBuf::new(&buf[..n]).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::common::{Attitude, MavType, RequestDataStream};

    fn heartbeat() -> Vec<u8> {
        let mut p = [0u8; 255];
        let n = Heartbeat {
            r#type: MavType::QUADROTOR,
            autopilot: MavAutopilot::ARDUPILOTMEGA,
            ..Heartbeat::default()
        }
        .encode(&mut p);
        p[..n].to_vec()
    }

    fn ids(frames: &[FrameBuf]) -> Vec<u32> {
        frames
            .iter()
            .map(|f| {
                let b = f.as_bytes();
                u32::from_le_bytes([b[7], b[8], b[9], 0])
            })
            .collect()
    }

    #[test]
    fn asks_after_the_first_heartbeat_then_falls_back_when_nothing_comes() {
        let t0 = Instant::now();
        let mut r = RateRequests::new(&[(Attitude::ID, 10.0)]);
        assert!(r.on_tick(t0).is_empty(), "nobody heard yet");
        let first = r.on_frame(t0, 1, 1, Heartbeat::ID, &heartbeat());
        assert_eq!(ids(&first), [CommandLong::ID]);
        // No ACK: once more after 0.5 s, then nothing more of that kind.
        assert_eq!(
            ids(&r.on_tick(t0 + Duration::from_millis(600))),
            [CommandLong::ID]
        );
        assert!(r.on_tick(t0 + Duration::from_millis(1200)).is_empty());
        // Still no ATTITUDE after 1.5 s: REQUEST_DATA_STREAM, once.
        let fallback = r.on_tick(t0 + Duration::from_millis(1600));
        assert_eq!(ids(&fallback), [RequestDataStream::ID]);
        assert!(r.on_tick(t0 + Duration::from_secs(5)).is_empty());
    }

    #[test]
    fn an_accepted_rate_whose_message_comes_needs_nothing_more() {
        let t0 = Instant::now();
        let mut r = RateRequests::new(&[(Attitude::ID, 10.0)]);
        let _ = r.on_frame(t0, 1, 1, Heartbeat::ID, &heartbeat());
        let mut ack = [0u8; 255];
        let n = CommandAck {
            command: MavCmd::SET_MESSAGE_INTERVAL,
            result: MavResult::ACCEPTED,
            ..CommandAck::default()
        }
        .encode(&mut ack);
        assert!(r.on_frame(t0, 1, 1, CommandAck::ID, &ack[..n]).is_empty());
        assert!(r.on_frame(t0, 1, 1, Attitude::ID, &[0; 28]).is_empty());
        assert!(r.on_tick(t0 + Duration::from_secs(5)).is_empty());
    }

    /// A vehicle that restarts forgets the rate: the message stops while its HEARTBEAT goes
    /// on, and it is asked for again (once per silence, not at every tick).
    #[test]
    fn a_rate_forgotten_by_a_restart_is_asked_for_again() {
        let t0 = Instant::now();
        let s = Duration::from_secs;
        let mut r = RateRequests::new(&[(Attitude::ID, 10.0)]);
        assert_eq!(
            ids(&r.on_frame(t0, 1, 1, Heartbeat::ID, &heartbeat())),
            [CommandLong::ID]
        );
        assert!(r.on_frame(t0, 1, 1, Attitude::ID, &[0; 28]).is_empty());
        // Only heartbeats from now on; within 3 s nothing is asked.
        for i in 1..=2 {
            let _ = r.on_frame(t0 + s(i), 1, 1, Heartbeat::ID, &heartbeat());
            assert!(r.on_tick(t0 + s(i)).is_empty());
        }
        let _ = r.on_frame(t0 + s(3), 1, 1, Heartbeat::ID, &heartbeat());
        assert_eq!(ids(&r.on_tick(t0 + s(3))), [CommandLong::ID]);
        assert!(r.on_tick(t0 + s(3)).is_empty(), "asked once");
        // It comes again: nothing more.
        assert!(
            r.on_frame(t0 + s(4), 1, 1, Attitude::ID, &[0; 28])
                .is_empty()
        );
        assert!(r.on_tick(t0 + s(5)).is_empty());
        // A vehicle gone quiet altogether (no HEARTBEAT) is not asked.
        assert!(r.on_tick(t0 + s(60)).is_empty());
    }
}
