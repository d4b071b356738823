//! The camera protocol's messages as plain values (units, text, `None` for "unknown"), both
//! ways: read from what a camera sends, and made into what a camera sends.

use alloc::format;
use alloc::string::String;

use mavstack_dialects::common::{
    CameraCapFlags, CameraCaptureStatus, CameraImageCaptured, CameraInformation, CameraMode,
    StorageInformation, StorageStatus, StorageType, StorageUsageFlag, VideoStreamEncoding,
    VideoStreamInformation, VideoStreamStatusFlags, VideoStreamType,
};
use mavstack_dialects::standard::MavBool;

use crate::Address;
use crate::gimbal::Euler;

/// A NUL-terminated text field as a string (invalid UTF-8 replaced).
fn text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// `s` in a NUL-padded field of `N` bytes (cut at a character boundary, leaving room for
/// the NUL where the field is a C string).
fn field<const N: usize>(s: &str, nul: bool) -> [u8; N] {
    let mut out = [0u8; N];
    let room = if nul { N - 1 } else { N };
    let mut end = s.len().min(room);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    out[..end].copy_from_slice(&s.as_bytes()[..end]);
    out
}

fn known(v: f32) -> Option<f32> {
    v.is_finite().then_some(v)
}

/// A firmware version as CAMERA_INFORMATION encodes it: `major.minor.patch.dev` in the
/// low to high bytes.
#[must_use]
pub fn firmware_version(encoded: u32) -> String {
    let [major, minor, patch, dev] = encoded.to_le_bytes();
    format!("{major}.{minor}.{patch}.{dev}")
}

/// A camera, as its CAMERA_INFORMATION describes it.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfo {
    /// The camera's address (its own component).
    pub component: Address,
    /// Its vendor.
    pub vendor: String,
    /// Its model.
    pub model: String,
    /// Its firmware version (`major.minor.patch.dev`), when given.
    pub firmware: Option<String>,
    /// Focal length, mm.
    pub focal_length_mm: Option<f32>,
    /// Sensor size, mm (horizontal, vertical).
    pub sensor_mm: Option<(f32, f32)>,
    /// Image resolution, pixels (horizontal, vertical).
    pub resolution: Option<(u16, u16)>,
    /// CAMERA_CAP_FLAGS.
    pub flags: CameraCapFlags,
    /// Where its definition file is (empty: none).
    pub definition_uri: String,
    /// The definition file's version.
    pub definition_version: u16,
    /// The component of the gimbal it is on (0: none).
    pub gimbal_device_id: u8,
}

impl CameraInfo {
    /// The camera at `component` as `info` describes it.
    #[must_use]
    pub fn from_information(component: Address, info: &CameraInformation) -> Self {
        let sensor = known(info.sensor_size_h).zip(known(info.sensor_size_v));
        let resolution = (info.resolution_h != 0 && info.resolution_v != 0)
            .then_some((info.resolution_h, info.resolution_v));
        Self {
            component,
            vendor: text(&info.vendor_name),
            model: text(&info.model_name),
            firmware: (info.firmware_version != 0).then(|| firmware_version(info.firmware_version)),
            focal_length_mm: known(info.focal_length),
            sensor_mm: sensor,
            resolution,
            flags: info.flags,
            definition_uri: text(&info.cam_definition_uri),
            definition_version: info.cam_definition_version,
            gimbal_device_id: info.gimbal_device_id,
        }
    }

