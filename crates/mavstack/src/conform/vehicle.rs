//! The vehicle role: conform plays a ground station and grades the vehicle it finds.
//!
//! The run (requests sent, the wire watched) is here; the rules graded against what it saw
//! are in `grade`.

use core::time::Duration;

use mavstack_core::signing::{self, SecretKey};
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit_message};
use mavstack_core::{Message, MessageTable};
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandInt, CommandLong, Heartbeat, MavAutopilot, MavCmd,
    MavFrame, MavMessage, MavState, MavType, ProtocolVersion,
};
use mavstack_transport::clock;

use super::wire::{Seen, Wire};
use super::{Report, Role, Rule, Verdict};
use crate::router::LinkId;
use crate::{NodeHandle, TapSubscription};

mod grade;

use grade::Facts;
pub(super) use grade::VEHICLE_RULES;
#[cfg(feature = "fuzzing")]
pub(super) use grade::fuzz_grade;

/// Settings of [`grade_vehicle`].
#[derive(Clone, Debug)]
pub struct VehicleOptions {
    /// How long to wait for the first HEARTBEAT (default 10 s).
    pub timeout: Duration,
    /// Sign every frame with this key, and require every frame of the vehicle to verify
    /// with it from the first (for systems that accept only signed frames).
    pub key: Option<SecretKey>,
    /// The signing link id (default 0).
    pub link_id: u8,
    /// The dialect whose CRC_EXTRA the checksums are checked with (default `common`).
    pub dialect: MessageTable,
    /// The ground station's own (sysid, compid) (default 255/190).
    pub own: (u8, u8),
}

impl Default for VehicleOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(10),
            key: None,
            link_id: 0,
            dialect: MessageTable::of::<MavMessage>(),
            own: (255, 190),
        }
    }
}

/// How long the start version is watched.
const WATCH_START: f64 = 2.0;
/// How long the switch is waited for after our MAVLink 2 frame.
const WATCH_SWITCH: f64 = 2.0;
/// How long one handshake request waits for its answer before it is sent again, once.
const WAIT_ANSWER: f64 = 1.2;
/// How long AUTOPILOT_VERSION is waited for.
const WAIT_AUTOPILOT_VERSION: f64 = 1.5;

/// One handshake request sent, with the window its answers are looked for in.
#[derive(Clone, Copy, Debug)]
struct Request {
    what: &'static str,
    command: MavCmd,
    sent: f64,
    attempts: u8,
}

/// The ground station's side of the link: crafts and sends frames, reads the tap.
struct Session<'a> {
    node: &'a NodeHandle,
    tap: TapSubscription,
    wire: Wire,
    options: &'a VehicleOptions,
    links: Vec<LinkId>,
    next_link_scan: f64,
    seq: u8,
    timestamp: u64,
    /// Our HEARTBEAT's framing.
    heartbeat_version: Version,
    next_heartbeat: f64,
    /// When our first MAVLink 2 frame went out.
    first_v2_sent: Option<f64>,
}

impl Session<'_> {
    fn now(&self) -> f64 {
        self.wire.secs(clock::now())
    }

    /// Frames `message` in `version` (signed MAVLink 2 with a key) and writes it on every
    /// link to the vehicle. Returns when it went out.
    async fn send<M: Message>(&mut self, version: Version, message: &M) -> f64 {
        let version = if self.options.key.is_some() {
            Version::V2
        } else {
            version
        };
        let header = FrameHeader {
            version,
            seq: self.seq,
            sysid: self.options.own.0,
            compid: self.options.own.1,
            signed: self.options.key.is_some(),
        };
        self.seq = self.seq.wrapping_add(1);
        let mut buf = [0u8; MAX_FRAME_LEN];
        let Ok(mut len) = emit_message(&header, message, &mut buf) else {
            return self.now();
        };
        if let Some(key) = &self.options.key {
            let now = signing::timestamp_from_unix_micros(clock::now().as_micros());
            self.timestamp = now.max(self.timestamp + 1);
            match signing::append_signature(
                &mut buf,
                len,
                self.options.link_id,
                self.timestamp,
                key,
            ) {
                Ok(n) => len = n,
                Err(_) => return self.now(),
            }
        }
        // Stamped before it goes: the answer may be read before this task runs again.
        let t = self.now();
        for &link in &self.links {
            let _ = self.node.send_bytes(link, &buf[..len]).await;
        }
        if version == Version::V2 {
            self.first_v2_sent.get_or_insert(t);
        }
        t
    }

    async fn heartbeat(&mut self) {
        let version = self.heartbeat_version;
        self.send(version, &gcs_heartbeat()).await;
    }

    /// Reads the wire until `until` (seconds since the start) or until `done` says so,
    /// sending our HEARTBEAT each second. Returns whether `done` said so.
    async fn pump(&mut self, until: f64, mut done: impl FnMut(&Wire) -> bool) -> bool {
        loop {
            let now = self.now();
            if now >= self.next_link_scan {
                self.next_link_scan = now + 0.5;
                if let Some(report) = self.node.report().await {
                    for id in report.links.iter().filter_map(|l| l.link_id) {
                        if !self.links.contains(&id) {
                            self.links.push(id);
                        }
                    }
                }
            }
            if now >= self.next_heartbeat {
                self.next_heartbeat = now + 1.0;
                self.heartbeat().await;
            }
            if done(&self.wire) {
                return true;
            }
            if now >= until {
                return false;
            }
            let wake = until.min(self.next_heartbeat).min(self.next_link_scan);
            let wait = Duration::from_secs_f64((wake - now).max(0.0));
            if let Ok(Some(t)) = tokio::time::timeout(wait, self.tap.recv()).await {
                if !self.links.contains(&t.link_id) {
                    self.links.push(t.link_id);
                }
                self.wire.feed(t.link_id, t.at, &t.bytes, t.datagram);
            }
        }
    }
}

