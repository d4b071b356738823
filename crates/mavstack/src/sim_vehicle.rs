//! [`SimVehicle`]: the simulated vehicle of `mavstack-sim` as a component of a [`Node`], for
//! ground stations' integration tests (feature `sim`).
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::sim::{Autopilot, SimConfig, params};
//! use mavstack::sim_vehicle::SimVehicle;
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let vehicle = SimVehicle::start(
//!     Node::builder().link(LinkSpec::parse("udpin:127.0.0.1:14550", &none)?),
//!     SimVehicle::config(Autopilot::Ardupilot, params::defaults(Autopilot::Ardupilot)),
//! )
//! .await?;
//! // ... a ground station talks to udp 127.0.0.1:14550 ...
//! vehicle.shutdown().await?;
//! # Ok(()) }
//! ```

use mavstack_channel::{RejectReason, SigningConfig, SigningSetup};
use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{AutopilotVersion, CommandLong, MavCmd, MavMessage};
use mavstack_router::{LinkId, LinkRole, ProtocolVersionSupport};
use mavstack_services::param::{Name, Value};
use mavstack_services::{Address, Outgoing, Service};
use mavstack_sim::{Autopilot, SimConfig, Vehicle};
use mavstack_transport::clock;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;

use crate::node::{
    EventSubscription, LinkEvent, Node, NodeBuilder, NodeError, NodeHandle, NodeReport,
};
use crate::serve::{Served, ServedHandle};

/// A simulated vehicle running on its own [`Node`]: it answers parameters, missions and
/// commands and streams telemetry on every link of the node, as `mavstack vehicle` does.
/// One vehicle, one parameter table and one mission store, whatever the number of links;
/// answers go back on the link the request came from, HEARTBEAT and telemetry go on every
/// link, and frames for other systems are forwarded between the links by the router's rules.
/// It is a [`Served`] component: the vehicle model is a `mavstack-services` [`Service`].
///
/// Unless the builder says otherwise ([`NodeBuilder::role`]), its links are vehicle links
/// ([`LinkRole::Vehicle`]): each answers the MAVLink 2 handshake by its own `version`
/// (PROTOCOL_VERSION, or a MAVLink 1 NACK on a `version=1` link), applies SETUP_SIGNING when
/// `secure`, and carries the MAVLINK2 capability bit in AUTOPILOT_VERSION exactly when it
/// accepts MAVLink 2. The ArduPilot flavour holds SETUP_SIGNING while armed
/// ([`NodeHandle::hold_setup_signing`]) and says so as ArduPilot does: "ERROR: Won't setup
/// signing when armed".
#[derive(Debug)]
pub struct SimVehicle {
    node: Node,
    served: Served<Narrated>,
    events: JoinHandle<()>,
}

/// One line of what the vehicle does (parameter sets, modes, plans, link versions,
/// handshakes, refused frames), for a log or a timeline.
pub type LogLines = mpsc::UnboundedSender<String>;

/// The simulated vehicle, saying what it does.
#[derive(Debug)]
struct Narrated {
    sim: Vehicle,
    log: Option<LogLines>,
    /// Whether the vehicle refuses SETUP_SIGNING now (the links hold it meanwhile).
    holds_signing: watch::Sender<bool>,
}

impl Narrated {
    fn tell(&mut self) {
        while let Some(line) = self.sim.poll_log() {
            say(&self.log, || format!("vehicle: {line}"));
        }
        let refuses = self.sim.refuses_setup_signing();
        self.holds_signing.send_if_modified(|held| {
            let changed = *held != refuses;
            *held = refuses;
            changed
        });
    }
}

impl Service for Narrated {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if let MavMessage::CommandLong(CommandLong {
            command, param1, ..
        }) = message
            && (*command == MavCmd::REQUEST_AUTOPILOT_CAPABILITIES
                || (*command == MavCmd::REQUEST_MESSAGE && *param1 == AutopilotVersion::ID as f32))
        {
            say(&self.log, || {
                "vehicle ← AUTOPILOT_VERSION requested".to_owned()
            });
        }
        self.sim.handle_message(now, from, message);
        self.tell();
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.sim.handle_timeout(now);
        self.tell();
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.sim.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        Some(self.sim.poll_timeout())
    }
}

impl SimVehicle {
    /// A system 1, component 1 vehicle of `autopilot`'s flavour with `params`, advertising
    /// MAVLink 2, serving MAVFTP (`@PARAM/param.pck` only) and its generated logs (LOG_*).
    #[must_use]
    pub const fn config(autopilot: Autopilot, params: Vec<(Name, Value)>) -> SimConfig {
        SimConfig {
            own: Address {
                system: 1,
                component: 1,
            },
            autopilot,
            mavlink2: true,
            params,
            estimator_settle: core::time::Duration::ZERO,
            data_streams_only: false,
            streams_on_request: false,
            ftp: true,
            ftp_files: None,
            log_dir: None,
        }
    }

    /// Starts a node from `builder` with the vehicle's identity, and the vehicle on it; what
    /// it does goes to `tracing` at level info.
    ///
    /// # Errors
    /// [`NodeError`] if a link cannot be opened.
    pub async fn start(builder: NodeBuilder, config: SimConfig) -> Result<Self, NodeError> {
        Self::start_logged(builder, config, None).await
    }

