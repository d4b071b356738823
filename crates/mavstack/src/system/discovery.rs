//! [`Discovery`]: the systems and components a node hears, as they appear, change and go.

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::MavMessage;
use mavstack_services::heartbeat::{HeartbeatConfig, HeartbeatEvent, Heartbeats, Peer};
use mavstack_services::{Address, Service as _};
use mavstack_transport::clock;

use crate::node::{NodeHandle, Subscription};

/// The systems and components a node hears, as they appear, change and go (from
/// [`Discovery::new`]): a table kept from their HEARTBEATs (and AUTOPILOT_VERSIONs); a
/// component silent for 3 s is lost, one heard again is new again.
///
/// ```no_run
/// # async fn run(node: &mavstack::NodeHandle) {
/// use mavstack::services::heartbeat::HeartbeatEvent;
/// use mavstack::system::Discovery;
/// let mut discovery = Discovery::new(node).await;
/// while let Some(event) = discovery.next().await {
///     match event {
///         HeartbeatEvent::New(peer) => println!("{} appeared: {:?}", peer.address, peer.autopilot),
///         HeartbeatEvent::Lost(address) => println!("{address} lost"),
///         _ => {}
///     }
/// }
/// # }
/// ```
#[derive(Debug)]
pub struct Discovery {
    frames: Subscription,
    table: Heartbeats,
}

impl Discovery {
    /// Starts listening on `node`.
    pub async fn new(node: &NodeHandle) -> Self {
        Self {
            frames: node.subscribe().await,
            table: Heartbeats::new(HeartbeatConfig::default()),
        }
    }

    /// The next appearance, change or loss; `None` once the node has stopped.
    pub async fn next(&mut self) -> Option<HeartbeatEvent> {
        loop {
            if let Some(event) = self.table.poll_event() {
                return Some(event);
            }
            let wake = self.table.poll_timeout().map(clock::to_tokio);
            let sleep = async {
                match wake {
                    Some(t) => tokio::time::sleep_until(t).await,
                    None => core::future::pending().await,
                }
            };
            tokio::select! {
                () = sleep => self.table.handle_timeout(clock::now()),
                incoming = self.frames.recv() => {
                    let incoming = incoming?;
                    let f = incoming.frame.frame.view();
                    let from = Address::new(f.sysid(), f.compid());
                    match MavMessage::decode(f.msg_id(), f.payload()) {
                        Ok(MavMessage::Heartbeat(hb)) => self.table.handle_heartbeat(
                            clock::now(),
                            from,
                            &hb,
                            Some(f.version().number()),
                        ),
                        Ok(MavMessage::AutopilotVersion(v)) => {
                            self.table.handle_autopilot_version(from, &v);
                        }
                        _ => {}
                    }
                }
            }
        }
    }

    /// The components heard and not lost.
    pub fn peers(&self) -> impl Iterator<Item = &Peer> {
        self.table.peers()
    }
}