    /// As CAMERA_INFORMATION, at `time_boot_ms` (a firmware version that is not four
    /// numbers up to 255 is sent as 0, unknown).
    #[must_use]
    pub fn to_information(&self, time_boot_ms: u32) -> CameraInformation {
        let firmware = self.firmware.as_deref().map_or(0, |f| {
            let parts: alloc::vec::Vec<u8> = f.split('.').filter_map(|p| p.parse().ok()).collect();
            if parts.len() == f.split('.').count() && parts.len() <= 4 {
                let mut b = [0u8; 4];
                b[..parts.len()].copy_from_slice(&parts);
                u32::from_le_bytes(b)
            } else {
                0
            }
        });
        let (h, v) = self.resolution.unwrap_or((0, 0));
        let (sh, sv) = self.sensor_mm.unwrap_or((f32::NAN, f32::NAN));
        CameraInformation {
            time_boot_ms,
            vendor_name: field(&self.vendor, false),
            model_name: field(&self.model, false),
            firmware_version: firmware,
            focal_length: self.focal_length_mm.unwrap_or(f32::NAN),
            sensor_size_h: sh,
            sensor_size_v: sv,
            resolution_h: h,
            resolution_v: v,
            lens_id: 0,
            flags: self.flags,
            cam_definition_version: self.definition_version,
            cam_definition_uri: field(&self.definition_uri, true),
            gimbal_device_id: self.gimbal_device_id,
            camera_device_id: 0,
        }
    }
}

/// What a camera is doing (CAMERA_CAPTURE_STATUS).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CaptureStatus {
    /// A photo is being taken.
    pub photo_busy: bool,
    /// Photos are being taken at an interval.
    pub interval_on: bool,
    /// The interval, seconds.
    pub interval_s: f32,
    /// Video is being recorded.
    pub video_on: bool,
    /// For how long, seconds (0 when not known).
    pub recording_s: f32,
    /// Free storage, MiB.
    pub available_mib: f32,
    /// Photos taken so far: the next photo's index.
    pub image_count: i32,
}

impl CaptureStatus {
    /// As CAMERA_CAPTURE_STATUS says.
    #[must_use]
    pub fn from_message(m: &CameraCaptureStatus) -> Self {
        Self {
            photo_busy: m.image_status & 1 != 0,
            interval_on: m.image_status >= 2,
            interval_s: m.image_interval,
            video_on: m.video_status == 1,
            recording_s: m.recording_time_ms as f32 / 1000.0,
            available_mib: m.available_capacity,
            image_count: m.image_count,
        }
    }

    /// As CAMERA_CAPTURE_STATUS, at `time_boot_ms`.
    #[must_use]
    pub fn to_message(&self, time_boot_ms: u32) -> CameraCaptureStatus {
        CameraCaptureStatus {
            time_boot_ms,
            image_status: u8::from(self.photo_busy) | (u8::from(self.interval_on) << 1),
            video_status: u8::from(self.video_on),
            image_interval: self.interval_s,
            recording_time_ms: (self.recording_s * 1000.0) as u32,
            available_capacity: self.available_mib,
            image_count: self.image_count,
            camera_device_id: 0,
        }
    }
}

/// A camera's storage (STORAGE_INFORMATION).
#[derive(Clone, Debug, PartialEq)]
pub struct StorageInfo {
    /// Its id (1 for the first).
    pub id: u8,
    /// How many the camera has.
    pub count: u8,
    /// STORAGE_STATUS.
    pub status: StorageStatus,
    /// MiB in all.
    pub total_mib: f32,
    /// MiB used.
    pub used_mib: f32,
    /// MiB free.
    pub available_mib: f32,
    /// STORAGE_TYPE.
    pub kind: StorageType,
    /// Its name for people.
    pub name: String,
}

impl StorageInfo {
    /// As STORAGE_INFORMATION says.
    #[must_use]
    pub fn from_message(m: &StorageInformation) -> Self {
        Self {
            id: m.storage_id,
            count: m.storage_count,
            status: m.status,
            total_mib: m.total_capacity,
            used_mib: m.used_capacity,
            available_mib: m.available_capacity,
            kind: m.r#type,
            name: text(&m.name),
        }
    }

