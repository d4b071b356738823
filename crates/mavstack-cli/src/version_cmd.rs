//! `mavstack vehicle`, `probe` and `radio`: the MAVLink version rules on real links.
//!
//! - `vehicle CONN`: a simulated vehicle ([`crate::sim`]: parameters, missions, commands,
//!   telemetry streams, a kinematic craft) behind the MAVLink 2 handshake, answered (or
//!   refused, or ignored) by its link's channel, and signing.
//! - `probe CONN`: the ground station's side: find the systems on a link, ask for
//!   AUTOPILOT_VERSION, run the handshake, print one JSON report per system.
//! - `radio CONN_A CONN_B`: a semi-transparent radio forwarding frames between a ground
//!   station (A) and a vehicle (B) and injecting RADIO_STATUS, MAVLink 1 until it has seen
//!   MAVLink 2.
//!
//! The version logic lives in `mavstack-channel`; these commands only move frames and decide
//! what to answer.

use core::time::Duration;
use std::collections::BTreeMap;

use anyhow::anyhow;
use clap::{Args, ValueEnum};
use mavstack_channel::{
    Authentication, CommandEncoding, Config, Event, HandshakeMethod, HandshakeResult, LinkStats,
    Radio, RadioConfig, Side, SigningConfig, Target, VehicleVersion,
};
use mavstack_core::signing::SecretKey;
use mavstack_core::wire::{MAX_FRAME_LEN, Version};
use mavstack_core::{Message, MessageSet};
use mavstack_dialects::common::{
    AutopilotVersion, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavMessage,
    MavProtocolCapability, MavType,
};
use mavstack_services::Address;
use mavstack_services::param::{Name, Value};
use mavstack_transport::channel_protocol::{
    ChannelCommand, ChannelEvent, ChannelEventKind, ChannelProtocol, RawMessage,
};
use mavstack_transport::{
    ConnSpec, Connection, Dest, FrameBuf, FrameCommand, FrameEvent, FrameProtocol, PeerId, clock,
};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::link_cmd::{interrupted, parse_spec, runtime, seconds};
use crate::sim::{SimConfig, Vehicle, params};
use crate::{Failure, other};

/// A message's name in the common dialect, or its number when the dialect has none.
pub(crate) fn message_name(id: u32) -> String {
    MavMessage::info(id).map_or_else(|| format!("message {id}"), |m| m.name.to_owned())
}

/// The autopilot a simulated vehicle claims to be.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Autopilot {
    /// ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA, 3).
    Ardupilot,
    /// PX4 (MAV_AUTOPILOT_PX4, 12).
    Px4,
}

impl core::fmt::Display for Autopilot {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Ardupilot => "ArduPilot",
            Self::Px4 => "PX4",
        })
    }
}

#[derive(Debug, Args)]
pub(crate) struct VehicleArgs {
    /// The vehicle's side of the link: udpout:HOST:PORT sends to a ground station listening
    /// there, udpin:HOST:PORT waits for one, tcpin:HOST:PORT serves TCP.
    conn: String,
    /// System id.
    #[arg(long, default_value_t = 1)]
    sysid: u8,
    /// Component id.
    #[arg(long, default_value_t = 1)]
    compid: u8,
    /// Which autopilot to claim.
    #[arg(long, value_enum, default_value = "ardupilot")]
    autopilot: Autopilot,
    /// MAVLink 1 only: refuse the handshake (failure COMMAND_ACK), never switch.
    #[arg(long, conflicts_with_all = ["start_mavlink2", "sign_key"])]
    mavlink1_only: bool,
    /// Send MAVLink 2 from the start (default: MAVLink 1 until a MAVLink 2 frame arrives).
    #[arg(long)]
    start_mavlink2: bool,
    /// Sign every frame with this key (64 hex digits) and accept only signed frames
    /// (RADIO_STATUS excepted); signed MAVLink 2 from the first frame.
    #[arg(long)]
    sign_key: Option<String>,
    /// Signing link id.
    #[arg(long, default_value_t = 0)]
    link_id: u8,
    /// Never answer the handshake (no PROTOCOL_VERSION support): neither ACK nor answer.
    #[arg(long)]
    no_protocol_version: bool,
    /// Treat the link as secure (a USB cable): accept SETUP_SIGNING on it.
    #[arg(long)]
    secure: bool,
    /// Parameter table to serve instead of the flavour's defaults: one `NAME VALUE`,
    /// `NAME,VALUE` or QGroundControl `SYSID COMPID NAME VALUE TYPE` line per parameter.
    #[arg(long, value_name = "FILE")]
    params: Option<String>,
    /// Print what happens (link versions, handshakes, rejections, modes, parameter sets,
    /// plans) to stderr.
    #[arg(long, short)]
    verbose: bool,
}

