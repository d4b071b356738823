//! Probing a link: the ground station's side of the MAVLink versions rules. Which systems
//! are on the link, how each frames its HEARTBEAT before and after the MAVLink 2 handshake,
//! how the handshake ended, the MAVLINK2 bit of its AUTOPILOT_VERSION and whether it signs.
//! `mavstack probe` prints [`ProbedSystem`]s as JSON (`docs/contracts/cli.md`).
//!
//! The conversation, on a ground station's node:
//!
//! 1. HEARTBEATs (a GCS's are ignored) until the first system, then 1.2 s longer for
//!    others;
//! 2. for each system, in order of its ids: REQUEST_MESSAGE for AUTOPILOT_VERSION in the
//!    link's current framing, up to three times;
//! 3. the handshake ([`NodeHandle::handshake`]: the method asked for, with the fallback to
//!    AUTOPILOT_VERSION in MAVLink 2 when PROTOCOL_VERSION is refused or unanswered);
//! 4. the framing of the system's next HEARTBEAT.
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::LinkSpec;
//! use mavstack::probe::{self, ProbeOptions};
//! let spec = LinkSpec::parse("udpin:0.0.0.0:14550", &|_| None)?;
//! for system in probe::run(spec, &ProbeOptions::default()).await? {
//!     println!(
//!         "{}/{}: MAVLink {} then {}",
//!         system.system_id,
//!         system.component_id,
//!         system.version_before.number(),
//!         system.version_after.number()
//!     );
//! }
//! # Ok(()) }
//! ```

use core::time::Duration;
use std::collections::BTreeMap;

use mavstack_channel::{
    Authentication, CommandEncoding, FallbackReason, HandshakeMethod, HandshakeOutcome,
    HandshakeResult, Target,
};
use mavstack_core::Message as _;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{
    AutopilotVersion, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavMessage,
    MavProtocolCapability, MavType,
};
use mavstack_router::LinkId;
use tokio::time::Instant;

use crate::node::{EventSubscription, Incoming, LinkEvent, NodeError, NodeHandle, Subscription};
use crate::{LinkSpec, Node};

/// How long the probe listens for more systems after the first.
const SETTLE: Duration = Duration::from_millis(1200);
/// How often AUTOPILOT_VERSION is asked for, and how long each answer is waited for.
const VERSION_REQUESTS: (usize, Duration) = (3, Duration::from_millis(400));
/// How long a handshake may take (the link retries and gives up well before).
const HANDSHAKE_LIMIT: Duration = Duration::from_secs(6);
/// How long the probe waits for the HEARTBEAT after the handshake.
const NEXT_HEARTBEAT: Duration = Duration::from_millis(2500);
/// How often the waits look at the clock.
const STEP: Duration = Duration::from_millis(100);
/// The period of our own HEARTBEAT on a link [`run`] opens: a vehicle waiting on `udpin`
/// learns the ground station at once.
const HEARTBEAT_PERIOD: Duration = Duration::from_millis(500);

/// How a probe runs.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct ProbeOptions {
    /// Our system id on a link [`run`] opens (default 255, a ground station's).
    pub system_id: u8,
    /// Our component id on a link [`run`] opens (default 190).
    pub component_id: u8,
    /// How long to wait for the first system (default 5 s).
    pub wait: Duration,
    /// The handshake's request (default REQUEST_MESSAGE(300)).
    pub method: HandshakeMethod,
    /// COMMAND_LONG or COMMAND_INT for the handshake's requests (default COMMAND_LONG).
    pub encoding: CommandEncoding,
}

impl Default for ProbeOptions {
    fn default() -> Self {
        Self {
            system_id: 255,
            component_id: 190,
            wait: Duration::from_secs(5),
            method: HandshakeMethod::RequestMessage300,
            encoding: CommandEncoding::Long,
        }
    }
}

impl ProbeOptions {
    /// Our ids on the link.
    #[must_use]
    pub const fn identity(mut self, system_id: u8, component_id: u8) -> Self {
        self.system_id = system_id;
        self.component_id = component_id;
        self
    }

    /// How long to wait for the first system.
    #[must_use]
    pub const fn wait(mut self, wait: Duration) -> Self {
        self.wait = wait;
        self
    }

    /// The handshake's request and how it is sent.
    #[must_use]
    pub const fn handshake(mut self, method: HandshakeMethod, encoding: CommandEncoding) -> Self {
        self.method = method;
        self.encoding = encoding;
        self
    }
}

