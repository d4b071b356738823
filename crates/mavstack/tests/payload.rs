//! Gimbals and cameras through the library (`System::gimbals`, `System::cameras`) against
//! the in-process simulated vehicle over loopback UDP: its gimbal (a manager in the
//! autopilot's component) found, controlled, pointed by angles, rates and at a location,
//! its attitude read back; an angle outside its limits refused before anything is sent. Its
//! camera (`SimCamera`, a component of its own joined to the vehicle's node) found, its
//! definition fetched over MAVFTP, photos written into a directory and announced, settings
//! read and written with what the definition rules out refused, video and intervals.
#![cfg(feature = "sim")]

use core::time::Duration;

use mavstack::dialects::common::{CameraMode, StorageStatus};
use mavstack::serve;
use mavstack::services::Address;
use mavstack::services::camera::{ExtValue, SettingError};
use mavstack::services::gimbal::{GimbalError, YawFrame};
use mavstack::sim::{Autopilot, params};
use mavstack::sim_camera::SimCamera;
use mavstack::sim_vehicle::SimVehicle;
use mavstack::system::{System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};
use tokio::sync::mpsc;

const DEADLINE: Duration = Duration::from_secs(60);

fn none(_: &str) -> Option<u32> {
    None
}

struct Rig {
    vehicle: SimVehicle,
    camera: SimCamera,
    gcs: Node,
    system: System,
    lines: mpsc::UnboundedReceiver<String>,
    dir: tempfile::TempDir,
}

/// A simulated vehicle with a camera beside it, saying what they do; a ground station; the
/// vehicle found.
async fn rig(autopilot: Autopilot) -> Rig {
    let (tx, lines) = mpsc::unbounded_channel();
    let dir = tempfile::tempdir().expect("a directory");
    let (to_camera, to_vehicle) = serve::joined("vehicle", "camera");
    let vehicle = SimVehicle::start_logged(
        Node::builder()
            .link(LinkSpec::parse("udpin:127.0.0.1:0", &none).expect("spec"))
            .opened_link(to_camera.0, to_camera.1),
        SimVehicle::config(autopilot, params::defaults(autopilot)),
        Some(tx.clone()),
    )
    .await
    .expect("vehicle starts");
    let camera = SimCamera::start(to_vehicle, Address::new(1, 100), dir.path(), Some(tx))
        .await
        .expect("camera starts");
    let port = vehicle.node().local_addrs()[0].expect("bound").port();
    let gcs = Node::ground_station(255, 190)
        .link(LinkSpec::parse(&format!("udpout:127.0.0.1:{port}"), &none).expect("spec"))
        .start()
        .await
        .expect("ground station starts");
    let system = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(10))
        .await
        .expect("the vehicle is found");
    Rig {
        vehicle,
        camera,
        gcs,
        system,
        lines,
        dir,
    }
}

impl Rig {
    async fn close(self) {
        drop(self.system);
        self.gcs.shutdown().await.expect("gcs");
        self.camera.shutdown().await.expect("camera");
        self.vehicle.shutdown().await.expect("vehicle");
    }

    /// The next line starting with `prefix` (without it).
    async fn line(&mut self, prefix: &str) -> String {
        loop {
            let line = tokio::time::timeout(DEADLINE, self.lines.recv())
                .await
                .expect("a line in time")
                .expect("the vehicle runs");
            // Shown when a test fails.
            eprintln!("{line}");
            if let Some(rest) = line.strip_prefix(prefix) {
                return rest.to_owned();
            }
        }
    }
}