    /// As STORAGE_INFORMATION, at `time_boot_ms`.
    #[must_use]
    pub fn to_message(&self, time_boot_ms: u32) -> StorageInformation {
        StorageInformation {
            time_boot_ms,
            storage_id: self.id,
            storage_count: self.count,
            status: self.status,
            total_capacity: self.total_mib,
            used_capacity: self.used_mib,
            available_capacity: self.available_mib,
            read_speed: f32::NAN,
            write_speed: f32::NAN,
            r#type: self.kind,
            name: field(&self.name, true),
            storage_usage: StorageUsageFlag::SET,
        }
    }
}

/// One photo (CAMERA_IMAGE_CAPTURED).
#[derive(Clone, Debug, PartialEq)]
pub struct ImageCaptured {
    /// Its index (0 for the camera's first).
    pub index: i32,
    /// When, µs since the UNIX epoch (0: not known).
    pub time_utc_us: u64,
    /// Where: latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Altitude above mean sea level, m.
    pub alt_m: f32,
    /// Height above ground (or home), m.
    pub relative_alt_m: f32,
    /// The camera's attitude, a quaternion (w, x, y, z).
    pub q: [f32; 4],
    /// Where the file is.
    pub file_url: String,
    /// Whether the photo was taken.
    pub success: bool,
}

impl ImageCaptured {
    /// As CAMERA_IMAGE_CAPTURED says.
    #[must_use]
    pub fn from_message(m: &CameraImageCaptured) -> Self {
        Self {
            index: m.image_index,
            time_utc_us: m.time_utc,
            lat: f64::from(m.lat) / 1e7,
            lon: f64::from(m.lon) / 1e7,
            alt_m: m.alt as f32 / 1000.0,
            relative_alt_m: m.relative_alt as f32 / 1000.0,
            q: m.q,
            file_url: text(&m.file_url),
            success: m.capture_result == MavBool::TRUE,
        }
    }

    /// The camera's attitude as angles, when its quaternion is a rotation.
    #[must_use]
    pub fn attitude(&self) -> Option<Euler> {
        crate::gimbal::euler_from_quaternion(self.q)
    }

    /// As CAMERA_IMAGE_CAPTURED, at `time_boot_ms` (a file URL over 204 bytes is cut).
    #[must_use]
    pub fn to_message(&self, time_boot_ms: u32) -> CameraImageCaptured {
        let deg_e7 = |d: f64| {
            if d.is_finite() {
                (d * 1e7).clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
            } else {
                0
            }
        };
        let mm = |m: f32| {
            if m.is_finite() {
                (m * 1000.0).clamp(i32::MIN as f32, i32::MAX as f32) as i32
            } else {
                0
            }
        };
        CameraImageCaptured {
            time_boot_ms,
            time_utc: self.time_utc_us,
            camera_id: 0,
            lat: deg_e7(self.lat),
            lon: deg_e7(self.lon),
            alt: mm(self.alt_m),
            relative_alt: mm(self.relative_alt_m),
            q: self.q,
            image_index: self.index,
            capture_result: if self.success {
                MavBool::TRUE
            } else {
                MavBool::FALSE
            },
            file_url: field(&self.file_url, true),
        }
    }
}

/// A video stream (VIDEO_STREAM_INFORMATION).
#[derive(Clone, Debug, PartialEq)]
pub struct VideoStream {
    /// Its id (1 for the first).
    pub id: u8,
    /// How many the camera has.
    pub count: u8,
    /// VIDEO_STREAM_TYPE (RTSP, RTPUDP, ...).
    pub kind: VideoStreamType,
    /// VIDEO_STREAM_STATUS_FLAGS (running, thermal).
    pub flags: VideoStreamStatusFlags,
    /// Frames per second.
    pub framerate: f32,
    /// Resolution, pixels.
    pub resolution: (u16, u16),
    /// Bits per second.
    pub bitrate: u32,
    /// Horizontal field of view, degrees.
    pub hfov_deg: u16,
    /// Its name.
    pub name: String,
    /// Where to get it (an RTSP URI, or a UDP port).
    pub uri: String,
    /// VIDEO_STREAM_ENCODING.
    pub encoding: VideoStreamEncoding,
}

