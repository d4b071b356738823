//! `mavstack.mavutil.mavlink_connection("udpin:0.0.0.0:14550")`: a live link with
//! pymavlink's receiving side (`recv_match`, `recv_msg`, `messages`, `target_system`,
//! `flightmode`, `motors_armed`) and the sending side its `mav` object is built on
//! (`encode`, `send_fields`, `send`, `write`).
//!
//! Each connection is one [`mavstack::Node`] with one link, opened from the connection
//! string by the stack's own parser ([`LinkSpec`]): the link's version handling and signing
//! come with it. The nodes run on one tokio runtime shared by every connection of the
//! process (one worker thread; a UDP link's node on a thread of its own, with its own
//! `epoll`); frames reach the connection in batches through the node's batch subscription
//! (`live/receive.rs`), and a blocking `recv_match` waits on it with the GIL released, waking
//! every 100 ms to let Python see a Ctrl-C. Sends are queued to the node without waiting for it. One thread may receive while
//! others send and read the connection's state (see [`LiveLink`]).
//!
//! What pymavlink keeps per system (the latest message of each type, the flight mode, the
//! armed flag) is kept the same way here, and `target_system` locks onto the first vehicle
//! HEARTBEAT as pymavlink's does (`target_component` stays 0 until set, as in pymavlink).
//!
//! This file has the connection's state; `live/receive.rs` how frames reach it and are
//! recorded; `live/methods.rs` its Python methods, `live/heartbeat.rs` what pymavlink reads of a HEARTBEAT (vehicle or not,
//! the flight mode's name), `live/fields.rs` Python values into payload bytes.

use core::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use core::time::Duration;
use std::collections::BTreeMap;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use mavstack::channel::SigningConfig;
use mavstack::modes::Flavour;
use mavstack::router::{LinkId, LocalDelivery, RouterConfig};
use mavstack::{LinkSpec, Node, NodeHandle};
use mavstack_core::signing::SecretKey;
use pyo3::exceptions::{PyConnectionError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::MutexExt as _;
use pyo3::types::{PyDict, PyString};
use tokio::runtime::Runtime;

use crate::connection::Conditions;
use crate::dialect::{Dialect, MessageType};

mod fields;
mod heartbeat;
mod methods;
mod receive;

pub(crate) use fields::put_field;
use receive::{RawFrame, Receiver};

/// How long a blocking receive waits between two looks at Python's signals.
const SIGNAL_CHECK: Duration = Duration::from_millis(100);

/// MAV_COMP_ID_MISSIONPLANNER: the component a connection opened with pymavlink's default
/// `source_component=0` sends from.
const MISSION_PLANNER: u8 = 190;
/// MAV_MODE_FLAG_SAFETY_ARMED.
const SAFETY_ARMED: u8 = 128;
/// MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.
const CUSTOM_MODE_ENABLED: u8 = 1;

/// The runtime every live connection's node runs on.
pub(crate) fn runtime() -> PyResult<&'static Runtime> {
    static RUNTIME: OnceLock<Result<Runtime, String>> = OnceLock::new();
    RUNTIME
        .get_or_init(|| {
            tokio::runtime::Builder::new_multi_thread()
                .worker_threads(1)
                .thread_name("mavstack-live")
                .enable_all()
                .build()
                .map_err(|e| e.to_string())
        })
        .as_ref()
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the link runtime: {e}")))
}

/// Seconds since the Unix epoch, as `time.time()`.
pub(crate) fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// What pymavlink keeps per system id (its `mavfile_state`).
struct SystemState {
    /// The latest message of each type, by name.
    messages: Py<PyDict>,
    /// The flight mode's name, from the latest vehicle HEARTBEAT.
    flightmode: String,
    /// Whether the latest vehicle HEARTBEAT said armed.
    armed: bool,
    /// HEARTBEAT `type`, `autopilot` and `base_mode` of the latest vehicle HEARTBEAT.
    mav_type: Option<u8>,
    autopilot: Option<u8>,
    base_mode: u8,
    /// The latest frame of each type (by message index) that no message object was made
    /// for yet (see `live/receive.rs`).
    latest: Vec<Option<Box<RawFrame>>>,
    /// The message indexes of `latest` marked newer than `messages`.
    marked: Vec<usize>,
}