fn close_to(a: f32, b: f32) -> bool {
    (a - b).abs() < 1.0
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_simulated_gimbal() {
    let mut rig = rig(Autopilot::Ardupilot).await;
    let gimbals = rig.system.gimbals().list().await.expect("list");
    assert_eq!(gimbals.len(), 1);
    let g = &gimbals[0];
    assert_eq!(
        (g.info().manager, g.info().device_id),
        (Address::new(1, 1), 1)
    );
    assert_eq!(g.info().model, "simulated gimbal");
    let pitch = g.info().pitch.expect("pitch limits");
    assert_eq!((pitch.min.round(), pitch.max.round()), (-90.0, 30.0));

    g.take_control(false).await.expect("control");
    let control = g.control(DEADLINE).await.expect("status");
    assert_eq!(control.primary, Some(rig.system.own()));

    // Out of its limits: refused here, nothing sent.
    let refused = g
        .set_angles(45.0, 0.0, YawFrame::Vehicle)
        .await
        .unwrap_err();
    assert!(
        matches!(
            refused,
            SystemError::Gimbal(GimbalError::OutOfLimits { what: "pitch", .. })
        ),
        "{refused}"
    );
    assert!(matches!(
        g.set_angles(f32::NAN, 0.0, YawFrame::Vehicle).await,
        Err(SystemError::Gimbal(GimbalError::NotANumber { .. }))
    ));
    g.set_angles(-30.0, 45.0, YawFrame::Vehicle)
        .await
        .expect("angles");
    // The first request the vehicle heard is this one.
    let said = rig.line("vehicle: gimbal: pitch ").await;
    assert!(said.starts_with("-30.0° yaw 45.0° (vehicle)"), "{said}");
    let end = tokio::time::Instant::now() + DEADLINE;
    loop {
        let a = g.attitude(DEADLINE).await.expect("attitude");
        if close_to(a.euler.pitch_deg, -30.0) && close_to(a.yaw_vehicle_deg.unwrap_or(0.0), 45.0) {
            assert_eq!(a.frame, YawFrame::Vehicle);
            // The vehicle's heading gives the yaw from north too.
            assert!(a.yaw_earth_deg.is_some());
            break;
        }
        assert!(tokio::time::Instant::now() < end, "never got there: {a:?}");
    }

    // At a point 100 m north of home, on the ground: from the ground, level and ahead.
    let home = rig.system.telemetry().home(DEADLINE).await.expect("home");
    let lat = f64::from(home.latitude) / 1e7 + 100.0 / 111_319.49;
    let lon = f64::from(home.longitude) / 1e7;
    g.point_at(lat, lon, home.altitude as f32 / 1000.0)
        .await
        .expect("roi");
    let said = rig.line("vehicle: gimbal: pointing at ").await;
    assert!(said.ends_with(" m"), "{said}");
    let end = tokio::time::Instant::now() + DEADLINE;
    loop {
        let a = g.attitude(DEADLINE).await.expect("attitude");
        if close_to(a.euler.pitch_deg, 0.0) && close_to(a.yaw_earth_deg.unwrap_or(99.0), 0.0) {
            break;
        }
        assert!(tokio::time::Instant::now() < end, "never got there: {a:?}");
    }
    g.clear_roi().await.expect("roi none");
    rig.line("vehicle: gimbal: pointing at a location ended")
        .await;
    let said = rig.line("vehicle: gimbal: pitch ").await;
    assert!(
        said.starts_with("0.0° yaw 0.0° (vehicle)"),
        "back to neutral: {said}"
    );
    g.set_rates(10.0, 0.0, YawFrame::Vehicle)
        .await
        .expect("rates");
    let said = rig.line("vehicle: gimbal: pitch ").await;
    assert!(said.contains("rates 10.0°/s 0.0°/s"), "{said}");
    g.release_control().await.expect("release");
    assert_eq!(g.control(DEADLINE).await.expect("status").primary, None);
    rig.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_simulated_camera() {
    let mut rig = rig(Autopilot::Px4).await;
    let cameras = rig.system.cameras().list().await.expect("list");
    assert_eq!(
        cameras.len(),
        1,
        "{cameras:?} among {:?}",
        rig.system.components()
    );
    let cam = &cameras[0];
    assert_eq!(cam.info().component, Address::new(1, 100));
    assert_eq!(cam.info().model, "Simulated camera");
    assert_eq!(cam.info().definition_uri, "mftp://camera.xml");

    let first = cam.take_photo().await.expect("photo");
    assert_eq!(first.index, 0);
    assert!(first.success);
    let path = rig.dir.path().join("IMG_0000.pgm");
    assert!(
        first.file_url.ends_with("/IMG_0000.pgm"),
        "{}",
        first.file_url
    );
    let bytes = std::fs::read(&path).expect("the photo is a file");
    assert!(bytes.starts_with(b"P5\n"));
    // Where the vehicle is.
    let home = rig.system.telemetry().home(DEADLINE).await.expect("home");
    assert!(
        (first.lat - f64::from(home.latitude) / 1e7).abs() < 1e-4,
        "{first:?}"
    );
    let second = cam.take_photo().await.expect("photo");
    assert_eq!(second.index, 1);
    assert_eq!(cam.capture_status().await.expect("status").image_count, 2);

    let storage = cam.storage().await.expect("storage");
    assert_eq!(storage.len(), 1);
    assert_eq!(storage[0].status, StorageStatus::READY);
    assert!(storage[0].used_mib > 0.0);

    let definition = cam
        .definition()
        .await
        .expect("fetched")
        .expect("it has one");
    assert_eq!(definition.settings.len(), 8);
    let settings = cam.settings().await.expect("settings");
    let iso = settings.iter().find(|s| s.name == "CAM_ISO").expect("ISO");
    assert!(iso.excluded, "automatic exposure rules ISO out");
    let wb = settings
        .iter()
        .find(|s| s.name == "CAM_WBMODE")
        .expect("WB");
    assert_eq!(wb.option.as_deref(), Some("Auto"));
    // Ruled out by the definition: not sent.
    let refused = cam.set("CAM_ISO", "400").await.unwrap_err();
    assert!(
        matches!(
            refused,
            SystemError::CameraSetting(SettingError::Excluded { .. })
        ),
        "{refused}"
    );
    assert!(matches!(
        cam.set("CAM_EV", "9").await,
        Err(SystemError::CameraSetting(SettingError::OutOfRange { .. }))
    ));
    assert_eq!(
        cam.set("CAM_WBMODE", "cloudy").await.expect("set"),
        ExtValue::U32(2)
    );
    assert_eq!(
        rig.line("camera: CAM_WBMODE = ").await,
        "2 (set by 255/190)"
    );
    cam.set("CAM_EXPMODE", "Manual").await.expect("manual");
    assert_eq!(
        cam.set("CAM_ISO", "400").await.expect("iso"),
        ExtValue::U32(400)
    );
    // A colour photo now.
    cam.set("CAM_PHOTOFMT", "PPM").await.expect("format");
    assert_eq!(cam.take_photo().await.expect("photo").index, 2);
    assert!(rig.dir.path().join("IMG_0002.ppm").exists());

    cam.start_video().await.expect("video");
    rig.line("camera: recording").await;
    assert!(cam.capture_status().await.expect("status").video_on);
    cam.stop_video().await.expect("stop");
    cam.set_mode(CameraMode::VIDEO).await.expect("mode");
    assert_eq!(cam.mode().await.expect("mode"), CameraMode::VIDEO);
    cam.set_mode(CameraMode::IMAGE).await.expect("mode");

    cam.start_photo_interval(0.2, 2).await.expect("interval");
    assert!(
        rig.line("camera: photo 4 → ")
            .await
            .ends_with("IMG_0004.ppm")
    );
    assert!(rig.dir.path().join("IMG_0003.ppm").exists());
    assert!(matches!(
        cam.start_photo_interval(0.0, 1).await,
        Err(SystemError::Invalid(_))
    ));
    rig.close().await;
}
