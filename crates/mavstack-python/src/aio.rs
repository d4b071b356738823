//! `mavstack.aio`: the native half of the asyncio API (the Python half is
//! `python/mavstack/aio.py`).
//!
//! Every operation runs as a task on the runtime the live links share (`live::runtime`, one
//! worker thread): a ground station's node ([`mavstack::Node::ground_station`]) and a
//! [`mavstack::system::System`] per vehicle for parameters, missions, commands and rates;
//! [`mavstack::serve::Served`] for a component that answers commands and offers parameters.
//! No thread is started per call or per message.
//!
//! Completion: an operation is given the loop's [`AioWaker`] and a `settle(ok, value)`
//! callable. When its task ends, the result is queued on the waker and one byte written to
//! the socket the loop watches (`loop.add_reader`); the loop's thread then runs
//! `AioWaker.drain`, which builds the Python values and calls `settle`, so the future is
//! completed on the loop's own thread (the Python side checks that the future is not done or
//! cancelled first). This is `loop.call_soon_threadsafe` without the runtime's thread ever
//! taking the GIL (see [`AioWaker`] for why). An error is settled as `(kind, message)`, which
//! the Python side turns into its exception classes. The [`Op`] returned aborts the task
//! when the awaiting Python task is cancelled: dropping a `System` future abandons its
//! operation, and the vehicle's lock is released with it.
//!
//! Streams (telemetry, requests to a served component) are a queue filled by a task and
//! emptied from Python; the task wakes the loop only while Python waits on an empty queue,
//! so a busy stream costs one wake-up per batch, not per message.

use core::future::Future;
use core::sync::atomic::{AtomicBool, Ordering};
use core::time::Duration;
use std::collections::VecDeque;
use std::io::{Read as _, Write as _};
use std::os::fd::AsRawFd as _;
use std::os::unix::net::UnixStream;
use std::sync::{Arc, Mutex, MutexGuard};

use mavstack::channel::{Authentication, SigningConfig};
use mavstack::dialects::common::{
    CommandInt, CommandLong, Heartbeat, MavAutopilot, MavCmd, MavFrame, MavMissionType, MavResult,
    MavState, MavType, MissionItemInt,
};
use mavstack::router::{LinkRole, LocalDelivery, ProtocolVersionSupport, RouterConfig};
use mavstack::serve::{Served, ServedHandle};
use mavstack::services::command::{
    Command, CommandError, CommandHandler, CommandServer, CommandServerConfig, Request, Response,
};
use mavstack::services::heartbeat::HeartbeatEvent;
use mavstack::services::mission::MissionError;
use mavstack::services::param::{Encoding, Name, ParamError, ParamServer, Value};
use mavstack::services::plan::{self, Convention};
use mavstack::services::{Address, Outgoing, Service};
use mavstack::system::{Discovery, ParamsVia, System, SystemError, Wanted};
use mavstack::transport::clock;
use mavstack::{Incoming, LinkSpec, Node, NodeHandle};
use mavstack_core::signing::SecretKey;
use pyo3::IntoPyObjectExt as _;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use tokio::sync::watch;
use tokio::task::AbortHandle;

use crate::dialect::{Dialect, MessageType};
use crate::live::runtime;
use crate::message::Message;

/// Messages a stream keeps while nobody reads it; the oldest go first beyond that.
const STREAM_DEPTH: usize = 1024;

/// MAV_COMP_ID_MISSIONPLANNER, the default component of a ground station.
const MISSION_PLANNER: u8 = 190;

/// The settled value of an operation, built on the loop's thread (with the GIL).
type Build = Box<dyn for<'py> FnOnce(Python<'py>) -> PyResult<Py<PyAny>> + Send>;

/// Why an operation failed: a kind the Python side maps to its exception class, and the
/// message.
#[derive(Debug)]
pub(crate) struct AioError {
    kind: &'static str,
    message: String,
}

impl AioError {
    fn new(kind: &'static str, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
        }
    }
}

/// The kind of a [`SystemError`]: `timeout` for everything that ran out of time (no
/// vehicle, no answer after the retries), `closed` when the node stopped, else the area.
fn system_error(e: SystemError) -> AioError {
    let kind = match &e {
        SystemError::NotFound { .. } | SystemError::Timeout { .. } => "timeout",
        SystemError::Param {
            source: ParamError::TimedOut { .. } | ParamError::ListIncomplete { .. },
            ..
        } => "timeout",
        SystemError::Param { .. } | SystemError::ParamFile { .. } => "param",
        SystemError::Mission {
            source: MissionError::TimedOut { .. },
            ..
        } => "timeout",
        SystemError::Mission { .. } => "mission",
        SystemError::Command {
            source: CommandError::TimedOut { .. } | CommandError::InProgressTimedOut { .. },
            ..
        } => "timeout",
        SystemError::Command { .. } => "command",
        SystemError::UnknownMode { .. } => "mode",
        SystemError::Stopped => "closed",
        _ => "error",
    };
    AioError::new(kind, e.to_string())
}

/// What the runtime hands to the loop's thread.
enum Entry {
    /// An operation's end: `settle(ok, value)`.
    Settle(Py<PyAny>, Result<Build, AioError>),
    /// A stream's reader to wake: `wake()`.
    Call(Py<PyAny>),
    /// An operation's progress: `callback(done, total)` with the latest values.
    Progress(Arc<ProgressSlot>),
}

/// The latest progress of an operation and whom to tell: values that come faster than the
/// loop takes them replace each other.
pub(crate) struct ProgressSlot {
    callback: Py<PyAny>,
    latest: Mutex<Option<(u64, u64)>>,
}

/// A progress function for a `System` operation: `(done, total)` to `callback` on the
/// loop's thread (nothing without a callback).
fn progress_fn(
    waker: &Arc<WakerInner>,
    callback: Option<Py<PyAny>>,
) -> impl FnMut(u64, u64) + Send + 'static {
    let slot = callback.map(|callback| {
        (
            Arc::clone(waker),
            Arc::new(ProgressSlot {
                callback,
                latest: Mutex::new(None),
            }),
        )
    });
    move |done, total| {
        if let Some((waker, slot)) = &slot
            && lock(&slot.latest).replace((done, total)).is_none()
        {
            waker.post(Entry::Progress(Arc::clone(slot)));
        }
    }
}

