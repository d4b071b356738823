//! [`Cameras`]: a system's cameras (the camera protocol v2) — found by their
//! CAMERA_INFORMATION, each a [`Camera`] to take photos with (each to its
//! CAMERA_IMAGE_CAPTURED, a lost one asked for again), record, read the status and storage
//! of, and whose settings its definition file describes (fetched over MAVFTP for `mftp://`
//! URIs, xz unpacked) and PARAM_EXT_* reads and writes. The protocol is
//! `mavstack_services::camera`'s.

use core::sync::atomic::{AtomicU32, Ordering};
use core::time::Duration;
use std::sync::Arc;

use mavstack_core::Message as _;
use mavstack_dialects::common::{
    CameraCaptureStatus, CameraMode, CameraSettings, MavCmd, MavMessage, StorageInformation,
    VideoStreamInformation,
};
use mavstack_services::camera::{
    CameraDefinition, CameraDiscovery, CameraInfo, CaptureConfig, CaptureStatus, DefinitionUri,
    ExtValue, ImageCaptured, MessageFetch, ParamExtClient, ParamExtConfig, ParamExtEvent,
    PhotoCapture, StorageInfo, VideoStream,
};
use mavstack_services::command::{Command, CommandConfig};
use mavstack_services::gimbal::DiscoveryConfig;
use mavstack_transport::clock;

use super::{System, SystemError, run};

/// How long one operation with a camera may take.
const LIMIT: Duration = Duration::from_secs(60);

/// The cameras of a system (from [`System::cameras`]).
#[derive(Clone, Debug)]
pub struct Cameras {
    system: System,
}

impl Cameras {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// The system's cameras: the components heard that answer a request for
    /// CAMERA_INFORMATION (within 3 s, or 0.7 s after the last answer), by component id.
    ///
    /// # Errors
    /// [`SystemError::Stopped`].
    pub async fn list(&self) -> Result<Vec<Camera>, SystemError> {
        let inner = &self.system.inner;
        let components = self.system.component_ids();
        let mut frames = self.system.frames().await;
        let mut discovery = CameraDiscovery::new(
            clock::now(),
            inner.target.system,
            &components,
            DiscoveryConfig::default(),
        );
        let found = run::drive(
            inner,
            &mut frames,
            &mut discovery,
            LIMIT,
            CameraDiscovery::poll_result,
        )
        .await?;
        let mut cameras = Vec::with_capacity(found.len());
        for info in found {
            let system = self.system.at(info.component).await;
            cameras.push(Camera::new(system, info));
        }
        Ok(cameras)
    }
}

/// One setting of a camera, with what its definition says about it.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct SettingView {
    /// Its name.
    pub name: String,
    /// Its value.
    pub value: ExtValue,
    /// The name of the option that value is, when it is one.
    pub option: Option<String>,
    /// What it is, for people.
    pub description: String,
    /// The values it takes now (name and value), when it is a choice.
    pub options: Vec<(String, ExtValue)>,
    /// Another setting's choice rules it out now.
    pub excluded: bool,
    /// It cannot be set.
    pub read_only: bool,
}

/// One camera of a system (from [`Cameras::list`]).
#[derive(Clone, Debug)]
pub struct Camera {
    system: System,
    info: CameraInfo,
    /// IMAGE_START_CAPTURE's sequence numbers.
    sequence: Arc<AtomicU32>,
    /// Its definition, once read (`Some(None)`: it has none).
    definition: Arc<tokio::sync::Mutex<Option<Option<CameraDefinition>>>>,
}

impl Camera {
    fn new(system: System, info: CameraInfo) -> Self {
        Self {
            system,
            info,
            sequence: Arc::new(AtomicU32::new(0)),
            definition: Arc::default(),
        }
    }

    /// What its CAMERA_INFORMATION says.
    #[must_use]
    pub const fn info(&self) -> &CameraInfo {
        &self.info
    }

    /// Its component, as a system handle of its own (commands, MAVFTP).
    #[must_use]
    pub const fn component(&self) -> &System {
        &self.system
    }

