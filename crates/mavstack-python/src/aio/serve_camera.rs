//! A camera served from Python (`mavstack.aio.serve_camera`): `mavstack::serve::Camera` on
//! a node of its own, its requests (take a photo, record) queued for Python, Python's
//! account of each photo handed back.

use super::link::link_spec;
use super::*;
use mavstack::serve::Camera;
use mavstack::services::camera::{CameraConfig, CameraEvent, mode_name};
use tokio::sync::{mpsc, oneshot};

use super::payload::{PyExt, py_ext};

/// What the camera asks of Python: (kind, a number, a text): `("photo", index, "")`,
/// `("video_start", stream, "")`, `("video_stop", milliseconds recorded, "")`,
/// `("mode", number, "photo"|"video")`, `("setting", 0, name)`, `("format", 0, "")`.
type EventTuple = (&'static str, i64, String);

/// Python's side of the camera's task.
enum Ask {
    /// Photo `index` went so: its file's URL (None: it failed).
    Photo(i32, Option<String>, f32),
    /// The settings now.
    Settings(oneshot::Sender<Vec<(String, PyExt)>>),
    /// Stop.
    Stop(oneshot::Sender<()>),
}

/// A camera served in Python.
#[pyclass(module = "mavstack._native", name = "AioCameraServer", frozen)]
pub(crate) struct AioCameraServer {
    device: String,
    events: Arc<Mutex<Queue<EventTuple>>>,
    asks: mpsc::UnboundedSender<Ask>,
    node: Mutex<Option<Node>>,
}

fn event_tuple(e: CameraEvent) -> Option<EventTuple> {
    Some(match e {
        CameraEvent::TakePhoto(p) => ("photo", i64::from(p.index), String::new()),
        CameraEvent::VideoStart { stream } => ("video_start", i64::from(stream), String::new()),
        CameraEvent::VideoStop { recorded } => (
            "video_stop",
            i64::try_from(recorded.as_millis()).unwrap_or(i64::MAX),
            String::new(),
        ),
        CameraEvent::Mode(m) => ("mode", i64::from(m.0), mode_name(m)),
        CameraEvent::Setting { name, .. } => ("setting", 0, name),
        CameraEvent::Format => ("format", 0, String::new()),
        _ => return None,
    })
}

/// The camera's task: its events to Python, Python's answers to it.
async fn run(
    mut camera: Camera,
    events: Arc<Mutex<Queue<EventTuple>>>,
    mut asks: mpsc::UnboundedReceiver<Ask>,
) {
    loop {
        tokio::select! {
            event = camera.next_event() => match event {
                Some(e) => {
                    if let Some(t) = event_tuple(e) {
                        push(&events, t);
                    }
                }
                None => break,
            },
            ask = asks.recv() => match ask {
                Some(Ask::Photo(index, url, mib)) => {
                    camera.photo_taken(index, url, mib).await;
                }
                Some(Ask::Settings(reply)) => {
                    let now = camera.settings().await;
                    let _ = reply.send(now.iter().map(|(n, v)| (n.clone(), py_ext(v))).collect());
                }
                Some(Ask::Stop(done)) => {
                    camera.stop().await;
                    end(&events);
                    let _ = done.send(());
                    return;
                }
                None => break,
            },
        }
    }
    camera.stop().await;
    end(&events);
}

/// Serves a camera on `device` as (`system`, `component`): `vendor` `model`, one storage of
/// `storage_mib` MiB, `definition` (a camera definition file's bytes, served over MAVFTP and
/// its settings with PARAM_EXT_*) when given. Settles with an `AioCameraServer`.
#[pyfunction]
#[pyo3(signature = (device, system, component, vendor, model, definition, storage_mib, dialect, key, link_id, waker, settle))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn aio_serve_camera(
    device: &str,
    system: u8,
    component: u8,
    vendor: &str,
    model: &str,
    definition: Option<Vec<u8>>,
    storage_mib: f32,
    dialect: &str,
    key: Option<&Bound<'_, PyAny>>,
    link_id: u8,
    waker: PyRef<'_, AioWaker>,
    settle: Py<PyAny>,
) -> PyResult<Op> {
    if system == 0 || component == 0 {
        return Err(PyValueError::new_err(
            "a served camera needs a system and a component id above 0",
        ));
    }
    if !(storage_mib.is_finite() && storage_mib >= 0.0) {
        return Err(PyValueError::new_err(format!(
            "storage_mib {storage_mib}: a number of MiB, 0 or more"
        )));
    }
    let own = Address::new(system, component);
    let config = CameraConfig::new(own, vendor, model, storage_mib);
    let dialect = Dialect::load(dialect)?;
    let key = crate::connection::parse_key(key)?;
    let spec = link_spec(device, &dialect, key, link_id)?;
    let shown = mavstack::redacted(device);
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
            .link(spec)
            .start()
            .await
            .map_err(|e| AioError::new("connection", format!("cannot open \"{shown}\": {e}")))?;
        let camera = match Camera::start(&node.handle(), config, definition).await {
            Ok(c) => c,
            Err(e) => {
                let _ = node.shutdown().await;
                return Err(AioError::new("value", e.to_string()));
            }
        };
        let events = Queue::new();
        let (asks, rx) = mpsc::unbounded_channel();
        tokio::spawn(run(camera, Arc::clone(&events), rx));
        let server = AioCameraServer {
            device: shown,
            events,
            asks,
            node: Mutex::new(Some(node)),
        };
        Ok(Box::new(move |py: Python<'_>| Ok(Py::new(py, server)?.into_any())) as Build)
    })
}

#[pymethods]
impl AioCameraServer {
    /// The next request, if one is waiting.
    fn pop_event(&self) -> Option<EventTuple> {
        lock(&self.events).items.pop_front()
    }

    /// Whether the reader should wait; see `AioStream.wait`.
    fn wait_event(&self, waker: PyRef<'_, AioWaker>, wake: Py<PyAny>) -> bool {
        set_waiter(&self.events, &waker, wake)
    }

    /// Whether it has stopped.
    #[getter]
    fn ended(&self) -> bool {
        lock(&self.events).ended
    }

    /// Photo `index` went so: the file's URL, or None when it failed; `size_mib` the
    /// storage it took.
    #[pyo3(signature = (index, file_url, size_mib=0.0))]
    fn photo_taken(&self, index: i32, file_url: Option<String>, size_mib: f32) {
        let _ = self.asks.send(Ask::Photo(index, file_url, size_mib));
    }

    /// Its settings now: settles with `{name: value}`.
    fn settings(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let (tx, rx) = oneshot::channel();
        let sent = self.asks.send(Ask::Settings(tx)).is_ok();
        spawn_op(&waker, settle, async move {
            let (true, Ok(values)) = (sent, rx.await) else {
                return Err(AioError::new("closed", "the camera has stopped"));
            };
            Ok(Box::new(move |py: Python<'_>| {
                let d = PyDict::new(py);
                for (n, v) in values {
                    d.set_item(n, v)?;
                }
                Ok(d.into_any().unbind())
            }) as Build)
        })
    }

    /// Stops serving and closes the link.
    fn close(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let (tx, rx) = oneshot::channel();
        let stopping = self.asks.send(Ask::Stop(tx)).is_ok();
        let node = lock(&self.node).take();
        let device = self.device.clone();
        spawn_op(&waker, settle, async move {
            if stopping {
                let _ = rx.await;
            }
            if let Some(node) = node {
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
}
