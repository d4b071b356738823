//! A ground station's connection (`mavstack.aio.connect`): its node, its vehicles found
//! with `System::wait`, and messages sent by name.

use super::*;

/// Options of a connection's node.
pub(super) fn link_spec(
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
pub(super) struct Shared {
    pub(super) device: String,
    pub(super) dialect: Arc<Dialect>,
    pub(super) handle: NodeHandle,
    /// Becomes true when the connection closes: streams end, operations fail.
    pub(super) closed: watch::Receiver<bool>,
}

/// Runs `op` until the connection closes (then `closed`).
pub(super) async fn until_closed<T>(
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
pub(super) fn send_fields(
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
                let vehicle = AioVehicle { shared, system };
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