    /// Asks for one kind of its messages (REQUEST_MESSAGE, or the older command it takes).
    async fn fetch(&self, msg_id: u32, param: f32) -> Result<Vec<MavMessage>, SystemError> {
        let inner = &self.system.inner;
        let _one = inner.locks.commands.lock().await;
        let mut frames = self.system.frames().await;
        let mut fetch = MessageFetch::start(
            clock::now(),
            inner.own,
            inner.target,
            msg_id,
            param,
            CommandConfig::default(),
        );
        run::drive(
            inner,
            &mut frames,
            &mut fetch,
            LIMIT,
            MessageFetch::poll_result,
        )
        .await?
        .map_err(|reason| SystemError::Command {
            command: format!("REQUEST_MESSAGE({})", crate::message_name(msg_id)),
            reason,
            statustext: Vec::new(),
        })
    }

    /// What it is doing (CAMERA_CAPTURE_STATUS).
    ///
    /// # Errors
    /// [`SystemError::Command`] (refused or unanswered), [`SystemError::Stopped`].
    pub async fn capture_status(&self) -> Result<CaptureStatus, SystemError> {
        let got = self.fetch(CameraCaptureStatus::ID, 0.0).await?;
        got.iter()
            .find_map(|m| match m {
                MavMessage::CameraCaptureStatus(s) => Some(CaptureStatus::from_message(s)),
                _ => None,
            })
            .ok_or(SystemError::Stopped)
    }

    /// Its storage (STORAGE_INFORMATION, every storage it has).
    ///
    /// # Errors
    /// As [`capture_status`](Self::capture_status).
    pub async fn storage(&self) -> Result<Vec<StorageInfo>, SystemError> {
        let got = self.fetch(StorageInformation::ID, 0.0).await?;
        Ok(got
            .iter()
            .filter_map(|m| match m {
                MavMessage::StorageInformation(s) => Some(StorageInfo::from_message(s)),
                _ => None,
            })
            .collect())
    }

    /// Its mode (CAMERA_SETTINGS).
    ///
    /// # Errors
    /// As [`capture_status`](Self::capture_status).
    pub async fn mode(&self) -> Result<CameraMode, SystemError> {
        let got = self.fetch(CameraSettings::ID, 0.0).await?;
        got.iter()
            .find_map(|m| match m {
                MavMessage::CameraSettings(s) => Some(s.mode_id),
                _ => None,
            })
            .ok_or(SystemError::Stopped)
    }

    /// Its video streams (VIDEO_STREAM_INFORMATION, every stream it has).
    ///
    /// # Errors
    /// As [`capture_status`](Self::capture_status).
    pub async fn video_streams(&self) -> Result<Vec<VideoStream>, SystemError> {
        let got = self.fetch(VideoStreamInformation::ID, 0.0).await?;
        Ok(got
            .iter()
            .filter_map(|m| match m {
                MavMessage::VideoStreamInformation(s) => Some(VideoStream::from_message(s)),
                _ => None,
            })
            .collect())
    }

    /// Takes one photo and gives its CAMERA_IMAGE_CAPTURED (whose `success` says whether
    /// the camera took it): the photo's index is the camera's image count before it
    /// (CAMERA_CAPTURE_STATUS); an announcement that does not come is asked for again by
    /// that index (REQUEST_MESSAGE, or REQUEST_CAMERA_IMAGE_CAPTURE where that is refused).
    ///
    /// # Errors
    /// [`SystemError::Photo`] (refused, unanswered, or never announced),
    /// [`SystemError::Stopped`].
    pub async fn take_photo(&self) -> Result<ImageCaptured, SystemError> {
        let expected = match self.capture_status().await {
            Ok(s) => Some(s.image_count),
            Err(SystemError::Stopped) => return Err(SystemError::Stopped),
            Err(_) => None,
        };
        let sequence = self.sequence.fetch_add(1, Ordering::Relaxed) + 1;
        let inner = &self.system.inner;
        let _one = inner.locks.commands.lock().await;
        let mut frames = self.system.frames().await;
        let mut capture = PhotoCapture::start(
            clock::now(),
            inner.own,
            inner.target,
            expected,
            sequence,
            CaptureConfig::default(),
        );
        let image = run::drive_with(
            inner,
            &mut frames,
            &mut capture,
            LIMIT,
            PhotoCapture::poll_result,
            |capture, from, id, payload| {
                if let Some(image) = feedback_image(id, payload) {
                    capture.handle_announcement(from, image);
                }
            },
        )
        .await??;
        Ok(image)
    }

