//! `mavstack probe`: the ground station's side of the version rules: find the systems on a
//! link, ask for AUTOPILOT_VERSION, run the MAVLink 2 handshake, print one JSON report per
//! system.

use core::time::Duration;
use std::collections::BTreeMap;

use anyhow::anyhow;
use clap::{Args, ValueEnum};
use mavstack::router::LinkId;
use mavstack::{EventSubscription, Incoming, LinkEvent, LinkSpec, NodeHandle, Subscription};
use mavstack_channel::{
    Authentication, CommandEncoding, FallbackReason, HandshakeMethod, HandshakeOutcome,
    SigningConfig, Target,
};
use mavstack_core::Message;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavProtocolCapability, MavType,
};
use tokio::time::Instant;

use crate::link_cmd::{runtime, seconds};
use crate::vehicle_cmd::secret_key;
use crate::{Failure, fail};

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
    /// Seconds to wait for the first system (from 0.001 to 86400).
    #[arg(long, default_value_t = 5.0, value_parser = crate::link_cmd::timeout_arg)]
    timeout: f64,
    /// Handshake request.
    #[arg(long, value_enum, default_value = "request-message-300")]
    method: Method,
    /// With `--method request-message-other`: the message to ask for (id from 256 to
    /// 16777215, a MAVLink 2 id).
    #[arg(long, default_value_t = 397, value_parser = clap::value_parser!(u32).range(256..=16_777_215))]
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

/// What the probe learnt about one system.
#[derive(Debug)]
struct System {
    link: LinkId,
    autopilot: u8,
    kind: u8,
    version_before: Version,
    version_after: Option<Version>,
    capability: Option<bool>,
    signed: bool,
    handshake: Option<HandshakeOutcome>,
}

struct Probe {
    node: NodeHandle,
    frames: Subscription,
    events: EventSubscription,
    systems: BTreeMap<(u8, u8), System>,
    outcomes: BTreeMap<LinkId, HandshakeOutcome>,
    /// Heartbeats seen after each system's handshake ended.
    after: BTreeMap<(u8, u8), Version>,
    handshake_done: BTreeMap<(u8, u8), bool>,
}

impl Probe {
    /// Takes what the node reports until `until`, recording what it says.
    async fn pump(&mut self, until: Instant) -> Result<(), Failure> {
        let closed = || Failure::Other(anyhow!("the link closed"));
        loop {
            tokio::select! {
                () = tokio::time::sleep_until(until) => return Ok(()),
                f = self.frames.recv() => self.note(f.ok_or_else(closed)?),
                e = self.events.recv() => {
                    let e = e.ok_or_else(closed)?;
                    if let LinkEvent::Handshake(outcome) = e.kind {
                        self.outcomes.insert(e.link_id, outcome);
                    }
                }
            }
        }
    }

