//! A Python component served on a node (`mavstack.aio.serve`): parameters, and commands
//! answered by a Python handler.

use super::link::{link_spec, send_fields};
use super::*;

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
    /// Who asked for the component's HEARTBEAT (REQUEST_MESSAGE(HEARTBEAT), which a ground
    /// station sends to find a system in one round trip): answered by the stack, not Python.
    heartbeat_asked: Vec<Address>,
}

/// Whether `command` is MAV_CMD_REQUEST_MESSAGE for HEARTBEAT.
fn asks_heartbeat(command: &Command) -> bool {
    match command {
        Command::Long(c) => c.command == MavCmd::REQUEST_MESSAGE && c.param1 == 0.0,
        Command::Int(c) => c.command == MavCmd::REQUEST_MESSAGE && c.param1 == 0.0,
    }
}

impl CommandHandler for Deferred {
    fn handle_command(
        &mut self,
        _now: mavstack_core::time::Instant,
        request: &Request,
    ) -> Response {
        if asks_heartbeat(&request.command) {
            if !self.heartbeat_asked.contains(&request.from) {
                self.heartbeat_asked.push(request.from);
            }
            return Response::done(MavResult::ACCEPTED);
        }
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
    /// Its HEARTBEAT, sent at once to who asks for it.
    heartbeat: Heartbeat,
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
        if let Some(to) = self.commands.handler_mut().heartbeat_asked.pop() {
            return Some(Outgoing {
                target: to,
                message: mavstack::dialects::common::MavMessage::Heartbeat(self.heartbeat),
            });
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
                    heartbeat_asked: Vec::new(),
                },
            ),
            heartbeat,
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
