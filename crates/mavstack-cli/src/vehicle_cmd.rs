//! `mavstack vehicle`: a simulated vehicle ([`crate::sim`]: parameters, missions, commands,
//! telemetry streams, a kinematic craft) behind the MAVLink 2 handshake, answered (or
//! refused, or ignored) by its link's channel, and signing.
//!
//! The version logic lives in `mavstack-channel`; this command only moves frames and
//! decides what to answer.

use core::time::Duration;
use std::collections::BTreeMap;

use anyhow::anyhow;
use clap::Args;
use mavstack_channel::{Config, Event, LinkStats, SigningConfig, VehicleVersion};
use mavstack_core::signing::SecretKey;
use mavstack_core::wire::Version;
use mavstack_core::{Message, MessageSet};
use mavstack_dialects::common::{AutopilotVersion, CommandLong, MavCmd, MavMessage};
use mavstack_services::Address;
use mavstack_services::param::{Name, Value};
use mavstack_transport::channel_protocol::{
    ChannelCommand, ChannelEvent, ChannelEventKind, ChannelProtocol, RawMessage,
};
use mavstack_transport::{ConnSpec, Connection, Dest, PeerId};
use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::link_cmd::{interrupted, parse_spec, runtime};
use crate::{Failure, other};
use mavstack_sim::Autopilot;
use mavstack_sim::{SimConfig, Vehicle, params};

/// A message's name in the common dialect, or its number when the dialect has none.
pub(crate) fn message_name(id: u32) -> String {
    MavMessage::info(id).map_or_else(|| format!("message {id}"), |m| m.name.to_owned())
}

/// `--autopilot NAME` (the names [`Autopilot`]'s `FromStr` takes).
fn autopilot_arg(name: &str) -> Result<Autopilot, String> {
    name.parse()
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
    /// Which autopilot to claim: ardupilot or px4.
    #[arg(long, default_value = "ardupilot", value_parser = autopilot_arg)]
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

pub(crate) fn say(log: &Log, line: impl FnOnce() -> String) {
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
pub(crate) fn stderr_log(on: bool) -> Log {
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
        Some(path) => params::load(path).map_err(|e| Failure::Input(e.into()))?,
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