/// How the probe runs the handshake.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Method {
    /// MAV_CMD_REQUEST_MESSAGE with param1 = 300 (PROTOCOL_VERSION).
    #[value(name = "request-message-300")]
    RequestMessage300,
    /// MAV_CMD_REQUEST_PROTOCOL_VERSION.
    RequestProtocolVersion,
    /// MAV_CMD_REQUEST_MESSAGE for another message the target sends (`--other-id`, ≥ 256).
    RequestMessageOther,
}

#[derive(Debug, Args)]
pub(crate) struct ProbeArgs {
    /// The ground station's side of the link (udpin:HOST:PORT waits for vehicles,
    /// udpout:HOST:PORT reaches one listening there, tcp:HOST:PORT, serial:...).
    conn: String,
    /// Seconds to wait for the first system.
    #[arg(long, default_value_t = 5.0)]
    timeout: f64,
    /// Handshake request.
    #[arg(long, value_enum, default_value = "request-message-300")]
    method: Method,
    /// With `--method request-message-other`: the message to ask for (id ≥ 256).
    #[arg(long, default_value_t = 397)]
    other_id: u32,
    /// Send the requests as COMMAND_INT instead of COMMAND_LONG.
    #[arg(long)]
    command_int: bool,
    /// Sign with this key (64 hex digits): talk to vehicles that accept only signed frames.
    #[arg(long)]
    key: Option<String>,
    /// Signing link id (with `--key`).
    #[arg(long, default_value_t = 0)]
    link_id: u8,
    /// Our system id.
    #[arg(long, default_value_t = 255)]
    sysid: u8,
    /// Our component id.
    #[arg(long, default_value_t = 190)]
    compid: u8,
}

#[derive(Debug, Args)]
pub(crate) struct RadioArgs {
    /// The ground station's side.
    conn_a: String,
    /// The vehicle's side.
    conn_b: String,
    /// Seconds between RADIO_STATUS frames.
    #[arg(long, default_value_t = 1.0)]
    interval: f64,
    /// Print the radio's events to stderr.
    #[arg(long, short)]
    verbose: bool,
}

pub(crate) fn secret_key(hex: &str, what: &str) -> Result<SecretKey, Failure> {
    SecretKey::from_hex(hex).map_err(|e| Failure::Input(anyhow!("{what}: {e}")))
}

/// The vehicle's settings, shared by `mavstack vehicle` and `mavstack demo`.
#[derive(Clone, Debug)]
pub(crate) struct VehicleSetup {
    pub(crate) sysid: u8,
    pub(crate) compid: u8,
    pub(crate) autopilot: Autopilot,
    pub(crate) version: VehicleVersion,
    pub(crate) signing: Option<SigningConfig>,
    pub(crate) protocol_version: bool,
    pub(crate) secure: bool,
    /// The parameter table (the flavour's defaults unless a file replaced them).
    pub(crate) params: Vec<(Name, Value)>,
}

impl VehicleSetup {
    fn config(&self) -> Config {
        let mut config = Config::vehicle(self.sysid, self.compid);
        config.signing.clone_from(&self.signing);
        config.secure = self.secure;
        if let Some(policy) = config.vehicle_policy_mut() {
            policy.version = self.version;
            if !self.protocol_version {
                policy.protocol_version = None;
            }
        }
        config
    }

    fn sim(&self) -> SimConfig {
        SimConfig {
            own: Address::new(self.sysid, self.compid),
            autopilot: self.autopilot,
            mavlink2: self.version != VehicleVersion::Mavlink1Only,
            params: self.params.clone(),
        }
    }
}

