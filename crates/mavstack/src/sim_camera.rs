//! [`SimCamera`]: a camera component beside a simulated vehicle (feature `sim`): the
//! camera protocol served as a component of its own ([`serve::Camera`],
//! with the simulated camera's definition file), each photo written as an image file into a
//! directory (`mavstack vehicle --camera DIR`).

use std::path::{Path, PathBuf};

use mavstack_router::{LinkConfig, LinkRole, ProtocolVersionSupport};
use mavstack_services::Address;
use mavstack_services::camera::{
    CameraConfig, CameraEvent, DefinitionError, ExtValue, SIMULATED_DEFINITION,
};
use mavstack_transport::Link;
use tokio::task::JoinHandle;

use crate::node::{Node, NodeError};
use crate::serve;
use crate::sim_vehicle::LogLines;

/// The simulated camera's image size, pixels.
pub const IMAGE_SIZE: (u16, u16) = (320, 240);

/// The component id a simulated vehicle's camera has by default (MAV_COMP_ID_CAMERA).
pub const CAMERA_COMPONENT: u8 = 100;

/// Why a [`SimCamera`] did not start.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimCameraError {
    /// Its node did not start.
    #[error("the simulated camera's node")]
    Node(#[from] NodeError),
    /// Its definition file is not one (a build of mavstack with a broken file).
    #[error("the simulated camera's definition file")]
    Definition(#[from] DefinitionError),
}

/// A camera beside a simulated vehicle, on a node of its own (from [`SimCamera::start`]).
#[derive(Debug)]
pub struct SimCamera {
    node: Node,
    task: JoinHandle<()>,
}

impl SimCamera {
    /// Starts the camera at `own` on a node of its own, on `link` (one of
    /// [`serve::joined`]'s, the other given to the vehicle's node), writing each photo into
    /// `dir` as `IMG_0000.pgm`, `IMG_0001.pgm`, ... (`.ppm` when its CAM_PHOTOFMT setting
    /// says so); what it does goes to `log` (or `tracing`).
    ///
    /// # Errors
    /// [`SimCameraError`] when its node cannot start.
    pub async fn start(
        link: (LinkConfig, Link),
        own: Address,
        dir: &Path,
        log: Option<LogLines>,
    ) -> Result<Self, SimCameraError> {
        let node = Node::builder()
            .identity(own.system, own.component)
            .role(LinkRole::Vehicle {
                protocol_version: ProtocolVersionSupport::Answer,
            })
            .opened_link(link.0, link.1)
            .start()
            .await?;
        let mut config = CameraConfig::new(own, "mavstack", "Simulated camera", 1024.0);
        config.info.firmware = Some("1.0.0.0".to_owned());
        config.info.focal_length_mm = Some(4.5);
        config.info.sensor_mm = Some((6.17, 4.55));
        config.info.resolution = Some(IMAGE_SIZE);
        let camera = serve::Camera::start(
            &node.handle(),
            config,
            Some(SIMULATED_DEFINITION.as_bytes().to_vec()),
        )
        .await?;
        let task = tokio::spawn(run(camera, dir.to_path_buf(), log));
        Ok(Self { node, task })
    }

    /// Its node.
    #[must_use]
    pub const fn node(&self) -> &Node {
        &self.node
    }

    /// Stops the camera and its node.
    ///
    /// # Errors
    /// [`NodeError`] if its link failed.
    pub async fn shutdown(self) -> Result<(), NodeError> {
        self.task.abort();
        self.node.shutdown().await.map(drop)
    }
}

fn say(log: &Option<LogLines>, line: String) {
    match log {
        Some(tx) => {
            let _ = tx.send(line);
        }
        None => tracing::info!("{line}"),
    }
}

/// The camera's owner: takes each photo (writes the file), says how it went.
async fn run(mut camera: serve::Camera, dir: PathBuf, log: Option<LogLines>) {
    while let Some(event) = camera.next_event().await {
        match event {
            CameraEvent::TakePhoto(photo) => {
                let color = camera
                    .settings()
                    .await
                    .iter()
                    .any(|(n, v)| n == "CAM_PHOTOFMT" && *v == ExtValue::U32(1));
                let name = format!(
                    "IMG_{:04}.{}",
                    photo.index,
                    if color { "ppm" } else { "pgm" }
                );
                let path = dir.join(&name);
                let bytes = image(photo.index, color);
                match tokio::fs::write(&path, &bytes).await {
                    Ok(()) => {
                        let url = file_url(&path, &name);
                        say(
                            &log,
                            format!("camera: photo {} → {}", photo.index, path.display()),
                        );
                        let mib = bytes.len() as f32 / (1024.0 * 1024.0);
                        camera.photo_taken(photo.index, Some(url), mib).await;
                    }
                    Err(e) => {
                        say(
                            &log,
                            format!(
                                "camera: photo {} not written to {}: {e}",
                                photo.index,
                                path.display()
                            ),
                        );
                        camera.photo_taken(photo.index, None, 0.0).await;
                    }
                }
            }
            CameraEvent::VideoStart { .. } => say(&log, "camera: recording".to_owned()),
            CameraEvent::VideoStop { recorded } => {
                say(
                    &log,
                    format!(
                        "camera: recording stopped after {:.1} s",
                        recorded.as_secs_f32()
                    ),
                );
            }
            CameraEvent::Mode(m) => say(
                &log,
                format!("camera: mode {}", mavstack_services::camera::mode_name(m)),
            ),
            CameraEvent::Setting { from, name, value } => {
                say(&log, format!("camera: {name} = {value} (set by {from})"));
            }
            CameraEvent::Format => say(&log, "camera: storage formatted".to_owned()),
            _ => {}
        }
    }
}

/// The file's URL for CAMERA_IMAGE_CAPTURED: `file://` and its absolute path, or its name
/// alone where that would not fit the message's 204 bytes.
fn file_url(path: &Path, name: &str) -> String {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let url = format!("file://{}", absolute.display());
    if url.len() <= 204 {
        url
    } else {
        name.to_owned()
    }
}

/// A synthetic photo: a gradient with a band whose place says its index, as a binary PGM
/// (grey) or PPM (colour).
fn image(index: i32, color: bool) -> Vec<u8> {
    let (w, h) = (usize::from(IMAGE_SIZE.0), usize::from(IMAGE_SIZE.1));
    let magic = if color { "P6" } else { "P5" };
    let mut out =
        format!("{magic}\n# mavstack simulated camera, image {index}\n{w} {h}\n255\n").into_bytes();
    let band = (index.unsigned_abs() as usize * 16) % w;
    for y in 0..h {
        for x in 0..w {
            let v = if x.abs_diff(band) < 4 {
                255
            } else {
                ((x + y) * 255 / (w + h)) as u8
            };
            if color {
                out.extend_from_slice(&[v, (y * 255 / h) as u8, 255 - v]);
            } else {
                out.push(v);
            }
        }
    }
    out
}
