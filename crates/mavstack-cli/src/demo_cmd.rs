//! `mavstack demo`: the version document's diagram, live, on loopback.
//!
//! A simulated vehicle (starting in MAVLink 1), a semi-transparent radio and a ground station
//! run over real UDP sockets on 127.0.0.1:
//!
//! ```text
//!   ground station ──udp──► radio (side A │ side B) ──udp──► vehicle
//!        ▲                                                  │
//!        └──────────────── frames, RADIO_STATUS ◄───────────┘
//!   attacker ──udp──► radio side A   (replayed and forged frames)
//!                                                  vehicle ◄──udp, version=1──► rangefinder
//! ```
//!
//! The ground station finds the vehicle, runs the MAVLink 2 handshake (both sides switch to
//! MAVLink 2, the radio's RADIO_STATUS follows), asks for AUTOPILOT_VERSION, sets up signing
//! with SETUP_SIGNING, exchanges signed traffic; an attacker on the ground link replays a
//! captured signed command and sends a forged one with a timestamp far in the future; the
//! vehicle rejects both and still accepts the genuine stream. Then, over the signed link, the
//! configuration services: the whole parameter table, a parameter set and confirmed, a
//! mission uploaded and read back identical. The vehicle also has a legacy peripheral, a
//! rangefinder that speaks only MAVLink 1, on a link of its own (`version=1`): its traffic
//! reaches the ground station in signed MAVLink 2 and the ground station's commands reach it
//! in MAVLink 1, converted by the vehicle's router, each link keeping its own version. Every
//! step is printed as a timeline; any step that does not happen fails the demo (exit 1).

use core::time::Duration;
use std::net::UdpSocket;

use clap::Args;
use mavstack::radio::{RadioBridge, RadioNotice};
use mavstack::router::LinkId;
use mavstack::serve::Served;
use mavstack::services::Address;
use mavstack::services::stream::{Due, MessageSource, StreamServer};
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, Wanted};
use mavstack::{
    EventSubscription, Incoming, LinkEvent, LinkSpec, Node, NodeEvent, NodeHandle, Subscription,
};
use mavstack_channel::{
    Authentication, CommandEncoding, HandshakeMethod, HandshakeResult, RadioConfig, ReceivedFrame,
    SigningConfig, Target,
};
use mavstack_core::Message;
use mavstack_core::signing::{self, SecretKey};
use mavstack_core::wire::{FrameHeader, MAX_FRAME_LEN, Version, emit_message};
use mavstack_dialects::common::{
    AutopilotVersion, CommandLong, DistanceSensor, Heartbeat, MavAutopilot, MavCmd,
    MavDistanceSensor, MavFrame, MavMessage, MavMissionType, MavProtocolCapability, MavType,
    MissionItemInt, ProtocolVersion, RadioStatus, SetupSigning,
};
use mavstack_services::param::Name;
use mavstack_transport::{ConnSpec, clock};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::link_cmd::runtime;
use crate::remote::value_text;
use crate::vehicle_cmd::{Log, say, version_name};
use crate::{Failure, fail, other};
use anyhow::Context as _;
use mavstack::system::{command_name, result_name};
use mavstack_sim::Autopilot;
use mavstack_sim::flight;

#[derive(Debug, Args)]
pub(crate) struct DemoArgs {}

/// The demo's signing key (a real deployment generates one per vehicle and keeps it secret).
const KEY: [u8; 32] = *b"mavstack demo key: not a secret!";

/// The vehicle's legacy peripheral: a rangefinder, system 1 component 158
/// (MAV_COMP_ID_PERIPHERAL), MAVLink 1 only.
const PERIPHERAL: (u8, u8) = (1, 158);

/// The timeline: lines from every actor, stamped with the time since the start.
struct Timeline {
    started: Instant,
    tx: mpsc::UnboundedSender<String>,
    printer: tokio::task::JoinHandle<()>,
}

impl Timeline {
    fn new() -> Self {
        let started = Instant::now();
        let (tx, mut rx) = mpsc::unbounded_channel::<String>();
        let printer = tokio::spawn(async move {
            while let Some(line) = rx.recv().await {
                let t = started.elapsed().as_secs_f64();
                println!("{t:7.3}s  {line}");
            }
        });
        Self {
            started,
            tx,
            printer,
        }
    }