/// One line of what happened, for `--verbose` and the demo's timeline.
pub(crate) type Log = Option<mpsc::UnboundedSender<String>>;

fn say(log: &Log, line: impl FnOnce() -> String) {
    if let Some(tx) = log {
        let _ = tx.send(line());
    }
}

pub(crate) fn version_name(v: Version) -> &'static str {
    match v {
        Version::V1 => "MAVLink 1",
        Version::V2 => "MAVLink 2",
    }
}

/// Opens the vehicle's link.
pub(crate) async fn open_vehicle(
    setup: &VehicleSetup,
    spec: &ConnSpec,
) -> Result<Connection<ChannelProtocol>, Failure> {
    let protocol = ChannelProtocol::new(setup.config())
        .map_err(|e| Failure::Input(anyhow!("vehicle configuration: {e}")))?;
    Connection::open(spec, protocol).await.map_err(other)
}

/// Where the services' messages go: the peers each address was last heard on.
#[derive(Debug, Default)]
pub(crate) struct Routes {
    peers: BTreeMap<Address, PeerId>,
}

impl Routes {
    /// Notes that `from` speaks on `peer`.
    pub(crate) fn heard(&mut self, from: Address, peer: PeerId) {
        self.peers.insert(from, peer);
    }

    /// Forgets a peer that went away.
    pub(crate) fn forget(&mut self, peer: PeerId) {
        self.peers.retain(|_, p| *p != peer);
    }

    /// The link(s) a message for `target` goes out on: the peer it was heard on, else all.
    pub(crate) fn dest(&self, target: Address) -> Dest {
        if target.system == 0 {
            return Dest::All;
        }
        let exact = self.peers.get(&target).copied();
        let same_system = || {
            self.peers
                .iter()
                .find(|(a, _)| a.system == target.system)
                .map(|(_, p)| *p)
        };
        exact.or_else(same_system).map_or(Dest::All, Dest::Peer)
    }
}

/// The services' time: microseconds since `start`.
pub(crate) fn service_time(start: Instant) -> mavstack_core::time::Instant {
    let us = u64::try_from(start.elapsed().as_micros()).unwrap_or(u64::MAX);
    mavstack_core::time::Instant::from_micros(us)
}

