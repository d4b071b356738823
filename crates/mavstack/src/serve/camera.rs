//! [`Camera`]: a camera served as a MAVLink component of its own (a companion computer's
//! camera), over `mavstack_services::camera::CameraServer`: its owner is asked for each
//! photo and recording ([`Camera::next_event`]) and says how each photo went
//! ([`Camera::photo_taken`]); its definition file is served over MAVFTP from the same
//! component.

use std::time::{SystemTime, UNIX_EPOCH};

use mavstack_core::time::Instant;
use mavstack_dialects::common::MavMessage;
use mavstack_services::camera::{
    CameraConfig, CameraDefinition, CameraEvent, CameraServer, DefinitionError, ExtValue,
};
use mavstack_services::ftp::{FtpServer, MemoryBackend, ServerConfig};
use mavstack_services::{Address, Outgoing, Service};
use tokio::sync::mpsc;

use super::Served;
use crate::node::NodeHandle;

/// Where a served camera's definition file is on its MAVFTP server (its URI is
/// `mftp://camera.xml`).
pub const DEFINITION_PATH: &str = "camera.xml";

/// The camera, its definition file's MAVFTP server, and the way out of its events.
struct Component {
    camera: CameraServer,
    files: Option<FtpServer<MemoryBackend>>,
    events: mpsc::UnboundedSender<CameraEvent>,
}

impl Component {
    fn tell(&mut self) {
        while let Some(e) = self.camera.poll_event() {
            // An owner that stopped listening still lets the camera answer.
            let _ = self.events.send(e);
        }
    }
}

impl Service for Component {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let a = self.camera.handle_message(now, from, message);
        let b = self
            .files
            .as_mut()
            .is_some_and(|f| f.handle_message(now, from, message));
        self.tell();
        a || b
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.camera.handle_timeout(now);
        if let Some(f) = &mut self.files {
            f.handle_timeout(now);
        }
        self.tell();
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.camera
            .poll_transmit()
            .or_else(|| self.files.as_mut().and_then(Service::poll_transmit))
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let files = self.files.as_ref().and_then(Service::poll_timeout);
        match (self.camera.poll_timeout(), files) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// A camera served on a node of its own (from [`Camera::start`]).
pub struct Camera {
    served: Served<Component>,
    events: mpsc::UnboundedReceiver<CameraEvent>,
}

impl core::fmt::Debug for Camera {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Camera").finish_non_exhaustive()
    }
}

impl Camera {
    /// Serves the camera `config` describes on `node`, whose identity is the camera's
    /// (`config.info.component`: a node of its own). With `definition` (a definition
    /// file's bytes), the camera serves it over MAVFTP at [`DEFINITION_PATH`], gives
    /// `mftp://camera.xml` and the file's version in CAMERA_INFORMATION, and serves the
    /// settings it describes with PARAM_EXT_*.
    ///
    /// # Errors
    /// [`DefinitionError`]: `definition` is not a camera definition (nothing is served).
    pub async fn start(
        node: &NodeHandle,
        mut config: CameraConfig,
        definition: Option<Vec<u8>>,
    ) -> Result<Self, DefinitionError> {
        let own = config.info.component;
        let files = match definition {
            Some(bytes) => {
                let parsed = CameraDefinition::parse(&bytes)?;
                config.info.definition_uri = format!("mftp://{DEFINITION_PATH}");
                config.info.definition_version = u16::try_from(parsed.version).unwrap_or(u16::MAX);
                config.definition = Some(parsed);
                let mut backend = MemoryBackend::new();
                backend.insert_file(DEFINITION_PATH, &bytes);
                Some(FtpServer::new(own, ServerConfig::default(), backend))
            }
            None => None,
        };
        let (tx, events) = mpsc::unbounded_channel();
        let now = mavstack_transport::clock::now();
        let component = Component {
            camera: CameraServer::new(now, config),
            files,
            events: tx,
        };
        let served = Served::start(node, component).await;
        Ok(Self { served, events })
    }

    /// The next thing the camera asks of its owner (take a photo, start or stop recording)
    /// or tells it (a mode, a setting changed, a format); `None` once it has stopped.
    pub async fn next_event(&mut self) -> Option<CameraEvent> {
        self.events.recv().await
    }

    /// Says how photo `index` went: the file's URL (`None`: it failed) and the storage it
    /// took (MiB). The camera announces it (CAMERA_IMAGE_CAPTURED, time and position
    /// included) and answers the command that asked for it. Returns whether that photo was
    /// being taken.
    pub async fn photo_taken(&self, index: i32, file_url: Option<String>, size_mib: f32) -> bool {
        let utc = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_micros()).unwrap_or(0));
        let now = mavstack_transport::clock::now();
        self.served
            .with(move |c| {
                c.camera
                    .photo_taken(now, index, file_url.as_deref(), utc, size_mib)
            })
            .await
            .unwrap_or(false)
    }

    /// Its settings (PARAM_EXT_*), in its definition's order; empty without one.
    pub async fn settings(&self) -> Vec<(String, ExtValue)> {
        self.served
            .with(|c| {
                c.camera
                    .settings()
                    .map(|s| s.values().to_vec())
                    .unwrap_or_default()
            })
            .await
            .unwrap_or_default()
    }

    /// Photos announced so far.
    pub async fn image_count(&self) -> i32 {
        self.served
            .with(|c| c.camera.image_count())
            .await
            .unwrap_or(0)
    }

    /// Stops serving.
    pub async fn stop(self) {
        let _ = self.served.stop().await;
    }
}
