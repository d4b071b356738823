//! [`Served`]: a `mavstack-services` server (a parameter table, a mission store, a command
//! handler, message-interval streams with
//! [`StreamServer`](mavstack_services::stream::StreamServer), or your own [`Service`])
//! running as a node's own component, for vehicles, companion computers and peripherals
//! (feature `services`).
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use mavstack::router::{LinkRole, ProtocolVersionSupport};
//! use mavstack::serve::Served;
//! use mavstack::services::Address;
//! use mavstack::services::mission::{MissionConfig, MissionServer};
//! use mavstack::services::param::{Encoding, Name, ParamServer, Value};
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let node = Node::builder()
//!     .identity(1, 191)
//!     .role(LinkRole::Vehicle { protocol_version: ProtocolVersionSupport::Answer })
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550", &none)?)
//!     .start()
//!     .await?;
//! let own = Address::new(1, 191);
//! let mut params = ParamServer::new(own, Encoding::Bytewise);
//! params.insert(Name::new("CAM_EXPOSURE")?, Value::F32(0.01))?;
//! let served = Served::start(&node.handle(), (params, MissionServer::new(own, MissionConfig::default()))).await;
//! // ... ground stations list and set CAM_EXPOSURE, upload plans ...
//! let exposure = served.with(|(params, _)| params.get(Name::new("CAM_EXPOSURE").ok()?)).await;
//! # Ok(()) }
//! ```
//!
//! Answers go back on the link the request came from (the router's routes, or the
//! requester's address for answers without target fields); broadcasts go on every link.
//! Handshake requests are the links' own ([`LinkRole::Vehicle`](crate::router::LinkRole)):
//! the service never sees them.
//!
//! Payloads a companion computer serves as components of their own: [`Camera`] (the camera
//! protocol, its owner taking the photos) and [`Gimbal`] (a gimbal manager in front of a
//! device its owner drives). A component of its own is a node of its own; [`joined`] links
//! it to another node in the same process (the camera of `mavstack vehicle --camera`).

mod camera;
mod gimbal;
mod joined;

pub use camera::{Camera, DEFINITION_PATH};
pub use gimbal::Gimbal;
pub use joined::joined;

use core::time::Duration;

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::MavMessage;
use mavstack_services::{Address, Service};
use mavstack_transport::clock;
use tokio::sync::{mpsc, oneshot};
use tokio::task::JoinHandle;

use crate::node::{NodeHandle, Subscription};

type Call<S> = Box<dyn FnOnce(&mut S) + Send>;

/// How long a service without timers sleeps before looking again.
const IDLE: Duration = Duration::from_secs(3600);

/// A service running on a node, in a task of its own (from [`Served::start`]).
pub struct Served<S> {
    handle: ServedHandle<S>,
    task: JoinHandle<S>,
    stop: oneshot::Sender<()>,
}

/// A cloneable handle on a [`Served`] service, to reach its state from other tasks.
pub struct ServedHandle<S> {
    calls: mpsc::Sender<Call<S>>,
}

impl<S> Clone for ServedHandle<S> {
    fn clone(&self) -> Self {
        Self {
            calls: self.calls.clone(),
        }
    }
}

impl<S> core::fmt::Debug for Served<S> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Served").finish_non_exhaustive()
    }
}

impl<S> core::fmt::Debug for ServedHandle<S> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ServedHandle").finish_non_exhaustive()
    }
}

impl<S> ServedHandle<S> {
    /// Runs `f` on the service in its task (read a parameter, replace a plan, publish
    /// something through it); what it queues goes out at once. `None` once it has stopped.
    pub async fn with<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut S) -> R + Send + 'static,
    ) -> Option<R> {
        let (done, result) = oneshot::channel();
        let call: Call<S> = Box::new(move |s| {
            let _ = done.send(f(s));
        });
        self.calls.send(call).await.ok()?;
        result.await.ok()
    }
}

impl<S: Service + Send + 'static> Served<S> {
    /// Runs `service` as `node`'s own component: the messages that reach the node go to it,
    /// what it sends goes out on the node's links, its timers run.
    pub async fn start(node: &NodeHandle, service: S) -> Self {
        let frames = node.subscribe().await;
        let (calls, rx) = mpsc::channel(16);
        let (stop, stopped) = oneshot::channel();
        let task = tokio::spawn(run(node.clone(), frames, service, rx, stopped));
        Self {
            handle: ServedHandle { calls },
            task,
            stop,
        }
    }

    /// A handle for other tasks.
    #[must_use]
    pub fn handle(&self) -> ServedHandle<S> {
        self.handle.clone()
    }

    /// See [`ServedHandle::with`].
    pub async fn with<R: Send + 'static>(
        &self,
        f: impl FnOnce(&mut S) -> R + Send + 'static,
    ) -> Option<R> {
        self.handle.with(f).await
    }

    /// Stops serving and gives the service back (its final state); `None` if its task
    /// panicked.
    pub async fn stop(self) -> Option<S> {
        let _ = self.stop.send(());
        self.task.await.ok()
    }
}

/// The served component's loop: messages for it in, its messages out, its timers.
async fn run<S: Service>(
    node: NodeHandle,
    mut frames: Subscription,
    mut service: S,
    mut calls: mpsc::Receiver<Call<S>>,
    mut stopped: oneshot::Receiver<()>,
) -> S {
    loop {
        while let Some(out) = service.poll_transmit() {
            // Answers go back where the requester was heard; broadcasts everywhere.
            let to = (out.target.system, out.target.component);
            node.send_answer(to, &out.message).await;
        }
        // No timer: wake up once an hour to look again.
        let wake = service
            .poll_timeout()
            .map_or_else(|| tokio::time::Instant::now() + IDLE, clock::to_tokio);
        tokio::select! {
            _ = &mut stopped => return service,
            call = calls.recv() => match call {
                Some(call) => call(&mut service),
                None => return service,
            },
            incoming = frames.recv() => {
                let Some(incoming) = incoming else { return service };
                let rf = &incoming.frame;
                // Handshake requests are the link's (answered, refused or ignored).
                if rf.protocol_version_request.is_some() || rf.answered {
                    continue;
                }
                let f = rf.frame.view();
                if let Ok(message) = MavMessage::decode(f.msg_id(), f.payload()) {
                    service.handle_message(clock::now(), Address::new(f.sysid(), f.compid()), &message);
                }
            }
            () = tokio::time::sleep_until(wake) => service.handle_timeout(clock::now()),
        }
    }
}