    async fn command(&self, id: MavCmd, p: [f32; 7]) -> Result<(), SystemError> {
        self.system
            .commands()
            .send(Command::long(id, p))
            .await
            .map(drop)
    }

    /// Takes a photo every `seconds`, `count` of them (0: until stopped).
    ///
    /// # Errors
    /// [`SystemError::Invalid`] for an interval that is not a positive number (nothing is
    /// sent); [`SystemError::Command`], [`SystemError::Stopped`].
    pub async fn start_photo_interval(&self, seconds: f32, count: u32) -> Result<(), SystemError> {
        if !(seconds.is_finite() && seconds > 0.0) {
            return Err(SystemError::Invalid(format!(
                "a photo interval of {seconds} s: it must be a positive number of seconds"
            )));
        }
        let nan = f32::NAN;
        self.command(
            MavCmd::IMAGE_START_CAPTURE,
            [0.0, seconds, count as f32, 0.0, 0.0, 0.0, nan],
        )
        .await
    }

    /// Stops taking photos at an interval.
    ///
    /// # Errors
    /// [`SystemError::Command`], [`SystemError::Stopped`].
    pub async fn stop_photo_interval(&self) -> Result<(), SystemError> {
        let nan = f32::NAN;
        self.command(
            MavCmd::IMAGE_STOP_CAPTURE,
            [0.0, nan, nan, nan, 0.0, 0.0, nan],
        )
        .await
    }

    /// Starts recording (all streams; no status messages while recording).
    ///
    /// # Errors
    /// As [`stop_photo_interval`](Self::stop_photo_interval).
    pub async fn start_video(&self) -> Result<(), SystemError> {
        let nan = f32::NAN;
        self.command(
            MavCmd::VIDEO_START_CAPTURE,
            [0.0, 0.0, 0.0, nan, 0.0, 0.0, nan],
        )
        .await
    }

    /// Stops recording.
    ///
    /// # Errors
    /// As [`stop_photo_interval`](Self::stop_photo_interval).
    pub async fn stop_video(&self) -> Result<(), SystemError> {
        let nan = f32::NAN;
        self.command(
            MavCmd::VIDEO_STOP_CAPTURE,
            [0.0, 0.0, nan, nan, 0.0, 0.0, nan],
        )
        .await
    }

    /// Switches it to photo or video mode (MAV_CMD_SET_CAMERA_MODE).
    ///
    /// # Errors
    /// As [`stop_photo_interval`](Self::stop_photo_interval).
    pub async fn set_mode(&self, mode: CameraMode) -> Result<(), SystemError> {
        let nan = f32::NAN;
        self.command(
            MavCmd::SET_CAMERA_MODE,
            [0.0, f32::from(mode.0), nan, nan, 0.0, 0.0, nan],
        )
        .await
    }

    /// Its definition file, read once and kept: fetched over MAVFTP from the camera for an
    /// `mftp://` (or `mavlinkftp://`) URI, unpacked when xz-compressed, and parsed; `None`
    /// when it has none.
    ///
    /// # Errors
    /// [`SystemError::CameraDefinition`] (a file that is not a definition, with its line
    /// and column), [`SystemError::Ftp`], [`SystemError::NotDone`] for a damaged xz file,
    /// [`SystemError::Invalid`] for an HTTP URI or a scheme the protocol does not have.
    pub async fn definition(&self) -> Result<Option<CameraDefinition>, SystemError> {
        let mut kept = self.definition.lock().await;
        if let Some(d) = kept.as_ref() {
            return Ok(d.clone());
        }
        let uri = self.info.definition_uri.as_str();
        let bytes = match DefinitionUri::of(uri) {
            DefinitionUri::None => {
                *kept = Some(None);
                return Ok(None);
            }
            DefinitionUri::Mavftp(path) => self.system.ftp().read(path, |_, _| {}).await?,
            DefinitionUri::Http(_) => {
                return Err(SystemError::Invalid(format!(
                    "camera definition {uri}: HTTP is not fetched here (only mftp:// over MAVFTP)"
                )));
            }
            DefinitionUri::Unknown(_) => {
                return Err(SystemError::Invalid(format!(
                    "camera definition {uri}: not an mftp:// or http:// URI"
                )));
            }
        };
        let xml = crate::events::unpack(&bytes).map_err(|e| SystemError::NotDone {
            what: format!("camera definition {uri}: {e}"),
            statustext: Vec::new(),
        })?;
        let definition =
            CameraDefinition::parse(&xml).map_err(|source| SystemError::CameraDefinition {
                uri: uri.to_owned(),
                source,
            })?;
        *kept = Some(Some(definition.clone()));
        Ok(Some(definition))
    }

