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
use mavstack::services::shell::ShellError;
use mavstack::services::{Address, Outgoing, Service};
use mavstack::system::{Discovery, ParamsVia, System, SystemError, Wanted, command_name};
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
        SystemError::Invalid(_) => "value",
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
            reason: CommandError::TimedOut { .. } | CommandError::InProgressTimedOut { .. },
            ..
        } => "timeout",
        SystemError::Command { .. } => "command",
        SystemError::UnknownMode { .. } => "mode",
        SystemError::Rtcm(_) | SystemError::Shell(ShellError::LineBreak) => "value",
        SystemError::Gimbal(_) | SystemError::CameraSetting(_) => "value",
        SystemError::Photo(_)
        | SystemError::CameraSettings(_)
        | SystemError::CameraDefinition { .. } => "camera",
        SystemError::Shell(ShellError::NoAnswer { .. }) => "timeout",
        SystemError::Stopped => "closed",
        _ => "error",
    };
    AioError::new(kind, mavstack::error_chain(&e))
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

/// `timeout` as a duration (non-negative, finite).
pub(super) fn seconds(s: f64, what: &str) -> PyResult<Duration> {
    Duration::try_from_secs_f64(s)
        .map_err(|_| PyValueError::new_err(format!("{what}: {s} is not a number of seconds")))
}

/// A parameter value for Python: an `int` for the integer types, a `float` for REAL32.
#[derive(Clone, Copy)]
pub(super) enum PyValue {
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

pub(super) fn py_value(v: Value) -> PyValue {
    match v {
        Value::F32(f) => PyValue::Float(f64::from(f)),
        other => PyValue::Int(other.as_f64() as i64),
    }
}

/// A Python number as a value: `int` as INT32 (REAL32 beyond its range), `float` as REAL32.
pub(super) fn value_of(v: &Bound<'_, PyAny>) -> PyResult<Value> {
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

pub(super) fn param_name(name: &str) -> PyResult<Name> {
    Name::new(name).map_err(|e| PyValueError::new_err(format!("parameter name {name:?}: {e}")))
}

mod flying;
mod link;
mod payload;
mod serve;
mod serve_camera;
mod vehicle;

use link::{AioLink, aio_connect};
use serve::{AioServer, aio_serve};
use serve_camera::{AioCameraServer, aio_serve_camera};
use vehicle::{AioStream, AioVehicle};

/// Registers the module's classes and functions.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(aio_connect, m)?)?;
    m.add_function(wrap_pyfunction!(aio_serve, m)?)?;
    m.add_function(wrap_pyfunction!(aio_serve_camera, m)?)?;
    m.add(
        "SIMULATED_CAMERA_DEFINITION",
        pyo3::types::PyBytes::new(
            m.py(),
            mavstack::services::camera::SIMULATED_DEFINITION.as_bytes(),
        ),
    )?;
    m.add_class::<Op>()?;
    m.add_class::<AioWaker>()?;
    m.add_class::<AioLink>()?;
    m.add_class::<AioVehicle>()?;
    m.add_class::<AioStream>()?;
    m.add_class::<flying::AioOffboard>()?;
    m.add_class::<flying::AioManual>()?;
    m.add_class::<AioServer>()?;
    m.add_class::<AioCameraServer>()?;
    m.add_class::<payload::AioGimbal>()?;
    m.add_class::<payload::AioCamera>()?;
    Ok(())
}