/// The runtime's side of an [`AioWaker`]: entries for the loop, and the socket that wakes it.
pub(crate) struct WakerInner {
    entries: Mutex<Vec<Entry>>,
    /// Set when a byte is on its way and the loop has not drained since.
    signaled: AtomicBool,
    tx: UnixStream,
}

impl WakerInner {
    /// Queues `entry` for the loop's thread and wakes the loop (one byte, only when none is
    /// pending): no Python, no GIL on the runtime's thread.
    fn post(&self, entry: Entry) {
        lock(&self.entries).push(entry);
        if !self.signaled.swap(true, Ordering::SeqCst) {
            // Full (a byte is pending anyway) or closed (the loop is gone): nothing to do.
            let _ = (&self.tx).write(&[1]);
        }
    }
}

/// One per asyncio loop: the runtime's results reach the loop's thread through it. The
/// loop watches `fileno()` (`loop.add_reader(w.fileno(), w.drain)`); the runtime queues
/// each result and writes one byte when none is pending, never taking the GIL, so a
/// result costs no thread switch into Python on the runtime's side, results that come
/// together are settled in one wake-up, and nothing on the runtime's thread can be caught
/// in Python at the interpreter's exit (what `loop.call_soon_threadsafe` from the runtime's
/// thread would risk: it releases the GIL inside, and a thread that wants it back during
/// finalization is ended).
#[pyclass(module = "mavstack._native", name = "AioWaker", frozen)]
pub(crate) struct AioWaker {
    inner: Arc<WakerInner>,
    rx: UnixStream,
}

#[pymethods]
impl AioWaker {
    #[new]
    fn new() -> PyResult<Self> {
        let (rx, tx) = UnixStream::pair()?;
        rx.set_nonblocking(true)?;
        tx.set_nonblocking(true)?;
        Ok(Self {
            inner: Arc::new(WakerInner {
                entries: Mutex::new(Vec::new()),
                signaled: AtomicBool::new(false),
                tx,
            }),
            rx,
        })
    }

    /// The descriptor the loop watches for reading.
    fn fileno(&self) -> i32 {
        self.rx.as_raw_fd()
    }

    /// Settles the operations that ended and wakes the streams' readers (on the loop's
    /// thread); an exception in one of them is reported as unraisable, the rest still run.
    fn drain(&self, py: Python<'_>) {
        // The byte first, then `signaled`, then the entries: a `post` that comes after the
        // byte was read either still sees `signaled` set (its entry is taken below) or writes
        // a byte of its own. Clearing `signaled` before reading would swallow that byte and
        // leave `signaled` set with nothing pending: every later result would wait forever.
        let mut buf = [0u8; 64];
        while matches!((&self.rx).read(&mut buf), Ok(n) if n > 0) {}
        self.inner.signaled.store(false, Ordering::SeqCst);
        let entries = core::mem::take(&mut *lock(&self.inner.entries));
        for entry in entries {
            let called = match entry {
                Entry::Settle(settle, result) => {
                    let args = match result.and_then(|build| {
                        build(py).map_err(|e| {
                            AioError::new("error", format!("building the result: {e}"))
                        })
                    }) {
                        Ok(value) => (true, value),
                        Err(e) => match (e.kind, e.message).into_py_any(py) {
                            Ok(t) => (false, t),
                            Err(e) => {
                                e.write_unraisable(py, None);
                                continue;
                            }
                        },
                    };
                    settle.call1(py, args).map(drop)
                }
                Entry::Call(wake) => wake.call0(py).map(drop),
                Entry::Progress(slot) => match lock(&slot.latest).take() {
                    Some(p) => slot.callback.call1(py, p).map(drop),
                    None => Ok(()),
                },
            };
            if let Err(e) = called {
                e.write_unraisable(py, None);
            }
        }
    }
}

/// Wakes a waiting stream reader.
fn wake(waiter: Option<(Arc<WakerInner>, Py<PyAny>)>) {
    if let Some((waker, wake)) = waiter {
        waker.post(Entry::Call(wake));
    }
}

/// Runs `op` on the runtime and settles the Python future with its result.
fn spawn_op<F>(waker: &AioWaker, settle: Py<PyAny>, op: F) -> PyResult<Op>
where
    F: Future<Output = Result<Build, AioError>> + Send + 'static,
{
    let rt = runtime()?;
    let waker = Arc::clone(&waker.inner);
    let task = rt.spawn(async move {
        let result = op.await;
        waker.post(Entry::Settle(settle, result));
    });
    Ok(Op {
        abort: task.abort_handle(),
    })
}

fn build<T>(value: T) -> Build
where
    T: for<'py> IntoPyObject<'py> + Send + 'static,
{
    Box::new(move |py| value.into_py_any(py))
}

/// `lock` that takes a lock poisoned by a panic as it is (every update is one assignment).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A running operation: `cancel()` abandons it.
#[pyclass(module = "mavstack._native", name = "AioOp", frozen)]
pub(crate) struct Op {
    abort: AbortHandle,
}

#[pymethods]
impl Op {
    /// Abandons the operation (its future is not settled any more).
    fn cancel(&self) {
        self.abort.abort();
    }
}

/// A queue filled by a task and read from Python, with the reader's wake-up.
struct Queue<T> {
    items: VecDeque<T>,
    /// The loop and callable to call when an item comes, while the reader waits.
    waiter: Option<(Arc<WakerInner>, Py<PyAny>)>,
    ended: bool,
    dropped: u64,
}

impl<T> Queue<T> {
    fn new() -> Arc<Mutex<Self>> {
        Arc::new(Mutex::new(Self {
            items: VecDeque::new(),
            waiter: None,
            ended: false,
            dropped: 0,
        }))
    }
}

/// Adds `item` to `queue` (the oldest dropped when full) and wakes its reader.
fn push<T>(queue: &Mutex<Queue<T>>, item: T) {
    let waiter = {
        let mut q = lock(queue);
        if q.ended {
            return;
        }
        if q.items.len() == STREAM_DEPTH {
            q.items.pop_front();
            q.dropped += 1;
        }
        q.items.push_back(item);
        q.waiter.take()
    };
    wake(waiter);
}

/// Ends `queue` (what it holds can still be read) and wakes its reader.
fn end<T>(queue: &Mutex<Queue<T>>) {
    let waiter = {
        let mut q = lock(queue);
        q.ended = true;
        q.waiter.take()
    };
    wake(waiter);
}

