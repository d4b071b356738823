//! The camera protocol (v2), in both roles.
//!
//! A MAVLink camera is a component of its own (MAV_TYPE_CAMERA, usually component 100 and
//! up). Ground stations ask it for CAMERA_INFORMATION (what it is, what it can do, where its
//! definition file is), CAMERA_SETTINGS (its mode), STORAGE_INFORMATION and
//! CAMERA_CAPTURE_STATUS with MAV_CMD_REQUEST_MESSAGE; take photos with
//! MAV_CMD_IMAGE_START_CAPTURE (one, or one every so many seconds), each announced by
//! CAMERA_IMAGE_CAPTURED with its index (a lost one asked for again by REQUEST_MESSAGE with
//! that index); record with MAV_CMD_VIDEO_START_CAPTURE / _STOP_CAPTURE; and read and write
//! the settings its definition file describes with PARAM_EXT_*.
//!
//! ```text
//!  ground station                                camera (1/100)
//!  REQUEST_MESSAGE(CAMERA_INFORMATION) ───────►  CAMERA_INFORMATION (cam_definition_uri)
//!  MAVFTP read of the definition ─────────────►  the XML file
//!  PARAM_EXT_REQUEST_LIST ────────────────────►  PARAM_EXT_VALUE × n
//!  IMAGE_START_CAPTURE(total 1, seq n) ───────►  COMMAND_ACK, CAMERA_IMAGE_CAPTURED(index i)
//!  REQUEST_MESSAGE(CAMERA_IMAGE_CAPTURED, i) ─►  CAMERA_IMAGE_CAPTURED(index i) again
//! ```
//!
//! **Client**: [`CameraDiscovery`] finds a system's cameras; [`CameraInfo`] and the other
//! message views; [`MessageFetch`] asks for one of a camera's messages (falling back to the
//! older commands); [`PhotoCapture`], one photo to its CAMERA_IMAGE_CAPTURED; [`ParamExtClient`] for the settings; [`CameraDefinition`] reads
//! a definition file (bounded, with positioned errors) and checks values against it.
//! **Server**: [`CameraServer`], a camera that asks its owner to take each photo and record,
//! and [`ParamExtServer`] for its settings.

mod capture;
mod definition;
mod discovery;
mod messages;
mod param_ext;
mod server;
mod value;

pub use capture::{CaptureConfig, CaptureError, PhotoCapture};
#[cfg(feature = "fuzzing")]
#[doc(hidden)]
pub use definition::fuzz_camera_definition;
pub use definition::{
    CameraDefinition, DefinitionError, DefinitionErrorKind, MAX_DEFINITION_LEN, MAX_OPTIONS,
    MAX_SETTINGS, OptionRange, Setting, SettingError, SettingOption,
};
pub use discovery::{CameraDiscovery, MessageFetch, legacy_request};
pub use messages::{
    CameraInfo, CaptureStatus, ImageCaptured, StorageInfo, VideoStream, firmware_version, mode_name,
};
pub use param_ext::{ParamExtClient, ParamExtConfig, ParamExtError, ParamExtEvent, ParamExtServer};
pub use server::{CameraConfig, CameraEvent, CameraServer, Photo};
pub use value::{ExtType, ExtValue, NAME_LEN, VALUE_LEN, name_field, name_of};

/// The definition file of mavstack's simulated camera (`mavstack vehicle --camera`): a
/// photo or video mode, exposure (auto, or manual with ISO and shutter speed), white
/// balance, the photo format (PGM or PPM) and the video resolution.
pub const SIMULATED_DEFINITION: &str = include_str!("simulated.xml");

/// Where a URI of `cam_definition_uri` says the file is.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DefinitionUri<'a> {
    /// Over MAVFTP from the camera itself (`mftp://PATH` or `mavlinkftp://PATH`).
    Mavftp(&'a str),
    /// Over HTTP(S) (the whole URI).
    Http(&'a str),
    /// No definition (an empty URI).
    None,
    /// A scheme the protocol does not have.
    Unknown(&'a str),
}

impl<'a> DefinitionUri<'a> {
    /// What `uri` says.
    #[must_use]
    pub fn of(uri: &'a str) -> Self {
        let uri = uri.trim();
        if uri.is_empty() {
            return Self::None;
        }
        for scheme in ["mftp://", "mavlinkftp://"] {
            if let Some(path) = uri.strip_prefix(scheme) {
                return Self::Mavftp(path);
            }
        }
        if uri.starts_with("http://") || uri.starts_with("https://") {
            return Self::Http(uri);
        }
        Self::Unknown(uri)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn definition_uris() {
        assert_eq!(
            DefinitionUri::of("mftp://camera.xml"),
            DefinitionUri::Mavftp("camera.xml")
        );
        assert_eq!(
            DefinitionUri::of("mavlinkftp:///fs/microsd/c.xml.xz"),
            DefinitionUri::Mavftp("/fs/microsd/c.xml.xz")
        );
        assert_eq!(
            DefinitionUri::of("https://x/c.xml"),
            DefinitionUri::Http("https://x/c.xml")
        );
        assert_eq!(DefinitionUri::of(""), DefinitionUri::None);
        assert_eq!(
            DefinitionUri::of("file:///c.xml"),
            DefinitionUri::Unknown("file:///c.xml")
        );
    }
}
