//! A running [`Node`] and its cloneable [`NodeHandle`]s: requests to the driver.

use core::net::SocketAddr;
use core::time::Duration;

use mavstack_channel::{CommandEncoding, HandshakeMethod, HandshakeOutcome, SigningConfig, Target};
use mavstack_core::{MAX_PAYLOAD_LEN, Message, MessageSet};
use mavstack_router::{LinkId, LinkRole, MessageTable, RouterConfig, SendTo};
use mavstack_transport::Options;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use super::batch::{BatchSink, BatchSubscription};
use super::builder::NodeBuilder;
use super::moderation::InputModeration;
use super::{
    Command, EventSubscription, LinkEvent, NodeError, NodeEvent, NodeReport, RequestError,
    SUBSCRIPTION_DEPTH, Subscription, TapSubscription,
};

/// A running node: a handle on its task.
#[derive(Debug)]
pub struct Node {
    pub(super) commands: mpsc::Sender<Command>,
    pub(super) task: JoinHandle<Result<NodeReport, NodeError>>,
    pub(super) local_addrs: Vec<Option<SocketAddr>>,
    pub(super) identity: (u8, u8),
    pub(super) http_addr: Option<SocketAddr>,
}

impl Node {
    /// How to build one.
    #[must_use]
    pub fn builder() -> NodeBuilder {
        NodeBuilder {
            router: RouterConfig::default(),
            dialect: MessageTable::of::<mavstack_dialects::common::MavMessage>(),
            links: Vec::new(),
            log_dir: None,
            options: Options::default(),
            heartbeat: None,
            role: None,
            moderation: InputModeration::Timer,
            own_thread: false,
            http: None,
            #[cfg(feature = "http")]
            web: crate::web::WebOptions::default(),
            taps: Vec::new(),
            watchers: Vec::new(),
        }
    }

    /// How to build a ground station's node: system `system_id`, component `component_id`,
    /// ground-station links (they run the MAVLink 2 handshake; [`LinkRole::GroundStation`]),
    /// and a ground station's HEARTBEAT (MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID, ACTIVE) every
    /// second. Add links and start it.
    #[must_use]
    pub fn ground_station(system_id: u8, component_id: u8) -> NodeBuilder {
        use mavstack_dialects::common::{Heartbeat, MavAutopilot, MavState, MavType};
        let heartbeat = Heartbeat {
            r#type: MavType::GCS,
            autopilot: MavAutopilot::INVALID,
            system_status: MavState::ACTIVE,
            mavlink_version: 3,
            ..Heartbeat::default()
        };
        Self::builder()
            .identity(system_id, component_id)
            .role(LinkRole::GroundStation)
            .heartbeat(&heartbeat, Duration::from_secs(1))
    }

    /// The local address of each link, in the order they were added (UDP sockets and TCP
    /// listeners; useful after binding port 0).
    #[must_use]
    pub fn local_addrs(&self) -> &[Option<SocketAddr>] {
        &self.local_addrs
    }

    /// The address the status page listens on (see [`NodeBuilder::http`]), if any.
    #[must_use]
    pub const fn http_addr(&self) -> Option<SocketAddr> {
        self.http_addr
    }

    /// A snapshot of every link and route; `None` once the node has stopped.
    pub async fn report(&self) -> Option<NodeReport> {
        let (tx, rx) = oneshot::channel();
        self.commands.send(Command::Report(tx)).await.ok()?;
        rx.await.ok()
    }

    /// A handle for other tasks: it sends, subscribes and reports like the node, and can be
    /// cloned; the node stops only through [`shutdown`](Self::shutdown).
    #[must_use]
    pub fn handle(&self) -> NodeHandle {
        NodeHandle {
            commands: self.commands.clone(),
            identity: self.identity,
        }
    }

    /// See [`NodeHandle::send`].
    pub async fn send<M: Message>(&self, message: &M) -> usize {
        self.handle().send(message).await
    }

