//! MAVSDK (the real SDK from PyPI: the native binding `mavsdk` 4.1.0) against mavstack's
//! camera and gimbal protocols, both ways: `tests-interop/mavsdk_payload.py`, run with the
//! Python that `scripts/setup-peers.sh` prepares (`$MAVSTACK_PYTHON`, else
//! `.venv/bin/python`), against this mavstack binary.
//!
//! - MAVSDK's Camera plugin against `mavstack vehicle --autopilot px4 --camera DIR`: the
//!   camera listed, its definition fetched over MAVFTP, two photos taken (index 0 and 1,
//!   each written into DIR as the file MAVSDK's capture_info names, the second a PPM after
//!   MAVSDK set CAM_PHOTOFMT), the settings as the definition has them (exclusions
//!   followed after CAM_EXPMODE is set), the mode switched and read back, the storage;
//! - MAVSDK's Gimbal plugin against the same vehicle's gimbal manager: control taken (the
//!   status names MAVSDK), angles in the vehicle and the earth frame, a region of interest
//!   and a yaw rate, each read back from MAVSDK's attitude stream, control released;
//! - `mavstack camera ... --json` against MAVSDK's CameraServer plugin: the camera listed
//!   with MAVSDK's information, two photos with the indices and URLs MAVSDK's handler
//!   answered, video started and stopped and the mode switched through its handlers.
//!
//! Never skipped: without mavsdk 4.1.0 the test fails.

use crate::support;

use std::ffi::OsStr;
use std::process::Command;
use std::sync::OnceLock;

use support::{python, run_script, text};

/// The MAVSDK release the script drives (scripts/setup-peers.sh installs it).
const MAVSDK: &str = "4.1.0";

/// Fails (never skips) unless the Python has the pinned mavsdk; checked once.
fn require_mavsdk() {
    static CHECKED: OnceLock<Result<(), String>> = OnceLock::new();
    let checked = CHECKED.get_or_init(|| {
        let probe = "from importlib.metadata import version; import mavsdk; \
                     print(version('mavsdk'))";
        let py = python();
        let out = Command::new(&py)
            .args(["-c", probe])
            .output()
            .map_err(|e| format!("cannot run python {}: {e}", py.display()))?;
        if !out.status.success() {
            return Err(format!(
                "python {} has no mavsdk: {}",
                py.display(),
                text(&out.stderr).trim()
            ));
        }
        let have = text(&out.stdout).trim().to_owned();
        if have != MAVSDK {
            return Err(format!(
                "python {} has mavsdk {have}, want {MAVSDK}",
                py.display()
            ));
        }
        Ok(())
    });
    if let Err(e) = checked {
        panic!("the payload interop needs MAVSDK (run scripts/setup-peers.sh): {e}");
    }
}

#[test]
fn mavsdk_camera_gimbal_and_camera_server_against_mavstack() {
    require_mavsdk();
    let bin = env!("CARGO_BIN_EXE_mavstack");
    let out = run_script(
        "mavsdk_payload.py",
        &[OsStr::new("--mavstack"), OsStr::new(bin)],
    );
    let last = out.lines().last().unwrap_or_default();
    let summary: serde_json::Value = serde_json::from_str(last)
        .unwrap_or_else(|e| panic!("mavsdk_payload.py: no JSON summary ({e}):\n{out}"));
    assert_eq!(summary["ok"], true, "{out}");
    // Each side's result as the other side reported it.
    let photos = &summary["camera"]["photos"];
    assert_eq!(photos[0]["index"], 0, "{last}");
    assert!(
        photos[1]["file_url"]
            .as_str()
            .is_some_and(|u| u.ends_with("/IMG_0001.ppm")),
        "{last}"
    );
    let roi = &summary["gimbal"]["roi"];
    let (pitch, yaw) = (roi[0].as_f64(), roi[1].as_f64());
    assert!(
        pitch.is_some_and(|p| (p + 45.0).abs() <= 2.0)
            && yaw.is_some_and(|y| (y - 90.0).abs() <= 2.0),
        "{last}"
    );
    let served = &summary["camera_server"]["photos"];
    assert_eq!(served[0]["index"], 7, "{last}");
    assert_eq!(
        served[1]["file_url"], "https://camera.invalid/photos/DSC00008.jpg",
        "{last}"
    );
    println!("{last}");
}