    fn log(&self) -> Log {
        Some(self.tx.clone())
    }

    fn say(&self, line: impl Into<String>) {
        let _ = self.tx.send(line.into());
    }
}

/// What the ground station's node reports: a frame for it, or something on its link.
#[allow(
    clippy::large_enum_variant,
    reason = "a few per second, moved once: boxing would buy nothing"
)]
enum Seen {
    Frame(Incoming),
    Link(NodeEvent),
}

/// The ground station's side of the demo: a ground-station node (its HEARTBEAT every second)
/// and what it sees.
struct Ground {
    node: Node,
    handle: NodeHandle,
    frames: Subscription,
    events: EventSubscription,
    link: Option<LinkId>,
    seen_v1_status: bool,
    seen_v2_status: bool,
    seen_hb: Option<Version>,
    seen_signed_hb: bool,
    /// The framing and signing of the rangefinder's HEARTBEATs, as last narrated.
    seen_peripheral: Option<(Version, bool)>,
}

impl Ground {
    /// Sends `message` on the link to the vehicle.
    async fn send(&self, message: &MavMessage) -> Result<(), Failure> {
        let link = self.link.ok_or_else(|| other("no link to the vehicle"))?;
        self.handle.send_on(link, message).await;
        Ok(())
    }

    /// Takes what the node reports until `found` says yes (returns it) or `within` passes
    /// (`None`), narrating what it sees.
    async fn wait(
        &mut self,
        timeline: &Timeline,
        within: Duration,
        mut found: impl FnMut(&Seen) -> bool,
    ) -> Result<Option<Seen>, Failure> {
        let deadline = Instant::now() + within;
        loop {
            let closed = || other("the ground station's node stopped");
            let seen = tokio::select! {
                () = tokio::time::sleep_until(deadline) => return Ok(None),
                f = self.frames.recv() => Seen::Frame(f.ok_or_else(closed)?),
                e = self.events.recv() => Seen::Link(e.ok_or_else(closed)?),
            };
            self.narrate(timeline, &seen);
            if found(&seen) {
                return Ok(Some(seen));
            }
        }
    }

    fn narrate(&mut self, timeline: &Timeline, seen: &Seen) {
        match seen {
            Seen::Frame(incoming) => {
                let rf = &incoming.frame;
                let f = &rf.frame;
                if f.msg_id() == RadioStatus::ID {
                    let first = match f.version() {
                        Version::V1 => !core::mem::replace(&mut self.seen_v1_status, true),
                        Version::V2 => !core::mem::replace(&mut self.seen_v2_status, true),
                    };
                    if first {
                        timeline.say(format!(
                            "ground station ← RADIO_STATUS from the radio ({}{})",
                            version_name(f.version()),
                            if matches!(rf.auth, Authentication::AllowedUnsigned) {
                                ", unsigned: on the allow-list"
                            } else {
                                ""
                            }
                        ));
                    }
                }
                if f.msg_id() == Heartbeat::ID && (f.sysid(), f.compid()) == PERIPHERAL {
                    let now = (
                        f.version(),
                        matches!(rf.auth, Authentication::Verified { .. }),
                    );
                    if self.seen_peripheral.replace(now) != Some(now) {
                        timeline.say(format!(
                            "ground station ← HEARTBEAT from the rangefinder 1/158 ({}{}){}",
                            version_name(now.0),
                            if now.1 { ", signed" } else { "" },
                            if now.0 == Version::V2 {
                                ": it speaks MAVLink 1, the vehicle converted it"
                            } else {
                                ""
                            }
                        ));
                    }
                }
                if f.msg_id() == Heartbeat::ID && (f.sysid(), f.compid()) == (1, 1) {
                    self.link.get_or_insert(incoming.link_id);
                    let signed = matches!(rf.auth, Authentication::Verified { .. });
                    if self.seen_hb != Some(f.version()) || (signed && !self.seen_signed_hb) {
                        self.seen_hb = Some(f.version());
                        self.seen_signed_hb |= signed;
                        timeline.say(format!(
                            "ground station ← HEARTBEAT from vehicle 1/1 ({}{})",
                            version_name(f.version()),
                            if signed {
                                ", signed, signature verified"
                            } else {
                                ""
                            }
                        ));
                    }
                }
            }
            Seen::Link(event) => match &event.kind {
                LinkEvent::VersionChanged { from, to, cause } => {
                    timeline.say(format!("ground station: link {from} → {to} ({cause})"));
                }
                LinkEvent::Rejected(r) => {
                    timeline.say(format!(
                        "ground station ✗ rejected {}: {}",
                        mavstack::message_name(r.msg_id),
                        r.reason
                    ));
                }
                _ => {}
            },
        }
    }
}

