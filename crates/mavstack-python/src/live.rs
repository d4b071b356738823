//! `mavstack.mavutil.mavlink_connection("udpin:0.0.0.0:14550")`: a live link with
//! pymavlink's receiving side (`recv_match`, `recv_msg`, `messages`, `target_system`,
//! `flightmode`, `motors_armed`) and the sending side its `mav` object is built on
//! (`encode`, `send_fields`, `send`, `write`).
//!
//! Each connection is one [`mavstack::Node`] with one link, opened from the connection
//! string by the stack's own parser ([`LinkSpec`]): the link's version handling and signing
//! come with it. The nodes run on one tokio runtime shared by every connection of the
//! process (one worker thread; a UDP link's node on a thread of its own, with its own
//! `epoll`); frames reach the connection through the node's subscription, and a blocking
//! `recv_match` waits on it with the GIL released, waking every 100 ms to let Python see a
//! Ctrl-C. Sends are queued to the node without waiting for it. One thread may receive while
//! others send and read the connection's state (see [`LiveLink`]).
//!
//! What pymavlink keeps per system (the latest message of each type, the flight mode, the
//! armed flag) is kept the same way here, and `target_system` locks onto the first vehicle
//! HEARTBEAT as pymavlink's does (`target_component` stays 0 until set, as in pymavlink).

use core::sync::atomic::{AtomicBool, AtomicU8, Ordering};
use core::time::Duration;
use std::collections::HashMap;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

