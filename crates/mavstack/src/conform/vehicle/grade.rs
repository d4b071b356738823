//! The vehicle role's grading: what the run saw ([`Facts`]) against each rule, one verdict
//! with its evidence per rule.

use std::collections::BTreeMap;

use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, Heartbeat, MavCmd, MavProtocolCapability, MavResult,
    ProtocolVersion, RadioStatus,
};

use super::super::wire::{Seen, Wire, protocol_version};
use super::super::{Rule, Verdict, secs, version_name};
use super::{Request, is_protocol_version};
use crate::message_name;

/// RADIO_STATUS frames within this of our first MAVLink 2 frame may have been on their way.
const RADIO_GRACE: f64 = 0.3;

/// A handshake answer in MAVLink 2 on a MAVLink 1 link is the documented exception.
fn is_handshake_answer(f: &Seen) -> bool {
    if f.is::<ProtocolVersion>() {
        return true;
    }
    f.is::<CommandAck>()
        && matches!(
            f.decode::<CommandAck>().command,
            MavCmd::REQUEST_MESSAGE | MavCmd::REQUEST_PROTOCOL_VERSION
        )
}

/// The vehicle role's rules, in the table's order.
pub(in crate::conform) const VEHICLE_RULES: [Rule; 16] = [
    Rule::Heartbeat,
    Rule::Crc,
    Rule::Sequence,
    Rule::Truncation,
    Rule::CapabilityFlag,
    Rule::SwitchOnV2,
    Rule::HandshakeAnswer,
    Rule::ProtocolVersionSupported,
    Rule::HandshakeV2Framing,
    Rule::Handshake519,
    Rule::HandshakeCommandInt,
    Rule::NackWithoutV2,
    Rule::ProtocolVersionValues,
    Rule::NoMixing,
    Rule::SignedFromStart,
    Rule::RadioV2AfterFirstV2,
];

/// What the run saw, for grading.
pub(super) struct Facts<'a> {
    pub(super) wire: &'a Wire,
    pub(super) target: (u8, u8),
    pub(super) keyed: bool,
    /// Our first MAVLink 2 frame.
    pub(super) t_v2: f64,
    pub(super) requests: Vec<Request>,
    pub(super) av_requested: Vec<(f64, Version)>,
}

/// What one handshake request got back.
#[derive(Debug, Default)]
struct Answer<'a> {
    ack: Option<(&'a Seen, CommandAck)>,
    protocol_version: Option<&'a Seen>,
}

impl Answer<'_> {
    fn genuine(&self) -> bool {
        self.protocol_version
            .is_some_and(|f| !f.v1_protocol_version && f.version == Version::V2)
    }

    fn nack(&self) -> bool {
        self.ack
            .is_some_and(|(_, a)| !matches!(a.result, MavResult::ACCEPTED | MavResult::IN_PROGRESS))
    }

    fn describe(&self) -> String {
        let mut parts = Vec::new();
        if let Some((f, a)) = &self.ack {
            parts.push(format!(
                "COMMAND_ACK {} in {} at {}",
                result_name(a.result),
                version_name(f.version),
                secs(f.t)
            ));
        }
        if let Some(f) = self.protocol_version {
            parts.push(if f.v1_protocol_version {
                format!(
                    "PROTOCOL_VERSION in a MAVLink 1 frame (msgid 44, CRC_EXTRA 217) at {}",
                    secs(f.t)
                )
            } else {
                format!(
                    "PROTOCOL_VERSION {} in {} at {}",
                    protocol_version(f).version,
                    version_name(f.version),
                    secs(f.t)
                )
            });
        }
        if parts.is_empty() {
            "nothing".to_owned()
        } else {
            parts.join(", ")
        }
    }
}

fn result_name(r: MavResult) -> &'static str {
    r.name()
        .and_then(|n| n.strip_prefix("MAV_RESULT_"))
        .unwrap_or("UNKNOWN")
}