/// Runs the vehicle role on `node` (a node with the link to the vehicle; its own identity
/// and HEARTBEAT are not used: conform writes its frames itself) and grades what it sees.
pub async fn grade_vehicle(node: &NodeHandle, options: &VehicleOptions) -> Report {
    let started = clock::now();
    let tap = node.tap().await;
    let mut s = Session {
        node,
        tap,
        wire: Wire::new(started, options.dialect, options.key.clone()),
        options,
        links: Vec::new(),
        next_link_scan: 0.0,
        seq: 0,
        timestamp: 0,
        heartbeat_version: if options.key.is_some() {
            Version::V2
        } else {
            Version::V1
        },
        next_heartbeat: 0.0,
        first_v2_sent: None,
    };
    let own = options.own;
    let found = |w: &Wire| first_vehicle(w, own).is_some();
    s.pump(options.timeout.as_secs_f64(), found).await;
    let Some(target) = first_vehicle(&s.wire, own) else {
        return Report {
            role: Role::Vehicle,
            target: None,
            verdicts: nobody_heard(options.timeout),
            seconds: s.now(),
        };
    };
    let t_found = s.now();
    // 1. The version it starts in.
    s.pump(t_found + WATCH_START, |_| false).await;
    // 2. Our first MAVLink 2 frame (a HEARTBEAT), and the switch.
    s.heartbeat_version = Version::V2;
    let t_v2 = s.send(Version::V2, &gcs_heartbeat()).await;
    let t_v2 = s.first_v2_sent.unwrap_or(t_v2);
    s.next_heartbeat = s.now() + 1.0;
    let mut switched_at = None;
    s.pump(t_v2 + WATCH_SWITCH, |w| {
        if switched_at.is_none() {
            switched_at = w
                .frames
                .iter()
                .find(|f| f.from(target) && f.t > t_v2 && f.version == Version::V2)
                .map(|f| f.t);
        }
        // Watch a second past the switch for frames that fall back.
        switched_at.is_some_and(|t| w.secs(clock::now()) > t + 1.0)
    })
    .await;
    // 3. The handshake in each form.
    let forms = [
        (
            "REQUEST_MESSAGE(300) as COMMAND_LONG",
            MavCmd::REQUEST_MESSAGE,
            false,
        ),
        (
            "REQUEST_PROTOCOL_VERSION (519) as COMMAND_LONG",
            MavCmd::REQUEST_PROTOCOL_VERSION,
            false,
        ),
        (
            "REQUEST_MESSAGE(300) as COMMAND_INT",
            MavCmd::REQUEST_MESSAGE,
            true,
        ),
    ];
    let mut requests = Vec::new();
    for (what, command, int) in forms {
        let mut request = Request {
            what,
            command,
            sent: 0.0,
            attempts: 0,
        };
        for confirmation in 0..2u8 {
            let t = send_request(&mut s, target, command, int, confirmation).await;
            if confirmation == 0 {
                request.sent = t;
            }
            request.attempts += 1;
            let since = request.sent;
            let answered = s
                .pump(t + WAIT_ANSWER, |w| answered(w, target, command, since))
                .await;
            if answered {
                // A PROTOCOL_VERSION may follow its ACK.
                let t = s.now();
                s.pump(t + 0.3, |w| {
                    w.frames
                        .iter()
                        .any(|f| f.from(target) && f.t > since && is_protocol_version(f))
                })
                .await;
                break;
            }
        }
        requests.push(request);
    }
    // 4. AUTOPILOT_VERSION, in MAVLink 1 too when the system showed no MAVLink 2.
    let t_av = send_av_request(&mut s, target, Version::V2).await;
    let got_av = |w: &Wire| {
        w.frames
            .iter()
            .any(|f| f.from(target) && f.t > t_av && f.is::<AutopilotVersion>())
    };
    let mut av_requested = vec![(t_av, Version::V2)];
    if !s.pump(t_av + WAIT_AUTOPILOT_VERSION, got_av).await && !shows_v2(&s.wire, target) {
        let t_v1 = send_av_request(&mut s, target, Version::V1).await;
        av_requested.push((t_v1, Version::V1));
        s.pump(t_v1 + WAIT_AUTOPILOT_VERSION, |w| {
            w.frames
                .iter()
                .any(|f| f.from(target) && f.t > t_v1 && f.is::<AutopilotVersion>())
        })
        .await;
    }
    s.wire.finish(clock::now());
    let facts = Facts {
        wire: &s.wire,
        target,
        keyed: options.key.is_some(),
        t_v2,
        requests,
        av_requested,
    };
    Report {
        role: Role::Vehicle,
        target: Some(target),
        verdicts: facts.grade(),
        seconds: s.now(),
    }
}

