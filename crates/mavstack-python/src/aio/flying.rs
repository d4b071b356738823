//! Offboard setpoints and manual control for `mavstack.aio` (`async with
//! vehicle.offboard()` and `vehicle.manual_control()`): the streams are the library's
//! (`System::offboard`, `System::manual_control`), running on the runtime's thread, so a
//! slow asyncio loop does not starve them; these classes only pass new setpoints on.

use std::sync::Mutex;

use mavstack::system::{ManualSession, OffboardSession, Setpoint, Sticks};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use super::{AioWaker, Build, Op, build, spawn_op, system_error};

/// A setpoint from its kind and up to four numbers (`None`: not given).
pub(super) fn setpoint(kind: &str, v: &[Option<f32>]) -> PyResult<Setpoint> {
    let at = |i: usize| v.get(i).copied().flatten();
    let need = |i: usize, name: &str| {
        at(i).ok_or_else(|| PyValueError::new_err(format!("setpoint {kind}: {name} is required")))
    };
    let sp = match kind {
        "velocity_ned" => Setpoint::VelocityNed {
            north: need(0, "north")?,
            east: need(1, "east")?,
            down: need(2, "down")?,
            yaw_deg: at(3),
        },
        "position_ned" => Setpoint::PositionNed {
            north: need(0, "north")?,
            east: need(1, "east")?,
            down: need(2, "down")?,
            yaw_deg: at(3),
        },
        "velocity_body" => Setpoint::VelocityBody {
            forward: need(0, "forward")?,
            right: need(1, "right")?,
            down: need(2, "down")?,
            yaw_rate_dps: at(3).unwrap_or(0.0),
        },
        "attitude" => Setpoint::Attitude {
            roll_deg: need(0, "roll")?,
            pitch_deg: need(1, "pitch")?,
            yaw_deg: need(2, "yaw")?,
            thrust: need(3, "thrust")?,
        },
        other => {
            return Err(PyValueError::new_err(format!(
                "setpoint kind {other:?}: one of velocity_ned, position_ned, velocity_body, attitude"
            )));
        }
    };
    sp.check()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(sp)
}

/// A running offboard stream.
#[pyclass(module = "mavstack._native", name = "AioOffboard", frozen)]
pub(crate) struct AioOffboard {
    session: Mutex<Option<OffboardSession>>,
}

impl AioOffboard {
    pub(super) fn new(session: OffboardSession) -> Self {
        Self {
            session: Mutex::new(Some(session)),
        }
    }
}

#[pymethods]
impl AioOffboard {
    /// Sends this setpoint from the next tick on (`kind` and up to four numbers).
    fn set(&self, kind: &str, values: Vec<Option<f32>>) -> PyResult<()> {
        let sp = setpoint(kind, &values)?;
        let guard = super::lock(&self.session);
        let session = guard
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("the offboard stream has ended"))?;
        session
            .set(sp)
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// How many setpoints went out.
    #[getter]
    fn sent(&self) -> u64 {
        super::lock(&self.session)
            .as_ref()
            .map_or(0, OffboardSession::sent)
    }

    /// Ends the stream and holds position; settles once the vehicle holds.
    fn stop(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let session = super::lock(&self.session).take();
        spawn_op(&waker, settle, async move {
            if let Some(session) = session {
                session.stop().await.map_err(system_error)?;
            }
            Ok::<Build, _>(build(()))
        })
    }
}

impl Drop for AioOffboard {
    fn drop(&mut self) {
        // Dropped without stop(): the session holds position from a task on the runtime.
        if let Some(session) = super::lock(&self.session).take()
            && let Ok(rt) = crate::live::runtime()
        {
            let _entered = rt.enter();
            drop(session);
        }
    }
}

/// A running MANUAL_CONTROL stream.
#[pyclass(module = "mavstack._native", name = "AioManual", frozen)]
pub(crate) struct AioManual {
    session: Mutex<Option<ManualSession>>,
}

impl AioManual {
    pub(super) fn new(session: ManualSession) -> Self {
        Self {
            session: Mutex::new(Some(session)),
        }
    }
}

#[pymethods]
impl AioManual {
    /// The sticks from the next tick on: x, y, r in -1..1, z in 0..1.
    #[pyo3(signature = (x, y, z, r, buttons=0))]
    fn set(&self, x: f32, y: f32, z: f32, r: f32, buttons: u16) -> PyResult<()> {
        let guard = super::lock(&self.session);
        let session = guard
            .as_ref()
            .ok_or_else(|| PyValueError::new_err("the manual control stream has ended"))?;
        session
            .set(Sticks {
                x,
                y,
                z,
                r,
                buttons,
            })
            .map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Stops the stream.
    fn close(&self) {
        super::lock(&self.session).take();
    }
}