fn request(command: MavCmd, param1: f32) -> MavMessage {
    MavMessage::CommandLong(CommandLong {
        target_system: 1,
        target_component: 1,
        command,
        param1,
        ..CommandLong::default()
    })
}

/// The frame, if `seen` is one with message `id`.
fn frame_of(seen: &Seen, id: u32) -> Option<&ReceivedFrame> {
    match seen {
        Seen::Frame(incoming) if incoming.frame.frame.msg_id() == id => Some(&incoming.frame),
        _ => None,
    }
}

fn is_message(seen: &Seen, id: u32) -> bool {
    frame_of(seen, id).is_some()
}

/// A forged COMMAND_LONG: signed with the wrong key, timestamp far in the future (the frame
/// that locks a pymavlink receiver out of the genuine stream).
fn forged_command() -> Result<Vec<u8>, Failure> {
    let header = FrameHeader {
        version: Version::V2,
        seq: 200,
        sysid: 255,
        compid: 190,
        signed: true,
    };
    let command = CommandLong {
        target_system: 1,
        target_component: 1,
        command: MavCmd::COMPONENT_ARM_DISARM,
        param1: 1.0,
        ..CommandLong::default()
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let len = emit_message(&header, &command, &mut buf).map_err(fail)?;
    let future =
        signing::timestamp_from_unix_micros(clock::now().as_micros()) + 100 * 24 * 3600 * 100_000;
    let wrong = SecretKey::new([0x42; 32]);
    let len = signing::append_signature(&mut buf, len, 1, future, &wrong).map_err(fail)?;
    Ok(buf[..len].to_vec())
}

pub(crate) fn demo(_args: &DemoArgs) -> Result<(), Failure> {
    runtime()?.block_on(async {
        let timeline = Timeline::new();
        let result = run(&timeline).await;
        let elapsed = timeline.started.elapsed().as_secs_f64();
        let Timeline { tx, printer, .. } = timeline;
        drop(tx);
        let _ = printer.await;
        if result.is_ok() {
            println!("demo finished in {elapsed:.1} s");
        }
        result
    })
}

async fn run(timeline: &Timeline) -> Result<(), Failure> {
    // The vehicle: MAVLink 1 until a MAVLink 2 frame, MAVLink 2 capable, a secure link
    // (think USB) so it accepts SETUP_SIGNING.
    let any_port = |scheme: &str| -> Result<ConnSpec, Failure> {
        format!("{scheme}:127.0.0.1:0").parse().map_err(fail)
    };
    let radio_link =
        LinkSpec::parse("udpin:127.0.0.1:0?secure=true&name=radio", &|_| None).map_err(fail)?;
    // Its legacy rangefinder's link: MAVLink 1 only; trusted (wired to the vehicle), so the
    // rangefinder's frames may be signed onto the signed radio link.
    let peripheral_link = LinkSpec::parse(
        "udpin:127.0.0.1:0?version=1&trusted=true&name=peripheral",
        &|_| None,
    )
    .map_err(fail)?;
    let vehicle = SimVehicle::start_logged(
        Node::builder().link(radio_link).link(peripheral_link),
        SimVehicle::config(
            Autopilot::Ardupilot,
            mavstack_sim::params::defaults(Autopilot::Ardupilot),
        ),
        timeline.log(),
    )
    .await
    .map_err(fail)?;
    let bound = |i: usize| {
        vehicle
            .node()
            .local_addrs()
            .get(i)
            .copied()
            .flatten()
            .ok_or_else(|| other("the vehicle's socket has no address"))
    };
    let vehicle_addr = bound(0)?;
    let peripheral = Peripheral::start(timeline, bound(1)?).await?;
    let mut radio_config = RadioConfig::default();
    radio_config.interval = Duration::from_millis(700);
    let radio_log = timeline.log();
    let radio = RadioBridge::start(
        &any_port("udpin")?,
        &format!("udpout:{vehicle_addr}").parse().map_err(fail)?,
        radio_config,
        move |n: &RadioNotice| say(&radio_log, || n.to_string()),
    )
    .await
    .map_err(fail)?;
    let radio_a_addr =
        radio.local_addrs()[0].ok_or_else(|| other("the radio's socket has no address"))?;
    timeline.say(format!(
        "setup: vehicle 1/1 on udp {vehicle_addr} (starts in MAVLink 1), radio {radio_a_addr} ⇄ vehicle, ground station 255/190 → radio"
    ));
    timeline.say(format!(
        "setup: rangefinder 1/158 (MAVLink 1 only) → the vehicle's link {} (version=1)",
        bound(1)?
    ));
    // A copy of every signed COMMAND_LONG the vehicle accepts: the attacker replays one.
    let (tap_tx, mut tap_rx) = mpsc::unbounded_channel();
    let mut for_vehicle = vehicle.node().subscribe().await;
    let tap = tokio::spawn(async move {
        while let Some(incoming) = for_vehicle.recv().await {
            let rf = &incoming.frame;
            if rf.frame.is_signed() && rf.frame.msg_id() == CommandLong::ID {
                let _ = tap_tx.send(rf.frame.as_bytes().to_vec());
            }
        }
    });
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:{radio_a_addr}"), &|_| None).map_err(fail)?)
        .start()
        .await
        .map_err(fail)?;
    let handle = gcs.handle();
    let frames = gcs.subscribe().await;
    let events = handle.events().await;
    let mut ground = Ground {
        node: gcs,
        handle,
        frames,
        events,
        link: None,
        seen_v1_status: false,
        seen_v2_status: false,
        seen_hb: None,
        seen_signed_hb: false,
        seen_peripheral: None,
    };
    let mut outcome = script(timeline, &mut ground, &mut tap_rx, radio_a_addr).await;
    if outcome.is_ok() {
        outcome = services(timeline, &ground.handle).await;
    }
    if outcome.is_ok() {
        outcome = peripheral_stream(timeline, &mut ground).await;
    }
    let _ = ground.node.shutdown().await;
    radio.stop().await.map_err(fail)?;
    let report = vehicle.shutdown().await.map_err(fail)?;
    let peripheral_report = peripheral.shutdown().await?;
    tap.abort();
    outcome?;
    for link in &report.links {
        timeline.say(link_summary(link));
    }
    let converted_for = |name: &str, kind: &str| -> u64 {
        report
            .links
            .iter()
            .filter(|l| l.name == name)
            .flat_map(|l| l.conversions)
            .filter(|(k, _)| *k == kind)
            .map(|(_, n)| n)
            .sum()
    };
    if converted_for("peripheral", "to_mavlink1") == 0 || converted_for("radio", "to_mavlink2") == 0
    {
        return Err(other(
            "the vehicle did not convert between its MAVLink 1 and MAVLink 2 links",
        ));
    }
    let peripheral_rx: u64 = peripheral_report.links.iter().map(|l| l.rx_frames).sum();
    let peripheral_dropped: u64 = peripheral_report
        .links
        .iter()
        .flat_map(|l| &l.dropped)
        .map(|(_, n)| n)
        .sum();
    timeline.say(format!(
        "rangefinder's link: {peripheral_rx} frames received, every one MAVLink 1 ({peripheral_dropped} refused)"
    ));
    if peripheral_dropped != 0 {
        return Err(other("the rangefinder received frames it cannot read"));
    }
    let dropped = |reason: &str| -> u64 {
        report
            .links
            .iter()
            .flat_map(|l| &l.dropped)
            .filter(|(r, _)| *r == reason)
            .map(|(_, n)| n)
            .sum()
    };
    let replayed = dropped("replay");
    let forged = dropped("bad_signature");
    timeline.say(format!(
        "vehicle's radio link: {replayed} replay and {forged} forgery rejected"
    ));
    if replayed == 0 || forged == 0 {
        return Err(other(
            "the vehicle did not reject the replayed and forged frames",
        ));
    }
    Ok(())
}

/// One line on a vehicle link: what it carries, what went through, what was converted for it.
fn link_summary(link: &mavstack::LinkReport) -> String {
    let carries = match link.version {
        "1" => "MAVLink 1",
        "2" => "MAVLink 2",
        "signed" => "signed MAVLink 2",
        _ => "MAVLink 1 until a MAVLink 2 frame",
    };
    let conversions: Vec<String> = link
        .conversions
        .iter()
        .filter(|(_, n)| *n > 0)
        .map(|(kind, n)| {
            let kind = match *kind {
                "to_mavlink1" => "to MAVLink 1",
                "to_mavlink2" => "to MAVLink 2",
                "signature_removed" => "signature removed",
                _ => "signed",
            };
            format!("{n} {kind}")
        })
        .collect();
    format!(
        "vehicle's {} link ({carries}): {} frames in, {} out; converted on the way out: {}",
        link.name,
        link.rx_frames,
        link.tx_frames,
        if conversions.is_empty() {
            "none".to_owned()
        } else {
            conversions.join(", ")
        }
    )
}

/// The rangefinder's telemetry: a distance that drifts slowly.
struct Rangefinder {
    distance_cm: u16,
}

impl MessageSource for Rangefinder {
    fn message(&mut self, now: mavstack_core::time::Instant, _due: &Due) -> Option<MavMessage> {
        self.distance_cm = 380 + ((now.as_micros() / 100_000) % 40) as u16;
        Some(MavMessage::DistanceSensor(DistanceSensor {
            time_boot_ms: (now.as_micros() / 1000) as u32,
            min_distance: 20,
            max_distance: 4000,
            current_distance: self.distance_cm,
            r#type: MavDistanceSensor::LASER,
            ..DistanceSensor::default()
        }))
    }
}

/// The vehicle's legacy peripheral: a node of its own on the vehicle's `version=1` link,
/// its DISTANCE_SENSOR stream served at the rate a ground station asks for.
struct Peripheral {
    node: Node,
    served: Served<StreamServer<Rangefinder>>,
    narrator: tokio::task::JoinHandle<()>,
}

impl Peripheral {
    async fn start(timeline: &Timeline, vehicle: core::net::SocketAddr) -> Result<Self, Failure> {
        let node = Node::builder()
            .identity(PERIPHERAL.0, PERIPHERAL.1)
            .heartbeat(
                &Heartbeat {
                    r#type: MavType::GENERIC,
                    autopilot: MavAutopilot::INVALID,
                    mavlink_version: 3,
                    ..Heartbeat::default()
                },
                Duration::from_secs(1),
            )
            .link(LinkSpec::parse(&format!("udpout:{vehicle}?version=1"), &|_| None).map_err(fail)?)
            .start()
            .await
            .map_err(fail)?;
        let own = Address::new(PERIPHERAL.0, PERIPHERAL.1);
        let mut streams = StreamServer::new(own, Rangefinder { distance_cm: 400 });
        streams.support(DistanceSensor::ID, None);
        let served = Served::start(&node.handle(), streams).await;
        // What reaches it from the ground station, in the framing it arrives in.
        let mut frames = node.subscribe().await;
        let log = timeline.tx.clone();
        let narrator = tokio::spawn(async move {
            while let Some(incoming) = frames.recv().await {
                let f = &incoming.frame.frame;
                if f.msg_id() == CommandLong::ID && f.sysid() == 255 {
                    let c = CommandLong::decode(f.payload());
                    let _ = log.send(format!(
                        "rangefinder ← COMMAND_LONG {} from 255/190 in {}{}",
                        command_name(c.command),
                        version_name(f.version()),
                        if f.version() == Version::V1 && !f.is_signed() {
                            ": the vehicle converted it, signature removed"
                        } else {
                            ""
                        }
                    ));
                }
            }
        });
        Ok(Self {
            node,
            served,
            narrator,
        })
    }

    async fn shutdown(self) -> Result<mavstack::NodeReport, Failure> {
        self.narrator.abort();
        let _ = self.served.stop().await;
        self.node.shutdown().await.map_err(fail)
    }
}

/// Step 9: the rangefinder's telemetry, asked for in signed MAVLink 2, sent in MAVLink 1, seen
/// signed: the vehicle converts both ways.
async fn peripheral_stream(timeline: &Timeline, ground: &mut Ground) -> Result<(), Failure> {
    let rangefinder = System::wait(
        &ground.handle,
        Wanted::System(PERIPHERAL.0, Some(PERIPHERAL.1)),
        Duration::from_secs(3),
    )
    .await
    .map_err(fail)?;
    timeline.say(
        "ground station → SET_MESSAGE_INTERVAL(DISTANCE_SENSOR, 100 ms) to the rangefinder 1/158, signed MAVLink 2",
    );
    let ack = rangefinder
        .commands()
        .set_message_interval(DistanceSensor::ID, Some(Duration::from_millis(100)))
        .await
        .context("demo step failed: the rangefinder's stream")
        .map_err(Failure::Other)?;
    timeline.say(format!(
        "ground station ← COMMAND_ACK {} from the rangefinder",
        result_name(ack.result)
    ));
    let mut signed = 0;
    let mut other_framing = 0;
    let mut last_cm = None;
    let _ = ground
        .wait(timeline, Duration::from_secs(1), |seen| {
            if let Some(rf) = frame_of(seen, DistanceSensor::ID) {
                if rf.frame.version() == Version::V2
                    && matches!(rf.auth, Authentication::Verified { .. })
                {
                    signed += 1;
                } else {
                    other_framing += 1;
                }
                last_cm = Some(DistanceSensor::decode(rf.frame.payload()).current_distance);
            }
            false
        })
        .await?;
    let last_cm = last_cm
        .ok_or_else(|| other("demo step failed: no DISTANCE_SENSOR from the rangefinder"))?;
    timeline.say(format!(
        "ground station ← {signed} DISTANCE_SENSOR in 1 s from the rangefinder, every one signed MAVLink 2 (last {last_cm} cm); it sent them in MAVLink 1"
    ));
    if signed < 5 || other_framing > 0 {
        return Err(other(format!(
            "demo step failed: {signed} signed DISTANCE_SENSOR and {other_framing} in another framing"
        )));
    }
    Ok(())
}

/// The demo's mission: home, take-off to 20 m, three waypoints, return to launch.
fn demo_mission() -> Vec<MissionItemInt> {
    let (lat, lon) = (flight::HOME.lat, flight::HOME.lon);
    let at = |command: MavCmd, north_m: f64, east_m: f64, z: f32| MissionItemInt {
        frame: MavFrame::GLOBAL_RELATIVE_ALT_INT,
        command,
        autocontinue: 1,
        x: ((lat + north_m / 111_319.49) * 1e7) as i32,
        y: ((lon + east_m / 91_000.0) * 1e7) as i32,
        z,
        ..MissionItemInt::default()
    };
    vec![
        at(MavCmd::NAV_WAYPOINT, 0.0, 0.0, 0.0),
        at(MavCmd::NAV_TAKEOFF, 0.0, 0.0, 20.0),
        at(MavCmd::NAV_WAYPOINT, 60.0, 0.0, 25.0),
        at(MavCmd::NAV_WAYPOINT, 60.0, 60.0, 25.0),
        at(MavCmd::NAV_WAYPOINT, 0.0, 60.0, 20.0),
        at(MavCmd::NAV_RETURN_TO_LAUNCH, 0.0, 0.0, 0.0),
    ]
}

/// Step 8: the configuration services over the signed link — the parameter table, a
/// parameter set, a mission uploaded and read back.
async fn services(timeline: &Timeline, node: &NodeHandle) -> Result<(), Failure> {
    let since = |began: Instant| began.elapsed().as_secs_f64() * 1000.0;
    let vehicle = System::wait(node, Wanted::System(1, Some(1)), Duration::from_secs(3))
        .await
        .map_err(fail)?;
    timeline.say("ground station → PARAM_REQUEST_LIST, signed");
    let began = Instant::now();
    let table = vehicle.params().get_all().await.map_err(fail)?;
    timeline.say(format!(
        "ground station ← {} PARAM_VALUEs in {:.0} ms (ArduPilot C-cast encoding)",
        table.len(),
        since(began)
    ));
    let name = Name::new("WPNAV_SPEED").map_err(fail)?;
    let current = table
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, v)| *v)
        .ok_or_else(|| other("demo step failed: no WPNAV_SPEED in the table"))?;
    let (_, set) = vehicle
        .params()
        .set_typed(name, 750.0)
        .await
        .map_err(fail)?;
    timeline.say(format!(
        "ground station → PARAM_SET WPNAV_SPEED {} → 750; vehicle confirms {}",
        value_text(current),
        value_text(set.value)
    ));
    let items = demo_mission();
    let count = items.len();
    let began = Instant::now();
    vehicle
        .mission()
        .upload(MavMissionType::MISSION, items.clone())
        .await
        .context("demo step failed: mission upload")
        .map_err(Failure::Other)?;
    timeline.say(format!(
        "ground station → mission of {count} items (MISSION_COUNT, MISSION_ITEM_INT × {count}) accepted in {:.0} ms",
        since(began)
    ));
    let back = vehicle
        .mission()
        .download(MavMissionType::MISSION)
        .await
        .context("demo step failed: mission download")
        .map_err(Failure::Other)?;
    let same = back.len() == items.len()
        && back.iter().zip(&items).all(|(a, b)| {
            (a.command, a.frame, a.x, a.y, a.z.to_bits())
                == (b.command, b.frame, b.x, b.y, b.z.to_bits())
        });
    if !same {
        return Err(other("demo step failed: the mission read back differs"));
    }
    timeline.say(format!(
        "ground station ← mission read back: {} items, identical",
        back.len()
    ));
    Ok(())
}