/// `wait(loop, wake)`: whether the reader should wait (the queue is empty and open); its
/// `wake` is then called once an item comes or the queue ends.
fn set_waiter<T>(queue: &Mutex<Queue<T>>, waker: &AioWaker, wake: Py<PyAny>) -> bool {
    let mut q = lock(queue);
    if !q.items.is_empty() || q.ended {
        return false;
    }
    q.waiter = Some((Arc::clone(&waker.inner), wake));
    true
}

/// Options of a connection's node.
fn link_spec(
    device: &str,
    dialect: &Dialect,
    key: Option<SecretKey>,
    link_id: u8,
) -> PyResult<LinkSpec> {
    let mut spec = LinkSpec::parse_in(device, &dialect.table)
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    if let Some(key) = key {
        spec.config.signing = Some(SigningConfig::new(key, link_id));
    }
    Ok(spec)
}

/// What a connection shares with its vehicles and streams.
struct Shared {
    device: String,
    dialect: Arc<Dialect>,
    handle: NodeHandle,
    /// Becomes true when the connection closes: streams end, operations fail.
    closed: watch::Receiver<bool>,
}

/// Runs `op` until the connection closes (then `closed`).
async fn until_closed<T>(
    mut closed: watch::Receiver<bool>,
    op: impl Future<Output = Result<T, AioError>>,
) -> Result<T, AioError> {
    tokio::select! {
        r = op => r,
        _ = closed.wait_for(|c| *c) => Err(AioError::new("closed", "the connection is closed")),
    }
}

/// Queues message `name` with `fields` (by name; the others zero) on `handle`'s links, in
/// each link's version and signing; never waits for the node unless its queue is full.
fn send_fields(
    handle: &NodeHandle,
    dialect: &Dialect,
    name: &str,
    fields: Option<&Bound<'_, PyDict>>,
) -> PyResult<()> {
    let ty = dialect
        .index_of_name(&name.to_ascii_uppercase())
        .map(|i| Arc::clone(&dialect.messages[i]))
        .ok_or_else(|| {
            PyValueError::new_err(format!("no message {name:?} in dialect {}", dialect.name))
        })?;
    let mut payload = vec![0u8; ty.max_len];
    if let Some(fields) = fields {
        for (k, v) in fields.iter() {
            let k: String = k.extract()?;
            let f = ty
                .field(&k)
                .ok_or_else(|| PyTypeError::new_err(format!("{} has no field {k:?}", ty.name)))?;
            crate::live::put_field(f, &v, &mut payload)?;
        }
    }
    if !handle.queue_raw(ty.id, &payload) {
        let handle = handle.clone();
        let id = ty.id;
        runtime()?.spawn(async move { handle.send_raw(id, &payload).await });
    }
    Ok(())
}

/// A component heard: (sysid, compid, autopilot, type).
type Heard = (u8, u8, u8, u8);

/// A ground station's connection: one node with one link (`mavstack.aio.connect`).
#[pyclass(module = "mavstack._native", name = "AioLink", frozen)]
pub(crate) struct AioLink {
    shared: Arc<Shared>,
    node: tokio::sync::Mutex<Option<Node>>,
    close_tx: watch::Sender<bool>,
    /// The components heard and not lost: (sysid, compid, autopilot, type).
    heard: Arc<Mutex<Vec<Heard>>>,
}