use mavstack::channel::{Authentication, SigningConfig};
use mavstack::core::wire::{self, FrameHeader, Version};
use mavstack::modes::{self, Flavour};
use mavstack::router::{LinkId, LocalDelivery, RouterConfig};
use mavstack::{Incoming, LinkSpec, Node, NodeHandle, Subscription};
use mavstack_core::signing::SecretKey;
use mavstack_xml::PrimitiveType;
use pyo3::exceptions::{PyConnectionError, PyOSError, PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::MutexExt as _;
use pyo3::types::{PyBytes, PyDict, PyString, PyTuple};
use tokio::runtime::Runtime;
use tokio::sync::mpsc::error::TryRecvError;

use crate::connection::{Conditions, eval_condition, wanted_mask};
use crate::dialect::{Dialect, FieldLayout, MessageType};
use crate::message::{Message, bytes_at};

/// How long a blocking receive waits between two looks at Python's signals.
const SIGNAL_CHECK: Duration = Duration::from_millis(100);

/// HEARTBEAT `type` values pymavlink does not take for a vehicle: GCS, ONBOARD_CONTROLLER,
/// GIMBAL, ADSB.
const NOT_VEHICLE_TYPES: [u8; 4] = [6, 18, 26, 27];
/// MAV_AUTOPILOT_INVALID.
const AUTOPILOT_INVALID: u8 = 8;
/// MAV_COMP_ID_GIMBAL.
const COMP_GIMBAL: u8 = 154;
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
    frames: Mutex<Subscription>,
    /// What the received frames built up.
    state: Mutex<State>,
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
    systems: HashMap<u8, SystemState>,
    conditions: Conditions,
    last_type: Option<(Py<PyAny>, Arc<Vec<bool>>)>,
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
                let frames = node.subscribe().await;
                Ok::<_, mavstack::NodeError>((node, frames))
            })
        });
        let (node, frames) =
            started.map_err(|e| PyOSError::new_err(format!("cannot open \"{shown}\": {e}")))?;
        let mut systems = HashMap::new();
        systems.insert(0, SystemState::new(py));
        Ok(Self {
            device: shown,
            handle: node.handle(),
            node: Mutex::new(Some(node)),
            closed: AtomicBool::new(false),
            dialect,
            frames: Mutex::new(frames),
            state: Mutex::new(State {
                sysid: 0,
                target_component: 0,
                systems,
                conditions: Conditions::default(),
                last_type: None,
                unknown_id: 0,
                received: 0,
            }),
            peers: Mutex::new((Vec::new(), None)),
            encode_seq: AtomicU8::new(0),
            names,
        })
    }

    /// The next frame from the node: at once, or (when `blocking`) waiting until `deadline`
    /// with the GIL released. `None` when nothing came in time or the node has stopped.
    fn next_frame(
        py: Python<'_>,
        frames: &mut Subscription,
        blocking: bool,
        deadline: Option<Instant>,
    ) -> PyResult<Option<Incoming>> {
        loop {
            match frames.try_recv() {
                Ok(i) => return Ok(Some(i)),
                Err(TryRecvError::Disconnected) => return Ok(None),
                Err(TryRecvError::Empty) => {}
            }
            if !blocking {
                return Ok(None);
            }
            let wait = match deadline {
                Some(d) => {
                    let now = Instant::now();
                    if d <= now {
                        return Ok(None);
                    }
                    (d - now).min(SIGNAL_CHECK)
                }
                None => SIGNAL_CHECK,
            };
            let rt = runtime()?;
            let frames = &mut *frames;
            let got = py
                .detach(|| rt.block_on(async { tokio::time::timeout(wait, frames.recv()).await }));
            match got {
                Ok(Some(i)) => return Ok(Some(i)),
                Ok(None) => return Ok(None),
                Err(_) => py.check_signals()?,
            }
        }
    }

    /// Records a received frame as pymavlink's `post_message` does and returns it as a
    /// message with its sender's system id and its type's index; `None` for a message id
    /// the dialect does not define.
    fn post(
        &self,
        py: Python<'_>,
        incoming: &Incoming,
    ) -> PyResult<Option<(Py<Message>, u8, usize)>> {
        let frame = incoming.frame.frame.view();
        let Some(index) = self.dialect.index_of_id(frame.msg_id()) else {
            lock(py, &self.state).unknown_id += 1;
            return Ok(None);
        };
        {
            let mut peers = lock(py, &self.peers);
            if !peers.0.contains(&incoming.link_id) {
                peers.0.push(incoming.link_id);
            }
        }
        let ty = Arc::clone(&self.dialect.messages[index]);
        let verified = matches!(incoming.frame.auth, Authentication::Verified { .. });
        let sysid = frame.sysid();
        let compid = frame.compid();
        let heartbeat = (ty.name == "HEARTBEAT").then(|| heartbeat_fields(&ty, frame.payload()));
        let message = Py::new(
            py,
            Message::live(
                Arc::clone(&ty),
                frame.as_bytes().to_vec(),
                unix_now(),
                verified,
            ),
        )?;
        let messages = {
            let mut st = lock(py, &self.state);
            st.received += 1;
            let target_unset = st.sysid == 0;
            let system = st
                .systems
                .entry(sysid)
                .or_insert_with(|| SystemState::new(py));
            if let Some(hb) = heartbeat
                && probably_vehicle(compid, &hb)
            {
                system.flightmode = mode_string(&hb);
                system.armed = hb.base_mode & SAFETY_ARMED != 0;
                system.mav_type = Some(hb.mav_type);
                system.autopilot = Some(hb.autopilot);
                system.base_mode = hb.base_mode;
                if target_unset {
                    st.sysid = sysid;
                }
            }
            st.systems
                .get(&sysid)
                .map(|s| s.messages.clone_ref(py))
                .ok_or_else(|| PyRuntimeError::new_err("no state for the sender"))?
        };
        messages
            .bind(py)
            .set_item(self.names[index].bind(py), &message)?;
        Ok(Some((message, sysid, index)))
    }

    /// The type mask of a `type` argument, remembered for the same argument as last time.
    fn wanted_cached(&self, ty: &Bound<'_, PyAny>) -> PyResult<Arc<Vec<bool>>> {
        let py = ty.py();
        let last = lock(py, &self.state)
            .last_type
            .as_ref()
            .map(|(t, m)| (t.clone_ref(py), Arc::clone(m)));
        if let Some((last, mask)) = last {
            let last = last.bind(py);
            if last.is(ty) || (last.get_type().is(ty.get_type()) && last.eq(ty)?) {
                return Ok(mask);
            }
        }
        let mask = Arc::new(wanted_mask(&self.dialect, ty)?);
        lock(py, &self.state).last_type = Some((ty.clone().unbind(), Arc::clone(&mask)));
        Ok(mask)
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

/// HEARTBEAT's fields pymavlink's `post_message` looks at.
struct HeartbeatFields {
    mav_type: u8,
    autopilot: u8,
    base_mode: u8,
    custom_mode: u32,
}

fn heartbeat_fields(ty: &MessageType, payload: &[u8]) -> HeartbeatFields {
    let byte = |name| {
        ty.field(name)
            .map_or(0, |f| bytes_at::<1>(payload, f.offset)[0])
    };
    HeartbeatFields {
        mav_type: byte("type"),
        autopilot: byte("autopilot"),
        base_mode: byte("base_mode"),
        custom_mode: ty
            .field("custom_mode")
            .map_or(0, |f| u32::from_le_bytes(bytes_at(payload, f.offset))),
    }
}

/// pymavlink's `probably_vehicle_heartbeat`.
fn probably_vehicle(compid: u8, hb: &HeartbeatFields) -> bool {
    compid != COMP_GIMBAL
        && !NOT_VEHICLE_TYPES.contains(&hb.mav_type)
        && hb.autopilot != AUTOPILOT_INVALID
}

/// Where pymavlink names an ArduPilot mode otherwise than the dialect's enums (COPTER_MODE,
/// PLANE_MODE, ...): by flavour and number, its name there (`None`: pymavlink does not name
/// it). Scripts compare `flightmode` with these names and pass them to `set_mode`.
const PYMAVLINK_NAMES: &[(Flavour, u32, Option<&str>)] = &[
    (Flavour::ArduCopter, 8, Some("POSITION")),
    (Flavour::ArduCopter, 10, Some("OF_LOITER")),
    (Flavour::ArduCopter, 29, Some("RATE_ACRO")),
    (Flavour::ArduPlane, 5, Some("FBWA")),
    (Flavour::ArduPlane, 6, Some("FBWB")),
    (Flavour::ArduPlane, 16, Some("INITIALISING")),
    (Flavour::ArduPlane, 25, Some("LOITERALTQLAND")),
    (Flavour::ArduRover, 2, Some("LEARNING")),
    (Flavour::ArduRover, 16, Some("INITIALISING")),
    (Flavour::ArduSub, 20, None),
    (Flavour::ArduSub, 21, None),
];

/// The modes of an ArduPilot flavour by pymavlink's names (the dialect's, but where
/// [`PYMAVLINK_NAMES`] says otherwise), in number order; PX4's as the stack names them.
fn ardupilot_modes(flavour: Flavour) -> Vec<(&'static str, u32)> {
    let mut out: Vec<(&'static str, u32)> = modes::modes(flavour)
        .into_iter()
        .filter_map(|m| match pymavlink_alias(flavour, m.custom_mode) {
            Some(alias) => alias.map(|a| (a, m.custom_mode)),
            None => Some((m.name, m.custom_mode)),
        })
        .collect();
    for &(f, number, name) in PYMAVLINK_NAMES {
        if f == flavour
            && let Some(name) = name
            && !out.iter().any(|(_, n)| *n == number)
        {
            out.push((name, number));
        }
    }
    out.sort_by_key(|(_, n)| *n);
    out
}

/// pymavlink's name of mode `number` where it differs from the dialect's.
fn pymavlink_alias(flavour: Flavour, number: u32) -> Option<Option<&'static str>> {
    PYMAVLINK_NAMES
        .iter()
        .find(|(f, n, _)| *f == flavour && *n == number)
        .map(|(_, _, name)| *name)
}

/// The flight mode's name, as pymavlink's `mode_string_v10` writes it. PX4: its name from
/// the main mode (and AUTO's sub mode), as pymavlink names them (`MISSION`, `POSCTL`,
/// `FOLLOWME`; `UNKNOWN` for the rest). Any other autopilot: `Mode(0xNN)` (the base mode)
/// without MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, else the mode's name in ArduPilot's table for the
/// vehicle type, else `Mode(N)`.
fn mode_string(hb: &HeartbeatFields) -> String {
    use mavstack::dialects::common::{MavAutopilot, MavType};
    if MavAutopilot(hb.autopilot) == MavAutopilot::PX4 {
        return px4_mode_string(hb.custom_mode);
    }
    if hb.base_mode & CUSTOM_MODE_ENABLED == 0 {
        return format!("Mode(0x{:08x})", hb.base_mode);
    }
    Flavour::of(MavAutopilot::ARDUPILOTMEGA, MavType(hb.mav_type))
        .and_then(|f| {
            ardupilot_modes(f)
                .into_iter()
                .find(|(_, n)| *n == hb.custom_mode)
        })
        .map_or_else(
            || format!("Mode({})", hb.custom_mode),
            |(name, _)| name.to_owned(),
        )
}

/// PX4's mode as pymavlink names it: by the main mode alone, but AUTO by its sub mode
/// without the `AUTO.` prefix (AUTO.FOLLOW_TARGET is `FOLLOWME`), and `UNKNOWN` for what
/// pymavlink does not name (AUTO.READY, AUTO.PRECLAND, AUTO.VTOL_TAKEOFF, unknown modes);
/// AUTO's sub mode 7 is `RTGS`.
fn px4_mode_string(custom_mode: u32) -> String {
    const MAIN_AUTO: u32 = 4;
    const MAIN_RATTITUDE: u32 = 8;
    const AUTO_RTGS: u32 = 7;
    const AUTO_NAMED: core::ops::RangeInclusive<u32> = 2..=8;
    let main = (custom_mode >> 16) & 0xff;
    let sub = (custom_mode >> 24) & 0xff;
    let name = match main {
        MAIN_AUTO if sub == AUTO_RTGS => Some("RTGS"),
        MAIN_AUTO if AUTO_NAMED.contains(&sub) => {
            modes::name_of(Flavour::Px4, custom_mode & 0xffff_0000).map(|n| {
                match n.strip_prefix("AUTO.").unwrap_or(n) {
                    "FOLLOW_TARGET" => "FOLLOWME",
                    short => short,
                }
            })
        }
        MAIN_AUTO => None,
        MAIN_RATTITUDE => Some("RATTITUDE"),
        m => modes::name_of(Flavour::Px4, m << 16),
    };
    name.unwrap_or("UNKNOWN").to_owned()
}

/// Writes `value` into `payload` as field `f` (pymavlink's argument of that name).
pub(crate) fn put_field(
    f: &FieldLayout,
    value: &Bound<'_, PyAny>,
    payload: &mut [u8],
) -> PyResult<()> {
    if f.is_text() && f.array_len.is_some() {
        let bytes: Vec<u8> = if let Ok(s) = value.cast::<PyString>() {
            s.to_cow()?.as_bytes().to_vec()
        } else if let Ok(b) = value.extract::<Vec<u8>>() {
            b
        } else {
            return Err(PyTypeError::new_err(format!(
                "{}: a str or bytes for char[{}]",
                f.name,
                f.count()
            )));
        };
        let n = bytes.len().min(f.count());
        payload[f.offset..f.offset + n].copy_from_slice(&bytes[..n]);
        return Ok(());
    }
    let size = f.primitive.size();
    match f.array_len {
        None => put_scalar(f, value, &mut payload[f.offset..f.offset + size]),
        Some(n) => {
            let items: Vec<Bound<'_, PyAny>> = if let Ok(b) = value.cast::<PyBytes>() {
                let py = value.py();
                b.as_bytes()
                    .iter()
                    .map(|&x| pyo3::types::PyInt::new(py, x).into_any())
                    .collect()
            } else {
                value
                    .try_iter()
                    .map_err(|_| {
                        PyTypeError::new_err(format!("{}: a sequence of {n} values", f.name))
                    })?
                    .collect::<PyResult<_>>()?
            };
            if items.len() > n {
                return Err(PyValueError::new_err(format!(
                    "{}: {} values for an array of {n}",
                    f.name,
                    items.len()
                )));
            }
            for (i, item) in items.iter().enumerate() {
                let at = f.offset + i * size;
                put_scalar(f, item, &mut payload[at..at + size])?;
            }
            Ok(())
        }
    }
}