/// Runs a simulated vehicle on `conn` (from [`open_vehicle`]) until `stop` resolves; returns
/// the statistics of its links. `tap` gets a copy of every signed COMMAND_LONG the vehicle
/// accepts (the demo replays one).
pub(crate) async fn run_vehicle(
    setup: VehicleSetup,
    mut conn: Connection<ChannelProtocol>,
    log: Log,
    tap: Option<mpsc::UnboundedSender<Vec<u8>>>,
    stop: impl Future<Output = ()>,
) -> Result<Vec<LinkStats>, Failure> {
    let start = Instant::now();
    let mut sim = Vehicle::new(setup.sim(), service_time(start));
    let mut routes = Routes::default();
    say(&log, || {
        format!(
            "vehicle: {} flavour, {} parameters",
            setup.autopilot,
            sim.param_count()
        )
    });
    tokio::pin!(stop);
    loop {
        while let Some(out) = sim.poll_transmit() {
            let message = ChannelCommand::Send {
                dest: routes.dest(out.target),
                message: RawMessage::of(&out.message),
            };
            conn.send(message).await.map_err(other)?;
        }
        while let Some(line) = sim.poll_log() {
            say(&log, || format!("vehicle: {line}"));
        }
        let wake = start + Duration::from_micros(sim.poll_timeout().as_micros());
        let event: ChannelEvent = tokio::select! {
            () = &mut stop => break,
            () = tokio::time::sleep_until(wake) => {
                sim.handle_timeout(service_time(start));
                continue;
            }
            e = conn.recv() => match e {
                Some(e) => e,
                None => break,
            },
        };
        let peer = event.peer;
        let event = match event.event {
            ChannelEventKind::Channel(event) => event,
            ChannelEventKind::CommandFailed(why) => {
                say(&log, || format!("vehicle: {why}"));
                continue;
            }
            ChannelEventKind::PeerRemoved => {
                routes.forget(peer);
                continue;
            }
            ChannelEventKind::PeerAdded(_) => {
                if let Some(hello) = sim.greeting(service_time(start)) {
                    let hello = ChannelCommand::Send {
                        dest: Dest::Peer(peer),
                        message: RawMessage::of(&hello),
                    };
                    conn.send(hello).await.map_err(other)?;
                }
                continue;
            }
            _ => continue,
        };
        match event {
            Event::Frame(rf) => {
                if let Some(tap) = &tap
                    && rf.frame.is_signed()
                    && rf.frame.msg_id() == CommandLong::ID
                {
                    let _ = tap.send(rf.frame.as_bytes().to_vec());
                }
                // Handshake requests are the channel's (answered, refused or ignored).
                if rf.protocol_version_request.is_some() || rf.answered {
                    continue;
                }
                let from = Address::new(rf.frame.sysid(), rf.frame.compid());
                routes.heard(from, peer);
                let Ok(message) = MavMessage::decode(rf.frame.msg_id(), rf.frame.payload()) else {
                    continue;
                };
                if let MavMessage::CommandLong(CommandLong {
                    command, param1, ..
                }) = &message
                    && (*command == MavCmd::REQUEST_AUTOPILOT_CAPABILITIES
                        || (*command == MavCmd::REQUEST_MESSAGE
                            && *param1 == AutopilotVersion::ID as f32))
                {
                    say(&log, || {
                        format!(
                            "vehicle ← AUTOPILOT_VERSION requested ({})",
                            version_name(rf.frame.version())
                        )
                    });
                }
                sim.handle_message(service_time(start), from, &message);
            }
            Event::VersionChanged { from, to, cause } => {
                say(&log, || format!("vehicle: link {from} → {to} ({cause})"));
            }
            Event::ProtocolVersionRequested { answer, .. } => {
                say(&log, || format!("vehicle ← handshake request: {answer}"));
            }
            Event::Rejected(r) => {
                say(&log, || {
                    format!(
                        "vehicle ✗ rejected {}: {}",
                        message_name(r.msg_id),
                        r.reason
                    )
                });
            }
            Event::SigningSetup { setup: s, .. } => {
                say(&log, || match s {
                    mavstack_channel::SigningSetup::Enabled { .. } => {
                        "vehicle: SETUP_SIGNING accepted, link signed from now on".to_owned()
                    }
                    mavstack_channel::SigningSetup::Disabled => {
                        "vehicle: SETUP_SIGNING turned signing off".to_owned()
                    }
                });
            }
            _ => {}
        }
    }
    let links = conn
        .stats()
        .protocol
        .links
        .into_iter()
        .map(|(_, stats)| stats)
        .collect();
    conn.close().await.map_err(other)?;
    Ok(links)
}

/// Prints `--verbose` lines to stderr as they come.
fn stderr_log(on: bool) -> Log {
    on.then(|| {
        let (tx, mut rx) = mpsc::unbounded_channel::<String>();
        tokio::spawn(async move {
            while let Some(line) = rx.recv().await {
                eprintln!("{line}");
            }
        });
        tx
    })
}

pub(crate) fn vehicle(args: &VehicleArgs) -> Result<(), Failure> {
    let spec = parse_spec(&args.conn)?;
    let signing = args
        .sign_key
        .as_deref()
        .map(|k| secret_key(k, "--sign-key").map(|key| SigningConfig::new(key, args.link_id)))
        .transpose()?;
    if args.sysid == 0 || args.compid == 0 {
        return Err(Failure::Input(anyhow!(
            "--sysid and --compid must be 1 to 255"
        )));
    }
    let version = if args.mavlink1_only {
        VehicleVersion::Mavlink1Only
    } else if args.start_mavlink2 {
        VehicleVersion::Mavlink2
    } else {
        VehicleVersion::StartMavlink1
    };
    let params = match &args.params {
        Some(path) => params::load(path).map_err(Failure::Input)?,
        None => params::defaults(args.autopilot),
    };
    let setup = VehicleSetup {
        sysid: args.sysid,
        compid: args.compid,
        autopilot: args.autopilot,
        version,
        signing,
        protocol_version: !args.no_protocol_version,
        secure: args.secure,
        params,
    };
    runtime()?.block_on(async {
        let log = stderr_log(args.verbose);
        let conn = open_vehicle(&setup, &spec).await?;
        run_vehicle(setup, conn, log, None, interrupted())
            .await
            .map(drop)
    })
}