/// Opens a ground station's link (`udpin:0.0.0.0:14550`, ...) as system `source_system`,
/// component `source_component`, signing with `key` when given; settles with an `AioLink`.
#[pyfunction]
#[pyo3(signature = (device, source_system, source_component, dialect, key, link_id, waker, settle))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn aio_connect(
    device: &str,
    source_system: u8,
    source_component: u8,
    dialect: &str,
    key: Option<&Bound<'_, PyAny>>,
    link_id: u8,
    waker: PyRef<'_, AioWaker>,
    settle: Py<PyAny>,
) -> PyResult<Op> {
    if source_system == 0 {
        return Err(PyValueError::new_err(
            "source_system 0 is the broadcast address, never a sender",
        ));
    }
    let dialect = Dialect::load(dialect)?;
    let key = crate::connection::parse_key(key)?;
    let spec = link_spec(device, &dialect, key, link_id)?;
    let shown = mavstack::redacted(device);
    let component = if source_component == 0 {
        MISSION_PLANNER
    } else {
        source_component
    };
    spawn_op(&waker, settle, async move {
        let node = Node::ground_station(source_system, component)
            .dialect(dialect.table)
            .link(spec)
            .start()
            .await
            .map_err(|e| AioError::new("connection", format!("cannot open \"{shown}\": {e}")))?;
        let handle = node.handle();
        let (close_tx, closed) = watch::channel(false);
        let heard = Arc::new(Mutex::new(Vec::new()));
        let mut discovery = Discovery::new(&handle).await;
        let table = Arc::clone(&heard);
        let watch_closed = closed.clone();
        tokio::spawn(until_closed(watch_closed, async move {
            while let Some(event) = discovery.next().await {
                if matches!(event, HeartbeatEvent::New(_) | HeartbeatEvent::Lost(_)) {
                    *lock(&table) = discovery
                        .peers()
                        .map(|p| {
                            (
                                p.address.system,
                                p.address.component,
                                p.autopilot.0,
                                p.mav_type.0,
                            )
                        })
                        .collect();
                }
            }
            Ok(())
        }));
        let link = AioLink {
            shared: Arc::new(Shared {
                device: shown,
                dialect,
                handle,
                closed,
            }),
            node: tokio::sync::Mutex::new(Some(node)),
            close_tx,
            heard,
        };
        Ok(Box::new(move |py: Python<'_>| Ok(Py::new(py, link)?.into_any())) as Build)
    })
}

#[pymethods]
impl AioLink {
    /// Waits up to `timeout` s for the first autopilot heard (or system `system`, component
    /// `component`); settles with an `AioVehicle`.
    #[pyo3(signature = (system, component, timeout, waker, settle))]
    fn vehicle(
        &self,
        system: Option<u8>,
        component: Option<u8>,
        timeout: f64,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let wait = seconds(timeout, "timeout")?;
        let shared = Arc::clone(&self.shared);
        let wanted = system.map_or(Wanted::AnyAutopilot, |s| Wanted::System(s, component));
        spawn_op(
            &waker,
            settle,
            until_closed(self.shared.closed.clone(), async move {
                let system = System::wait(&shared.handle, wanted, wait)
                    .await
                    .map_err(system_error)?;
                let vehicle = AioVehicle {
                    target: system.target(),
                    autopilot: system.autopilot().0,
                    mav_type: system.mav_type().0,
                    link_name: system.link_name().to_owned(),
                    system: Arc::new(tokio::sync::Mutex::new(system)),
                    shared,
                };
                Ok(Box::new(move |py: Python<'_>| Ok(Py::new(py, vehicle)?.into_any())) as Build)
            }),
        )
    }

    /// The components heard and not lost (silent 3 s): `(sysid, compid, autopilot, type)`.
    fn systems(&self) -> Vec<Heard> {
        lock(&self.heard).clone()
    }

    /// Closes the link: streams end, running operations fail with `closed`.
    fn close(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let _ = self.close_tx.send(true);
        let node = self.node.try_lock().ok().and_then(|mut n| n.take());
        let device = self.shared.device.clone();
        spawn_op(&waker, settle, async move {
            if let Some(node) = node {
                node.shutdown()
                    .await
                    .map_err(|e| AioError::new("connection", format!("{device}: {e}")))?;
            }
            Ok(build(()))
        })
    }

    /// Sends message `name` with `fields` (by name, as pymavlink's `*_send` arguments; the
    /// others zero) as this connection's own, on its link.
    #[pyo3(signature = (name, fields=None))]
    fn send(&self, name: &str, fields: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        if self.closed() {
            return Err(pyo3::exceptions::PyConnectionError::new_err(format!(
                "\"{}\" is closed",
                self.shared.device
            )));
        }
        send_fields(&self.shared.handle, &self.shared.dialect, name, fields)
    }

    /// Whether `close` was called.
    #[getter]
    fn closed(&self) -> bool {
        *self.shared.closed.borrow()
    }

    /// The connection string (keys redacted).
    #[getter]
    fn address(&self) -> &str {
        &self.shared.device
    }

    /// This connection's own (system, component).
    #[getter]
    fn identity(&self) -> (u8, u8) {
        self.shared.handle.identity()
    }
}

/// `timeout` as a duration (non-negative, finite).
fn seconds(s: f64, what: &str) -> PyResult<Duration> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| PyValueError::new_err(format!("{what}: {s} is not a number of seconds")))
}

/// A parameter value for Python: an `int` for the integer types, a `float` for REAL32.
#[derive(Clone, Copy)]
enum PyValue {
    Int(i64),
    Float(f64),
}

impl<'py> IntoPyObject<'py> for PyValue {
    type Target = PyAny;
    type Output = Bound<'py, PyAny>;
    type Error = core::convert::Infallible;

    fn into_pyobject(self, py: Python<'py>) -> Result<Self::Output, Self::Error> {
        Ok(match self {
            Self::Int(v) => v.into_pyobject(py)?.into_any(),
            Self::Float(v) => v.into_pyobject(py)?.into_any(),
        })
    }
}

fn py_value(v: Value) -> PyValue {
    match v {
        Value::F32(f) => PyValue::Float(f64::from(f)),
        other => PyValue::Int(other.as_f64() as i64),
    }
}

/// A Python number as a value: `int` as INT32 (REAL32 beyond its range), `float` as REAL32.
fn value_of(v: &Bound<'_, PyAny>) -> PyResult<Value> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Ok(Value::I32(i32::from(v.extract::<bool>()?)));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(i32::try_from(i).map_or(Value::F32(i as f32), Value::I32));
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(Value::F32(f as f32));
    }
    Err(PyTypeError::new_err(format!(
        "a parameter value is an int or a float, not {}",
        v.get_type().name()?
    )))
}

fn param_name(name: &str) -> PyResult<Name> {
    Name::new(name).map_err(|e| PyValueError::new_err(format!("parameter name {name:?}: {e}")))
}

/// One mission item as Python passes it: (frame, command, current, autocontinue, param1,
/// param2, param3, param4, x, y, z).
type ItemTuple = (u8, u16, u8, u8, f32, f32, f32, f32, i32, i32, f32);

fn item_of(t: ItemTuple, seq: u16, kind: MavMissionType) -> MissionItemInt {
    MissionItemInt {
        seq,
        frame: MavFrame(t.0),
        command: MavCmd(t.1),
        current: t.2,
        autocontinue: t.3,
        param1: t.4,
        param2: t.5,
        param3: t.6,
        param4: t.7,
        x: t.8,
        y: t.9,
        z: t.10,
        mission_type: kind,
        ..MissionItemInt::default()
    }
}

fn tuple_of(i: &MissionItemInt) -> ItemTuple {
    (
        i.frame.0,
        i.command.0,
        i.current,
        i.autocontinue,
        i.param1,
        i.param2,
        i.param3,
        i.param4,
        i.x,
        i.y,
        i.z,
    )
}

/// A command's name without MAV_CMD_, or its number.
fn command_name(c: MavCmd) -> String {
    c.name().map_or_else(
        || c.0.to_string(),
        |n| n.strip_prefix("MAV_CMD_").unwrap_or(n).to_owned(),
    )
}

/// A MAV_RESULT's name without MAV_RESULT_, or its number.
fn result_name(r: MavResult) -> String {
    r.name().map_or_else(
        || r.0.to_string(),
        |n| n.strip_prefix("MAV_RESULT_").unwrap_or(n).to_owned(),
    )
}

/// A command's outcome as Python builds its result: (result, its name, progress,
/// result_param2, STATUSTEXT lines, the command's name).
type CommandOutcome = (u8, String, u8, i32, Vec<String>, String);

/// The outcome of `System::command` (or `set_mode`): a final ACK, accepted or not, is a
/// result; no answer is an error.
fn command_outcome(
    command: MavCmd,
    result: Result<mavstack::dialects::common::CommandAck, SystemError>,
) -> Result<CommandOutcome, AioError> {
    match result {
        Ok(ack) => Ok((
            ack.result.0,
            result_name(ack.result),
            ack.progress,
            ack.result_param2,
            Vec::new(),
            command_name(command),
        )),
        Err(SystemError::Command {
            source:
                CommandError::Rejected {
                    result,
                    result_param2,
                },
            statustext,
            ..
        }) => Ok((
            result.0,
            result_name(result),
            0,
            result_param2,
            statustext,
            command_name(command),
        )),
        Err(e) => Err(system_error(e)),
    }
}

/// A vehicle found on a connection (`await gcs.vehicle()`): its operations run one at a
/// time (the services' clients are not shared), each abandoned when its Python task is
/// cancelled.
#[pyclass(module = "mavstack._native", name = "AioVehicle", frozen)]
pub(crate) struct AioVehicle {
    shared: Arc<Shared>,
    system: Arc<tokio::sync::Mutex<System>>,
    target: Address,
    autopilot: u8,
    mav_type: u8,
    link_name: String,
}

impl AioVehicle {
    /// Runs `f` on the vehicle's `System` (after the operations before it), until the
    /// connection closes.
    fn run<F, Fut>(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>, f: F) -> PyResult<Op>
    where
        F: FnOnce(Arc<tokio::sync::Mutex<System>>) -> Fut + Send + 'static,
        Fut: Future<Output = Result<Build, AioError>> + Send + 'static,
    {
        let system = Arc::clone(&self.system);
        spawn_op(
            &waker,
            settle,
            until_closed(self.shared.closed.clone(), f(system)),
        )
    }

    fn convention(&self, kind: MavMissionType, as_plan: bool) -> Convention {
        if as_plan && kind == MavMissionType::MISSION {
            Convention::of(MavAutopilot(self.autopilot))
        } else {
            Convention::Plain
        }
    }
}

fn mission_type(kind: &str) -> PyResult<MavMissionType> {
    match kind {
        "mission" => Ok(MavMissionType::MISSION),
        "fence" => Ok(MavMissionType::FENCE),
        "rally" => Ok(MavMissionType::RALLY),
        other => Err(PyValueError::new_err(format!(
            "mission type {other:?}: one of \"mission\", \"fence\", \"rally\""
        ))),
    }
}

#[pymethods]
impl AioVehicle {
    /// Its system id.
    #[getter]
    fn system(&self) -> u8 {
        self.target.system
    }

    /// The component that answered.
    #[getter]
    fn component(&self) -> u8 {
        self.target.component
    }

    /// Its HEARTBEAT's MAV_AUTOPILOT.
    #[getter]
    fn autopilot(&self) -> u8 {
        self.autopilot
    }

    /// Its HEARTBEAT's MAV_TYPE.
    #[getter]
    fn mav_type(&self) -> u8 {
        self.mav_type
    }

    /// The link it was found on.
    #[getter]
    fn link_name(&self) -> &str {
        &self.link_name
    }

    /// The whole parameter table, `{name: value}` in the vehicle's order, and the way it
    /// came (`"ftp"` or `"list"`); `via` is `"auto"` (MAVFTP when offered), `"ftp"` or
    /// `"list"`; `progress(done, total)` in bytes of the file over MAVFTP, else in
    /// parameters.
    #[pyo3(signature = (via, progress, waker, settle))]
    fn params_all(
        &self,
        via: &str,
        progress: Option<Py<PyAny>>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let mut progress = progress_fn(&waker.inner, progress);
        let via = match via {
            "auto" => ParamsVia::Auto,
            "ftp" => ParamsVia::Ftp,
            "list" => ParamsVia::List,
            other => {
                return Err(PyValueError::new_err(format!(
                    "via {other:?}: one of \"auto\", \"ftp\", \"list\""
                )));
            }
        };
        self.run(waker, settle, move |system| async move {
            let (table, how) = system
                .lock()
                .await
                .params_by(via, |_, done, total| progress(done, total))
                .await
                .map_err(system_error)?;
            let how = if how == ParamsVia::Ftp { "ftp" } else { "list" };
            Ok(Box::new(move |py: Python<'_>| {
                let d = PyDict::new(py);
                for (name, value) in table {
                    d.set_item(name.as_str(), py_value(value))?;
                }
                Ok((d, how).into_pyobject(py)?.into_any().unbind())
            }) as Build)
        })
    }

    /// One parameter's value, read by name.
    fn param_get(&self, name: &str, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let name = param_name(name)?;
        self.run(waker, settle, move |system| async move {
            let p = system
                .lock()
                .await
                .param(name)
                .await
                .map_err(system_error)?;
            Ok(build(py_value(p.value)))
        })
    }

    /// Sets a parameter (in its type on the vehicle, read first) and settles with the value
    /// in force once the vehicle confirmed it.
    fn param_set(
        &self,
        name: &str,
        value: &Bound<'_, PyAny>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let name = param_name(name)?;
        let value = value_of(value)?;
        self.run(waker, settle, move |system| async move {
            let mut system = system.lock().await;
            let before = system.param(name).await.map_err(system_error)?;
            let typed = value
                .converted_to(before.value.param_type())
                .ok_or_else(|| {
                    AioError::new("param", format!("{name}: a type PARAM_SET cannot carry"))
                })?;
            let after = system.set_param(name, typed).await.map_err(system_error)?;
            Ok(build(py_value(after.value)))
        })
    }

    /// Uploads `items` (tuples, see `ItemTuple`) as the plan of `kind`; with `as_plan`, a
    /// mission's item 0 is home, as in a plan file, for every autopilot (PX4's left out).
    /// `progress(sent, count)` hears each time the vehicle asked for more.
    fn mission_upload(
        &self,
        items: Vec<ItemTuple>,
        kind: &str,
        as_plan: bool,
        progress: Option<Py<PyAny>>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let mut progress = progress_fn(&waker.inner, progress);
        let kind = mission_type(kind)?;
        if items.len() > usize::from(u16::MAX) {
            return Err(PyValueError::new_err("a plan holds at most 65,535 items"));
        }
        let convention = self.convention(kind, as_plan);
        let plan: Vec<MissionItemInt> = (0u16..)
            .zip(items)
            .map(|(seq, t)| item_of(t, seq, kind))
            .collect();
        let items = plan::to_vehicle(convention, &plan);
        self.run(waker, settle, move |system| async move {
            system
                .lock()
                .await
                .upload_mission_with_progress(kind, items, |sent, count| {
                    progress(sent as u64, count as u64);
                })
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Downloads the plan of `kind` as tuples (see `mission_upload` for `as_plan`);
    /// `progress(received, count)` as items come (the vehicle's count: PX4's has no home).
    fn mission_download(
        &self,
        kind: &str,
        as_plan: bool,
        progress: Option<Py<PyAny>>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let mut progress = progress_fn(&waker.inner, progress);
        let kind = mission_type(kind)?;
        let convention = self.convention(kind, as_plan);
        self.run(waker, settle, move |system| async move {
            let mut system = system.lock().await;
            let items = system
                .download_mission_with_progress(kind, |got, count| {
                    progress(got as u64, count as u64);
                })
                .await
                .map_err(system_error)?;
            let home = if convention == Convention::Px4 {
                system.home_item(Duration::from_secs(3)).await
            } else {
                None
            };
            let plan = plan::from_vehicle(convention, &items, home);
            let tuples: Vec<ItemTuple> = plan.iter().map(tuple_of).collect();
            Ok(build(tuples))
        })
    }

    /// Clears the plan of `kind`.
    fn mission_clear(
        &self,
        kind: &str,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let kind = mission_type(kind)?;
        self.run(waker, settle, move |system| async move {
            system
                .lock()
                .await
                .clear_mission(kind)
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Sends command `command` (an id, or a name with or without MAV_CMD_) with up to seven
    /// parameters, as COMMAND_LONG (or COMMAND_INT with `frame`, where params 5 and 6 are
    /// x and y as integers); settles with its outcome (see `CommandOutcome`).
    #[pyo3(signature = (command, params, frame, waker, settle))]
    fn command(
        &self,
        command: &Bound<'_, PyAny>,
        params: Vec<f64>,
        frame: Option<u8>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let id = self.command_id(command)?;
        if params.len() > 7 {
            return Err(PyValueError::new_err(format!(
                "a command has 7 parameters, not {}",
                params.len()
            )));
        }
        let mut p = [0.0f64; 7];
        p[..params.len()].copy_from_slice(&params);
        let f = |i: usize| p[i] as f32;
        let cmd = MavCmd(id);
        let command = match frame {
            None => Command::Long(CommandLong {
                command: cmd,
                param1: f(0),
                param2: f(1),
                param3: f(2),
                param4: f(3),
                param5: f(4),
                param6: f(5),
                param7: f(6),
                ..CommandLong::default()
            }),
            Some(frame) => Command::Int(CommandInt {
                command: cmd,
                frame: MavFrame(frame),
                param1: f(0),
                param2: f(1),
                param3: f(2),
                param4: f(3),
                x: p[4] as i32,
                y: p[5] as i32,
                z: f(6),
                ..CommandInt::default()
            }),
        };
        self.run(waker, settle, move |system| async move {
            let result = system.lock().await.command(command, |_| {}).await;
            Ok(build(command_outcome(cmd, result)?))
        })
    }

    /// Switches to the mode called `name` (the autopilot's names, `mavstack command mode`'s);
    /// settles with the command's outcome.
    fn set_mode(
        &self,
        name: String,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            let result = system.lock().await.set_mode(&name).await;
            Ok(build(command_outcome(MavCmd::DO_SET_MODE, result)?))
        })
    }

    /// Messages `name` from the vehicle, from now on; with `rate_hz`, the vehicle is asked
    /// for that rate first (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM where refused).
    #[pyo3(signature = (name, rate_hz=None))]
    fn telemetry(&self, name: &str, rate_hz: Option<f32>) -> PyResult<AioStream> {
        let index = self.shared.dialect.index_of_name(name).ok_or_else(|| {
            PyValueError::new_err(format!(
                "no message {name:?} in dialect {}",
                self.shared.dialect.name
            ))
        })?;
        let ty = Arc::clone(&self.shared.dialect.messages[index]);
        let queue = Queue::new();
        let rt = runtime()?;
        let (id, sysid) = (ty.id, self.target.system);
        let handle = self.shared.handle.clone();
        let system = Arc::clone(&self.system);
        let filled = Arc::clone(&queue);
        let closed = self.shared.closed.clone();
        let task = rt.spawn(async move {
            let forward = async {
                let mut frames = handle.subscribe().await;
                if let Some(hz) = rate_hz {
                    let _ = system.lock().await.request_rate(id, hz).await;
                }
                while let Some(incoming) = frames.recv().await {
                    let f = incoming.frame.frame.view();
                    if f.msg_id() == id && f.sysid() == sysid {
                        push(&filled, incoming);
                    }
                }
                Ok::<(), AioError>(())
            };
            let _ = until_closed(closed, forward).await;
            end(&filled);
        });
        Ok(AioStream {
            ty,
            queue,
            abort: task.abort_handle(),
        })
    }
}

impl AioVehicle {
    fn command_id(&self, command: &Bound<'_, PyAny>) -> PyResult<u16> {
        if let Ok(id) = command.extract::<u16>() {
            return Ok(id);
        }
        let name: String = command.extract().map_err(|_| {
            PyTypeError::new_err("a command is a MAV_CMD number or name (\"COMPONENT_ARM_DISARM\")")
        })?;
        let upper = name.to_ascii_uppercase();
        let full = if upper.starts_with("MAV_CMD_") {
            upper
        } else {
            format!("MAV_CMD_{upper}")
        };
        self.shared
            .dialect
            .constants
            .iter()
            .find(|(n, _)| *n == full)
            .and_then(|(_, v)| u16::try_from(*v).ok())
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "no command {name:?} in dialect {}",
                    self.shared.dialect.name
                ))
            })
    }
}

