//! [`Gimbal`]: a gimbal manager served as a MAVLink component of its own, in front of a
//! gimbal device its owner drives (a companion computer's servos or serial gimbal), over
//! `mavstack_services::gimbal::GimbalManager`.

use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_services::gimbal::{DeviceAttitude, GimbalManager, ManagerConfig, ManagerEvent};
use mavstack_services::{Address, Outgoing, Service};
use tokio::sync::mpsc;

use super::Served;
use crate::node::NodeHandle;

/// The manager and the way out of its events.
struct Component {
    manager: GimbalManager,
    events: mpsc::UnboundedSender<ManagerEvent>,
}

impl Component {
    fn tell(&mut self) {
        while let Some(e) = self.manager.poll_event() {
            let _ = self.events.send(e);
        }
    }
}

impl Service for Component {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let used = self.manager.handle_message(now, from, message);
        self.tell();
        used
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.manager.handle_timeout(now);
        self.tell();
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.manager.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.manager.poll_timeout()
    }
}

/// A gimbal manager served on a node (from [`Gimbal::start`]).
pub struct Gimbal {
    served: Served<Component>,
    events: mpsc::UnboundedReceiver<ManagerEvent>,
}

impl core::fmt::Debug for Gimbal {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Gimbal").finish_non_exhaustive()
    }
}

impl Gimbal {
    /// Serves the manager `config` describes on `node` (whose identity is `config.own`;
    /// with `config.own_component` it sends its own HEARTBEAT as MAV_TYPE_GIMBAL and
    /// answers other commands UNSUPPORTED).
    pub async fn start(node: &NodeHandle, config: ManagerConfig) -> Self {
        let (tx, events) = mpsc::unbounded_channel();
        let now = mavstack_transport::clock::now();
        let component = Component {
            manager: GimbalManager::new(now, config),
            events: tx,
        };
        let served = Served::start(node, component).await;
        Self { served, events }
    }

    /// The next setpoint for the device (or change of control, or location pointed at);
    /// `None` once it has stopped.
    pub async fn next_event(&mut self) -> Option<ManagerEvent> {
        self.events.recv().await
    }

    /// What the device measured: reported on its behalf (GIMBAL_DEVICE_ATTITUDE_STATUS)
    /// from now on.
    pub async fn set_attitude(&self, attitude: DeviceAttitude) {
        let _ = self
            .served
            .with(move |c| c.manager.set_device_attitude(attitude))
            .await;
    }

    /// Who is in primary and secondary control.
    pub async fn control(&self) -> (Option<Address>, Option<Address>) {
        self.served
            .with(|c| c.manager.control())
            .await
            .unwrap_or((None, None))
    }

    /// Stops serving.
    pub async fn stop(self) {
        let _ = self.served.stop().await;
    }
}