    /// See [`NodeHandle::subscribe`].
    pub async fn subscribe(&self) -> Subscription {
        self.handle().subscribe().await
    }

    /// See [`NodeHandle::subscribe_batched`].
    pub async fn subscribe_batched(&self) -> BatchSubscription {
        self.handle().subscribe_batched().await
    }

    /// Whether the node's task has ended (a link failed).
    #[must_use]
    pub fn is_finished(&self) -> bool {
        self.task.is_finished()
    }

    /// Resolves when the node's task has ended on its own (a link failed); then
    /// [`shutdown`](Self::shutdown) says why.
    pub async fn closed(&self) {
        self.commands.closed().await;
    }

    /// Stops the node: queued frames go out, links close, the log is written out.
    /// Returns the final report.
    ///
    /// # Errors
    /// [`NodeError`] if a link failed or the log could not be written.
    pub async fn shutdown(self) -> Result<NodeReport, NodeError> {
        let _ = self.commands.send(Command::Shutdown).await;
        self.task
            .await
            .map_err(|e| NodeError::Stopped(e.to_string()))?
    }
}

/// A cloneable handle on a running [`Node`] (from [`Node::handle`]).
#[derive(Clone, Debug)]
pub struct NodeHandle {
    pub(super) commands: mpsc::Sender<Command>,
    pub(super) identity: (u8, u8),
}

impl NodeHandle {
    /// The node's own (system id, component id).
    #[must_use]
    pub const fn identity(&self) -> (u8, u8) {
        self.identity
    }