    /// Runs one PARAM_EXT_* operation to its event.
    async fn param_ext(
        &self,
        start: impl FnOnce(&mut ParamExtClient) -> Result<(), mavstack_services::camera::ParamExtError>,
    ) -> Result<ParamExtEvent, SystemError> {
        let inner = &self.system.inner;
        let _one = inner.locks.params.lock().await;
        let mut frames = self.system.frames().await;
        let mut client = ParamExtClient::new(inner.target, ParamExtConfig::default());
        start(&mut client)?;
        run::drive(
            inner,
            &mut frames,
            &mut client,
            LIMIT,
            ParamExtClient::poll_event,
        )
        .await
    }

    /// Its settings' values (PARAM_EXT_REQUEST_LIST), in its order.
    ///
    /// # Errors
    /// [`SystemError::CameraSettings`], [`SystemError::Stopped`].
    pub async fn values(&self) -> Result<Vec<(String, ExtValue)>, SystemError> {
        let now = clock::now();
        match self.param_ext(|c| c.list(now)).await? {
            ParamExtEvent::Listed(r) => Ok(r?),
            _ => Err(SystemError::Stopped),
        }
    }

    /// Its settings with what its definition says about each (description, options as the
    /// other settings narrow them, whether one rules it out now); settings the definition
    /// lacks are listed with their values only.
    ///
    /// # Errors
    /// As [`values`](Self::values) and [`definition`](Self::definition).
    pub async fn settings(&self) -> Result<Vec<SettingView>, SystemError> {
        let definition = self.definition().await?;
        let values = self.values().await?;
        let current = |n: &str| values.iter().find(|(k, _)| k == n).map(|(_, v)| v.clone());
        let excluded = definition
            .as_ref()
            .map(|d| d.excluded(&current))
            .unwrap_or_default();
        Ok(values
            .iter()
            .map(|(name, value)| {
                let setting = definition.as_ref().and_then(|d| d.setting(name));
                let options = definition
                    .as_ref()
                    .map(|d| d.options_of(name, &current))
                    .unwrap_or_default();
                SettingView {
                    name: name.clone(),
                    value: value.clone(),
                    option: options
                        .iter()
                        .find(|(_, v)| v == value)
                        .map(|(n, _)| n.clone()),
                    description: setting.map(|s| s.description.clone()).unwrap_or_default(),
                    options,
                    excluded: excluded.contains(name),
                    read_only: setting.is_some_and(|s| s.read_only),
                }
            })
            .collect())
    }

