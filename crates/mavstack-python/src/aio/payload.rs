//! A vehicle's gimbals and cameras (`await vehicle.gimbals()`, `await vehicle.cameras()`):
//! each Python method converts its arguments, calls one `mavstack::system::Gimbal` or
//! `Camera` method, and converts the result.

use super::link::{Shared, until_closed};
use super::*;
use mavstack::dialects::common::CameraMode;
use mavstack::services::camera::{CameraInfo, CaptureStatus, ExtValue, ImageCaptured, StorageInfo};
use mavstack::services::gimbal::{Attitude, GimbalInfo, Range, YawFrame};
use mavstack::system::{Camera, Gimbal, SettingView};

/// A setting's value for Python: an `int`, a `float` or a `str`.
#[derive(Clone)]
pub(super) enum PyExt {
    Int(i64),
    UInt(u64),
    Float(f64),
    Text(String),
}

impl<'py> IntoPyObject<'py> for PyExt {
    type Target = PyAny;
    type Output = Bound<'py, PyAny>;
    type Error = core::convert::Infallible;

    fn into_pyobject(self, py: Python<'py>) -> Result<Self::Output, Self::Error> {
        Ok(match self {
            Self::Int(v) => v.into_pyobject(py)?.into_any(),
            Self::UInt(v) => v.into_pyobject(py)?.into_any(),
            Self::Float(v) => v.into_pyobject(py)?.into_any(),
            Self::Text(v) => v.into_pyobject(py)?.into_any(),
        })
    }
}

pub(super) fn py_ext(v: &ExtValue) -> PyExt {
    match v {
        ExtValue::U64(u) => PyExt::UInt(*u),
        ExtValue::I64(i) => PyExt::Int(*i),
        ExtValue::F32(f) => PyExt::Float(f64::from(*f)),
        ExtValue::F64(f) => PyExt::Float(*f),
        ExtValue::Custom(s) => PyExt::Text(s.clone()),
        other => PyExt::Int(other.as_f64().map_or(0, |f| f as i64)),
    }
}

/// A frame by name: `vehicle` or `earth`.
fn frame_of(name: &str) -> PyResult<YawFrame> {
    match name {
        "vehicle" => Ok(YawFrame::Vehicle),
        "earth" => Ok(YawFrame::Earth),
        other => Err(PyValueError::new_err(format!(
            "frame {other:?}: \"vehicle\" or \"earth\""
        ))),
    }
}

type Limits = Option<(f32, f32)>;

fn limits(r: Option<Range>) -> Limits {
    r.map(|r| (r.min, r.max))
}

/// A gimbal as Python builds it: (manager system, manager component, device id, capability
/// flags, pitch limits, yaw limits, roll limits, vendor, model, custom name).
type GimbalTuple = (
    u8,
    u8,
    u8,
    u32,
    Limits,
    Limits,
    Limits,
    String,
    String,
    String,
);

fn gimbal_tuple(g: &GimbalInfo) -> GimbalTuple {
    (
        g.manager.system,
        g.manager.component,
        g.device_id,
        g.cap_flags.0,
        limits(g.pitch),
        limits(g.yaw),
        limits(g.roll),
        g.vendor.clone(),
        g.model.clone(),
        g.custom_name.clone(),
    )
}

