//! The ground-station role: conform plays a simulated vehicle that answers, NACKs or ignores
//! the handshake, and grades the ground station that connects to it.

use core::time::Duration;

use mavstack_channel::{LinkVersion, ProtocolVersionAnswer};
use mavstack_core::Message as _;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandInt, CommandLong, Heartbeat, MavCmd, ProtocolVersion,
};
use mavstack_router::{LinkRole, ProtocolVersionSupport, VersionMode};
use mavstack_sim::Autopilot;
use mavstack_transport::clock;

use super::wire::{Seen, Wire};
use super::{Report, Role, Rule, Verdict, secs, version_name};
use crate::sim_vehicle::SimVehicle;
use crate::{LinkEvent, LinkSpec, Node, NodeError, message_name};

/// How the simulated vehicle treats the ground station's handshake.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum VehicleMode {
    /// Starts in MAVLink 1, switches on the first MAVLink 2 frame, answers the handshake with
    /// PROTOCOL_VERSION in MAVLink 2, advertises MAVLINK2.
    #[default]
    Answer,
    /// MAVLink 1 only: NACKs the handshake, no MAVLINK2 capability.
    Nack,
    /// MAVLink 1 only: does not answer the handshake at all.
    Silent,
}

impl VehicleMode {
    /// `"answer"`, `"nack"` or `"silent"`.
    #[must_use]
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::Answer => "answer",
            Self::Nack => "nack",
            Self::Silent => "silent",
        }
    }
}

/// Settings of [`grade_ground_station`].
#[derive(Clone, Copy, Debug)]
pub struct GcsOptions {
    /// How long to wait for the ground station's first frame (default 10 s).
    pub timeout: Duration,
    /// How the vehicle treats the handshake.
    pub mode: VehicleMode,
    /// How long the ground station is watched after its first frame (default 10 s; at
    /// least 5 s after its first handshake request, within 14 s).
    pub watch: Duration,
    /// The simulated vehicle's flavour (default ArduPilot).
    pub autopilot: Autopilot,
}

impl Default for GcsOptions {
    fn default() -> Self {
        Self {
            timeout: Duration::from_secs(10),
            mode: VehicleMode::Answer,
            watch: Duration::from_secs(10),
            autopilot: Autopilot::Ardupilot,
        }
    }
}

/// The ground-station role's rules, in the table's order.
const GCS_RULES: [Rule; 4] = [
    Rule::GcsHandshakeV2Framing,
    Rule::GcsSwitch,
    Rule::GcsFallback,
    Rule::GcsNoMixing,
];

