//! Finding a system: [`System::wait`] on a running node, and [`System::connect`], which opens
//! a ground station's link first — the one way every command, binding and example reaches a
//! remote system.

use core::sync::atomic::AtomicU8;
use core::time::Duration;
use std::sync::{Arc, Mutex};

use mavstack_channel::{CommandEncoding, HandshakeMethod, Target};
use mavstack_core::MessageSet as _;
use mavstack_core::wire::Version;
use mavstack_dialects::common::{CommandLong, MavAutopilot, MavCmd, MavMessage, MavType};
use mavstack_router::MessageTable;
use mavstack_services::Address;
use tokio::sync::watch;

use super::state::{self, State};
use super::{Inner, Locks, PATIENT_RETRIES, System, SystemError, Wanted};
use crate::node::{NodeError, NodeHandle, NodeReport};
use crate::{LinkSpec, Node};

/// Who we are on a link [`System::connect`] opens.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct ConnectOptions {
    /// Our system id (default 255, a ground station's).
    pub system_id: u8,
    /// Our component id (default 190, MAV_COMP_ID_MISSIONPLANNER).
    pub component_id: u8,
    /// The dialect frames are read and routed in (default `common`).
    pub dialect: Option<MessageTable>,
}

impl Default for ConnectOptions {
    fn default() -> Self {
        Self {
            system_id: 255,
            component_id: 190,
            dialect: None,
        }
    }
}

impl ConnectOptions {
    /// Our ids on the link.
    #[must_use]
    pub const fn identity(mut self, system_id: u8, component_id: u8) -> Self {
        self.system_id = system_id;
        self.component_id = component_id;
        self
    }

    /// The dialect of the link.
    #[must_use]
    pub fn dialect(mut self, table: MessageTable) -> Self {
        self.dialect = Some(table);
        self
    }
}

/// A ground station's link opened by [`System::connect`] and the system found on it.
#[derive(Debug)]
pub struct Session {
    node: Node,
    system: System,
    started: tokio::time::Instant,
}

impl Session {
    /// The system found.
    #[must_use]
    pub const fn system(&self) -> &System {
        &self.system
    }

    /// The node that holds the link.
    #[must_use]
    pub const fn node(&self) -> &Node {
        &self.node
    }

    /// Time since the link was opened.
    #[must_use]
    pub fn elapsed(&self) -> Duration {
        self.started.elapsed()
    }

    /// Closes the link (the system's handles stop working); returns the node's final report.
    ///
    /// # Errors
    /// [`NodeError`] if a link failed or the log could not be written.
    pub async fn close(self) -> Result<NodeReport, NodeError> {
        drop(self.system);
        self.node.shutdown().await
    }
}

impl System {
    /// Opens `spec` as a ground station (system 255, component 190, a HEARTBEAT every
    /// second) and waits up to `timeout` for the `wanted` system, as [`wait`](Self::wait)
    /// does.
    ///
    /// # Errors
    /// [`SystemError::Open`] (the link cannot be opened), [`SystemError::NotFound`] (it
    /// names the link with its key redacted), [`SystemError::Stopped`].
    pub async fn connect(
        spec: LinkSpec,
        wanted: Wanted,
        timeout: Duration,
    ) -> Result<Session, SystemError> {
        Self::connect_with(spec, wanted, timeout, &ConnectOptions::default()).await
    }

    /// Like [`connect`](Self::connect), as `options` say.
    ///
    /// # Errors
    /// As [`connect`](Self::connect).
    pub async fn connect_with(
        spec: LinkSpec,
        wanted: Wanted,
        timeout: Duration,
        options: &ConnectOptions,
    ) -> Result<Session, SystemError> {
        let shown = spec.redacted().to_owned();
        let started = tokio::time::Instant::now();
        let mut builder = Node::ground_station(options.system_id, options.component_id);
        if let Some(table) = &options.dialect {
            builder = builder.dialect(*table);
        }
        let node = builder
            .link(spec)
            .start()
            .await
            .map_err(|source| SystemError::Open {
                link: shown.clone(),
                source,
            })?;
        match Self::wait(&node.handle(), wanted, timeout).await {
            Ok(system) => Ok(Session {
                node,
                system,
                started,
            }),
            Err(e) => {
                let _ = node.shutdown().await;
                Err(match e {
                    SystemError::NotFound { seconds, .. } => SystemError::NotFound {
                        link: shown,
                        seconds,
                    },
                    e => e,
                })
            }
        }
    }