impl SystemState {
    fn new(py: Python<'_>) -> Self {
        Self {
            messages: PyDict::new(py).unbind(),
            flightmode: "UNKNOWN".to_owned(),
            armed: false,
            mav_type: None,
            autopilot: None,
            base_mode: 0,
            latest: Vec::new(),
            marked: Vec::new(),
        }
    }
}

/// A live MAVLink connection (pymavlink's `mavudp`, `mavtcp`, `mavserial`): one
/// `mavstack::Node` with one link.
///
/// One thread may wait in `recv_match` while others send or read `messages` and
/// `target_system`: the object is shared (`frozen`), its parts behind their own locks, each
/// taken without holding the GIL while it waits (`lock_py_attached`), and no lock but the
/// receiving thread's hold on the frames is kept while Python code runs.
#[pyclass(module = "mavstack", name = "LiveLink", frozen)]
pub(crate) struct LiveLink {
    /// The connection string as given (keys redacted).
    device: String,
    dialect: Arc<Dialect>,
    /// The node, until `close`.
    node: Mutex<Option<Node>>,
    closed: AtomicBool,
    handle: NodeHandle,
    /// The node's frames: held by the thread that receives.
    frames: Mutex<Receiver>,
    /// What the received frames built up.
    state: Mutex<State>,
    /// Some system has frames recorded without a message object (`SystemState::marked`):
    /// set with `state` held, read without it (most calls find nothing to make).
    marked: AtomicBool,
    /// The router links (peers) heard from or reported, for `write`, and when the node was
    /// last asked for them.
    peers: Mutex<(Vec<LinkId>, Option<Instant>)>,
    /// Sequence number of the frames `encode` builds.
    encode_seq: AtomicU8,
    /// The messages' names as Python strings (interned), by message index: the keys of
    /// `messages`, made once rather than for every frame.
    names: Vec<Py<PyString>>,
}

/// What a connection keeps of the frames it received (pymavlink's per-system state).
struct State {
    /// pymavlink's `sysid`: the target system (0 until the first vehicle HEARTBEAT).
    sysid: u8,
    target_component: u8,
    /// By system id (a B-tree finds one of the few heard without hashing).
    systems: BTreeMap<u8, SystemState>,
    conditions: Conditions,
    /// Frames of message ids the dialect does not define (counted, never returned).
    unknown_id: u64,
    /// Messages received.
    received: u64,
}

impl State {
    /// The state of the target system (pymavlink's `sysid_state[sysid]`).
    fn target(&mut self, py: Python<'_>) -> &SystemState {
        self.systems
            .entry(self.sysid)
            .or_insert_with(|| SystemState::new(py))
    }

    /// The flavour of the target's modes, from its latest HEARTBEAT.
    fn flavour(&mut self, py: Python<'_>) -> Option<Flavour> {
        use mavstack::dialects::common::{MavAutopilot, MavType};
        let s = self.target(py);
        Flavour::of(MavAutopilot(s.autopilot?), MavType(s.mav_type?))
    }
}