/// Messages of one type from one vehicle, as they come (`vehicle.telemetry(...)`).
#[pyclass(module = "mavstack._native", name = "AioStream", frozen)]
pub(crate) struct AioStream {
    ty: Arc<MessageType>,
    queue: Arc<Mutex<Queue<Incoming>>>,
    abort: AbortHandle,
}

#[pymethods]
impl AioStream {
    /// The next message received, if one is waiting.
    fn pop(&self, py: Python<'_>) -> PyResult<Option<Py<Message>>> {
        let Some(incoming) = lock(&self.queue).items.pop_front() else {
            return Ok(None);
        };
        let verified = matches!(incoming.frame.auth, Authentication::Verified { .. });
        let frame = incoming.frame.frame.view();
        let m = Message::live(
            Arc::clone(&self.ty),
            frame.as_bytes().to_vec(),
            crate::live::unix_now(),
            verified,
        );
        Ok(Some(Py::new(py, m)?))
    }

    /// Whether the reader should wait (nothing waiting, not ended); `wake` is then called
    /// through `waker` once something comes.
    fn wait(&self, waker: PyRef<'_, AioWaker>, wake: Py<PyAny>) -> bool {
        set_waiter(&self.queue, &waker, wake)
    }

    /// Whether the stream has ended (the connection closed, or `close`); what it holds can
    /// still be read.
    #[getter]
    fn ended(&self) -> bool {
        lock(&self.queue).ended
    }