/// Plays a vehicle on `link` (given from the vehicle's side, as for `mavstack vehicle`) in
/// `options.mode`, waits for a ground station and grades it.
///
/// # Errors
/// [`NodeError`] if the link cannot be opened.
pub async fn grade_ground_station(
    mut link: LinkSpec,
    options: &GcsOptions,
) -> Result<Report, NodeError> {
    let started = clock::now();
    if options.mode != VehicleMode::Answer {
        link.config.version = VersionMode::Mavlink1;
    }
    let mut config = SimVehicle::config(
        options.autopilot,
        mavstack_sim::params::defaults(options.autopilot),
    );
    config.mavlink2 = options.mode == VehicleMode::Answer;
    let own = (config.own.system, config.own.component);
    // Subscribed before the link is read: a ground station that goes quiet after its first
    // few frames (one that gives up after a NACK) must still be seen.
    let (builder, mut tap) = Node::builder()
        .link(link)
        .role(LinkRole::Vehicle {
            protocol_version: if options.mode == VehicleMode::Silent {
                ProtocolVersionSupport::Silent
            } else {
                ProtocolVersionSupport::Answer
            },
        })
        .with_tap();
    let (builder, mut events) = builder.with_events();
    let vehicle = SimVehicle::start(builder, config).await?;
    let mut wire = Wire::new(
        started,
        mavstack_core::MessageTable::of::<mavstack_dialects::common::MavMessage>(),
        None,
    );
    let mut facts = GcsFacts {
        mode: options.mode,
        gcs: None,
        vehicle_v2_at: None,
        answered_at: None,
    };
    let mut until = options.timeout.as_secs_f64();
    let mut first_request: Option<f64> = None;
    loop {
        let now = wire.secs(clock::now());
        if now >= until {
            break;
        }
        let wait = Duration::from_secs_f64(until - now);
        tokio::select! {
            () = tokio::time::sleep(wait) => {}
            t = tap.recv() => {
                let Some(t) = t else { break };
                wire.feed(t.link_id, t.at, &t.bytes, t.datagram);
            }
            e = events.recv() => {
                let Some(e) = e else { break };
                let t = wire.secs(clock::now());
                match e.kind {
                    LinkEvent::VersionChanged { to, .. } if to != LinkVersion::Mavlink1 => {
                        facts.vehicle_v2_at.get_or_insert(t);
                    }
                    // Silence is no answer: the ground station has nothing to switch on.
                    LinkEvent::ProtocolVersionRequested { answer, .. }
                        if answer != ProtocolVersionAnswer::Ignored =>
                    {
                        facts.answered_at.get_or_insert(t);
                    }
                    _ => {}
                }
            }
        }
        if facts.gcs.is_none() {
            facts.gcs = wire
                .frames
                .iter()
                .find(|f| (f.sysid, f.compid) != own)
                .map(|f| ((f.sysid, f.compid), f.t));
            if let Some((_, t)) = facts.gcs {
                until = t + options.watch.as_secs_f64();
            }
        }
        if first_request.is_none()
            && let Some((gcs, t0)) = facts.gcs
        {
            first_request = wire
                .frames
                .iter()
                .find(|f| f.from(gcs) && is_request(f))
                .map(|f| f.t);
            if let Some(t) = first_request {
                until = until.max(t + 5.0).min(t0 + 14.0);
            }
        }
    }
    let seconds = wire.secs(clock::now());
    let _ = vehicle.shutdown().await;
    let Some((gcs, _)) = facts.gcs else {
        let verdicts = GCS_RULES
            .iter()
            .map(|&rule| {
                Verdict::na(
                    rule,
                    format!(
                        "no ground station heard within {:.1} s",
                        options.timeout.as_secs_f64()
                    ),
                )
            })
            .collect();
        return Ok(Report {
            role: Role::GroundStation,
            target: None,
            verdicts,
            seconds,
        });
    };
    Ok(Report {
        role: Role::GroundStation,
        target: Some(gcs),
        verdicts: facts.grade(&wire, gcs),
        seconds,
    })
}

/// The command and param1 of a COMMAND_LONG or COMMAND_INT, and whether it was an INT.
fn command_of(f: &Seen) -> Option<(MavCmd, f32, bool)> {
    if f.is::<CommandLong>() {
        let c = f.decode::<CommandLong>();
        Some((c.command, c.param1, false))
    } else if f.is::<CommandInt>() {
        let c = f.decode::<CommandInt>();
        Some((c.command, c.param1, true))
    } else {
        None
    }
}

/// A handshake request: REQUEST_MESSAGE(300) or REQUEST_PROTOCOL_VERSION, long or int.
fn is_request(f: &Seen) -> bool {
    command_of(f).is_some_and(|(command, param1, _)| {
        command == MavCmd::REQUEST_PROTOCOL_VERSION
            || (command == MavCmd::REQUEST_MESSAGE && param1 == ProtocolVersion::ID as f32)
    })
}

/// A request for AUTOPILOT_VERSION (REQUEST_MESSAGE(148) or REQUEST_AUTOPILOT_CAPABILITIES).
fn asks_capabilities(f: &Seen) -> bool {
    command_of(f).is_some_and(|(command, param1, _)| {
        command == MavCmd::REQUEST_AUTOPILOT_CAPABILITIES
            || (command == MavCmd::REQUEST_MESSAGE && param1 == AutopilotVersion::ID as f32)
    })
}