/// What the probe learnt about one system.
#[derive(Debug)]
struct System {
    peer: PeerId,
    autopilot: u8,
    kind: u8,
    version_before: Version,
    version_after: Option<Version>,
    capability: Option<bool>,
    signed: bool,
    handshake: Option<&'static str>,
}

struct Probe {
    conn: Connection<ChannelProtocol>,
    systems: BTreeMap<(u8, u8), System>,
    outcomes: BTreeMap<PeerId, HandshakeResult>,
    /// Heartbeats seen after each system's handshake ended.
    after: BTreeMap<(u8, u8), Version>,
    handshake_done: BTreeMap<(u8, u8), bool>,
}

impl Probe {
    async fn send(&self, command: ChannelCommand) -> Result<(), Failure> {
        self.conn.send(command).await.map_err(other)
    }

    /// Takes events until `until`, recording what they say.
    async fn pump(&mut self, until: Instant) -> Result<(), Failure> {
        loop {
            let event = tokio::select! {
                () = tokio::time::sleep_until(until) => return Ok(()),
                e = self.conn.recv() => match e {
                    Some(e) => e,
                    None => return Err(Failure::Other(anyhow!("the link closed"))),
                },
            };
            self.note(event);
        }
    }

    fn note(&mut self, event: ChannelEvent) {
        let peer = event.peer;
        let ChannelEventKind::Channel(event) = event.event else {
            return;
        };
        match event {
            Event::Frame(rf) => {
                let f = &rf.frame;
                let key = (f.sysid(), f.compid());
                let signed = !matches!(
                    rf.auth,
                    Authentication::Unsigned | Authentication::AllowedUnsigned
                );
                if f.msg_id() == Heartbeat::ID {
                    let hb = Heartbeat::decode(f.payload());
                    if hb.r#type == MavType::GCS {
                        return;
                    }
                    let system = self.systems.entry(key).or_insert(System {
                        peer,
                        autopilot: hb.autopilot.0,
                        kind: hb.r#type.0,
                        version_before: f.version(),
                        version_after: None,
                        capability: None,
                        signed: false,
                        handshake: None,
                    });
                    system.signed |= signed && f.is_signed();
                    if self.handshake_done.get(&key).copied().unwrap_or(false) {
                        self.after.entry(key).or_insert(f.version());
                    }
                } else if let Some(system) = self.systems.get_mut(&key) {
                    system.signed |= f.is_signed();
                    if f.msg_id() == AutopilotVersion::ID {
                        let av = AutopilotVersion::decode(f.payload());
                        system.capability =
                            Some(av.capabilities.0 & MavProtocolCapability::MAVLINK2.0 != 0);
                    }
                }
            }
            Event::Handshake(outcome) => {
                self.outcomes.insert(peer, outcome.result);
            }
            _ => {}
        }
    }
}

fn report(key: (u8, u8), s: &System, method: &str) -> String {
    let v = |v: Version| v.number();
    let capability = s
        .capability
        .map_or_else(|| "null".to_owned(), |c| c.to_string());
    format!(
        "{{\"sysid\":{},\"compid\":{},\"autopilot\":{},\"type\":{},\"version_before\":{},\"version_after\":{},\"handshake\":{{\"method\":\"{method}\",\"result\":\"{}\"}},\"mavlink2_capability\":{capability},\"signed\":{}}}",
        key.0,
        key.1,
        s.autopilot,
        s.kind,
        v(s.version_before),
        v(s.version_after.unwrap_or(s.version_before)),
        s.handshake.unwrap_or("timeout"),
        s.signed
    )
}