    /// Messages left out because nobody read them in time (the oldest go first).
    #[getter]
    fn dropped(&self) -> u64 {
        lock(&self.queue).dropped
    }

    /// Stops the stream (its reader sees the end).
    fn close(&self) {
        self.abort.abort();
        lock(&self.queue).items.clear();
        end(&self.queue);
    }
}

impl Drop for AioStream {
    fn drop(&mut self) {
        self.abort.abort();
    }
}

// ----- serving -------------------------------------------------------------------------

/// A command waiting for the Python handler: (token, sender, the command).
type Pending = (u64, Address, Command);

/// The command handler of a served component: every new command goes to Python, and the
/// server answers IN_PROGRESS to retries until Python's answer finishes it.
struct Deferred {
    requests: Arc<Mutex<Queue<Pending>>>,
    next: u64,
    /// Commands just handed over, whose first IN_PROGRESS ACK is not sent: the final ACK
    /// follows as soon as the handler answers.
    fresh: Vec<(Address, MavCmd)>,
}

impl CommandHandler for Deferred {
    fn handle_command(
        &mut self,
        _now: mavstack_core::time::Instant,
        request: &Request,
    ) -> Response {
        self.next += 1;
        self.fresh.push((request.from, request.command.id()));
        push(
            &self.requests,
            (self.next, request.from, request.command.clone()),
        );
        Response::in_progress(255)
    }
}