    /// Sets `name` to `value` (an option's name, or a value of its type), checked against
    /// its definition with the camera's current values first (PARAM_EXT_SET); returns the
    /// value the camera took.
    ///
    /// # Errors
    /// [`SystemError::CameraSetting`] for a value the definition does not allow (nothing is
    /// sent); [`SystemError::CameraSettings`] when the camera refuses or does not answer;
    /// as [`definition`](Self::definition).
    pub async fn set(&self, name: &str, value: &str) -> Result<ExtValue, SystemError> {
        let definition = self.definition().await?;
        let values = self.values().await?;
        let typed = match &definition {
            Some(d) => {
                let v = d.value_of(name, value)?;
                let current = |n: &str| values.iter().find(|(k, _)| k == n).map(|(_, v)| v.clone());
                d.check(name, &v, &current)?;
                v
            }
            None => {
                // No definition: the camera's own type for it.
                let (_, now) = values.iter().find(|(n, _)| n == name).ok_or_else(|| {
                    SystemError::Invalid(format!("the camera has no setting {name}"))
                })?;
                ExtValue::parse(now.ty(), value).ok_or_else(|| {
                    SystemError::Invalid(format!(
                        "{value:?} is not a {} value for {name}",
                        now.ty().name()
                    ))
                })?
            }
        };
        let now = clock::now();
        match self.param_ext(|c| c.set(now, name, typed)).await? {
            ParamExtEvent::Set(r) => Ok(r?.1),
            _ => Err(SystemError::Stopped),
        }
    }
}

/// ArduPilot's announcement of a photo, CAMERA_FEEDBACK (its own dialect's), as the
/// camera protocol's CAMERA_IMAGE_CAPTURED would say it: ArduPilot sends no
/// CAMERA_IMAGE_CAPTURED. `None` for another message, or a video frame's feedback.
fn feedback_image(id: u32, payload: &[u8]) -> Option<ImageCaptured> {
    use mavstack_dialects::ardupilotmega::{CameraFeedback, CameraFeedbackFlags};
    if id != CameraFeedback::ID {
        return None;
    }
    let f = CameraFeedback::decode(payload);
    if f.flags == CameraFeedbackFlags::CAMERA_FEEDBACK_VIDEO {
        return None;
    }
    Some(ImageCaptured {
        index: i32::from(f.img_idx),
        time_utc_us: f.time_usec,
        lat: f64::from(f.lat) / 1e7,
        lon: f64::from(f.lng) / 1e7,
        alt_m: f.alt_msl,
        relative_alt_m: f.alt_rel,
        q: mavstack_services::gimbal::quaternion_from_euler(f.roll, f.pitch, f.yaw),
        file_url: String::new(),
        success: f.flags != CameraFeedbackFlags::CAMERA_FEEDBACK_BADEXPOSURE,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavstack_dialects::ardupilotmega::{CameraFeedback, CameraFeedbackFlags};

    fn payload(flags: CameraFeedbackFlags) -> Vec<u8> {
        let f = CameraFeedback {
            time_usec: 1_765_000_000_000_000,
            img_idx: 2,
            lat: -353_632_610,
            lng: 1_491_652_300,
            alt_msl: 584.5,
            alt_rel: 0.5,
            yaw: 90.0,
            flags,
            ..CameraFeedback::default()
        };
        let mut buf = [0u8; 255];
        let n = f.encode(&mut buf);
        buf[..n].to_vec()
    }

    #[test]
    fn ardupilots_camera_feedback_reads_as_the_photos_announcement() {
        let image = feedback_image(
            CameraFeedback::ID,
            &payload(CameraFeedbackFlags::CAMERA_FEEDBACK_PHOTO),
        )
        .expect("a photo");
        assert_eq!(image.index, 2);
        assert_eq!(image.time_utc_us, 1_765_000_000_000_000);
        assert!((image.lat + 35.363_261).abs() < 1e-9 && (image.lon - 149.165_23).abs() < 1e-9);
        assert_eq!((image.alt_m, image.relative_alt_m), (584.5, 0.5));
        assert!(image.success && image.file_url.is_empty());
        // Yaw 90 degrees: a quarter turn about z.
        let h = core::f32::consts::FRAC_1_SQRT_2;
        assert!(
            (image.q[0] - h).abs() < 1e-5 && (image.q[3] - h).abs() < 1e-5,
            "{:?}",
            image.q
        );
        let bad = feedback_image(
            CameraFeedback::ID,
            &payload(CameraFeedbackFlags::CAMERA_FEEDBACK_BADEXPOSURE),
        );
        assert!(bad.is_some_and(|i| !i.success));
        let video = payload(CameraFeedbackFlags::CAMERA_FEEDBACK_VIDEO);
        assert_eq!(feedback_image(CameraFeedback::ID, &video), None);
        assert_eq!(feedback_image(0, &video), None);
    }
}