    /// Waits up to `wait` for the `wanted` system's HEARTBEAT on any link of `node`; if it
    /// came in MAVLink 1 on a ground-station link
    /// ([`LinkRole::GroundStation`](crate::router::LinkRole::GroundStation)), runs the
    /// MAVLink 2 handshake (REQUEST_MESSAGE(300)) there: whatever its outcome, the link goes
    /// on in the version it settles on ([`handshake`](Self::handshake) tells).
    ///
    /// A vehicle that answers requests is found in one round trip: its HEARTBEAT is asked
    /// for at once (MAV_CMD_REQUEST_MESSAGE to the wanted system, or to component 1 of any
    /// system), rather than waiting up to a second for the next one.
    ///
    /// # Errors
    /// [`SystemError::NotFound`], [`SystemError::Stopped`].
    pub async fn wait(
        node: &NodeHandle,
        wanted: Wanted,
        wait: Duration,
    ) -> Result<Self, SystemError> {
        let mut frames = node.subscribe().await;
        ask_for_heartbeats(node, wanted).await;
        let deadline = tokio::time::Instant::now() + wait;
        let found = tokio::time::timeout_at(deadline, async {
            while let Some(incoming) = frames.recv().await {
                let f = incoming.frame.frame.view();
                let Ok(MavMessage::Heartbeat(hb)) = MavMessage::decode(f.msg_id(), f.payload())
                else {
                    continue;
                };
                let ok = match wanted {
                    Wanted::AnyAutopilot => {
                        hb.autopilot != MavAutopilot::INVALID && hb.r#type != MavType::GCS
                    }
                    Wanted::System(s, c) => f.sysid() == s && c.is_none_or(|c| c == f.compid()),
                };
                if ok {
                    let component = match wanted {
                        Wanted::System(_, Some(c)) => c,
                        _ => f.compid(),
                    };
                    let target = Address::new(f.sysid(), component);
                    return Some((incoming.link_id, incoming.link, target, hb, f.version()));
                }
            }
            None
        })
        .await;
        let (link, link_name, target, hb, found_in) = match found {
            Ok(Some(found)) => found,
            Ok(None) => return Err(SystemError::Stopped),
            Err(_) => {
                let names = node.report().await.map_or_else(String::new, |r| {
                    r.links
                        .iter()
                        .map(|l| l.name.clone())
                        .collect::<Vec<_>>()
                        .join(", ")
                });
                return Err(SystemError::NotFound {
                    link: names,
                    seconds: wait.as_secs_f64(),
                });
            }
        };
        let (sysid, compid) = node.identity();
        let own = Address::new(sysid, compid);
        let mut first = State::default();
        first.heartbeat = Some((hb, tokio::time::Instant::now()));
        let (state, _) = watch::channel(first);
        let handshake = if found_in == Version::V1 {
            // A link that cannot handshake (not a ground-station link, version=1) stays as
            // it is.
            node.handshake(
                link,
                Target::new(target.system, target.component),
                HandshakeMethod::RequestMessage300,
                CommandEncoding::Long,
            )
            .await
            .ok()
        } else {
            None
        };
        let tracker = tokio::spawn(state::track(frames, state.clone(), own, target));
        let system = Self {
            inner: Arc::new(Inner {
                node: node.clone(),
                own,
                target,
                link,
                link_name,
                autopilot: hb.autopilot,
                mav_type: hb.r#type,
                found_in,
                handshake,
                state,
                tasks: Mutex::new(vec![tracker.abort_handle()]),
                retries: AtomicU8::new(PATIENT_RETRIES),
                ftp_seq: Mutex::new(clock_seed()),
                locks: Locks::default(),
                event_texts: tokio::sync::Mutex::default(),
                logs: Mutex::new(None),
                rates: Mutex::default(),
            }),
        };
        Ok(system)
    }
    /// The ids of the components heard from the system, the target's among them: where a
    /// discovery (cameras, gimbal managers) asks.
    pub(super) fn component_ids(&self) -> Vec<u8> {
        let mut ids: Vec<u8> = self.state().components.keys().copied().collect();
        ids.push(self.inner.target.component);
        ids
    }