fn request_name(f: &Seen) -> String {
    let (command, _, int) = command_of(f).unwrap_or((MavCmd::REQUEST_MESSAGE, 0.0, false));
    format!(
        "{} as {}",
        if command == MavCmd::REQUEST_PROTOCOL_VERSION {
            "REQUEST_PROTOCOL_VERSION"
        } else {
            "REQUEST_MESSAGE(300)"
        },
        if int { "COMMAND_INT" } else { "COMMAND_LONG" }
    )
}

/// What the run saw besides the wire.
struct GcsFacts {
    mode: VehicleMode,
    /// The ground station and when its first frame came.
    gcs: Option<((u8, u8), f64)>,
    /// When the vehicle's link went to MAVLink 2 (its frames MAVLink 2 from then on).
    vehicle_v2_at: Option<f64>,
    /// When the vehicle answered (or NACKed) a handshake request.
    answered_at: Option<f64>,
}

impl GcsFacts {
    fn grade(&self, wire: &Wire, gcs: (u8, u8)) -> Vec<Verdict> {
        let frames: Vec<&Seen> = wire.frames.iter().filter(|f| f.from(gcs)).collect();
        GCS_RULES
            .iter()
            .map(|&rule| match rule {
                Rule::GcsHandshakeV2Framing => Self::request_framing(&frames),
                Rule::GcsSwitch => self.switch(&frames),
                Rule::GcsFallback => self.fallback(&frames),
                _ => self.no_mixing(&frames),
            })
            .collect()
    }

    fn request_framing(frames: &[&Seen]) -> Verdict {
        let rule = Rule::GcsHandshakeV2Framing;
        let requests: Vec<&&Seen> = frames.iter().filter(|f| is_request(f)).collect();
        let Some(first) = requests.first() else {
            return Verdict::na(rule, "the ground station sent no handshake request");
        };
        match requests.iter().find(|f| f.version == Version::V1) {
            Some(f) => Verdict::fail(
                rule,
                format!(
                    "{} in MAVLink 1 at {} ({} of {} requests in MAVLink 1)",
                    request_name(f),
                    secs(f.t),
                    requests.iter().filter(|f| f.version == Version::V1).count(),
                    requests.len()
                ),
            ),
            None => Verdict::pass(
                rule,
                format!(
                    "{} in MAVLink 2 at {} ({} request(s), all MAVLink 2)",
                    request_name(first),
                    secs(first.t),
                    requests.len()
                ),
            ),
        }
    }

    /// When the ground station could know the vehicle has MAVLink 2: the vehicle's first
    /// MAVLink 2 frame, or its AUTOPILOT_VERSION (MAVLINK2 set) after a request.
    fn vehicle_shows_v2(&self, frames: &[&Seen]) -> Option<(f64, &'static str)> {
        if self.mode != VehicleMode::Answer {
            return None;
        }
        let capability = frames
            .iter()
            .find(|f| asks_capabilities(f))
            .map(|f| (f.t, "its AUTOPILOT_VERSION with MAVLINK2"));
        let switch = self
            .vehicle_v2_at
            .map(|t| (t, "the vehicle's first MAVLink 2 frame"));
        match (capability, switch) {
            (Some(a), Some(b)) => Some(if a.0 <= b.0 { a } else { b }),
            (a, b) => a.or(b),
        }
    }