/// A served component: a parameter table and the commands handled in Python.
struct Component {
    params: ParamServer,
    commands: CommandServer<Deferred>,
    /// Parameters a peer set, for Python: (name, value).
    changed: Arc<Mutex<Queue<(Name, Value)>>>,
}

impl Service for Component {
    fn handle_message(
        &mut self,
        now: mavstack_core::time::Instant,
        from: Address,
        message: &mavstack::dialects::common::MavMessage,
    ) -> bool {
        let a = self.params.handle_message(now, from, message);
        while let Some(event) = self.params.poll_event() {
            if let mavstack::services::param::ParamServerEvent::Changed { name, value, .. } = event
            {
                push(&self.changed, (name, value));
            }
        }
        let b = self.commands.handle_message(now, from, message);
        a || b
    }

    fn handle_timeout(&mut self, now: mavstack_core::time::Instant) {
        self.params.handle_timeout(now);
        self.commands.handle_timeout(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        if let Some(out) = self.params.poll_transmit() {
            return Some(out);
        }
        loop {
            let out = self.commands.poll_transmit()?;
            if let mavstack::dialects::common::MavMessage::CommandAck(ack) = &out.message
                && ack.result == MavResult::IN_PROGRESS
            {
                let fresh = &mut self.commands.handler_mut().fresh;
                if let Some(i) = fresh
                    .iter()
                    .position(|&(to, c)| to == out.target && c == ack.command)
                {
                    fresh.remove(i);
                    continue;
                }
            }
            return Some(out);
        }
    }

    fn poll_timeout(&self) -> Option<mavstack_core::time::Instant> {
        match (self.params.poll_timeout(), self.commands.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// A component served in Python (`mavstack.aio.serve`): its own node, answering commands
/// and offering parameters.
#[pyclass(module = "mavstack._native", name = "AioServer", frozen)]
pub(crate) struct AioServer {
    device: String,
    handle: NodeHandle,
    dialect: Arc<Dialect>,
    node: tokio::sync::Mutex<Option<(Node, Served<Component>)>>,
    served: ServedHandle<Component>,
    requests: Arc<Mutex<Queue<Pending>>>,
    changed: Arc<Mutex<Queue<(Name, Value)>>>,
    /// The commands handed to Python and not answered yet, by token.
    waiting: Mutex<Vec<Pending>>,
}

/// Serves a component on `device` as (`system`, `component`), sending HEARTBEAT with
/// `mav_type` and `autopilot` every second; `params` its table (`(name, value)`, in order),
/// `encoding` `"bytewise"` or `"c_cast"`. Settles with an `AioServer`.
#[pyfunction]
#[pyo3(signature = (device, system, component, mav_type, autopilot, params, encoding, dialect, key, link_id, waker, settle))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn aio_serve(
    device: &str,
    system: u8,
    component: u8,
    mav_type: u8,
    autopilot: u8,
    params: Vec<(String, Bound<'_, PyAny>)>,
    encoding: &str,
    dialect: &str,
    key: Option<&Bound<'_, PyAny>>,
    link_id: u8,
    waker: PyRef<'_, AioWaker>,
    settle: Py<PyAny>,
) -> PyResult<Op> {
    if system == 0 || component == 0 {
        return Err(PyValueError::new_err(
            "a served component needs a system and a component id above 0",
        ));
    }
    let encoding = match encoding {
        "bytewise" => Encoding::Bytewise,
        "c_cast" => Encoding::CCast,
        other => {
            return Err(PyValueError::new_err(format!(
                "encoding {other:?}: \"bytewise\" or \"c_cast\""
            )));
        }
    };
    let own = Address::new(system, component);
    let mut table = ParamServer::new(own, encoding);
    for (name, value) in &params {
        table
            .insert(param_name(name)?, value_of(value)?)
            .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))?;
    }
    let dialect = Dialect::load(dialect)?;
    let key = crate::connection::parse_key(key)?;
    let spec = link_spec(device, &dialect, key, link_id)?;
    let shown = mavstack::redacted(device);
    let heartbeat = Heartbeat {
        r#type: MavType(mav_type),
        autopilot: MavAutopilot(autopilot),
        system_status: MavState::ACTIVE,
        mavlink_version: 3,
        ..Heartbeat::default()
    };
    let mut router = RouterConfig::default();
    router.system_id = system;
    router.component_id = component;
    router.local = LocalDelivery::Addressed;
    router.forward = false;
    spawn_op(&waker, settle, async move {
        let node = Node::builder()
            .router(router)
            .dialect(dialect.table)
            .role(LinkRole::Vehicle {
                protocol_version: ProtocolVersionSupport::Answer,
            })
            .heartbeat(&heartbeat, Duration::from_secs(1))
            .link(spec)
            .start()
            .await
            .map_err(|e| AioError::new("connection", format!("cannot open \"{shown}\": {e}")))?;
        let requests = Queue::new();
        let changed = Queue::new();
        let component = Component {
            params: table,
            commands: CommandServer::new(
                own,
                CommandServerConfig::default(),
                Deferred {
                    requests: Arc::clone(&requests),
                    next: 0,
                    fresh: Vec::new(),
                },
            ),
            changed: Arc::clone(&changed),
        };
        let served = Served::start(&node.handle(), component).await;
        let server = AioServer {
            device: shown,
            handle: node.handle(),
            dialect,
            served: served.handle(),
            node: tokio::sync::Mutex::new(Some((node, served))),
            requests,
            changed,
            waiting: Mutex::new(Vec::new()),
        };
        Ok(Box::new(move |py: Python<'_>| Ok(Py::new(py, server)?.into_any())) as Build)
    })
}

/// A command for Python: (token, sender system, sender component, command id, its name,
/// the seven parameters, COMMAND_INT's frame or None).
type RequestTuple = (u64, u8, u8, u16, String, Vec<f64>, Option<u8>);

#[pymethods]
impl AioServer {
    /// The next command for the handler, if one is waiting.
    fn pop_request(&self) -> Option<RequestTuple> {
        let pending = lock(&self.requests).items.pop_front()?;
        let (token, from, command) = &pending;
        let (params, frame) = match command {
            Command::Long(c) => (
                [
                    c.param1, c.param2, c.param3, c.param4, c.param5, c.param6, c.param7,
                ]
                .iter()
                .map(|&p| f64::from(p))
                .collect(),
                None,
            ),
            Command::Int(c) => (
                vec![
                    f64::from(c.param1),
                    f64::from(c.param2),
                    f64::from(c.param3),
                    f64::from(c.param4),
                    f64::from(c.x),
                    f64::from(c.y),
                    f64::from(c.z),
                ],
                Some(c.frame.0),
            ),
        };
        let id = command.id();
        let out = (
            *token,
            from.system,
            from.component,
            id.0,
            command_name(id),
            params,
            frame,
        );
        lock(&self.waiting).push(pending);
        Some(out)
    }

    /// Whether the request reader should wait; see `AioStream.wait`.
    fn wait_request(&self, waker: PyRef<'_, AioWaker>, wake: Py<PyAny>) -> bool {
        set_waiter(&self.requests, &waker, wake)
    }

    /// Whether the server has stopped.
    #[getter]
    fn ended(&self) -> bool {
        lock(&self.requests).ended
    }

    /// Answers command `token` with MAV_RESULT `result` and `result_param2` (the final
    /// COMMAND_ACK, sent at once). False when it was answered already.
    fn answer(&self, token: u64, result: u8, result_param2: i32) -> PyResult<bool> {
        let pending = {
            let mut waiting = lock(&self.waiting);
            let Some(i) = waiting.iter().position(|p| p.0 == token) else {
                return Ok(false);
            };
            waiting.remove(i)
        };
        let (_, from, command) = pending;
        let id = command.id();
        let served = self.served.clone();
        let response = Response {
            result: MavResult(result),
            progress: 0,
            result_param2,
        };
        runtime()?.spawn(async move {
            served
                .with(move |c| {
                    // A fresh note left by a command answered before its first poll.
                    c.commands
                        .handler_mut()
                        .fresh
                        .retain(|&(to, cmd)| !(to == from && cmd == id));
                    c.commands.finish(clock::now(), from, id, response);
                })
                .await;
        });
        Ok(true)
    }

    /// Sends message `name` with `fields` (by name; the others zero) as the served
    /// component, on its link (to every peer).
    #[pyo3(signature = (name, fields=None))]
    fn send(&self, name: &str, fields: Option<&Bound<'_, PyDict>>) -> PyResult<()> {
        if lock(&self.requests).ended {
            return Err(pyo3::exceptions::PyConnectionError::new_err(format!(
                "\"{}\" is closed",
                self.device
            )));
        }
        send_fields(&self.handle, &self.dialect, name, fields)
    }

    /// Parameters peers set since the last call: `[(name, value)]`.
    fn changes(&self) -> Vec<(String, PyValue)> {
        lock(&self.changed)
            .items
            .drain(..)
            .map(|(n, v)| (n.as_str().to_owned(), py_value(v)))
            .collect()
    }

    /// The table now: settles with `{name: value}`.
    fn params(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let served = self.served.clone();
        spawn_op(&waker, settle, async move {
            let table: Vec<(String, PyValue)> = served
                .with(|c| {
                    c.params
                        .iter()
                        .map(|(n, v)| (n.as_str().to_owned(), py_value(*v)))
                        .collect()
                })
                .await
                .ok_or_else(|| AioError::new("closed", "the server has stopped"))?;
            Ok(Box::new(move |py: Python<'_>| {
                let d = PyDict::new(py);
                for (n, v) in table {
                    d.set_item(n, v)?;
                }
                Ok(d.into_any().unbind())
            }) as Build)
        })
    }

    /// Sets (or adds) a parameter locally and broadcasts its PARAM_VALUE; settles with the
    /// value in force (converted to an existing parameter's type).
    fn set_param(
        &self,
        name: &str,
        value: &Bound<'_, PyAny>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let name = param_name(name)?;
        let value = value_of(value)?;
        let served = self.served.clone();
        spawn_op(&waker, settle, async move {
            let v = served
                .with(move |c| {
                    if c.params.get(name).is_none() {
                        c.params.insert(name, value).map(|_| value)
                    } else {
                        c.params.set(name, value)
                    }
                })
                .await
                .ok_or_else(|| AioError::new("closed", "the server has stopped"))?
                .map_err(|e| AioError::new("param", format!("{name}: {e}")))?;
            Ok(build(py_value(v)))
        })
    }

    /// Stops serving and closes the link.
    fn close(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        end(&self.requests);
        let taken = self.node.try_lock().ok().and_then(|mut n| n.take());
        let device = self.device.clone();
        spawn_op(&waker, settle, async move {
            if let Some((node, served)) = taken {
                served.stop().await;
                node.shutdown()
                    .await
                    .map_err(|e| AioError::new("connection", format!("{device}: {e}")))?;
            }
            Ok(build(()))
        })
    }

    /// The connection string (keys redacted).
    #[getter]
    fn address(&self) -> &str {
        &self.device
    }

    /// The dialect's name.
    #[getter]
    fn dialect(&self) -> &str {
        &self.dialect.name
    }
}

/// Registers the module's classes and functions.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(aio_connect, m)?)?;
    m.add_function(wrap_pyfunction!(aio_serve, m)?)?;
    m.add_class::<Op>()?;
    m.add_class::<AioWaker>()?;
    m.add_class::<AioLink>()?;
    m.add_class::<AioVehicle>()?;
    m.add_class::<AioStream>()?;
    m.add_class::<AioServer>()?;
    Ok(())
}