    /// A handle on the component at `address` of this system: this handle for the target,
    /// else [`System::component`].
    pub(super) async fn at(&self, address: Address) -> Self {
        if address == self.inner.target {
            self.clone()
        } else {
            self.component(address.component).await
        }
    }

    /// Another component of the same system (a camera, a gimbal manager), reached over the
    /// same link: a handle of its own, with its own state and one operation of each service
    /// at a time of its own. Its autopilot and type are those of its HEARTBEAT when one was
    /// heard (else MAV_AUTOPILOT_INVALID and MAV_TYPE_GENERIC).
    pub async fn component(&self, component: u8) -> Self {
        let inner = &self.inner;
        let target = Address::new(inner.target.system, component);
        let heard = self.state().components.get(&component).copied();
        let (autopilot, mav_type) = heard.unwrap_or((MavAutopilot::INVALID, MavType::GENERIC));
        let frames = inner.node.subscribe().await;
        let (state, _) = watch::channel(State::default());
        let tracker = tokio::spawn(state::track(frames, state.clone(), inner.own, target));
        Self {
            inner: Arc::new(Inner {
                node: inner.node.clone(),
                own: inner.own,
                target,
                link: inner.link(),
                link_name: inner.link_name.clone(),
                autopilot,
                mav_type,
                found_in: inner.found_in,
                handshake: None,
                state,
                tasks: Mutex::new(vec![tracker.abort_handle()]),
                retries: AtomicU8::new(self.retries()),
                ftp_seq: Mutex::new(clock_seed()),
                locks: Locks::default(),
                event_texts: tokio::sync::Mutex::default(),
                logs: Mutex::new(None),
                rates: Mutex::default(),
            }),
        }
    }

    /// The components of the system heard so far (by their HEARTBEAT), with their
    /// autopilot and type.
    #[must_use]
    pub fn components(&self) -> Vec<(u8, MavAutopilot, MavType)> {
        self.state()
            .components
            .iter()
            .map(|(&c, &(a, t))| (c, a, t))
            .collect()
    }
}

/// Sends MAV_CMD_REQUEST_MESSAGE(HEARTBEAT) to the wanted system (any system's autopilot,
/// component 1, when any will do; other components, such as companions, are not asked) on
/// every link of `node` where a peer is known (a UDP server link has none until one sends).
async fn ask_for_heartbeats(node: &NodeHandle, wanted: Wanted) {
    /// MAV_COMP_ID_AUTOPILOT1.
    const AUTOPILOT: u8 = 1;
    let (target_system, target_component) = match wanted {
        Wanted::AnyAutopilot => (0, AUTOPILOT),
        Wanted::System(s, c) => (s, c.unwrap_or(0)),
    };
    let request = MavMessage::CommandLong(CommandLong {
        target_system,
        target_component,
        command: MavCmd::REQUEST_MESSAGE,
        param1: 0.0,
        ..CommandLong::default()
    });
    node.send_message(&request).await;
}

/// A number that differs between runs (the wall clock's nanoseconds), to start MAVFTP
/// sequence numbers where another process's client is unlikely to have stopped.
fn clock_seed() -> u16 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| (d.subsec_nanos() >> 8) as u16 ^ d.as_secs() as u16)
}
