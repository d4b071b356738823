//! `mavstack gimbal` and `mavstack camera` against `mavstack vehicle --camera DIR` on
//! loopback: the simulated gimbal listed, set and read back (text and JSON), an angle
//! outside its limits refused with exit 2 and nothing moved; the camera listed, a photo
//! written into DIR and announced, video, an interval, settings listed and set, one the
//! definition rules out refused with exit 2. Against MAVSDK: `interop_payload.rs`.

use crate::vehicle;

use std::process::{Command, Output};

use vehicle::Vehicle;

fn mavstack(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mavstack"))
        .args(args)
        .output()
        .expect("mavstack runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn at(port: u16) -> String {
    format!("udpout:127.0.0.1:{port}")
}

#[test]
fn gimbal_list_set_and_limits() {
    let v = Vehicle::start(&["--autopilot", "ardupilot"]);
    let conn = at(v.port);
    let out = mavstack(&["gimbal", &conn, "list"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(
        text(&out.stdout),
        "gimbal 1: manager 1/1, device 1, pitch -90..30°, yaw -180..180°, mavstack simulated gimbal\n"
    );
    let out = mavstack(&["gimbal", &conn, "list", "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(j["manager"]["component"], 1);
    assert_eq!(j["pitch"], serde_json::json!([-90.0, 30.0]));

    let out = mavstack(&[
        "gimbal", &conn, "set", "-30", "45", "--json", "--wait", "20",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert!((j["pitch"].as_f64().unwrap() + 30.0).abs() <= 2.0, "{j}");
    assert!(
        (j["yaw_vehicle"].as_f64().unwrap() - 45.0).abs() <= 2.0,
        "{j}"
    );
    assert_eq!(j["frame"], "vehicle");

    // Beyond its pitch limit: nothing sent, exit 2, the gimbal where it was.
    let out = mavstack(&["gimbal", &conn, "set", "60", "0"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains("pitch 60° is outside the gimbal's limits (-90° to 30°)"),
        "{err}"
    );
    let out = mavstack(&["gimbal", &conn, "attitude"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let line = text(&out.stdout);
    assert!(
        line.starts_with("gimbal 1: roll 0.0° pitch -30.0° yaw 45.0° (vehicle frame)"),
        "{line}"
    );

    let out = mavstack(&[
        "gimbal", &conn, "point", "-35.3623", "149.1652", "584", "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(text(&out.stdout).contains("\"result\":\"ACCEPTED\""));
    let out = mavstack(&["gimbal", &conn, "point", "95", "0", "0"]);
    assert_eq!(out.status.code(), Some(2));
    let out = mavstack(&["gimbal", &conn, "--gimbal", "2", "attitude"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("has 1 gimbal(s): no gimbal 2"));
}

#[test]
fn camera_photo_video_interval_and_settings() {
    let dir = tempfile::tempdir().expect("a directory");
    let path = dir.path().to_str().expect("a path");
    let v = Vehicle::start(&["--autopilot", "px4", "--camera", path]);
    let conn = at(v.port);
    let out = mavstack(&["camera", &conn, "list"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let line = text(&out.stdout);
    assert!(
        line.starts_with("camera 1: 1/100 mavstack Simulated camera, 320x240, definition mftp://camera.xml v1, 0 photos"),
        "{line}"
    );

    let out = mavstack(&["camera", &conn, "photo", "--json"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(j["index"], 0);
    assert_eq!(j["success"], true);
    let file = dir.path().join("IMG_0000.pgm");
    assert!(file.exists());
    assert_eq!(j["file_url"], format!("file://{}", file.display()));
    let out = mavstack(&["camera", &conn, "photo"]);
    assert!(
        text(&out.stdout).starts_with("camera 1: photo 1 file://"),
        "{}",
        text(&out.stdout)
    );

    for action in ["start", "stop"] {
        let out = mavstack(&["camera", &conn, "video", action]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        assert_eq!(
            text(&out.stdout),
            format!("camera 1: video {action} accepted\n")
        );
    }
    let out = mavstack(&["camera", &conn, "interval", "start", "0.2", "--count", "2"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let deadline = std::time::Instant::now() + core::time::Duration::from_secs(30);
    while !dir.path().join("IMG_0003.pgm").exists() {
        assert!(
            std::time::Instant::now() < deadline,
            "the interval's photos"
        );
        std::thread::sleep(core::time::Duration::from_millis(50));
    }
    let out = mavstack(&["camera", &conn, "interval", "start"]);
    assert_eq!(out.status.code(), Some(2));

    let out = mavstack(&["camera", &conn, "settings"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let listing = text(&out.stdout);
    assert_eq!(listing.lines().count(), 8, "{listing}");
    assert!(
        listing
            .lines()
            .any(|l| l.starts_with("CAM_ISO") && l.ends_with("[does not apply now]")),
        "{listing}"
    );
    // ISO under automatic exposure: refused before anything is sent.
    let out = mavstack(&["camera", &conn, "settings", "--set", "CAM_ISO=400"]);
    assert_eq!(out.status.code(), Some(2), "{}", text(&out.stderr));
    assert!(text(&out.stderr).contains("CAM_ISO does not apply while CAM_EXPMODE is Auto"));
    let out = mavstack(&[
        "camera",
        &conn,
        "settings",
        "--json",
        "--set",
        "CAM_EXPMODE=manual",
        "--set",
        "CAM_ISO=400",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let iso = text(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).expect("JSON"))
        .find(|j| j["name"] == "CAM_ISO")
        .expect("ISO");
    assert_eq!(iso["value"], 400);
    assert_eq!(iso["excluded"], false);
}

#[test]
fn no_camera_and_bad_arguments() {
    let v = Vehicle::start(&["--autopilot", "px4"]);
    let out = mavstack(&["camera", &at(v.port), "photo"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("system 1 has no camera"),
        "{}",
        text(&out.stderr)
    );
    let out = mavstack(&["vehicle", "udpin:127.0.0.1:0", "--camera", "/no/such/dir"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(text(&out.stderr).contains("--camera /no/such/dir: not a directory"));
}