fn gcs_heartbeat() -> Heartbeat {
    Heartbeat {
        r#type: MavType::GCS,
        autopilot: MavAutopilot::INVALID,
        system_status: MavState::ACTIVE,
        mavlink_version: 3,
        ..Heartbeat::default()
    }
}

async fn send_request(
    s: &mut Session<'_>,
    target: (u8, u8),
    command: MavCmd,
    int: bool,
    confirmation: u8,
) -> f64 {
    let param1 = if command == MavCmd::REQUEST_MESSAGE {
        ProtocolVersion::ID as f32
    } else {
        1.0
    };
    if int {
        let c = CommandInt {
            target_system: target.0,
            target_component: target.1,
            frame: MavFrame::GLOBAL,
            command,
            param1,
            ..CommandInt::default()
        };
        s.send(Version::V2, &c).await
    } else {
        let c = CommandLong {
            target_system: target.0,
            target_component: target.1,
            command,
            confirmation,
            param1,
            ..CommandLong::default()
        };
        s.send(Version::V2, &c).await
    }
}

async fn send_av_request(s: &mut Session<'_>, target: (u8, u8), version: Version) -> f64 {
    let c = CommandLong {
        target_system: target.0,
        target_component: target.1,
        command: MavCmd::REQUEST_MESSAGE,
        param1: AutopilotVersion::ID as f32,
        ..CommandLong::default()
    };
    s.send(version, &c).await
}

/// The first system heard sending a HEARTBEAT that is not a ground station's (nor ours).
fn first_vehicle(w: &Wire, own: (u8, u8)) -> Option<(u8, u8)> {
    w.frames
        .iter()
        .filter(|f| f.is::<Heartbeat>() && (f.sysid, f.compid) != own)
        .find(|f| f.decode::<Heartbeat>().r#type != MavType::GCS)
        .map(|f| (f.sysid, f.compid))
}

fn is_protocol_version(f: &Seen) -> bool {
    f.is::<ProtocolVersion>() || f.v1_protocol_version
}

/// Whether `target` answered a `command` sent at `since` (an ACK, or PROTOCOL_VERSION).
fn answered(w: &Wire, target: (u8, u8), command: MavCmd, since: f64) -> bool {
    w.frames.iter().any(|f| {
        f.from(target)
            && f.t > since
            && (is_protocol_version(f)
                || (f.is::<CommandAck>() && f.decode::<CommandAck>().command == command))
    })
}

/// Whether `target` sent a MAVLink 2 frame that is not part of a handshake answer, or
/// answered the handshake in MAVLink 2.
fn shows_v2(w: &Wire, target: (u8, u8)) -> bool {
    w.frames
        .iter()
        .any(|f| f.from(target) && f.version == Version::V2)
}

/// The verdicts when no system was heard: `heartbeat` fails, the rest are n/a.
fn nobody_heard(timeout: Duration) -> Vec<Verdict> {
    VEHICLE_RULES
        .iter()
        .map(|&rule| {
            if rule == Rule::Heartbeat {
                Verdict::fail(
                    rule,
                    format!(
                        "no HEARTBEAT from any vehicle within {:.1} s",
                        timeout.as_secs_f64()
                    ),
                )
            } else {
                Verdict::na(rule, "no system heard")
            }
        })
        .collect()
}