pub(crate) fn probe(args: &ProbeArgs) -> Result<(), Failure> {
    let spec = parse_spec(&args.conn)?;
    let wait = seconds(args.timeout, "--timeout")?;
    if args.method == Method::RequestMessageOther && args.other_id < 256 {
        return Err(Failure::Input(anyhow!(
            "--other-id: {} is below 256",
            args.other_id
        )));
    }
    let method = match args.method {
        Method::RequestMessage300 => HandshakeMethod::RequestMessage300,
        Method::RequestProtocolVersion => HandshakeMethod::RequestProtocolVersion,
        Method::RequestMessageOther => HandshakeMethod::RequestMessageOther {
            msg_id: args.other_id,
        },
    };
    let encoding = if args.command_int {
        CommandEncoding::Int
    } else {
        CommandEncoding::Long
    };
    let mut config = Config::ground_station(args.sysid, args.compid);
    config.signing = args
        .key
        .as_deref()
        .map(|k| secret_key(k, "--key").map(|key| SigningConfig::new(key, args.link_id)))
        .transpose()?;
    let protocol =
        ChannelProtocol::new(config).map_err(|e| Failure::Input(anyhow!("probe: {e}")))?;
    runtime()?.block_on(async {
        let conn = Connection::open(&spec, protocol).await.map_err(other)?;
        let mut probe = Probe {
            conn,
            systems: BTreeMap::new(),
            outcomes: BTreeMap::new(),
            after: BTreeMap::new(),
            handshake_done: BTreeMap::new(),
        };
        let gcs_heartbeat = RawMessage::new(&Heartbeat {
            r#type: MavType::GCS,
            autopilot: MavAutopilot::INVALID,
            mavlink_version: 3,
            ..Heartbeat::default()
        });
        // 1. Find the systems: heartbeats until the first, then a little longer for others.
        let give_up = Instant::now() + wait;
        while probe.systems.is_empty() && Instant::now() < give_up {
            probe.send(ChannelCommand::to_all(gcs_heartbeat)).await?;
            let next = (Instant::now() + Duration::from_millis(500)).min(give_up);
            probe.pump(next).await?;
        }
        if probe.systems.is_empty() {
            probe.conn.close().await.map_err(other)?;
            return Err(Failure::Other(anyhow!(
                "no system found on {} within {} s",
                args.conn,
                args.timeout
            )));
        }
        probe
            .pump(Instant::now() + Duration::from_millis(1200))
            .await?;
        let keys: Vec<(u8, u8)> = probe.systems.keys().copied().collect();
        let method_name = method.name();
        for key in keys {
            let Some(peer) = probe.systems.get(&key).map(|s| s.peer) else {
                continue;
            };
            // 2. AUTOPILOT_VERSION, in the link's current framing.
            let request = RawMessage::new(&CommandLong {
                target_system: key.0,
                target_component: key.1,
                command: MavCmd::REQUEST_MESSAGE,
                param1: AutopilotVersion::ID as f32,
                ..CommandLong::default()
            });
            for _ in 0..3 {
                probe
                    .send(ChannelCommand::Send {
                        dest: Dest::Peer(peer),
                        message: request,
                    })
                    .await?;
                probe
                    .pump(Instant::now() + Duration::from_millis(400))
                    .await?;
                if probe
                    .systems
                    .get(&key)
                    .is_some_and(|s| s.capability.is_some())
                {
                    break;
                }
            }
            // 3. The handshake; the channel retries and times out by itself.
            probe.outcomes.remove(&peer);
            probe
                .send(ChannelCommand::StartHandshake {
                    peer,
                    target: Target::new(key.0, key.1),
                    method,
                    encoding,
                })
                .await?;
            let deadline = Instant::now() + Duration::from_secs(5);
            while !probe.outcomes.contains_key(&peer) && Instant::now() < deadline {
                probe
                    .pump(Instant::now() + Duration::from_millis(100))
                    .await?;
            }
            let result = probe.outcomes.get(&peer).map(HandshakeResult::name);
            probe.handshake_done.insert(key, true);
            // 4. The version the system uses now: its next heartbeat.
            let deadline = Instant::now() + Duration::from_millis(2500);
            while !probe.after.contains_key(&key) && Instant::now() < deadline {
                probe.send(ChannelCommand::to_all(gcs_heartbeat)).await?;
                probe
                    .pump(Instant::now() + Duration::from_millis(250))
                    .await?;
            }
            if let Some(system) = probe.systems.get_mut(&key) {
                system.handshake = result;
                system.version_after = probe.after.get(&key).copied();
            }
        }
        for (key, system) in &probe.systems {
            println!("{}", report(*key, system, method_name));
        }
        probe.conn.close().await.map_err(other)?;
        Ok(())
    })
}