/// `lock_py_attached`; a lock poisoned by a panic is taken as it is (what it guards stays
/// consistent: every update is a single assignment or insertion).
fn lock<'a, T>(py: Python<'_>, m: &'a Mutex<T>) -> MutexGuard<'a, T> {
    m.lock_py_attached(py)
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl LiveLink {
    /// Opens `text` (a connection string with optional link options) as system
    /// `source_system`, component `source_component`, signing with `key` when given.
    pub(crate) fn open(
        py: Python<'_>,
        text: &str,
        source_system: u8,
        source_component: u8,
        dialect: &str,
        key: Option<SecretKey>,
        link_id: u8,
    ) -> PyResult<Self> {
        let dialect = Dialect::load(dialect)?;
        let mut spec = LinkSpec::parse_in(text, &dialect.table)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        if let Some(key) = key {
            spec.config.signing = Some(SigningConfig::new(key, link_id));
        }
        let shown = mavstack::redacted(text);
        if source_system == 0 {
            return Err(PyValueError::new_err(
                "source_system 0 is the broadcast address, never a sender",
            ));
        }
        let mut router = RouterConfig::default();
        router.system_id = source_system;
        // pymavlink's default component 0 is MAV_COMP_ID_ALL, which the stack never sends
        // from: a ground station's own id instead.
        router.component_id = if source_component == 0 {
            MISSION_PLANNER
        } else {
            source_component
        };
        router.local = LocalDelivery::All;
        router.forward = false;
        let table = dialect.table;
        let names = dialect
            .messages
            .iter()
            .map(|m| PyString::intern(py, &m.name).unbind())
            .collect();
        let rt = runtime()?;
        let started = py.detach(|| {
            rt.block_on(async move {
                let node = Node::builder()
                    .router(router)
                    .dialect(table)
                    .own_thread(true)
                    .link(spec)
                    .start()
                    .await?;
                let frames = node.subscribe_batched().await;
                Ok::<_, mavstack::NodeError>((node, frames))
            })
        });
        let (node, frames) =
            started.map_err(|e| PyOSError::new_err(format!("cannot open \"{shown}\": {e}")))?;
        let mut systems = BTreeMap::new();
        systems.insert(0, SystemState::new(py));
        Ok(Self {
            device: shown,
            handle: node.handle(),
            node: Mutex::new(Some(node)),
            closed: AtomicBool::new(false),
            dialect,
            frames: Mutex::new(Receiver::new(frames)),
            state: Mutex::new(State {
                sysid: 0,
                target_component: 0,
                systems,
                conditions: Conditions::default(),
                unknown_id: 0,
                received: 0,
            }),
            marked: AtomicBool::new(false),
            peers: Mutex::new((Vec::new(), None)),
            encode_seq: AtomicU8::new(0),
            names,
        })
    }

    /// The message type called `name` (a message's name, any case).
    fn message_type(&self, name: &str) -> PyResult<Arc<MessageType>> {
        self.dialect
            .index_of_name(&name.to_ascii_uppercase())
            .map(|i| Arc::clone(&self.dialect.messages[i]))
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "no message {name:?} in dialect {}",
                    self.dialect.name
                ))
            })
    }

    fn node_handle(&self) -> PyResult<&NodeHandle> {
        if self.closed.load(Ordering::Acquire) {
            return Err(PyConnectionError::new_err(format!(
                "\"{}\" is closed",
                self.device
            )));
        }
        Ok(&self.handle)
    }

    /// Queues `payload` of message `id` on the link, in order; `ConnectionError` once it is
    /// closed. Returns without waiting for the node unless its request queue is full.
    fn send_payload(&self, py: Python<'_>, id: u32, payload: &[u8]) -> PyResult<()> {
        let handle = self.node_handle()?;
        if handle.queue_raw(id, payload) {
            return Ok(());
        }
        let handle = handle.clone();
        let rt = runtime()?;
        py.detach(|| rt.block_on(handle.send_raw(id, payload)));
        Ok(())
    }

    /// Sets `signing` on the link: its peers now and those to come.
    fn apply_signing(&self, py: Python<'_>, signing: Option<SigningConfig>) -> PyResult<()> {
        let handle = self.node_handle()?.clone();
        let rt = runtime()?;
        py.detach(|| rt.block_on(handle.set_signing_all(signing)))
            .map_err(|e| {
                PyValueError::new_err(format!("setup_signing on \"{}\": {e}", self.device))
            })
    }
}