/// An attitude as Python builds it: (roll, pitch, yaw, frame, yaw from the nose, yaw from
/// north, failure flags).
type AttitudeTuple = (f32, f32, f32, &'static str, Option<f32>, Option<f32>, u32);

fn attitude_tuple(a: &Attitude) -> AttitudeTuple {
    (
        a.euler.roll_deg,
        a.euler.pitch_deg,
        a.euler.yaw_deg,
        a.frame.name(),
        a.yaw_vehicle_deg,
        a.yaw_earth_deg,
        a.failure_flags,
    )
}

/// A gimbal of a vehicle.
#[pyclass(module = "mavstack._native", name = "AioGimbal", frozen)]
pub(crate) struct AioGimbal {
    shared: Arc<Shared>,
    gimbal: Gimbal,
}

impl AioGimbal {
    fn run<F, Fut>(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>, f: F) -> PyResult<Op>
    where
        F: FnOnce(Gimbal) -> Fut + Send + 'static,
        Fut: Future<Output = Result<Build, AioError>> + Send + 'static,
    {
        spawn_op(
            &waker,
            settle,
            until_closed(self.shared.closed.clone(), f(self.gimbal.clone())),
        )
    }
}

#[pymethods]
impl AioGimbal {
    /// What its manager says about it.
    #[getter]
    fn info(&self) -> GimbalTuple {
        gimbal_tuple(self.gimbal.info())
    }

    /// Takes primary (or `secondary`) control.
    fn take_control(
        &self,
        secondary: bool,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |g| async move {
            g.take_control(secondary).await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Gives up control.
    fn release_control(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |g| async move {
            g.release_control().await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Points it at `pitch` and `yaw` degrees in `frame` (`vehicle` or `earth`).
    fn set_angles(
        &self,
        pitch: f32,
        yaw: f32,
        frame: &str,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let frame = frame_of(frame)?;
        self.run(waker, settle, move |g| async move {
            g.set_angles(pitch, yaw, frame)
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Turns it at `pitch` and `yaw` degrees per second.
    fn set_rates(
        &self,
        pitch: f32,
        yaw: f32,
        frame: &str,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let frame = frame_of(frame)?;
        self.run(waker, settle, move |g| async move {
            g.set_rates(pitch, yaw, frame).await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Keeps it on a location (degrees, metres above mean sea level).
    fn point_at(
        &self,
        lat: f64,
        lon: f64,
        alt: f32,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |g| async move {
            g.point_at(lat, lon, alt).await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Stops keeping it on a location.
    fn clear_roi(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |g| async move {
            g.clear_roi().await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Where it looks: settles with an attitude tuple.
    fn attitude(
        &self,
        timeout: f64,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        let wait = seconds(timeout, "timeout")?;
        self.run(waker, settle, move |g| async move {
            let a = g.attitude(wait).await.map_err(system_error)?;
            Ok(build(attitude_tuple(&a)))
        })
    }

    /// Who controls it: settles with ((system, component) or None, the same for secondary).
    fn control(&self, timeout: f64, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let wait = seconds(timeout, "timeout")?;
        self.run(waker, settle, move |g| async move {
            let c = g.control(wait).await.map_err(system_error)?;
            let pair = |a: Option<Address>| a.map(|a| (a.system, a.component));
            Ok(build((pair(c.primary), pair(c.secondary))))
        })
    }
}

/// A camera as Python builds it: (system, component, vendor, model, firmware, resolution,
/// focal length, capability flags, definition URI, definition version).
type CameraTuple = (
    u8,
    u8,
    String,
    String,
    Option<String>,
    Option<(u16, u16)>,
    Option<f32>,
    u32,
    String,
    u16,
);

fn camera_tuple(c: &CameraInfo) -> CameraTuple {
    (
        c.component.system,
        c.component.component,
        c.vendor.clone(),
        c.model.clone(),
        c.firmware.clone(),
        c.resolution,
        c.focal_length_mm,
        c.flags.0,
        c.definition_uri.clone(),
        c.definition_version,
    )
}

/// A photo as Python builds it: (index, time µs, lat, lon, alt, relative alt, quaternion,
/// file URL, success).
type ImageTuple = (i32, u64, f64, f64, f32, f32, [f32; 4], String, bool);

fn image_tuple(i: &ImageCaptured) -> ImageTuple {
    (
        i.index,
        i.time_utc_us,
        i.lat,
        i.lon,
        i.alt_m,
        i.relative_alt_m,
        i.q,
        i.file_url.clone(),
        i.success,
    )
}

/// A capture status as Python builds it.
type StatusTuple = (bool, bool, f32, bool, f32, f32, i32);

fn status_tuple(s: &CaptureStatus) -> StatusTuple {
    (
        s.photo_busy,
        s.interval_on,
        s.interval_s,
        s.video_on,
        s.recording_s,
        s.available_mib,
        s.image_count,
    )
}

/// A storage as Python builds it.
type StorageTuple = (u8, u8, u8, f32, f32, f32, u8, String);

fn storage_tuple(s: &StorageInfo) -> StorageTuple {
    (
        s.id,
        s.count,
        s.status.0,
        s.total_mib,
        s.used_mib,
        s.available_mib,
        s.kind.0,
        s.name.clone(),
    )
}

/// A setting as Python builds it: (name, value, option, description, options, excluded,
/// read-only).
type SettingTuple = (
    String,
    PyExt,
    Option<String>,
    String,
    Vec<(String, PyExt)>,
    bool,
    bool,
);

fn setting_tuple(s: &SettingView) -> SettingTuple {
    (
        s.name.clone(),
        py_ext(&s.value),
        s.option.clone(),
        s.description.clone(),
        s.options
            .iter()
            .map(|(n, v)| (n.clone(), py_ext(v)))
            .collect(),
        s.excluded,
        s.read_only,
    )
}

/// A camera of a vehicle.
#[pyclass(module = "mavstack._native", name = "AioCamera", frozen)]
pub(crate) struct AioCamera {
    shared: Arc<Shared>,
    camera: Camera,
}

impl AioCamera {
    fn run<F, Fut>(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>, f: F) -> PyResult<Op>
    where
        F: FnOnce(Camera) -> Fut + Send + 'static,
        Fut: Future<Output = Result<Build, AioError>> + Send + 'static,
    {
        spawn_op(
            &waker,
            settle,
            until_closed(self.shared.closed.clone(), f(self.camera.clone())),
        )
    }

    fn simple(
        &self,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
        what: &'static str,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            match what {
                "start_video" => c.start_video().await,
                "stop_video" => c.stop_video().await,
                _ => c.stop_photo_interval().await,
            }
            .map_err(system_error)?;
            Ok(build(()))
        })
    }
}

#[pymethods]
impl AioCamera {
    /// What its CAMERA_INFORMATION says.
    #[getter]
    fn info(&self) -> CameraTuple {
        camera_tuple(self.camera.info())
    }

    /// Takes a photo: settles with its image tuple.
    fn take_photo(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            let i = c.take_photo().await.map_err(system_error)?;
            Ok(build(image_tuple(&i)))
        })
    }

    /// Starts recording.
    fn start_video(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.simple(waker, settle, "start_video")
    }

    /// Stops recording.
    fn stop_video(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.simple(waker, settle, "stop_video")
    }

    /// Photos every `seconds`, `count` of them (0: until stopped).
    fn start_photo_interval(
        &self,
        seconds: f32,
        count: u32,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            c.start_photo_interval(seconds, count)
                .await
                .map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// Stops the photos at an interval.
    fn stop_photo_interval(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.simple(waker, settle, "stop_photo_interval")
    }

    /// Switches to `photo` or `video` mode.
    fn set_mode(&self, mode: &str, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        let mode = match mode {
            "photo" => CameraMode::IMAGE,
            "video" => CameraMode::VIDEO,
            other => {
                return Err(PyValueError::new_err(format!(
                    "mode {other:?}: \"photo\" or \"video\""
                )));
            }
        };
        self.run(waker, settle, move |c| async move {
            c.set_mode(mode).await.map_err(system_error)?;
            Ok(build(()))
        })
    }

    /// What it is doing: settles with a status tuple.
    fn capture_status(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            let s = c.capture_status().await.map_err(system_error)?;
            Ok(build(status_tuple(&s)))
        })
    }

    /// Its storage: settles with a list of storage tuples.
    fn storage(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            let s = c.storage().await.map_err(system_error)?;
            Ok(build(s.iter().map(storage_tuple).collect::<Vec<_>>()))
        })
    }

    /// Its settings: settles with a list of setting tuples.
    fn settings(&self, waker: PyRef<'_, AioWaker>, settle: Py<PyAny>) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            let s = c.settings().await.map_err(system_error)?;
            Ok(build(s.iter().map(setting_tuple).collect::<Vec<_>>()))
        })
    }

    /// Sets setting `name` to `value` (an option's name or a value, as text): settles with
    /// the value it took.
    fn set(
        &self,
        name: String,
        value: String,
        waker: PyRef<'_, AioWaker>,
        settle: Py<PyAny>,
    ) -> PyResult<Op> {
        self.run(waker, settle, move |c| async move {
            let v = c.set(&name, &value).await.map_err(system_error)?;
            Ok(build(py_ext(&v)))
        })
    }
}

/// The vehicle's gimbals, as Python objects.
pub(super) async fn gimbals(shared: Arc<Shared>, system: System) -> Result<Build, AioError> {
    let list = system.gimbals().list().await.map_err(system_error)?;
    Ok(Box::new(move |py: Python<'_>| {
        let items = list
            .into_iter()
            .map(|gimbal| {
                Py::new(
                    py,
                    AioGimbal {
                        shared: Arc::clone(&shared),
                        gimbal,
                    },
                )
            })
            .collect::<PyResult<Vec<_>>>()?;
        items.into_py_any(py)
    }))
}

/// The vehicle's cameras, as Python objects.
pub(super) async fn cameras(shared: Arc<Shared>, system: System) -> Result<Build, AioError> {
    let list = system.cameras().list().await.map_err(system_error)?;
    Ok(Box::new(move |py: Python<'_>| {
        let items = list
            .into_iter()
            .map(|camera| {
                Py::new(
                    py,
                    AioCamera {
                        shared: Arc::clone(&shared),
                        camera,
                    },
                )
            })
            .collect::<PyResult<Vec<_>>>()?;
        items.into_py_any(py)
    }))
}
