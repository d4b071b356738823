//! The PX4 flavour's events (libevents): PX4 v1.16 refuses to arm with COMMAND_ACK
//! TEMPORARILY_REJECTED and says why only in EVENT messages, whose texts a ground station
//! finds in the metadata PX4 serves over MAVFTP — COMPONENT_METADATA names
//! [`GENERAL_PATH`], which names [`EVENTS_PATH`], both xz-compressed JSON. The simulator
//! does the same with a catalog of its own (PX4's real texts where it says the same thing).

use mavstack_dialects::common::{ComponentMetadata, Event};
use mavstack_services::ftp::overlay::{dir_entry, file_entry};
use mavstack_services::ftp::payload::crc32;
use mavstack_services::ftp::{BackendError, DirEntry, Provider};

/// The general metadata file, as PX4 names it.
pub const GENERAL_PATH: &str = "/etc/extras/component_general.json.xz";

/// The events metadata file, as PX4 names it.
pub const EVENTS_PATH: &str = "/etc/extras/all_events.json.xz";

/// The component id of PX4's events in the metadata (the top 8 bits of an event id).
const COMPONENT: u32 = 1;

/// Sub id of "Arming denied: Resolve system health failures first".
const ARM_DENIED: u32 = 0x0070_7e01;

/// Sub id of the estimator check, with the seconds until it settles.
const ESTIMATOR_NOT_READY: u32 = 0x0070_7e02;

/// Log levels of an arming refusal: external critical (2), internal info (6).
const CRITICAL: u8 = 2 | (6 << 4);

/// Log levels of a failed check: external error (3), internal info (6).
const ERROR: u8 = 3 | (6 << 4);

const GENERAL_JSON: &str = r#"{
  "version": 1,
  "metadataTypes": [
    {"type": 4, "uri": "mftp://etc/extras/all_events.json.xz", "fileCrc": 0}
  ]
}"#;

const EVENTS_JSON: &str = r#"{
  "version": 1,
  "components": {
    "1": {
      "namespace": "px4",
      "component_id": 1,
      "event_groups": {
        "default": {
          "name": "default",
          "events": {
            "7372289": {
              "name": "commander_arm_denied_resolve_failures",
              "message": "Arming denied: Resolve system health failures first"
            }
          }
        },
        "arming_check": {
          "name": "arming_check",
          "events": {
            "7372290": {
              "name": "sim_estimator_not_ready",
              "message": "Preflight Fail: position estimate not valid yet, about {1:.0} s to go",
              "arguments": [{"type": "float", "name": "seconds"}]
            }
          }
        }
      }
    }
  }
}"#;

fn packed(json: &str) -> Vec<u8> {
    let mut out = Vec::new();
    let mut input = json.as_bytes();
    // Writing into a Vec cannot fail.
    let _ = lzma_rs::xz_compress(&mut input, &mut out);
    out
}

/// The EVENTs the vehicle sends, numbered in sequence.
#[derive(Debug, Default)]
pub struct Events {
    sequence: u16,
    pending: Vec<Event>,
}

impl Events {
    fn push(&mut self, boot_ms: u32, sub_id: u32, log_levels: u8, arguments: &[u8]) {
        let mut e = Event {
            id: (COMPONENT << 24) | sub_id,
            event_time_boot_ms: boot_ms,
            sequence: self.sequence,
            log_levels,
            ..Event::default()
        };
        let n = arguments.len().min(e.arguments.len());
        e.arguments[..n].copy_from_slice(&arguments[..n]);
        self.sequence = self.sequence.wrapping_add(1);
        self.pending.push(e);
    }

    /// Arming refused because the estimator settles in `seconds`: the failed check, then
    /// the refusal, as PX4 reports them.
    pub fn arm_refused(&mut self, boot_ms: u32, seconds: f32) {
        self.push(boot_ms, ESTIMATOR_NOT_READY, ERROR, &seconds.to_le_bytes());
        self.push(boot_ms, ARM_DENIED, CRITICAL, &[]);
    }

    /// The events to send, oldest first.
    pub fn take(&mut self) -> Vec<Event> {
        core::mem::take(&mut self.pending)
    }
}

/// COMPONENT_METADATA: where the general metadata file is.
#[must_use]
pub fn component_metadata(boot_ms: u32) -> ComponentMetadata {
    let mut m = ComponentMetadata {
        time_boot_ms: boot_ms,
        file_crc: crc32(0, &packed(GENERAL_JSON)),
        ..ComponentMetadata::default()
    };
    let uri = b"mftp://etc/extras/component_general.json.xz";
    m.uri[..uri.len()].copy_from_slice(uri);
    m
}

/// The metadata files under `/etc/extras`, for the vehicle's MAVFTP server (the PX4 flavour
/// serves them; the ArduPilot flavour's [`MetadataFiles::none`] serves nothing).
#[derive(Debug)]
pub struct MetadataFiles {
    files: Vec<(&'static str, Vec<u8>)>,
}

impl MetadataFiles {
    /// PX4's two files.
    #[must_use]
    pub fn px4() -> Self {
        Self {
            files: vec![
                (GENERAL_PATH, packed(GENERAL_JSON)),
                (EVENTS_PATH, packed(EVENTS_JSON)),
            ],
        }
    }

    /// No files.
    #[must_use]
    pub const fn none() -> Self {
        Self { files: Vec::new() }
    }

    fn file(&self, path: &str) -> Option<&[u8]> {
        let path = path.strip_prefix('/').unwrap_or(path);
        self.files
            .iter()
            .find(|(p, _)| p.trim_start_matches('/') == path)
            .map(|(_, data)| data.as_slice())
    }
}

impl Provider for MetadataFiles {
    fn provides(&self, path: &str) -> bool {
        self.file(path).is_some()
    }

    fn contents(&mut self, path: &str) -> Result<Vec<u8>, BackendError> {
        self.file(path)
            .map(<[u8]>::to_vec)
            .ok_or(BackendError::NotFound)
    }

    fn entries(&mut self, dir: &str) -> Vec<DirEntry> {
        if self.files.is_empty() {
            return Vec::new();
        }
        match dir.trim_matches('/') {
            "" => vec![dir_entry("etc")],
            "etc" => vec![dir_entry("extras")],
            "etc/extras" => self
                .files
                .iter()
                .map(|(p, data)| file_entry(p.rsplit('/').next().unwrap_or(p), data.len()))
                .collect(),
            _ => Vec::new(),
        }
    }
}