    /// Like [`start`](Self::start), with what the vehicle does sent to `log` as lines
    /// (`vehicle: link MAVLink 1 → MAVLink 2 (...)`, `vehicle ← handshake request: ...`).
    ///
    /// # Errors
    /// [`NodeError`] if a link cannot be opened.
    pub async fn start_logged(
        builder: NodeBuilder,
        config: SimConfig,
        log: Option<LogLines>,
    ) -> Result<Self, NodeError> {
        let builder = if builder.link_role().is_none() {
            builder.role(LinkRole::Vehicle {
                protocol_version: ProtocolVersionSupport::Answer,
            })
        } else {
            builder
        };
        let node = builder
            .identity(config.own.system, config.own.component)
            .start()
            .await?;
        let events = node.handle().events().await;
        let flavour = config.autopilot;
        let sim = Vehicle::new(config, clock::now());
        say(&log, || {
            format!(
                "vehicle: {flavour} flavour, {} parameters",
                sim.param_count()
            )
        });
        let (holds_signing, held) = watch::channel(false);
        let served = Served::start(
            &node.handle(),
            Narrated {
                sim,
                log: log.clone(),
                holds_signing,
            },
        )
        .await;
        let events = tokio::spawn(link_events(
            node.handle(),
            served.handle(),
            events,
            held,
            log,
        ));
        Ok(Self {
            node,
            served,
            events,
        })
    }

    /// The node the vehicle runs on (its links' addresses, reports).
    #[must_use]
    pub const fn node(&self) -> &Node {
        &self.node
    }

    /// Stops the vehicle and its node; returns the node's last report.
    ///
    /// # Errors
    /// [`NodeError`] if a link failed.
    pub async fn shutdown(self) -> Result<NodeReport, NodeError> {
        self.events.abort();
        let _ = self.served.stop().await;
        self.node.shutdown().await
    }
}

fn say(log: &Option<LogLines>, line: impl FnOnce() -> String) {
    match log {
        Some(tx) => {
            let _ = tx.send(line());
        }
        None => tracing::info!("{}", line()),
    }
}

/// A vehicle has one key, as ArduPilot does: SETUP_SIGNING accepted on one link signs (or
/// stops signing) every other link too, and those then refuse unsigned frames (ArduPilot
/// takes them only on its USB port). `version=1` links cannot sign and are left as they are.
/// Returns how many links changed.
async fn sign_other_links(node: &NodeHandle, from: LinkId, setup: &SigningSetup) -> usize {
    let Some(report) = node.report().await else {
        return 0;
    };
    let mut others: Vec<LinkId> = Vec::new();
    for id in report.links.iter().filter_map(|l| l.link_id) {
        // A server link's clients each have an entry under the link's id.
        if id != from && !others.contains(&id) {
            others.push(id);
        }
    }
    let mut changed = 0;
    for id in others {
        let signing = match setup {
            SigningSetup::Enabled {
                key,
                initial_timestamp,
            } => {
                let mut config = SigningConfig::new(key.clone(), 0);
                config.initial_timestamp = *initial_timestamp;
                Some(config)
            }
            SigningSetup::Disabled => None,
        };
        if node.set_signing(id, signing).await.is_ok() {
            changed += 1;
        }
    }
    changed
}

/// What the vehicle does about its links' events: greets a new peer, says why it refused a
/// SETUP_SIGNING it held, says the rest; and holds SETUP_SIGNING on every link while the
/// vehicle refuses it.
async fn link_events(
    node: NodeHandle,
    vehicle: ServedHandle<Narrated>,
    mut events: EventSubscription,
    mut held: watch::Receiver<bool>,
    log: Option<LogLines>,
) {
    loop {
        let event = tokio::select! {
            event = events.recv() => event,
            changed = held.changed() => {
                if changed.is_err() {
                    return;
                }
                let hold = *held.borrow_and_update();
                if node.hold_setup_signing(hold).await.is_err() {
                    return;
                }
                continue;
            }
        };
        let Some(event) = event else { return };
        let link = &event.link;
        match event.kind {
            LinkEvent::PeerAdded { .. } => {
                let now = clock::now();
                if let Some(Some(hello)) = vehicle.with(move |v| v.sim.greeting(now)).await {
                    node.send_on(event.link_id, &hello).await;
                }
            }
            LinkEvent::VersionChanged { from, to, cause } => {
                say(&log, || {
                    format!("vehicle: link {from} → {to} ({cause}) [{link}]")
                });
            }
            LinkEvent::ProtocolVersionRequested { answer, .. } => {
                say(&log, || {
                    format!("vehicle ← handshake request: {answer} [{link}]")
                });
            }
            LinkEvent::Rejected(r) if r.reason == RejectReason::SetupSigningHeld => {
                let _ = vehicle.with(|v| v.sim.setup_signing_refused()).await;
                say(&log, || {
                    format!("vehicle ✗ SETUP_SIGNING refused: the vehicle is armed [{link}]")
                });
            }
            LinkEvent::Rejected(r) => say(&log, || {
                format!(
                    "vehicle ✗ rejected {}: {} [{link}]",
                    crate::message_name(r.msg_id),
                    r.reason
                )
            }),
            LinkEvent::SigningSetup { setup, .. } => {
                let signed = sign_other_links(&node, event.link_id, &setup).await;
                say(&log, || match setup {
                    SigningSetup::Enabled { .. } => format!(
                        "vehicle: SETUP_SIGNING accepted, link signed from now on, and {signed} \
                         other link(s) [{link}]"
                    ),
                    SigningSetup::Disabled => format!(
                        "vehicle: SETUP_SIGNING turned signing off, here and on {signed} other \
                         link(s) [{link}]"
                    ),
                });
            }
            _ => {}
        }
    }
}