impl Facts<'_> {
    fn mine(&self) -> impl Iterator<Item = &Seen> {
        let target = self.target;
        self.wire.frames.iter().filter(move |f| f.from(target))
    }

    /// The answers to request `i`, in its window (until the next request).
    fn answer(&self, i: usize) -> Answer<'_> {
        let Some(r) = self.requests.get(i) else {
            return Answer::default();
        };
        let end = self.requests.get(i + 1).map_or_else(
            || self.av_requested.first().map_or(f64::INFINITY, |a| a.0),
            |n| n.sent,
        );
        let mut a = Answer::default();
        for f in self.mine().filter(|f| f.t > r.sent && f.t <= end) {
            if is_protocol_version(f) {
                a.protocol_version.get_or_insert(f);
            } else if f.is::<CommandAck>() {
                let ack = f.decode::<CommandAck>();
                if ack.command == r.command && a.ack.is_none() {
                    a.ack = Some((f, ack));
                }
            }
        }
        a
    }

    /// When the link became MAVLink 2: the system's first MAVLink 2 frame that is not a
    /// handshake answer.
    fn link_v2_at(&self) -> Option<f64> {
        self.mine()
            .find(|f| f.version == Version::V2 && !is_handshake_answer(f))
            .map(|f| f.t)
    }

    /// Whether the system has MAVLink 2, by behaviour.
    fn has_v2(&self) -> bool {
        self.link_v2_at().is_some() || (0..self.requests.len()).any(|i| self.answer(i).genuine())
    }

    fn autopilot_version(&self) -> Option<(&Seen, AutopilotVersion)> {
        let first = self.av_requested.first()?.0;
        self.mine()
            .find(|f| f.t > first && f.is::<AutopilotVersion>())
            .map(|f| (f, f.decode::<AutopilotVersion>()))
    }

    fn flag(&self) -> Option<bool> {
        self.autopilot_version()
            .map(|(_, av)| av.capabilities.0 & MavProtocolCapability::MAVLINK2.0 != 0)
    }

    pub(super) fn grade(&self) -> Vec<Verdict> {
        VEHICLE_RULES
            .iter()
            .map(|&rule| match rule {
                Rule::Heartbeat => self.heartbeat(),
                Rule::Crc => self.crc(),
                Rule::Sequence => self.sequence(),
                Rule::Truncation => self.truncation(),
                Rule::CapabilityFlag => self.capability_flag(),
                Rule::SwitchOnV2 => self.switch_on_v2(),
                Rule::HandshakeAnswer => self.handshake_answer(),
                Rule::ProtocolVersionSupported => self.protocol_version_supported(),
                Rule::HandshakeV2Framing => self.handshake_v2_framing(),
                Rule::Handshake519 => self.same_way(Rule::Handshake519, 1),
                Rule::HandshakeCommandInt => self.same_way(Rule::HandshakeCommandInt, 2),
                Rule::NackWithoutV2 => self.nack_without_v2(),
                Rule::ProtocolVersionValues => self.protocol_version_values(),
                Rule::NoMixing => self.no_mixing(),
                Rule::SignedFromStart => self.signed_from_start(),
                _ => self.radio(),
            })
            .collect()
    }

    fn heartbeat(&self) -> Verdict {
        let hbs: Vec<&Seen> = self.mine().filter(|f| f.is::<Heartbeat>()).collect();
        let rule = Rule::Heartbeat;
        let (Some(first), Some(last)) = (hbs.first(), hbs.last()) else {
            return Verdict::fail(rule, "no HEARTBEAT");
        };
        if hbs.len() < 2 {
            return Verdict::fail(
                rule,
                format!(
                    "only 1 HEARTBEAT in {} of watching",
                    secs(self.end() - first.t)
                ),
            );
        }
        let mean = (last.t - first.t) / (hbs.len() - 1) as f64;
        let wrong: Vec<u8> = hbs
            .iter()
            .map(|f| f.decode::<Heartbeat>().mavlink_version)
            .filter(|&v| v != 3)
            .collect();
        let ok = (0.5..=2.0).contains(&mean) && wrong.is_empty();
        let mut evidence = format!("{} HEARTBEATs, mean interval {mean:.2} s", hbs.len());
        if let Some(v) = wrong.first() {
            evidence.push_str(&format!(
                ", {} with mavlink_version {v} (expected 3)",
                wrong.len()
            ));
        } else {
            evidence.push_str(", mavlink_version 3");
        }
        if !(0.5..=2.0).contains(&mean) {
            evidence.push_str(" (expected 0.5–2 s)");
        }
        Verdict::check(rule, ok, evidence)
    }

    fn end(&self) -> f64 {
        self.wire.frames.last().map_or(0.0, |f| f.t)
    }

    fn crc(&self) -> Verdict {
        let n = self.wire.frames.len();
        let unchecked = self.wire.frames.iter().filter(|f| f.unchecked).count();
        let rule = Rule::Crc;
        if self.wire.bad_crc == 0 {
            let mut e = format!("{n} frames, every checksum good");
            if unchecked > 0 {
                e.push_str(&format!(
                    " ({unchecked} of ids the dialect does not define, unchecked)"
                ));
            }
            Verdict::pass(rule, e)
        } else {
            Verdict::fail(
                rule,
                format!(
                    "{} frames failed their checksum (the first at {}), {n} passed",
                    self.wire.bad_crc,
                    secs(self.wire.first_bad_crc.unwrap_or(0.0))
                ),
            )
        }
    }

    fn sequence(&self) -> Verdict {
        let mut last: BTreeMap<(u8, u8), u8> = BTreeMap::new();
        let (mut steps, mut gaps) = (0usize, 0usize);
        let mut first_gap = None;
        for f in self.wire.frames.iter().filter(|f| f.sysid == self.target.0) {
            if let Some(prev) = last.insert((f.sysid, f.compid), f.seq) {
                steps += 1;
                if f.seq != prev.wrapping_add(1) {
                    gaps += 1;
                    first_gap.get_or_insert((f.sysid, f.compid, prev, f.seq, f.t));
                }
            }
        }
        let rule = Rule::Sequence;
        if steps == 0 {
            return Verdict::na(rule, "fewer than two frames from any component");
        }
        match first_gap {
            None => Verdict::pass(rule, format!("seq rose by one in {steps} of {steps} steps")),
            Some((sys, comp, a, b, t)) => Verdict::fail(
                rule,
                format!(
                    "{gaps} of {steps} steps skip or repeat (first: {sys}/{comp} seq {a} → {b} at {})",
                    secs(t)
                ),
            ),
        }
    }

    fn truncation(&self) -> Verdict {
        let v2: Vec<&Seen> = self
            .wire
            .frames
            .iter()
            .filter(|f| f.sysid == self.target.0 && f.version == Version::V2)
            .collect();
        let rule = Rule::Truncation;
        if v2.is_empty() {
            return Verdict::na(rule, "no MAVLink 2 frame");
        }
        let bad: Vec<&&Seen> = v2
            .iter()
            .filter(|f| {
                f.payload.is_empty() || (f.payload.len() > 1 && f.payload.last() == Some(&0))
            })
            .collect();
        match bad.first() {
            None => Verdict::pass(
                rule,
                format!(
                    "{} MAVLink 2 frames, none with a trailing zero byte",
                    v2.len()
                ),
            ),
            Some(f) => Verdict::fail(
                rule,
                format!(
                    "{} of {} MAVLink 2 frames end in a zero byte (first: {} seq {} at {}, {} payload bytes)",
                    bad.len(),
                    v2.len(),
                    message_name(f.msg_id),
                    f.seq,
                    secs(f.t),
                    f.payload.len()
                ),
            ),
        }
    }

    /// How the system shows MAVLink 2, in words.
    fn v2_behaviour(&self) -> String {
        if let Some(f) = self
            .mine()
            .find(|f| f.version == Version::V2 && !is_handshake_answer(f))
        {
            return format!(
                "it sends MAVLink 2 ({} at {})",
                message_name(f.msg_id),
                secs(f.t)
            );
        }
        if (0..self.requests.len()).any(|i| self.answer(i).genuine()) {
            return "it answers the handshake in MAVLink 2".to_owned();
        }
        "no MAVLink 2 frame and no MAVLink 2 answer to the handshake".to_owned()
    }

    fn capability_flag(&self) -> Verdict {
        let rule = Rule::CapabilityFlag;
        let Some((f, _)) = self.autopilot_version() else {
            let asked: Vec<String> = self
                .av_requested
                .iter()
                .map(|(t, v)| format!("{} at {}", version_name(*v), secs(*t)))
                .collect();
            return Verdict::fail(
                rule,
                format!(
                    "no AUTOPILOT_VERSION for REQUEST_MESSAGE(148) (asked in {})",
                    asked.join(" and ")
                ),
            );
        };
        let flag = self.flag().unwrap_or(false);
        let has = self.has_v2();
        Verdict::check(
            rule,
            flag == has,
            format!(
                "MAVLINK2 {} in AUTOPILOT_VERSION ({} at {}); {}",
                if flag { "set" } else { "clear" },
                version_name(f.version),
                secs(f.t),
                self.v2_behaviour()
            ),
        )
    }

    fn switch_on_v2(&self) -> Verdict {
        let rule = Rule::SwitchOnV2;
        let Some(first) = self.mine().next() else {
            return Verdict::na(rule, "no frame");
        };
        if first.version == Version::V2 {
            return Verdict::na(
                rule,
                format!(
                    "started in MAVLink 2 ({} at {})",
                    message_name(first.msg_id),
                    secs(first.t)
                ),
            );
        }
        if !self.has_v2() && self.flag() != Some(true) {
            return Verdict::na(rule, format!("no MAVLink 2: {}", self.v2_behaviour()));
        }
        let until = self.requests.first().map_or(f64::INFINITY, |r| r.sent);
        let hbs_v1 = self
            .mine()
            .filter(|f| f.t > self.t_v2 && f.t <= until && f.is::<Heartbeat>())
            .filter(|f| f.version == Version::V1)
            .count();
        match self.link_v2_at() {
            Some(t) if t > self.t_v2 && t <= until => Verdict::pass(
                rule,
                format!(
                    "MAVLink 1 until our MAVLink 2 HEARTBEAT at {}, MAVLink 2 from {} ({:.2} s later)",
                    secs(self.t_v2),
                    secs(t),
                    t - self.t_v2
                ),
            ),
            Some(t) if t <= self.t_v2 => Verdict::na(
                rule,
                format!(
                    "MAVLink 2 from {} before any MAVLink 2 frame of ours",
                    secs(t)
                ),
            ),
            other => Verdict::fail(
                rule,
                format!(
                    "still MAVLink 1 after our MAVLink 2 HEARTBEAT at {}: {hbs_v1} HEARTBEAT(s) in MAVLink 1 until the handshake at {}{}",
                    secs(self.t_v2),
                    secs(until),
                    other.map_or(String::new(), |t| format!(
                        "; MAVLink 2 only from {}",
                        secs(t)
                    ))
                ),
            ),
        }
    }

    fn handshake_answer(&self) -> Verdict {
        let rule = Rule::HandshakeAnswer;
        let a = self.answer(0);
        let Some(r) = self.requests.first() else {
            return Verdict::na(rule, "no request sent");
        };
        if !self.has_v2() && a.protocol_version.is_none() && self.flag() != Some(true) {
            return Verdict::na(rule, format!("no MAVLink 2: {}", self.v2_behaviour()));
        }
        let asked = format!(
            "{} in MAVLink 2 at {} ({} sent): {}",
            r.what,
            secs(r.sent),
            r.attempts,
            a.describe()
        );
        if a.protocol_version.is_some() {
            return Verdict::pass(rule, asked);
        }
        // The documents' fallback: a system that refuses 300 proves MAVLink 2 by answering a
        // request for another message it emits in MAVLink 2 framing.
        match (a.nack(), self.fallback_answer()) {
            (true, Some(f)) => Verdict::pass(
                rule,
                format!(
                    "{asked}; then REQUEST_MESSAGE(148) in MAVLink 2 answered with AUTOPILOT_VERSION in MAVLink 2 at {} (the documents' fallback)",
                    secs(f.t)
                ),
            ),
            (true, None) => Verdict::fail(
                rule,
                format!(
                    "{asked}; and no AUTOPILOT_VERSION in MAVLink 2 for REQUEST_MESSAGE(148) in MAVLink 2"
                ),
            ),
            (false, _) => Verdict::fail(rule, asked),
        }
    }

    /// AUTOPILOT_VERSION in MAVLink 2 framing after our MAVLink 2 request for it.
    fn fallback_answer(&self) -> Option<&Seen> {
        let (t, v) = *self.av_requested.first()?;
        if v != Version::V2 {
            return None;
        }
        self.mine()
            .find(|f| f.t > t && f.is::<AutopilotVersion>() && f.version == Version::V2)
    }

    fn protocol_version_supported(&self) -> Verdict {
        let rule = Rule::ProtocolVersionSupported;
        let answers: Vec<(usize, Answer<'_>)> = (0..self.requests.len())
            .map(|i| (i, self.answer(i)))
            .collect();
        if answers.is_empty() {
            return Verdict::na(rule, "no request sent");
        }
        match answers.iter().find(|(_, a)| a.protocol_version.is_some()) {
            Some((i, a)) => Verdict::pass(
                rule,
                format!("{}: {}", self.requests[*i].what, a.describe()),
            ),
            None => Verdict::fail(
                rule,
                answers
                    .iter()
                    .map(|(i, a)| format!("{} → {}", self.requests[*i].what, a.describe()))
                    .collect::<Vec<_>>()
                    .join("; "),
            ),
        }
    }

    fn handshake_v2_framing(&self) -> Verdict {
        let rule = Rule::HandshakeV2Framing;
        let answers: Vec<(usize, Answer<'_>)> = (0..self.requests.len())
            .map(|i| (i, self.answer(i)))
            .collect();
        if let Some((i, a)) = answers
            .iter()
            .find(|(_, a)| a.protocol_version.is_some_and(|f| f.v1_protocol_version))
        {
            return Verdict::fail(
                rule,
                format!("{}: {}", self.requests[*i].what, a.describe()),
            );
        }
        let accepted_only = answers.iter().find(|(_, a)| {
            a.ack
                .is_some_and(|(_, ack)| ack.result == MavResult::ACCEPTED)
                && !a.genuine()
        });
        if let Some((i, a)) = accepted_only {
            return Verdict::fail(
                rule,
                format!(
                    "{}: {} without a MAVLink 2 PROTOCOL_VERSION",
                    self.requests[*i].what,
                    a.describe()
                ),
            );
        }
        match answers.iter().find(|(_, a)| a.genuine()) {
            Some((i, a)) => Verdict::pass(
                rule,
                format!(
                    "{}: {} after {} request(s)",
                    self.requests[*i].what,
                    a.describe(),
                    self.requests[*i].attempts
                ),
            ),
            None => Verdict::na(rule, "no PROTOCOL_VERSION and no ACCEPTED answer"),
        }
    }

    fn same_way(&self, rule: Rule, i: usize) -> Verdict {
        let Some(r) = self.requests.get(i) else {
            return Verdict::na(rule, "not sent");
        };
        let a = self.answer(i);
        let has = self.has_v2();
        // A system that refuses PROTOCOL_VERSION everywhere (ArduPilot) answers the other
        // forms the same way when it refuses them too.
        let refuses_300 = has && self.answer(0).nack() && self.answer(0).protocol_version.is_none();
        let ok = if refuses_300 {
            a.nack() || a.genuine()
        } else if has {
            a.genuine()
        } else {
            a.nack()
        };
        let expected = match (refuses_300, has) {
            (true, _) => "a NACK, as for REQUEST_MESSAGE(300), or PROTOCOL_VERSION in MAVLink 2",
            (false, true) => "PROTOCOL_VERSION in MAVLink 2",
            (false, false) => "a NACK",
        };
        Verdict::check(
            rule,
            ok,
            format!(
                "{} at {}: {} (expected {expected}, as the system {})",
                r.what,
                secs(r.sent),
                a.describe(),
                if has {
                    "has MAVLink 2"
                } else {
                    "has no MAVLink 2"
                }
            ),
        )
    }

    fn nack_without_v2(&self) -> Verdict {
        let rule = Rule::NackWithoutV2;
        if self.has_v2() || self.answer(0).protocol_version.is_some() {
            return Verdict::na(
                rule,
                format!("the system has MAVLink 2: {}", self.v2_behaviour()),
            );
        }
        let answers: Vec<Answer<'_>> = (0..self.requests.len()).map(|i| self.answer(i)).collect();
        match answers.iter().position(Answer::nack) {
            Some(i) => Verdict::pass(
                rule,
                format!("{}: {}", self.requests[i].what, answers[i].describe()),
            ),
            None => Verdict::fail(
                rule,
                format!(
                    "no NACK for any of {} handshake requests: {}",
                    self.requests.len(),
                    answers
                        .iter()
                        .zip(&self.requests)
                        .map(|(a, r)| format!("{} → {}", r.what, a.describe()))
                        .collect::<Vec<_>>()
                        .join("; ")
                ),
            ),
        }
    }

    fn protocol_version_values(&self) -> Verdict {
        let rule = Rule::ProtocolVersionValues;
        let Some(f) = (0..self.requests.len()).find_map(|i| self.answer(i).protocol_version) else {
            return Verdict::na(rule, "no PROTOCOL_VERSION");
        };
        let pv = protocol_version(f);
        let ok =
            pv.min_version <= pv.version && pv.version <= pv.max_version && pv.max_version >= 200;
        Verdict::check(
            rule,
            ok,
            format!(
                "version {}, min {}, max {}",
                pv.version, pv.min_version, pv.max_version
            ),
        )
    }

    fn no_mixing(&self) -> Verdict {
        let rule = Rule::NoMixing;
        let mut problems = Vec::new();
        if let Some(t) = self.link_v2_at() {
            // The C library's MAVLink 1 PROTOCOL_VERSION is handshake_v2_framing's failure.
            let after: Vec<&Seen> = self
                .mine()
                .filter(|f| f.t > t && !f.v1_protocol_version)
                .collect();
            let v1: Vec<&&Seen> = after.iter().filter(|f| f.version == Version::V1).collect();
            if let Some(f) = v1.first() {
                problems.push(format!(
                    "{} of {} frames in MAVLink 1 after the switch at {} (first: {} at {})",
                    v1.len(),
                    after.len(),
                    secs(t),
                    message_name(f.msg_id),
                    secs(f.t)
                ));
            }
        }
        if let Some(s) = self.mine().find(|f| f.signed) {
            let after: Vec<&Seen> = self.mine().filter(|f| f.t > s.t).collect();
            let unsigned: Vec<&&Seen> = after.iter().filter(|f| !f.signed).collect();
            if let Some(f) = unsigned.first() {
                problems.push(format!(
                    "{} of {} frames unsigned after the first signed one at {} (first: {} at {})",
                    unsigned.len(),
                    after.len(),
                    secs(s.t),
                    message_name(f.msg_id),
                    secs(f.t)
                ));
            }
        }
        if !problems.is_empty() {
            return Verdict::fail(rule, problems.join("; "));
        }
        match self.link_v2_at() {
            Some(t) => {
                let n = self.mine().filter(|f| f.t > t).count();
                Verdict::pass(
                    rule,
                    format!(
                        "all {n} frames after the switch at {} in MAVLink 2",
                        secs(t)
                    ),
                )
            }
            None => Verdict::pass(rule, "the link stayed MAVLink 1 (handshake answers aside)"),
        }
    }

    fn signed_from_start(&self) -> Verdict {
        let rule = Rule::SignedFromStart;
        let all: Vec<&Seen> = self.mine().collect();
        if self.keyed {
            let bad: Vec<&&Seen> = all.iter().filter(|f| f.verified != Some(true)).collect();
            return match bad.first() {
                None => Verdict::pass(
                    rule,
                    format!("all {} frames signed and verified with the key", all.len()),
                ),
                Some(f) => Verdict::fail(
                    rule,
                    format!(
                        "{} of {} frames {} (first: {} at {}{})",
                        bad.len(),
                        all.len(),
                        if f.signed {
                            "do not verify with the key"
                        } else {
                            "unsigned or not verified"
                        },
                        message_name(f.msg_id),
                        secs(f.t),
                        all.iter().find(|g| g.verified == Some(true)).map_or(
                            String::new(),
                            |g| format!("; the first verified one at {}", secs(g.t))
                        )
                    ),
                ),
            };
        }
        let Some(signed) = all.iter().find(|f| f.signed) else {
            return Verdict::na(rule, "the system does not sign");
        };
        let before = all.iter().filter(|f| f.t < signed.t).count();
        Verdict::check(
            rule,
            before == 0,
            format!(
                "the first signed frame at {}, after {before} unsigned ones",
                secs(signed.t)
            ),
        )
    }

    fn radio(&self) -> Verdict {
        let rule = Rule::RadioV2AfterFirstV2;
        let statuses: Vec<&Seen> = self
            .wire
            .frames
            .iter()
            .filter(|f| f.is::<RadioStatus>())
            .collect();
        let Some(source) = statuses.first().map(|f| (f.sysid, f.compid)) else {
            return Verdict::na(
                rule,
                "no RADIO_STATUS: no semi-transparent radio in the path",
            );
        };
        let from = |f: &&&Seen| (f.sysid, f.compid) == source;
        let before: Vec<&&Seen> = statuses
            .iter()
            .filter(from)
            .filter(|f| f.t < self.t_v2)
            .collect();
        let before_v1 = before.iter().filter(|f| f.version == Version::V1).count();
        let after: Vec<&&Seen> = statuses
            .iter()
            .filter(from)
            .filter(|f| f.t > self.t_v2 + RADIO_GRACE)
            .collect();
        let v1 = after.iter().filter(|f| f.version == Version::V1).count();
        let who = format!("RADIO_STATUS from {}/{}", source.0, source.1);
        if after.is_empty() {
            return Verdict::na(
                rule,
                format!(
                    "{who}: none after our first MAVLink 2 frame at {}",
                    secs(self.t_v2)
                ),
            );
        }
        Verdict::check(
            rule,
            v1 == 0,
            format!(
                "{who}: {} before our first MAVLink 2 frame at {} ({before_v1} in MAVLink 1), then {v1} of {} in MAVLink 1",
                before.len(),
                secs(self.t_v2),
                after.len()
            ),
        )
    }
}

/// Conform's wire reader and every vehicle-role grader fed `data` as input on two links
/// (the first byte sets the piece size and whether they alternate links; pieces 100 ms
/// apart), our MAVLink 2 frame and the
/// three handshake requests after pieces 0, 1 and 2, AUTOPILOT_VERSION after piece 3.
#[cfg(feature = "fuzzing")]
pub(in crate::conform) fn fuzz_grade(data: &[u8]) -> Vec<Verdict> {
    use mavstack_core::MessageTable;
    use mavstack_core::signing::SecretKey;
    use mavstack_dialects::common::MavMessage;

    use crate::router::LinkId;

    let key = SecretKey::new([7; 32]);
    let mut wire = Wire::new(
        mavstack_core::time::Instant::ZERO,
        MessageTable::of::<MavMessage>(),
        Some(key),
    );
    let (first, rest) = data.split_first().map_or((1, data), |(&p, r)| (p, r));
    // The low 7 bits: the piece size; the top bit: pieces alternate between two links.
    let piece = usize::from(first & 0x7f).max(1);
    for (i, chunk) in rest.chunks(piece).enumerate() {
        let at = mavstack_core::time::Instant::from_millis(i as u64 * 100);
        let link = if first & 0x80 != 0 { i % 2 } else { 0 };
        wire.feed(LinkId::new(link as u32), at, chunk, false);
    }
    wire.finish(mavstack_core::time::Instant::from_millis(
        (rest.len() / piece) as u64 * 100,
    ));
    let target = wire.frames.first().map_or((1, 1), |f| (f.sysid, f.compid));
    let request = |what, command, sent| Request {
        what,
        command,
        sent,
        attempts: 1,
    };
    let facts = Facts {
        wire: &wire,
        target,
        keyed: true,
        t_v2: 0.05,
        requests: vec![
            request("300", MavCmd::REQUEST_MESSAGE, 0.05),
            request("519", MavCmd::REQUEST_PROTOCOL_VERSION, 0.15),
            request("300 int", MavCmd::REQUEST_MESSAGE, 0.25),
        ],
        av_requested: vec![(0.35, Version::V2)],
    };
    facts.grade()
}