    /// Sends `message` as the node's own component: on the links its target fields lead to
    /// (every link for a broadcast or a system not heard yet), each link framing it in its
    /// own version and signing it when it signs (see `mavstack_router::Router::send`).
    /// Returns on how many links it was queued; 0 once the node has stopped.
    pub async fn send<M: Message>(&self, message: &M) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Target, M::ID, payload[..len].to_vec())
            .await
    }

    /// Like [`send`](Self::send), for a message of a dialect's enum (`MavMessage`).
    pub async fn send_message<S: MessageSet>(&self, message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Target, message.id(), payload[..len].to_vec())
            .await
    }

    /// Like [`send_message`](Self::send_message), sent where component `(sysid, compid)`
    /// was heard as if the message were addressed to it: an answer without target fields
    /// (PARAM_VALUE for a read or a set) goes back to the link the request came from.
    pub async fn send_answer<S: MessageSet>(&self, to: (u8, u8), message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(
            SendTo::Component(to.0, to.1),
            message.id(),
            payload[..len].to_vec(),
        )
        .await
    }

    /// Like [`send_message`](Self::send_message), onto one router link only (the one an
    /// [`Incoming`](crate::Incoming) or a [`NodeEvent`](crate::NodeEvent) names); 0 if it is gone.
    pub async fn send_on<S: MessageSet>(&self, link: LinkId, message: &S) -> usize {
        let mut payload = [0u8; MAX_PAYLOAD_LEN];
        let len = message.encode(&mut payload);
        self.send_payload(SendTo::Link(link), message.id(), payload[..len].to_vec())
            .await
    }

    /// Like [`send_message`](Self::send_message), for a message known only by its id and
    /// payload (a dialect loaded at run time from XML): routed by the target fields the
    /// node's dialect ([`NodeBuilder::dialect`]) gives message `msg_id`. `payload` is the
    /// full payload (extensions included); each link truncates or cuts it for its version.
    /// Returns on how many links it was queued; 0 once the node has stopped.
    pub async fn send_raw(&self, msg_id: u32, payload: &[u8]) -> usize {
        let len = payload.len().min(MAX_PAYLOAD_LEN);
        self.send_payload(SendTo::Target, msg_id, payload[..len].to_vec())
            .await
    }

    /// Like [`send_raw`](Self::send_raw) without waiting for the node: queues the message
    /// behind the requests already made and returns at once, from any thread, in or out of
    /// the runtime. `false` if the node's request queue is full or the node has stopped (then
    /// nothing was queued: [`send_raw`](Self::send_raw) waits for room, in order).
    #[must_use]
    pub fn queue_raw(&self, msg_id: u32, payload: &[u8]) -> bool {
        let len = payload.len().min(MAX_PAYLOAD_LEN);
        let (done, _) = oneshot::channel();
        let command = Command::Send {
            to: SendTo::Target,
            msg_id,
            payload: payload[..len].to_vec(),
            done,
        };
        self.commands.try_send(command).is_ok()
    }

    async fn send_payload(&self, to: SendTo, msg_id: u32, payload: Vec<u8>) -> usize {
        let (done, rx) = oneshot::channel();
        let command = Command::Send {
            to,
            msg_id,
            payload,
            done,
        };
        if self.commands.send(command).await.is_err() {
            return 0;
        }
        rx.await.unwrap_or(0)
    }

    /// Every frame that reaches the node's component from now on: addressed to it or
    /// broadcast (with [`NodeBuilder::identity`]; everything the router delivers locally
    /// otherwise). Dropping the receiver unsubscribes.
    pub async fn subscribe(&self) -> Subscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self
            .commands
            .send(Command::Subscribe(tx, done))
            .await
            .is_ok()
        {
            // Registered before this returns: nothing that arrives later is missed.
            let _ = registered.await;
        }
        rx
    }

    /// Every frame [`subscribe`](Self::subscribe) would give, in batches, for a reader on a
    /// thread of its own (see [`BatchSubscription`]): the frames of a driver turn are handed
    /// over together, their bytes copied once, with one wake-up when the reader waits.
    /// Dropping the subscription unsubscribes; once the node stops, the reader is told
    /// ([`BatchWait::Closed`](super::BatchWait::Closed)) after the last frame.
    pub async fn subscribe_batched(&self) -> BatchSubscription {
        let (sink, subscription) = BatchSink::new();
        let (done, registered) = oneshot::channel();
        if self
            .commands
            .send(Command::SubscribeBatched(sink, done))
            .await
            .is_ok()
        {
            // Registered before this returns: nothing that arrives later is missed.
            let _ = registered.await;
        }
        subscription
    }

    /// A copy of every input from now on, as it arrived on its link, before any parsing:
    /// for tools that judge the wire itself (checksums, framing, sequence numbers), such as
    /// `mavstack conform`. Dropping the receiver ends the tap.
    pub async fn tap(&self) -> TapSubscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self.commands.send(Command::Tap(tx, done)).await.is_ok() {
            let _ = registered.await;
        }
        rx
    }

    /// Writes `bytes` on `link` exactly as given: no framing by the link's version, no
    /// signing, no sequence number. For test tools that craft frames (a MAVLink 2 frame on a
    /// link still in MAVLink 1, a deliberately bad one); everything else goes through
    /// [`send_on`](Self::send_on). Returns whether the link exists.
    pub async fn send_bytes(&self, link: LinkId, bytes: &[u8]) -> bool {
        let (done, rx) = oneshot::channel();
        let command = Command::SendBytes {
            link,
            bytes: bytes.to_vec(),
            done,
        };
        if self.commands.send(command).await.is_err() {
            return false;
        }
        rx.await.unwrap_or(false)
    }

    /// Runs the MAVLink 2 handshake with `target` on `link` (a
    /// [`LinkRole::GroundStation`] link) and waits for its outcome: PROTOCOL_VERSION (the
    /// link is MAVLink 2 now), a NACK, or no answer after the retries.
    ///
    /// # Errors
    /// [`RequestError::Handshake`] if it cannot start there, [`RequestError::Stopped`].
    pub async fn handshake(
        &self,
        link: LinkId,
        target: Target,
        method: HandshakeMethod,
        encoding: CommandEncoding,
    ) -> Result<HandshakeOutcome, RequestError> {
        let mut events = self.events().await;
        let (done, started) = oneshot::channel();
        let command = Command::Handshake {
            link,
            target,
            method,
            encoding,
            done,
        };
        self.commands
            .send(command)
            .await
            .map_err(|_| RequestError::Stopped)?;
        started.await.map_err(|_| RequestError::Stopped)??;
        while let Some(event) = events.recv().await {
            if let NodeEvent {
                link_id,
                kind: LinkEvent::Handshake(outcome),
                ..
            } = event
                && link_id == link
            {
                return Ok(outcome);
            }
        }
        Err(RequestError::Stopped)
    }

    /// Turns signing on or off on `link` (after sending SETUP_SIGNING to the peer, for one).
    ///
    /// # Errors
    /// [`RequestError::Signing`] on a `version=1` link, [`RequestError::Stopped`].
    pub async fn set_signing(
        &self,
        link: LinkId,
        signing: Option<SigningConfig>,
    ) -> Result<(), RequestError> {
        let (done, rx) = oneshot::channel();
        self.commands
            .send(Command::SetSigning {
                link,
                signing,
                done,
            })
            .await
            .map_err(|_| RequestError::Stopped)?;
        Ok(rx.await.map_err(|_| RequestError::Stopped)??)
    }

    /// Turns signing on or off on every link of the node, as after a SETUP_SIGNING (which
    /// the caller sends): the peers it has now and those that come later (a new UDP or TCP
    /// client of a server link).
    ///
    /// # Errors
    /// [`RequestError::Signing`] if a link cannot sign (`version=1`; the others are set all
    /// the same), [`RequestError::Stopped`].
    pub async fn set_signing_all(
        &self,
        signing: Option<SigningConfig>,
    ) -> Result<(), RequestError> {
        let (done, rx) = oneshot::channel();
        self.commands
            .send(Command::SetSigningAll { signing, done })
            .await
            .map_err(|_| RequestError::Stopped)?;
        Ok(rx.await.map_err(|_| RequestError::Stopped)??)
    }

    /// Holds SETUP_SIGNING on every link of the node, those that come later too (`true`), or
    /// takes it again (`false`): a vehicle holds it while it will not change its key
    /// (ArduPilot while armed). A held SETUP_SIGNING changes nothing and comes as a
    /// [`LinkEvent::Rejected`] with
    /// [`RejectReason::SetupSigningHeld`](mavstack_channel::RejectReason::SetupSigningHeld),
    /// for the vehicle to say why.
    ///
    /// # Errors
    /// [`RequestError::Stopped`].
    pub async fn hold_setup_signing(&self, held: bool) -> Result<(), RequestError> {
        let (done, rx) = oneshot::channel();
        self.commands
            .send(Command::HoldSetupSigning { held, done })
            .await
            .map_err(|_| RequestError::Stopped)?;
        rx.await.map_err(|_| RequestError::Stopped)
    }

    /// Every link event from now on (peers, version changes, handshakes answered, signing
    /// set up, frames refused). Dropping the receiver unsubscribes.
    pub async fn events(&self) -> EventSubscription {
        let (tx, rx) = mpsc::channel(SUBSCRIPTION_DEPTH);
        let (done, registered) = oneshot::channel();
        if self.commands.send(Command::Events(tx, done)).await.is_ok() {
            let _ = registered.await;
        }
        rx
    }

    /// A snapshot of every link and route; `None` once the node has stopped.
    pub async fn report(&self) -> Option<NodeReport> {
        let (tx, rx) = oneshot::channel();
        self.commands.send(Command::Report(tx)).await.ok()?;
        rx.await.ok()
    }

    /// Resolves when the node has stopped.
    pub async fn closed(&self) {
        self.commands.closed().await;
    }
}