/// Writes one element of field `f` into `out` (its size).
fn put_scalar(f: &FieldLayout, value: &Bound<'_, PyAny>, out: &mut [u8]) -> PyResult<()> {
    let range = |e: PyErr| {
        PyValueError::new_err(format!(
            "{}: {} does not fit a {:?} ({e})",
            f.name,
            value
                .repr()
                .map_or_else(|_| "?".to_owned(), |r| r.to_string()),
            f.primitive
        ))
    };
    match f.primitive {
        PrimitiveType::F32 => {
            let v: f64 = value.extract()?;
            out.copy_from_slice(&(v as f32).to_le_bytes());
        }
        PrimitiveType::F64 => {
            let v: f64 = value.extract()?;
            out.copy_from_slice(&v.to_le_bytes());
        }
        PrimitiveType::Char => {
            let b: u8 = if let Ok(s) = value.cast::<PyString>() {
                s.to_cow()?.bytes().next().unwrap_or(0)
            } else {
                value.extract().map_err(range)?
            };
            out[0] = b;
        }
        PrimitiveType::U8 => {
            out.copy_from_slice(&value.extract::<u8>().map_err(range)?.to_le_bytes())
        }
        PrimitiveType::I8 => {
            out.copy_from_slice(&value.extract::<i8>().map_err(range)?.to_le_bytes())
        }
        PrimitiveType::U16 => {
            out.copy_from_slice(&value.extract::<u16>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I16 => {
            out.copy_from_slice(&value.extract::<i16>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::U32 => {
            out.copy_from_slice(&value.extract::<u32>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I32 => {
            out.copy_from_slice(&value.extract::<i32>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::U64 => {
            out.copy_from_slice(&value.extract::<u64>().map_err(range)?.to_le_bytes());
        }
        PrimitiveType::I64 => {
            out.copy_from_slice(&value.extract::<i64>().map_err(range)?.to_le_bytes());
        }
    }
    Ok(())
}

/// The full payload of `ty` from its fields' values in XML order (pymavlink's arguments).
fn encode_payload(ty: &MessageType, args: &Bound<'_, PyTuple>) -> PyResult<Vec<u8>> {
    if args.len() != ty.fields.len() {
        return Err(PyTypeError::new_err(format!(
            "{}: {} values for {} fields",
            ty.name,
            args.len(),
            ty.fields.len()
        )));
    }
    let mut payload = vec![0u8; ty.max_len];
    for (f, v) in ty.fields.iter().zip(args.iter()) {
        put_field(f, &v, &mut payload)?;
    }
    Ok(payload)
}

#[pymethods]
impl LiveLink {
    /// The next message, or `None` when none has arrived (pymavlink's `recv_msg`: it does
    /// not wait).
    fn recv_msg(&self, py: Python<'_>) -> PyResult<Option<Py<Message>>> {
        let mut frames = lock(py, &self.frames);
        while let Some(i) = Self::next_frame(py, &mut frames, false, None)? {
            if let Some((m, _, _)) = self.post(py, &i)? {
                return Ok(Some(m));
            }
        }
        Ok(None)
    }

    /// The next message of the given type(s) for which `condition` holds (a Python
    /// expression over the latest messages of the sender's system, as pymavlink's); with
    /// `blocking`, waiting up to `timeout` seconds (forever without one) with the GIL
    /// released. `None` when nothing matched in time.
    #[pyo3(signature = (condition=None, r#type=None, blocking=false, timeout=None))]
    fn recv_match(
        &self,
        py: Python<'_>,
        condition: Option<&str>,
        r#type: Option<&Bound<'_, PyAny>>,
        blocking: bool,
        timeout: Option<f64>,
    ) -> PyResult<Option<Py<Message>>> {
        let wanted = match r#type {
            Some(t) if !t.is_none() => Some(self.wanted_cached(t)?),
            _ => None,
        };
        let deadline = match timeout {
            Some(t) if t.is_finite() => {
                Some(Instant::now() + Duration::try_from_secs_f64(t.max(0.0)).unwrap_or_default())
            }
            _ => None,
        };
        let mut frames = lock(py, &self.frames);
        loop {
            if deadline.is_some_and(|d| Instant::now() >= d) {
                return Ok(None);
            }
            let Some(incoming) = Self::next_frame(py, &mut frames, blocking, deadline)? else {
                return Ok(None);
            };
            let Some((message, sysid, index)) = self.post(py, &incoming)? else {
                continue;
            };
            if wanted.as_ref().is_some_and(|w| !w[index]) {
                continue;
            }
            if let Some(c) = condition {
                let (globals, code, locals) = {
                    let mut st = lock(py, &self.state);
                    let (globals, code) = st.conditions.prepare(py, c)?;
                    let locals = st
                        .systems
                        .get(&sysid)
                        .map(|s| s.messages.clone_ref(py))
                        .ok_or_else(|| PyRuntimeError::new_err("no state for the sender"))?;
                    (globals, code, locals)
                };
                if !eval_condition(py, &globals, &code, locals.bind(py).as_any())? {
                    continue;
                }
            }
            return Ok(Some(message));
        }
    }

    /// The latest message of each type from the target system (pymavlink's `messages`, a
    /// dict by name).
    #[getter]
    fn messages(&self, py: Python<'_>) -> Py<PyDict> {
        lock(py, &self.state).target(py).messages.clone_ref(py)
    }

    /// The latest messages of each system heard: `{sysid: {name: message}}`.
    fn messages_by_system<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let all: Vec<(u8, Py<PyDict>)> = lock(py, &self.state)
            .systems
            .iter()
            .map(|(k, s)| (*k, s.messages.clone_ref(py)))
            .collect();
        let d = PyDict::new(py);
        for (sysid, m) in all {
            d.set_item(sysid, m)?;
        }
        Ok(d)
    }

    /// The target system: the first vehicle heard (0 until then), or what was set.
    #[getter]
    fn get_target_system(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).sysid
    }

    #[setter]
    fn set_target_system(&self, py: Python<'_>, value: u8) {
        let mut st = lock(py, &self.state);
        st.sysid = value;
        let _ = st.target(py);
    }

    /// The target component (0, every component, until set: as pymavlink).
    #[getter]
    fn get_target_component(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).target_component
    }

    #[setter]
    fn set_target_component(&self, py: Python<'_>, value: u8) {
        lock(py, &self.state).target_component = value;
    }

    /// The target's flight mode, by name (`"GUIDED"`), from its latest HEARTBEAT.
    #[getter]
    fn flightmode(&self, py: Python<'_>) -> String {
        lock(py, &self.state).target(py).flightmode.clone()
    }

    /// Whether the target's latest HEARTBEAT said armed.
    fn motors_armed(&self, py: Python<'_>) -> bool {
        lock(py, &self.state).target(py).armed
    }

    /// The target's HEARTBEAT `type` (None before one came).
    #[getter]
    fn mav_type(&self, py: Python<'_>) -> Option<u8> {
        lock(py, &self.state).target(py).mav_type
    }

    /// The target's HEARTBEAT `autopilot` (None before one came).
    #[getter]
    fn mav_autopilot(&self, py: Python<'_>) -> Option<u8> {
        lock(py, &self.state).target(py).autopilot
    }

    /// The target's HEARTBEAT `base_mode`.
    #[getter]
    fn base_mode(&self, py: Python<'_>) -> u8 {
        lock(py, &self.state).target(py).base_mode
    }

    /// The target's modes, name → `custom_mode`, for its autopilot and vehicle type (ArduPilot's
    /// by pymavlink's names); `None` before its HEARTBEAT or for an autopilot whose modes are
    /// not known.
    fn mode_mapping<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(flavour) = lock(py, &self.state).flavour(py) else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        for (name, number) in ardupilot_modes(flavour) {
            d.set_item(name, number)?;
        }
        Ok(Some(d))
    }

    /// MAV_CMD_DO_SET_MODE's param1-3 for `mode` (a name, or an ArduPilot mode number) on
    /// the target; `None` for a name it does not have.
    fn mode_params(
        &self,
        py: Python<'_>,
        mode: &Bound<'_, PyAny>,
    ) -> PyResult<Option<(f32, f32, f32)>> {
        let flavour = lock(py, &self.state).flavour(py);
        if let Ok(n) = mode.extract::<u32>() {
            return Ok(Some(match flavour {
                Some(f) => f.command_params(n),
                None => (f32::from(CUSTOM_MODE_ENABLED), n as f32, 0.0),
            }));
        }
        let name: String = mode.extract()?;
        Ok(flavour.and_then(|f| {
            let pymavlink = ardupilot_modes(f)
                .into_iter()
                .find(|(n, _)| *n == name)
                .map(|(_, number)| number);
            pymavlink
                .or_else(|| modes::by_name(f, &name).map(|m| m.custom_mode))
                .map(|number| f.command_params(number))
        }))
    }

    /// A message of `name` from its fields' values in XML order, framed (MAVLink 2) as
    /// this connection's system and component would send it: pymavlink's `*_encode`.
    fn encode(&self, name: &str, args: &Bound<'_, PyTuple>) -> PyResult<Message> {
        let ty = self.message_type(name)?;
        let payload = encode_payload(&ty, args)?;
        let info = self.dialect.table.info(ty.id).ok_or_else(|| {
            PyValueError::new_err(format!("no message id {} in the dialect", ty.id))
        })?;
        let (sysid, compid) = self.handle.identity();
        let header = FrameHeader {
            version: Version::V2,
            seq: self.encode_seq.fetch_add(1, Ordering::Relaxed),
            sysid,
            compid,
            signed: false,
        };
        let mut out = [0u8; wire::MAX_FRAME_LEN];
        let len = wire::emit(&header, info, &payload, &mut out)
            .map_err(|e| PyValueError::new_err(format!("{}: {e}", ty.name)))?;
        Ok(Message::live(ty, out[..len].to_vec(), unix_now(), false))
    }

    /// Sends message `name` from its fields' values in XML order: pymavlink's `*_send`.
    /// The link frames it in its version (and signs it when it signs).
    fn send_fields(&self, py: Python<'_>, name: &str, args: &Bound<'_, PyTuple>) -> PyResult<()> {
        let ty = self.message_type(name)?;
        let payload = encode_payload(&ty, args)?;
        self.send_payload(py, ty.id, &payload)?;
        Ok(())
    }

    /// Sends `message` (one received or encoded) as this connection's own: pymavlink's
    /// `mav.send`.
    fn send(&self, py: Python<'_>, message: PyRef<'_, Message>) -> PyResult<()> {
        let id = message.message_type().id;
        let payload = message.payload().to_vec();
        drop(message);
        self.send_payload(py, id, &payload)?;
        Ok(())
    }

    /// Writes `data` (whole frames) to every peer of the link as they are: pymavlink's
    /// `write`, what a forwarder does with `get_msgbuf()`.
    fn write(&self, py: Python<'_>, data: &[u8]) -> PyResult<()> {
        let handle = self.node_handle()?.clone();
        let rt = runtime()?;
        let stale = lock(py, &self.peers)
            .1
            .is_none_or(|t| t.elapsed() > Duration::from_secs(1));
        if stale {
            let report = py.detach(|| rt.block_on(handle.report()));
            let mut peers = lock(py, &self.peers);
            if let Some(report) = report {
                for link in report.links.iter().filter_map(|l| l.link_id) {
                    if !peers.0.contains(&link) {
                        peers.0.push(link);
                    }
                }
            }
            peers.1 = Some(Instant::now());
        }
        let peers = lock(py, &self.peers).0.clone();
        let kept: Vec<LinkId> = py.detach(|| {
            rt.block_on(async {
                let mut kept = Vec::new();
                for link in peers {
                    if handle.send_bytes(link, data).await {
                        kept.push(link);
                    }
                }
                kept
            })
        });
        lock(py, &self.peers).0.retain(|l| kept.contains(l));
        Ok(())
    }

    /// Signs every frame sent from now on with `key` (32 bytes) and accepts only signed
    /// frames, but the message ids in `allow_unsigned` (at most 8); `link_id` goes into the
    /// signatures, `initial_timestamp` (10 µs units since 2015) is the least one issued.
    #[pyo3(signature = (key, link_id=0, initial_timestamp=0, allow_unsigned=Vec::new()))]
    fn setup_signing(
        &self,
        py: Python<'_>,
        key: &[u8],
        link_id: u8,
        initial_timestamp: u64,
        allow_unsigned: Vec<u32>,
    ) -> PyResult<()> {
        let key: [u8; 32] = key.try_into().map_err(|_| {
            PyValueError::new_err(format!(
                "secret_key: {} bytes, a signing key is 32 bytes",
                key.len()
            ))
        })?;
        let mut config = SigningConfig::new(SecretKey::new(key), link_id);
        config.initial_timestamp = initial_timestamp;
        if !allow_unsigned.is_empty() {
            config.clear_allowed_unsigned();
            for id in allow_unsigned {
                config
                    .allow_unsigned(id)
                    .map_err(|e| PyValueError::new_err(format!("allow_unsigned_callback: {e}")))?;
            }
        }
        self.apply_signing(py, Some(config))
    }

    /// Stops signing (pymavlink's `disable_signing`).
    fn disable_signing(&self, py: Python<'_>) -> PyResult<()> {
        self.apply_signing(py, None)
    }

    /// Closes the link: queued frames go out, the socket or port closes.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.closed.store(true, Ordering::Release);
        let Some(node) = lock(py, &self.node).take() else {
            return Ok(());
        };
        let rt = runtime()?;
        let res = py.detach(|| rt.block_on(node.shutdown()));
        match res {
            Ok(_) => Ok(()),
            Err(e) => Err(PyOSError::new_err(format!("{}: {e}", self.device))),
        }
    }

    /// This connection's own system id (pymavlink's `mav.srcSystem`).
    #[getter]
    fn src_system(&self) -> u8 {
        self.handle.identity().0
    }

    /// This connection's own component id (pymavlink's `mav.srcComponent`).
    #[getter]
    fn src_component(&self) -> u8 {
        self.handle.identity().1
    }

    /// The dialect's name.
    #[getter]
    fn dialect(&self) -> &str {
        &self.dialect.name
    }

    /// The connection string (keys redacted).
    #[getter]
    fn address(&self) -> &str {
        &self.device
    }

    /// For each message of the dialect: its name, and its fields in XML order (pymavlink's
    /// arguments), each with its default (`None`: a required argument; else the value of an
    /// optional one -- 0 for an extension, 3 for HEARTBEAT's `mavlink_version` -- and, for an
    /// array extension, its length: pymavlink's default is that many zeros, `b""` for text,
    /// whose length is given as 0).
    #[allow(clippy::type_complexity)]
    fn message_signatures(&self) -> Vec<(String, Vec<(String, Option<u8>, Option<usize>)>)> {
        self.dialect
            .messages
            .iter()
            .map(|m| {
                let fields = m
                    .fields
                    .iter()
                    .map(|f| {
                        let default = if f.mavlink_version {
                            Some(3)
                        } else if f.extension {
                            Some(0)
                        } else {
                            None
                        };
                        // A text extension's array length is reported as 0: its default is b"".
                        let array = f
                            .array_len
                            .filter(|_| f.extension)
                            .map(|n| if f.is_text() { 0 } else { n });
                        (f.name.clone(), default, array)
                    })
                    .collect();
                (m.name.clone(), fields)
            })
            .collect()
    }

    /// The node's report (links, peers, counters), as text: for diagnosing a link.
    fn report(&self, py: Python<'_>) -> PyResult<String> {
        let handle = self.node_handle()?.clone();
        let rt = runtime()?;
        let finished = lock(py, &self.node).as_ref().is_some_and(Node::is_finished);
        let report = py.detach(|| rt.block_on(handle.report()));
        Ok(format!("finished: {finished}; {report:#?}"))
    }

    /// The ids of the dialect's messages.
    fn message_ids(&self) -> Vec<u32> {
        self.dialect.messages.iter().map(|m| m.id).collect()
    }

    /// Counts: `received` (messages returned or recorded), `unknown_id`.
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (received, unknown_id) = {
            let st = lock(py, &self.state);
            (st.received, st.unknown_id)
        };
        let d = PyDict::new(py);
        d.set_item("received", received)?;
        d.set_item("unknown_id", unknown_id)?;
        Ok(d)
    }
}
