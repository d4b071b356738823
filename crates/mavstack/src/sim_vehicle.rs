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

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::MavMessage;
use mavstack_services::Address;
use mavstack_services::param::{Name, Value};
use mavstack_sim::{Autopilot, SimConfig, Vehicle};
use mavstack_transport::clock;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

use crate::node::{Node, NodeBuilder, NodeError, NodeHandle, NodeReport, Subscription};

/// A simulated vehicle running on its own [`Node`]: it answers parameters, missions and
/// commands and streams telemetry on the node's links, as `mavstack vehicle` does (the
/// node's links forward between them like any node's; the MAVLink 2 handshake and
/// SETUP_SIGNING are `mavstack vehicle`'s, not this one's yet).
#[derive(Debug)]
pub struct SimVehicle {
    node: Node,
    stop: oneshot::Sender<()>,
    task: JoinHandle<()>,
}

impl SimVehicle {
    /// A system 1, component 1 vehicle of `autopilot`'s flavour with `params`, advertising
    /// MAVLink 2.
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
        }
    }

    /// Starts a node from `builder` with the vehicle's identity, and the vehicle on it.
    ///
    /// # Errors
    /// [`NodeError`] if a link cannot be opened.
    pub async fn start(builder: NodeBuilder, config: SimConfig) -> Result<Self, NodeError> {
        let node = builder
            .identity(config.own.system, config.own.component)
            .start()
            .await?;
        let frames = node.subscribe().await;
        let sim = Vehicle::new(config, clock::now());
        let (stop, stopped) = oneshot::channel();
        let task = tokio::spawn(drive(node.handle(), frames, sim, stopped));
        Ok(Self { node, stop, task })
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
        let _ = self.stop.send(());
        let _ = self.task.await;
        self.node.shutdown().await
    }
}

/// The vehicle's loop: frames for it in, its messages out, its timers.
async fn drive(
    node: NodeHandle,
    mut frames: Subscription,
    mut sim: Vehicle,
    mut stopped: oneshot::Receiver<()>,
) {
    loop {
        while let Some(out) = sim.poll_transmit() {
            node.send_message(&out.message).await;
        }
        while let Some(line) = sim.poll_log() {
            tracing::info!("vehicle: {line}");
        }
        let wake = clock::to_tokio(sim.poll_timeout());
        tokio::select! {
            _ = &mut stopped => break,
            incoming = frames.recv() => {
                let Some(incoming) = incoming else { break };
                let frame = incoming.frame.frame.view();
                let from = Address {
                    system: frame.sysid(),
                    component: frame.compid(),
                };
                if let Ok(message) = MavMessage::decode(frame.msg_id(), frame.payload()) {
                    sim.handle_message(clock::now(), from, &message);
                }
            }
            () = tokio::time::sleep_until(wake) => sim.handle_timeout(clock::now()),
        }
    }
}