    fn switch(&self, frames: &[&Seen]) -> Verdict {
        let rule = Rule::GcsSwitch;
        if self.mode != VehicleMode::Answer {
            return Verdict::na(
                rule,
                format!(
                    "the vehicle is MAVLink 1 only (--vehicle-mode {})",
                    self.mode.as_str()
                ),
            );
        }
        let Some((t, what)) = self.vehicle_shows_v2(frames) else {
            return Verdict::na(
                rule,
                "the ground station never learned of MAVLink 2: no MAVLink 2 frame from it and no AUTOPILOT_VERSION request",
            );
        };
        // Its own MAVLink 2 frame may be what switched the vehicle.
        let first_v2 = frames
            .iter()
            .find(|f| f.version == Version::V2 && f.t >= t - 0.5);
        let hbs: Vec<&&Seen> = frames
            .iter()
            .filter(|f| f.t > t + 1.5 && f.is::<Heartbeat>())
            .collect();
        let v1_hbs = hbs.iter().filter(|f| f.version == Version::V1).count();
        match first_v2 {
            Some(f) if v1_hbs == 0 => Verdict::pass(
                rule,
                format!(
                    "MAVLink 2 from {} ({} at {}); {} HEARTBEAT(s) after, all MAVLink 2",
                    secs(f.t.max(t)),
                    what,
                    secs(t),
                    hbs.len()
                ),
            ),
            _ => Verdict::fail(
                rule,
                format!(
                    "after {what} at {}: {v1_hbs} of {} HEARTBEATs in MAVLink 1{}",
                    secs(t),
                    hbs.len(),
                    if first_v2.is_none() {
                        ", no MAVLink 2 frame"
                    } else {
                        ""
                    }
                ),
            ),
        }
    }

    fn fallback(&self, frames: &[&Seen]) -> Verdict {
        let rule = Rule::GcsFallback;
        if self.mode == VehicleMode::Answer {
            return Verdict::na(
                rule,
                "the vehicle answers the handshake (--vehicle-mode answer)",
            );
        }
        let Some(request) = frames.iter().find(|f| is_request(f)) else {
            return Verdict::na(rule, "the ground station sent no handshake request");
        };
        let from = match (self.mode, self.answered_at) {
            (VehicleMode::Nack, Some(t)) => t + 0.5,
            _ => request.t + 2.0,
        };
        let after: Vec<&&Seen> = frames.iter().filter(|f| f.t > from).collect();
        let v1 = after.iter().filter(|f| f.version == Version::V1).count();
        let v1_hb = after
            .iter()
            .filter(|f| f.version == Version::V1 && f.is::<Heartbeat>())
            .count();
        let cause = if self.mode == VehicleMode::Nack {
            "the NACK"
        } else {
            "the unanswered request"
        };
        let evidence = format!(
            "after {cause} ({} at {}): {v1} frame(s) in MAVLink 1 ({v1_hb} HEARTBEATs), {} in MAVLink 2, from {}",
            request_name(request),
            secs(request.t),
            after.len() - v1,
            secs(from)
        );
        Verdict::check(rule, v1 >= 2 && v1_hb >= 1, evidence)
    }

    fn no_mixing(&self, frames: &[&Seen]) -> Verdict {
        let rule = Rule::GcsNoMixing;
        let reference = match (self.answered_at, self.vehicle_v2_at) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        let Some(reference) = reference else {
            return Verdict::na(
                rule,
                "the vehicle neither answered a handshake nor sent MAVLink 2",
            );
        };
        // A handshake request in MAVLink 2 is the documented exception, not a switch.
        let Some(switch) = frames
            .iter()
            .find(|f| f.t > reference && f.version == Version::V2 && !is_request(f))
        else {
            return Verdict::na(rule, "the ground station never switched to MAVLink 2");
        };
        let after: Vec<&&Seen> = frames.iter().filter(|f| f.t > switch.t).collect();
        let v1: Vec<&&&Seen> = after.iter().filter(|f| f.version == Version::V1).collect();
        match v1.first() {
            None => Verdict::pass(
                rule,
                format!(
                    "all {} frames after its switch at {} in MAVLink 2",
                    after.len(),
                    secs(switch.t)
                ),
            ),
            Some(f) => Verdict::fail(
                rule,
                format!(
                    "{} of {} frames in {} after its switch at {} (first: {} at {})",
                    v1.len(),
                    after.len(),
                    version_name(Version::V1),
                    secs(switch.t),
                    message_name(f.msg_id),
                    secs(f.t)
                ),
            ),
        }
    }
}