/// What the probe learnt about one system (a HEARTBEAT's system and component).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct ProbedSystem {
    /// Its system id.
    pub system_id: u8,
    /// Its component id.
    pub component_id: u8,
    /// The autopilot its first HEARTBEAT names.
    pub autopilot: MavAutopilot,
    /// The vehicle type its first HEARTBEAT names.
    pub kind: MavType,
    /// The framing of its HEARTBEATs before the handshake.
    pub version_before: Version,
    /// The framing of its first HEARTBEAT after the handshake; the one before when none came.
    pub version_after: Version,
    /// How the handshake ended; `None` when it did not end in time.
    pub handshake: Option<HandshakeOutcome>,
    /// The request that decided the handshake: the fallback's
    /// ([`HandshakeMethod::RequestMessageOther`]) when its message proved MAVLink 2, else the
    /// one asked for.
    pub handshake_method: HandshakeMethod,
    /// `Some(false)` when the system refused or ignored PROTOCOL_VERSION and the fallback
    /// showed MAVLink 2, or when it refused it outright; `None` when nothing says so.
    pub protocol_version_supported: Option<bool>,
    /// The MAVLINK2 bit of its AUTOPILOT_VERSION; `None` when AUTOPILOT_VERSION never came.
    pub mavlink2_capability: Option<bool>,
    /// Whether its frames were signed.
    pub signed: bool,
}

impl ProbedSystem {
    /// The handshake's result as reports name it (`protocol_version`, `message_v2`, `nack`,
    /// `timeout`): `timeout` too when it did not end in time.
    #[must_use]
    pub fn handshake_result(&self) -> &'static str {
        self.handshake
            .as_ref()
            .map_or(HandshakeResult::Timeout { acked: false }.name(), |o| {
                o.result.name()
            })
    }
}

/// Why a probe found nothing to report.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ProbeError {
    /// The link could not be opened.
    #[error("cannot open {link}")]
    Open {
        /// The link as shown to people (its key redacted).
        link: String,
        /// Why.
        #[source]
        source: NodeError,
    },
    /// No system's HEARTBEAT in time.
    #[error("no system found on {link} within {} s", wait.as_secs_f64())]
    NotFound {
        /// The link as shown to people (its key redacted).
        link: String,
        /// How long the probe waited.
        wait: Duration,
    },
    /// The node stopped while the probe ran.
    #[error("the link closed")]
    Closed,
    /// The node, stopped at the end, reports a failure (a link failed).
    #[error("closing the link")]
    Close(#[source] NodeError),
}