/// Asks the vehicle for AUTOPILOT_VERSION on the signed link and waits for a verified answer;
/// `failure` names the step if none comes.
async fn signed_autopilot_version(
    timeline: &Timeline,
    ground: &mut Ground,
    failure: &str,
) -> Result<(), Failure> {
    ground
        .send(&request(
            MavCmd::REQUEST_MESSAGE,
            AutopilotVersion::ID as f32,
        ))
        .await?;
    let answer = ground
        .wait(timeline, Duration::from_secs(3), |e| {
            frame_of(e, AutopilotVersion::ID)
                .is_some_and(|rf| matches!(rf.auth, Authentication::Verified { .. }))
        })
        .await?;
    answer
        .map(drop)
        .ok_or_else(|| other(format!("demo step failed: {failure}")))
}

async fn script(
    timeline: &Timeline,
    ground: &mut Ground,
    tap: &mut mpsc::UnboundedReceiver<Vec<u8>>,
    radio_addr: core::net::SocketAddr,
) -> Result<(), Failure> {
    let need = |found: Option<Seen>, what: &str| {
        found.ok_or_else(|| other(format!("demo step failed: {what}")))
    };
    // 1. Discovery, in MAVLink 1.
    let hb = ground
        .wait(timeline, Duration::from_secs(4), |e| {
            frame_of(e, Heartbeat::ID)
                .is_some_and(|rf| (rf.frame.sysid(), rf.frame.compid()) == (1, 1))
        })
        .await?;
    need(hb, "no HEARTBEAT from the vehicle")?;
    let link = ground.link.ok_or_else(|| other("no link to the vehicle"))?;
    let _ = ground
        .wait(timeline, Duration::from_millis(900), |e| {
            is_message(e, RadioStatus::ID)
        })
        .await?;
    // The rangefinder's HEARTBEAT (once a second) too, while the links still speak MAVLink 1:
    // its first one can beat the ground station's first frame to the radio and be lost.
    if ground.seen_peripheral.is_none() {
        let _ = ground
            .wait(timeline, Duration::from_millis(1500), |e| {
                frame_of(e, Heartbeat::ID)
                    .is_some_and(|rf| (rf.frame.sysid(), rf.frame.compid()) == PERIPHERAL)
            })
            .await?;
    }
    // 2. The handshake.
    timeline.say("ground station → COMMAND_LONG REQUEST_MESSAGE(300) in MAVLink 2 (the handshake)");
    let handshake = {
        let node = ground.handle.clone();
        tokio::spawn(async move {
            node.handshake(
                link,
                Target::new(1, 1),
                HandshakeMethod::RequestMessage300,
                CommandEncoding::Long,
            )
            .await
        })
    };
    let done = ground
        .wait(timeline, Duration::from_secs(4), |e| {
            matches!(
                e,
                Seen::Link(NodeEvent {
                    kind: LinkEvent::Handshake(_),
                    ..
                })
            )
        })
        .await?;
    need(done, "no handshake outcome")?;
    let outcome = handshake.await.map_err(fail)?.map_err(fail)?;
    match &outcome.result {
        HandshakeResult::ProtocolVersion(v) => timeline.say(format!(
            "ground station ← {} {} (min {}, max {}) in MAVLink 2 after {} request(s): the vehicle speaks MAVLink 2",
            ProtocolVersion::NAME,
            v.version,
            v.min_version,
            v.max_version,
            outcome.attempts
        )),
        other_result => {
            return Err(other(format!(
                "demo step failed: handshake ended with {}",
                other_result.name()
            )));
        }
    }
    let v2 = ground
        .wait(timeline, Duration::from_secs(3), |e| {
            frame_of(e, Heartbeat::ID).is_some_and(|rf| rf.frame.version() == Version::V2)
        })
        .await?;
    need(v2, "the vehicle's heartbeats did not switch to MAVLink 2")?;
    let _ = ground
        .wait(timeline, Duration::from_millis(900), |_| false)
        .await?;
    // 3. Capabilities.
    timeline.say("ground station → REQUEST_MESSAGE(AUTOPILOT_VERSION)");
    ground
        .send(&request(
            MavCmd::REQUEST_MESSAGE,
            AutopilotVersion::ID as f32,
        ))
        .await?;
    let av = ground
        .wait(timeline, Duration::from_secs(3), |e| {
            is_message(e, AutopilotVersion::ID)
        })
        .await?;
    let av = need(av, "no AUTOPILOT_VERSION")?;
    if let Some(rf) = frame_of(&av, AutopilotVersion::ID) {
        let caps = AutopilotVersion::decode(rf.frame.payload()).capabilities;
        timeline.say(format!(
            "ground station ← AUTOPILOT_VERSION: MAV_PROTOCOL_CAPABILITY_MAVLINK2 {}",
            if caps.0 & MavProtocolCapability::MAVLINK2.0 != 0 {
                "set"
            } else {
                "NOT set"
            }
        ));
    }
    // 4. Signing.
    let now_ts = signing::timestamp_from_unix_micros(clock::now().as_micros());
    timeline.say(
        "ground station → SETUP_SIGNING (key, timestamp) over the secure link; signs from now on",
    );
    ground
        .send(&MavMessage::SetupSigning(SetupSigning {
            target_system: 1,
            target_component: 1,
            secret_key: KEY,
            initial_timestamp: now_ts,
        }))
        .await?;
    ground
        .handle
        .set_signing(link, Some(SigningConfig::new(SecretKey::new(KEY), 1)))
        .await
        .map_err(fail)?;
    let signed = ground
        .wait(timeline, Duration::from_secs(3), |e| {
            frame_of(e, Heartbeat::ID)
                .is_some_and(|rf| matches!(rf.auth, Authentication::Verified { .. }))
        })
        .await?;
    need(signed, "no signed HEARTBEAT from the vehicle")?;
    // 5. Signed traffic both ways.
    timeline.say("ground station → REQUEST_MESSAGE(AUTOPILOT_VERSION), signed");
    signed_autopilot_version(timeline, ground, "no signed AUTOPILOT_VERSION").await?;
    timeline.say("ground station ← AUTOPILOT_VERSION, signed, signature verified");
    // 6. Attacks from the ground link.
    let captured = tokio::time::timeout(Duration::from_secs(1), tap.recv())
        .await
        .ok()
        .flatten()
        .ok_or_else(|| other("demo step failed: no signed command captured"))?;
    let attacker = UdpSocket::bind("127.0.0.1:0").map_err(fail)?;
    timeline.say("attacker → replays the captured signed COMMAND_LONG, byte for byte");
    attacker.send_to(&captured, radio_addr).map_err(fail)?;
    let _ = ground
        .wait(timeline, Duration::from_millis(400), |_| false)
        .await?;
    timeline.say("attacker → forged COMMAND_LONG (ARM): wrong key, timestamp 100 days ahead");
    attacker
        .send_to(&forged_command()?, radio_addr)
        .map_err(fail)?;
    let _ = ground
        .wait(timeline, Duration::from_millis(400), |_| false)
        .await?;
    // 7. The genuine stream still flows.
    timeline.say("ground station → REQUEST_MESSAGE(AUTOPILOT_VERSION), signed, after the attacks");
    signed_autopilot_version(timeline, ground, "the genuine stream was locked out").await?;
    timeline.say("ground station ← AUTOPILOT_VERSION: the genuine stream is still accepted");
    Ok(())
}