impl VideoStream {
    /// As VIDEO_STREAM_INFORMATION says.
    #[must_use]
    pub fn from_message(m: &VideoStreamInformation) -> Self {
        Self {
            id: m.stream_id,
            count: m.count,
            kind: m.r#type,
            flags: m.flags,
            framerate: m.framerate,
            resolution: (m.resolution_h, m.resolution_v),
            bitrate: m.bitrate,
            hfov_deg: m.hfov,
            name: text(&m.name),
            uri: text(&m.uri),
            encoding: m.encoding,
        }
    }

    /// As VIDEO_STREAM_INFORMATION.
    #[must_use]
    pub fn to_message(&self) -> VideoStreamInformation {
        VideoStreamInformation {
            stream_id: self.id,
            count: self.count,
            r#type: self.kind,
            flags: self.flags,
            framerate: self.framerate,
            resolution_h: self.resolution.0,
            resolution_v: self.resolution.1,
            bitrate: self.bitrate,
            rotation: 0,
            hfov: self.hfov_deg,
            name: field(&self.name, true),
            uri: field(&self.uri, true),
            encoding: self.encoding,
            camera_device_id: 0,
        }
    }
}

/// The mode CAMERA_SETTINGS reports, by name: `photo`, `video`, `survey` or the number.
#[must_use]
pub fn mode_name(mode: CameraMode) -> String {
    match mode {
        CameraMode::IMAGE => String::from("photo"),
        CameraMode::VIDEO => String::from("video"),
        CameraMode::IMAGE_SURVEY => String::from("survey"),
        m => format!("{}", m.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn information_both_ways() {
        let info = CameraInfo {
            component: Address::new(1, 100),
            vendor: "mavstack".into(),
            model: "Simulated camera".into(),
            firmware: Some("1.2.3.0".into()),
            focal_length_mm: Some(4.5),
            sensor_mm: None,
            resolution: Some((640, 480)),
            flags: CameraCapFlags::CAPTURE_IMAGE,
            definition_uri: "mftp://camera.xml".into(),
            definition_version: 1,
            gimbal_device_id: 0,
        };
        let m = info.to_information(5);
        assert_eq!(m.firmware_version, 0x0003_0201);
        assert_eq!(CameraInfo::from_information(Address::new(1, 100), &m), info);
        // A URI of 140 bytes keeps its NUL.
        let long = CameraInfo {
            definition_uri: "x".repeat(200),
            ..info
        };
        let m = long.to_information(0);
        assert_eq!(m.cam_definition_uri[139], 0);
        assert_eq!(firmware_version(0x0403_0201), "1.2.3.4");
    }

    #[test]
    fn capture_status_and_images() {
        let s = CaptureStatus {
            photo_busy: false,
            interval_on: true,
            interval_s: 2.0,
            video_on: true,
            recording_s: 1.5,
            available_mib: 100.0,
            image_count: 7,
        };
        let m = s.to_message(0);
        assert_eq!((m.image_status, m.video_status), (2, 1));
        assert_eq!(CaptureStatus::from_message(&m), s);
        let image = ImageCaptured {
            index: 3,
            time_utc_us: 1_700_000_000_000_000,
            lat: 47.3977419,
            lon: 8.5455938,
            alt_m: 488.0,
            relative_alt_m: 10.0,
            q: [1.0, 0.0, 0.0, 0.0],
            file_url: "file:///tmp/IMG_0003.pgm".into(),
            success: true,
        };
        let back = ImageCaptured::from_message(&image.to_message(0));
        assert_eq!(back.index, 3);
        assert_eq!(back.file_url, image.file_url);
        assert!((back.lat - image.lat).abs() < 1e-7 && back.success);
        assert_eq!(mode_name(CameraMode::VIDEO), "video");
    }
}