/// Opens `spec` as a ground station (our ids from `options`, a GCS HEARTBEAT twice a
/// second), probes it as [`run_on`] does and closes it. The reports are in order of their
/// ids.
///
/// # Errors
/// [`ProbeError::Open`], [`ProbeError::NotFound`] (both name the link with its key
/// redacted), [`ProbeError::Closed`], [`ProbeError::Close`].
pub async fn run(spec: LinkSpec, options: &ProbeOptions) -> Result<Vec<ProbedSystem>, ProbeError> {
    let link = spec.redacted().to_owned();
    let gcs = Heartbeat {
        r#type: MavType::GCS,
        autopilot: MavAutopilot::INVALID,
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let node = Node::ground_station(options.system_id, options.component_id)
        .heartbeat(&gcs, HEARTBEAT_PERIOD)
        .link(spec)
        .start()
        .await
        .map_err(|source| ProbeError::Open {
            link: link.clone(),
            source,
        })?;
    let probed = run_on(&node.handle(), options).await;
    let closed = node.shutdown().await;
    let systems = probed?;
    if systems.is_empty() {
        return Err(ProbeError::NotFound {
            link,
            wait: options.wait,
        });
    }
    closed.map_err(ProbeError::Close)?;
    Ok(systems)
}

/// Probes the ground-station links of a running node: every system heard on any of them,
/// in order of their ids; none when no system was heard within [`ProbeOptions::wait`].
///
/// # Errors
/// [`ProbeError::Closed`] when the node stops.
pub async fn run_on(
    node: &NodeHandle,
    options: &ProbeOptions,
) -> Result<Vec<ProbedSystem>, ProbeError> {
    let mut probe = Probe {
        frames: node.subscribe().await,
        events: node.events().await,
        node: node.clone(),
        systems: BTreeMap::new(),
        outcomes: BTreeMap::new(),
    };
    let give_up = Instant::now() + options.wait;
    while probe.systems.is_empty() && Instant::now() < give_up {
        probe.pump((Instant::now() + STEP).min(give_up)).await?;
    }
    if probe.systems.is_empty() {
        return Ok(Vec::new());
    }
    probe.pump(Instant::now() + SETTLE).await?;
    let keys: Vec<(u8, u8)> = probe.systems.keys().copied().collect();
    for key in keys {
        probe.one(key, options).await?;
    }
    Ok(probe
        .systems
        .into_iter()
        .map(|(key, seen)| seen.report(key, options.method))
        .collect())
}

/// What the probe has seen of one system so far.
#[derive(Debug)]
struct Seen {
    link: LinkId,
    autopilot: MavAutopilot,
    kind: MavType,
    version_before: Version,
    capability: Option<bool>,
    signed: bool,
    /// The handshake has ended (or was given up): the next HEARTBEAT is the one after it.
    handshake_done: bool,
    version_after: Option<Version>,
    handshake: Option<HandshakeOutcome>,
}

impl Seen {
    fn report(self, (system_id, component_id): (u8, u8), asked: HandshakeMethod) -> ProbedSystem {
        let (handshake_method, protocol_version_supported) = match &self.handshake {
            None => (asked, None),
            Some(o) => {
                let proved_by_fallback = o.fallback.is_some() && o.result.is_success();
                let refused = matches!(o.fallback, Some(FallbackReason::Refused(_)));
                (
                    if proved_by_fallback {
                        o.request.method
                    } else {
                        asked
                    },
                    (refused || proved_by_fallback).then_some(false),
                )
            }
        };
        ProbedSystem {
            system_id,
            component_id,
            autopilot: self.autopilot,
            kind: self.kind,
            version_before: self.version_before,
            version_after: self.version_after.unwrap_or(self.version_before),
            handshake: self.handshake,
            handshake_method,
            protocol_version_supported,
            mavlink2_capability: self.capability,
            signed: self.signed,
        }
    }
}

/// The probe's subscriptions and what they said.
struct Probe {
    node: NodeHandle,
    frames: Subscription,
    events: EventSubscription,
    systems: BTreeMap<(u8, u8), Seen>,
    /// The last handshake outcome of each link.
    outcomes: BTreeMap<LinkId, HandshakeOutcome>,
}

impl Probe {
    /// Steps 2 to 4 for the system `key`.
    async fn one(&mut self, key: (u8, u8), options: &ProbeOptions) -> Result<(), ProbeError> {
        let Some(link) = self.systems.get(&key).map(|s| s.link) else {
            return Ok(());
        };
        // AUTOPILOT_VERSION, in the link's current framing.
        let request = MavMessage::CommandLong(CommandLong {
            target_system: key.0,
            target_component: key.1,
            command: MavCmd::REQUEST_MESSAGE,
            param1: AutopilotVersion::ID as f32,
            ..CommandLong::default()
        });
        let (times, each) = VERSION_REQUESTS;
        for _ in 0..times {
            self.node.send_on(link, &request).await;
            self.pump(Instant::now() + each).await?;
            if self
                .systems
                .get(&key)
                .is_some_and(|s| s.capability.is_some())
            {
                break;
            }
        }
        // The handshake; the link retries and times out by itself.
        self.outcomes.remove(&link);
        let handshake = {
            let node = self.node.clone();
            let (target, method, encoding) =
                (Target::new(key.0, key.1), options.method, options.encoding);
            tokio::spawn(async move { node.handshake(link, target, method, encoding).await })
        };
        let deadline = Instant::now() + HANDSHAKE_LIMIT;
        while !self.outcomes.contains_key(&link) && Instant::now() < deadline {
            self.pump(Instant::now() + STEP).await?;
        }
        handshake.abort();
        let outcome = self.outcomes.get(&link).copied();
        if let Some(seen) = self.systems.get_mut(&key) {
            seen.handshake = outcome;
            seen.handshake_done = true;
        }
        // The framing the system uses now: its next HEARTBEAT.
        let deadline = Instant::now() + NEXT_HEARTBEAT;
        while self
            .systems
            .get(&key)
            .is_some_and(|s| s.version_after.is_none())
            && Instant::now() < deadline
        {
            self.pump(Instant::now() + STEP).await?;
        }
        Ok(())
    }

    /// Takes what the node reports until `until`, noting what it says.
    async fn pump(&mut self, until: Instant) -> Result<(), ProbeError> {
        loop {
            tokio::select! {
                () = tokio::time::sleep_until(until) => return Ok(()),
                f = self.frames.recv() => self.note(&f.ok_or(ProbeError::Closed)?),
                e = self.events.recv() => {
                    let e = e.ok_or(ProbeError::Closed)?;
                    if let LinkEvent::Handshake(outcome) = e.kind {
                        self.outcomes.insert(e.link_id, outcome);
                    }
                }
            }
        }
    }

    fn note(&mut self, incoming: &Incoming) {
        let rf = &incoming.frame;
        let f = &rf.frame;
        let key = (f.sysid(), f.compid());
        if f.msg_id() == Heartbeat::ID {
            let hb = Heartbeat::decode(f.payload());
            if hb.r#type == MavType::GCS {
                return;
            }
            let verified = !matches!(
                rf.auth,
                Authentication::Unsigned | Authentication::AllowedUnsigned
            );
            let seen = self.systems.entry(key).or_insert(Seen {
                link: incoming.link_id,
                autopilot: hb.autopilot,
                kind: hb.r#type,
                version_before: f.version(),
                capability: None,
                signed: false,
                handshake_done: false,
                version_after: None,
                handshake: None,
            });
            seen.signed |= verified && f.is_signed();
            if seen.handshake_done && seen.version_after.is_none() {
                seen.version_after = Some(f.version());
            }
        } else if let Some(seen) = self.systems.get_mut(&key) {
            seen.signed |= f.is_signed();
            if f.msg_id() == AutopilotVersion::ID {
                let av = AutopilotVersion::decode(f.payload());
                seen.capability = Some(av.capabilities.0 & MavProtocolCapability::MAVLINK2.0 != 0);
            }
        }
    }
}