    fn note(&mut self, incoming: Incoming) {
        let rf = &incoming.frame;
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
                link: incoming.link_id,
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
}

/// The handshake's method and result as the report gives them, and whether PROTOCOL_VERSION
/// is known to be unsupported. The method is the request that decided: the fallback's
/// (`request_message_other`) when its message proved MAVLink 2, else the one asked for.
fn handshake_fields(
    outcome: Option<&HandshakeOutcome>,
    asked: HandshakeMethod,
) -> (&'static str, &'static str, bool) {
    let Some(o) = outcome else {
        return (asked.name(), "timeout", false);
    };
    let method = if o.fallback.is_some() && o.result.is_success() {
        o.request.method.name()
    } else {
        asked.name()
    };
    let unsupported = matches!(o.fallback, Some(FallbackReason::Refused(_)))
        || (o.fallback.is_some() && o.result.is_success());
    (method, o.result.name(), unsupported)
}

fn report(key: (u8, u8), s: &System, asked: HandshakeMethod) -> String {
    let v = |v: Version| v.number();
    let capability = s
        .capability
        .map_or_else(|| "null".to_owned(), |c| c.to_string());
    let (method, result, unsupported) = handshake_fields(s.handshake.as_ref(), asked);
    let supported = if unsupported {
        ",\"protocol_version_supported\":false"
    } else {
        ""
    };
    format!(
        "{{\"sysid\":{},\"compid\":{},\"autopilot\":{},\"type\":{},\"version_before\":{},\"version_after\":{},\"handshake\":{{\"method\":\"{method}\",\"result\":\"{result}\"}},\"mavlink2_capability\":{capability},\"signed\":{}{supported}}}",
        key.0,
        key.1,
        s.autopilot,
        s.kind,
        v(s.version_before),
        v(s.version_after.unwrap_or(s.version_before)),
        s.signed
    )
}

pub(crate) fn probe(args: &ProbeArgs) -> Result<(), Failure> {
    let mut spec = LinkSpec::parse(&args.conn, &|_| None).map_err(|e| Failure::Input(e.into()))?;
    let shown = spec.redacted().to_owned();
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
    spec.config.signing = args
        .key
        .as_deref()
        .map(|k| secret_key(k, "--key").map(|key| SigningConfig::new(key, args.link_id)))
        .transpose()?;
    if args.sysid == 0 || args.compid == 0 {
        return Err(Failure::Input(anyhow!(
            "probe: --sysid and --compid must be 1 to 255"
        )));
    }
    runtime()?.block_on(async {
        // Our HEARTBEAT twice a second: a vehicle waiting on udpin learns us at once.
        let gcs = Heartbeat {
            r#type: MavType::GCS,
            autopilot: MavAutopilot::INVALID,
            mavlink_version: 3,
            ..Heartbeat::default()
        };
        let node = mavstack::Node::ground_station(args.sysid, args.compid)
            .heartbeat(&gcs, Duration::from_millis(500))
            .link(spec)
            .start()
            .await
            .map_err(fail)?;
        let handle = node.handle();
        let mut probe = Probe {
            frames: node.subscribe().await,
            events: handle.events().await,
            node: handle,
            systems: BTreeMap::new(),
            outcomes: BTreeMap::new(),
            after: BTreeMap::new(),
            handshake_done: BTreeMap::new(),
        };
        // 1. Find the systems: heartbeats until the first, then a little longer for others.
        let give_up = Instant::now() + wait;
        while probe.systems.is_empty() && Instant::now() < give_up {
            let next = (Instant::now() + Duration::from_millis(100)).min(give_up);
            probe.pump(next).await?;
        }
        if probe.systems.is_empty() {
            drop(probe);
            node.shutdown().await.map_err(fail)?;
            return Err(Failure::Other(anyhow!(
                "no system found on {} within {} s",
                shown,
                args.timeout
            )));
        }
        probe
            .pump(Instant::now() + Duration::from_millis(1200))
            .await?;
        let keys: Vec<(u8, u8)> = probe.systems.keys().copied().collect();
        for key in keys {
            let Some(link) = probe.systems.get(&key).map(|s| s.link) else {
                continue;
            };
            // 2. AUTOPILOT_VERSION, in the link's current framing.
            let request = CommandLong {
                target_system: key.0,
                target_component: key.1,
                command: MavCmd::REQUEST_MESSAGE,
                param1: AutopilotVersion::ID as f32,
                ..CommandLong::default()
            };
            for _ in 0..3 {
                probe
                    .node
                    .send_on(
                        link,
                        &mavstack_dialects::common::MavMessage::CommandLong(request),
                    )
                    .await;
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
            // 3. The handshake; the link retries and times out by itself.
            probe.outcomes.remove(&link);
            let handshake = {
                let node = probe.node.clone();
                tokio::spawn(async move {
                    node.handshake(link, Target::new(key.0, key.1), method, encoding)
                        .await
                })
            };
            let deadline = Instant::now() + Duration::from_secs(6);
            while !probe.outcomes.contains_key(&link) && Instant::now() < deadline {
                probe
                    .pump(Instant::now() + Duration::from_millis(100))
                    .await?;
            }
            handshake.abort();
            let result = probe.outcomes.get(&link).copied();
            probe.handshake_done.insert(key, true);
            // 4. The version the system uses now: its next heartbeat.
            let deadline = Instant::now() + Duration::from_millis(2500);
            while !probe.after.contains_key(&key) && Instant::now() < deadline {
                probe
                    .pump(Instant::now() + Duration::from_millis(100))
                    .await?;
            }
            if let Some(system) = probe.systems.get_mut(&key) {
                system.handshake = result;
                system.version_after = probe.after.get(&key).copied();
            }
        }
        for (key, system) in &probe.systems {
            println!("{}", report(*key, system, method));
        }
        drop(probe);
        node.shutdown().await.map_err(fail)?;
        Ok(())
    })
}
