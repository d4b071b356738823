//! A vehicle of a connection (`await gcs.vehicle()`): each Python method converts its
//! arguments, calls one `mavstack::system::System` handle method, and converts the result.

use super::link::{Shared, until_closed};
use super::*;
use mavstack::system::CommandOutcome;

/// A Python number (`int`, `float`, `bool`) as the f64 a typed parameter set takes.
fn number_of(v: &Bound<'_, PyAny>) -> PyResult<f64> {
    if v.is_instance_of::<pyo3::types::PyBool>() {
        return Ok(f64::from(u8::from(v.extract::<bool>()?)));
    }
    if let Ok(i) = v.extract::<i64>() {
        return Ok(i as f64);
    }
    if let Ok(f) = v.extract::<f64>() {
        return Ok(f);
    }
    Err(PyTypeError::new_err(format!(
        "a parameter value is an int or a float, not {}",
        v.get_type().name()?
    )))
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

/// A command's outcome as Python builds its result: (result, its name, progress,
/// result_param2, STATUSTEXT lines, the command's name).
type OutcomeTuple = (u8, String, u8, i32, Vec<String>, String);

/// The library's outcome of a command as the tuple Python takes; no answer is an error.
fn outcome_tuple(o: CommandOutcome) -> Result<OutcomeTuple, AioError> {
    let Some(result) = o.result else {
        return Err(AioError::new(
            "timeout",
            format!("command {}: no acknowledgement", command_name(o.command)),
        ));
    };
    Ok((
        result.0,
        o.result_name().to_owned(),
        o.progress,
        o.result_param2,
        o.statustext,
        command_name(o.command),
    ))
}

/// A mode change's result as a command's outcome (DO_SET_MODE): accepted once the vehicle
/// reports the mode; a refusal with its reasons.
fn mode_outcome(set: Result<(), SystemError>) -> Result<OutcomeTuple, AioError> {
    let mut outcome = CommandOutcome::new(MavCmd::DO_SET_MODE, None, 0, Vec::new(), 0.0);
    match set {
        Ok(()) => outcome.result = Some(MavResult::ACCEPTED),
        Err(SystemError::Command {
            reason:
                CommandError::Rejected {
                    result,
                    result_param2,
                },
            statustext,
            ..
        }) => {
            outcome.result = Some(result);
            outcome.result_param2 = result_param2;
            outcome.statustext = statustext;
        }
        Err(e) => return Err(system_error(e)),
    }
    outcome_tuple(outcome)
}

/// A vehicle found on a connection (`await gcs.vehicle()`): its operations run one at a
/// time (the services' clients are not shared), each abandoned when its Python task is
/// cancelled.
#[pyclass(module = "mavstack._native", name = "AioVehicle", frozen)]
pub(crate) struct AioVehicle {
    pub(super) shared: Arc<Shared>,
    pub(super) system: System,
}

/// A mode as Python builds it: (name, standard name or None, custom_mode, selectable).
type ModeTuple = (String, Option<String>, u32, bool);

fn mode_tuple(m: &mavstack::system::Mode) -> ModeTuple {
    (
        m.name.clone(),
        m.standard_name(),
        m.custom_mode,
        m.selectable,
    )
}

impl AioVehicle {
    /// `arm` or `disarm` (forced with 21196) through the library's command names.
    fn named_command(
        &self,
        name: &'static str,
        force: bool,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let params = if force {
            vec![mavstack::system::FORCE_DISARM]
        } else {
            Vec::new()
        };
        self.run(waker, settle, move |system| async move {
            let commands = system.commands();
            let command = commands.build(name, &params).await.map_err(system_error)?;
            let outcome = commands
                .outcome(command, |_| {})
                .await
                .map_err(system_error)?;
            Ok(build(outcome_tuple(outcome)?))
        })
    }

    /// Runs `f` on the vehicle's `System` until the connection closes.
    fn run<F, Fut>(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>, f: F) -> PyResult<Op>
    where
        F: FnOnce(System) -> Fut + Send + 'static,
        Fut: Future<Output = Result<Build, AioError>> + Send + 'static,
    {
        spawn_op(
            &waker,
            settle,
            until_closed(self.shared.closed.clone(), f(self.system.clone())),
        )
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
        self.system.target().system
    }

    /// The component that answered.
    #[getter]
    fn component(&self) -> u8 {
        self.system.target().component
    }

    /// Its HEARTBEAT's MAV_AUTOPILOT.
    #[getter]
    fn autopilot(&self) -> u8 {
        self.system.autopilot().0
    }

    /// Its HEARTBEAT's MAV_TYPE.
    #[getter]
    fn mav_type(&self) -> u8 {
        self.system.mav_type().0
    }

    /// The link it was found on.
    #[getter]
    fn link_name(&self) -> &str {
        self.system.link_name()
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
                .params()
                .get_all_via(via, |_, done, total| progress(done, total))
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
            let p = system.params().get(name).await.map_err(system_error)?;
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
        let value = number_of(value)?;
        self.run(waker, settle, move |system| async move {
            let (_, after) = system
                .params()
                .set_typed(name, value)
                .await
                .map_err(system_error)?;
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
        let plan: Vec<MissionItemInt> = (0u16..)
            .zip(items)
            .map(|(seq, t)| item_of(t, seq, kind))
            .collect();
        self.run(waker, settle, move |system| async move {
            let mission = system.mission();
            let tell = |sent: usize, count: usize| progress(sent as u64, count as u64);
            if as_plan {
                mission.upload_plan(kind, &plan, tell).await.map(drop)
            } else {
                mission.upload_with_progress(kind, plan, tell).await
            }
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
        self.run(waker, settle, move |system| async move {
            let mission = system.mission();
            let tell = |got: usize, count: usize| progress(got as u64, count as u64);
            let plan = if as_plan {
                mission.download_plan(kind, tell).await
            } else {
                mission.download_with_progress(kind, tell).await
            }
            .map_err(system_error)?;
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
            system.mission().clear(kind).await.map_err(system_error)?;
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
            let outcome = system
                .commands()
                .outcome(command, |_| {})
                .await
                .map_err(system_error)?;
            Ok(build(outcome_tuple(outcome)?))
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
            let set = system.modes().set(&name).await.map(drop);
            Ok(build(mode_outcome(set)?))
        })
    }

    /// Arms it (`force`: past the checks); settles with the command's outcome.
    fn arm(&self, force: bool, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.named_command("arm", force, waker, settle)
    }

    /// Disarms it (`force`: even in the air); settles with the command's outcome.
    fn disarm(&self, force: bool, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.named_command("disarm", force, waker, settle)
    }

    /// Its modes: `(name, standard or None, custom_mode, selectable)` each (AVAILABLE_MODES
    /// where offered, else the autopilot's table).
    fn modes(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            let list: Vec<ModeTuple> = system.modes().list().await.iter().map(mode_tuple).collect();
            Ok(build(list))
        })
    }

    /// The mode it is in (`None` before a HEARTBEAT came).
    fn mode(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            Ok(build(
                system.modes().current().await.as_ref().map(mode_tuple),
            ))
        })
    }

    /// Takes off to `height` m above home and settles once it is there; `progress(height)`.
    #[pyo3(signature = (height, progress, waker, settle))]
    fn takeoff(
        &self,
        height: f32,
        progress: Option<Py<PyAny>>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let mut progress = progress_fn(&waker.inner, progress);
        self.run(waker, settle, move |system| async move {
            system
                .action()
                .takeoff(height, |h| {
                    progress(
                        f64::from(h).max(0.0) as u64,
                        u64::from(height.max(0.0) as u32),
                    )
                })
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// `land`, `return_home`, `hold`: settles once the vehicle reports the mode; `land` and
    /// `return_home` with `wait` settle once it has landed and disarmed.
    #[pyo3(signature = (what, wait, waker, settle))]
    fn fly(
        &self,
        what: &str,
        wait: bool,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let what = match what {
            "land" | "return_home" | "hold" => what.to_owned(),
            other => return Err(PyValueError::new_err(format!("no action {other:?}"))),
        };
        self.run(waker, settle, move |system| async move {
            let action = system.action();
            match what.as_str() {
                "land" => action.land().await,
                "return_home" => action.return_home().await,
                _ => action.hold().await,
            }
            .map_err(system_error)?;
            if wait && what != "hold" {
                action
                    .wait_landed(Duration::from_secs(600), |_| {})
                    .await
                    .map_err(system_error)?;
            }
            Ok(build(()))
        })
    }

    /// Goes to a point at `height` m above home (facing `yaw` when given); with `wait`,
    /// settles once within 1.5 m of it.
    #[pyo3(signature = (lat, lon, height, yaw, wait, waker, settle))]
    #[allow(clippy::too_many_arguments)]
    fn goto(
        &self,
        lat: f64,
        lon: f64,
        height: f32,
        yaw: Option<f32>,
        wait: bool,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            system
                .action()
                .goto(lat, lon, height, yaw, wait, |_| {})
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Sends one RTCM message (up to 720 bytes) in GPS_RTCM_DATA with the vehicle's next
    /// sequence id; settles with how many GPS_RTCM_DATA it took.
    fn inject_rtcm(
        &self,
        data: &[u8],
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let data = data.to_vec();
        self.run(waker, settle, move |system| async move {
            let sent = system.rtk().inject(&data).await.map_err(system_error)?;
            Ok(build(sent))
        })
    }

    /// Runs one command line on the vehicle's shell (SERIAL_CONTROL, as PX4's nsh) and
    /// settles with its output; `timeout` seconds for the prompt to come back.
    fn shell(
        &self,
        command: String,
        timeout: f64,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let limit = Duration::try_from_secs_f64(timeout)
            .ok()
            .filter(|d| !d.is_zero() && d.as_secs() <= 86_400)
            .ok_or_else(|| {
                PyValueError::new_err(format!(
                    "timeout {timeout}: a number of seconds above 0, at most 86400"
                ))
            })?;
        self.run(waker, settle, move |system| async move {
            let output = system
                .shell()
                .run(&command, limit)
                .await
                .map_err(system_error)?;
            Ok(build(output))
        })
    }

    /// Its gimbals (the gimbal protocol v2): settles with a list of `AioGimbal`.
    fn gimbals(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let shared = Arc::clone(&self.shared);
        self.run(waker, settle, move |system| {
            payload::gimbals(shared, system)
        })
    }

    /// Its cameras (the camera protocol v2): settles with a list of `AioCamera`.
    fn cameras(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let shared = Arc::clone(&self.shared);
        self.run(waker, settle, move |system| {
            payload::cameras(shared, system)
        })
    }

    /// Where it is: `(lat, lon, height above home, altitude)`, or `None`.
    fn position(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            let p = system.telemetry().position(Duration::from_secs(3)).await;
            Ok(build(
                p.map(|p| (p.lat_deg, p.lon_deg, p.height_m, p.alt_m)),
            ))
        })
    }

    /// Its home: `(lat, lon, altitude)`, or `None`.
    fn home(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |system| async move {
            let h = system.telemetry().home(Duration::from_secs(3)).await;
            Ok(build(h.map(|h| {
                (
                    f64::from(h.latitude) * 1e-7,
                    f64::from(h.longitude) * 1e-7,
                    f64::from(h.altitude) / 1000.0,
                )
            })))
        })
    }

    /// Whether its latest HEARTBEAT says armed.
    #[getter]
    fn armed(&self) -> bool {
        self.system.armed()
    }

    /// Whether it is in the air.
    #[getter]
    fn in_air(&self) -> bool {
        self.system.telemetry().in_air()
    }

    /// Starts an offboard stream at `rate_hz` with a first setpoint (see `AioOffboard.set`);
    /// settles with an `AioOffboard` once the vehicle is in OFFBOARD or GUIDED.
    #[pyo3(signature = (rate_hz, kind, values, waker, settle))]
    fn offboard(
        &self,
        rate_hz: f32,
        kind: &str,
        values: Vec<Option<f32>>,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let first = flying::setpoint(kind, &values)?;
        self.run(waker, settle, move |system| async move {
            let session = system
                .offboard()
                .start(rate_hz, first)
                .await
                .map_err(system_error)?;
            let native = flying::AioOffboard::new(session);
            Ok(Box::new(move |py: Python<'_>| Ok(Py::new(py, native)?.into_any())) as Build)
        })
    }

    /// Sends MANUAL_CONTROL at `rate_hz` until the returned `AioManual` is closed.
    fn manual_control(&self, rate_hz: f32) -> PyResult<flying::AioManual> {
        let _entered = runtime()?.enter();
        let session = self
            .system
            .manual_control()
            .start(rate_hz)
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(flying::AioManual::new(session))
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
        let (id, sysid) = (ty.id, self.system.target().system);
        let handle = self.shared.handle.clone();
        let system = self.system.clone();
        let filled = Arc::clone(&queue);
        let closed = self.shared.closed.clone();
        let task = rt.spawn(async move {
            let forward = async {
                let mut frames = handle.subscribe().await;
                if let Some(hz) = rate_hz {
                    let _ = system.telemetry().request_rate(id, hz).await;
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
            frame.as_bytes(),
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