/// A radio side: frames of any id, forwarded as they are.
pub(crate) type RadioLink = Connection<FrameProtocol<fn(u32) -> Option<u8>>>;

pub(crate) async fn open_radio_side(spec: &ConnSpec) -> Result<RadioLink, Failure> {
    let lookup: fn(u32) -> Option<u8> = mavstack_transport::frame::crc_extra_of::<MavMessage>;
    Connection::open(
        spec,
        FrameProtocol::new(lookup)
            .keep_unknown(true)
            .peer_events(false),
    )
    .await
    .map_err(other)
}

/// Runs a semi-transparent radio between `side_a` (ground) and `side_b` (vehicle) until
/// `stop`.
pub(crate) async fn run_radio(
    mut side_a: RadioLink,
    mut side_b: RadioLink,
    interval: Duration,
    log: Log,
    stop: impl Future<Output = ()>,
) -> Result<(), Failure> {
    let mut config = RadioConfig::default();
    config.interval = interval;
    let mut radio = Radio::new(config);
    tokio::pin!(stop);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut last_injected = None;
    loop {
        let wake = radio
            .poll_timeout()
            .map(|t| t.as_micros().saturating_sub(clock::now().as_micros()))
            .map_or(Duration::from_secs(1), Duration::from_micros);
        let (side, event) = tokio::select! {
            () = &mut stop => break,
            () = tokio::time::sleep(wake) => {
                radio.handle_timeout(clock::now());
                (None, None)
            }
            e = side_a.recv() => (Some(Side::A), e),
            e = side_b.recv() => (Some(Side::B), e),
        };
        if let Some(side) = side {
            let Some(event) = event else { break };
            if let FrameEvent::Frame(f) | FrameEvent::Unknown(f) = event {
                let mut rest = f.frame.as_bytes();
                while !rest.is_empty() {
                    let taken = radio.handle_input(clock::now(), side, rest);
                    rest = &rest[taken..];
                    if taken == 0 {
                        break;
                    }
                }
            }
        }
        while let Some(mavstack_channel::RadioEvent::FirstMavlink2 { from }) = radio.poll_event() {
            say(&log, || {
                format!(
                    "radio: first MAVLink 2 frame (from side {from:?}); RADIO_STATUS in MAVLink 2 from now on"
                )
            });
        }
        while let Some(t) = radio.poll_transmit(clock::now(), &mut buf) {
            let Ok(frame) = FrameBuf::new(&buf[..t.len]) else {
                continue;
            };
            if t.injected && last_injected != Some(t.version) {
                last_injected = Some(t.version);
                say(&log, || {
                    format!(
                        "radio → RADIO_STATUS ({}), every {interval:?}",
                        version_name(t.version)
                    )
                });
            }
            let conn = if t.to == Side::A { &side_a } else { &side_b };
            conn.send(FrameCommand::to_all(frame))
                .await
                .map_err(other)?;
        }
    }
    side_a.close().await.map_err(other)?;
    side_b.close().await.map_err(other)?;
    Ok(())
}

pub(crate) fn radio(args: &RadioArgs) -> Result<(), Failure> {
    let a = parse_spec(&args.conn_a)?;
    let b = parse_spec(&args.conn_b)?;
    let interval = seconds(args.interval, "--interval")?;
    runtime()?.block_on(async {
        let log = stderr_log(args.verbose);
        let side_a = open_radio_side(&a).await?;
        let side_b = open_radio_side(&b).await?;
        run_radio(side_a, side_b, interval, log, interrupted()).await
    })
}
