//! The camera protocol in both roles through the simulated link: a ground station's photo
//! (its announcement lost and asked for again, by REQUEST_MESSAGE or the older command),
//! settings with PARAM_EXT_* against a camera definition, requests for the camera's
//! messages, video and photo intervals.

mod util;

use core::time::Duration;

use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CameraCapFlags, CameraMode, CommandLong, MavCmd, MavMessage, StorageStatus, StorageType,
};
use mavstack_services::camera::{
    CameraConfig, CameraDefinition, CameraEvent, CameraInfo, CameraServer, CaptureConfig,
    CaptureError, ExtValue, ParamExtClient, ParamExtConfig, ParamExtError, ParamExtEvent,
    PhotoCapture, SIMULATED_DEFINITION, StorageInfo,
};
use mavstack_services::command::{CommandClient, CommandEvent};
use mavstack_services::{Address, Outgoing, Service};
use util::{Knobs, Pair, T0};

const GCS: Address = Address::new(255, 190);
const CAMERA: Address = Address::new(1, 100);

fn config() -> CameraConfig {
    CameraConfig {
        info: CameraInfo {
            component: CAMERA,
            vendor: "mavstack".into(),
            model: "Simulated camera".into(),
            firmware: Some("1.0.0.0".into()),
            focal_length_mm: Some(4.5),
            sensor_mm: Some((6.17, 4.55)),
            resolution: Some((640, 480)),
            flags: CameraCapFlags(
                CameraCapFlags::CAPTURE_IMAGE.0
                    | CameraCapFlags::CAPTURE_VIDEO.0
                    | CameraCapFlags::HAS_MODES.0,
            ),
            definition_uri: "mftp://camera.xml".into(),
            definition_version: 1,
            gimbal_device_id: 0,
        },
        storage: StorageInfo {
            id: 1,
            count: 1,
            status: StorageStatus::READY,
            total_mib: 1000.0,
            used_mib: 0.0,
            available_mib: 1000.0,
            kind: StorageType::OTHER,
            name: "files".into(),
        },
        streams: Vec::new(),
        definition: Some(CameraDefinition::parse(SIMULATED_DEFINITION.as_bytes()).unwrap()),
        heartbeat: true,
        photo_timeout: Duration::from_secs(5),
    }
}

/// A camera whose owner takes every photo at once, and which loses some of what it sends.
struct Camera {
    server: CameraServer,
    /// Announcements of these indices are lost the first time.
    lose_first: Vec<i32>,
    /// REQUEST_MESSAGE for CAMERA_IMAGE_CAPTURED is refused (as MAVSDK's camera server does).
    refuse_request_message: bool,
    /// Asked for announcements, by index, in order.
    asked: Vec<(MavCmd, i32)>,
    /// The owner takes no photo.
    asleep: bool,
    events: Vec<CameraEvent>,
}

impl Camera {
    fn new(server: CameraServer) -> Self {
        Self {
            server,
            lose_first: Vec::new(),
            refuse_request_message: false,
            asked: Vec::new(),
            asleep: false,
            events: Vec::new(),
        }
    }

    fn react(&mut self, now: Instant) {
        while let Some(e) = self.server.poll_event() {
            if let CameraEvent::TakePhoto(p) = &e
                && !self.asleep
            {
                let url = format!("file:///photos/IMG_{:04}.pgm", p.index);
                self.server
                    .photo_taken(now, p.index, Some(&url), 1_700_000_000_000_000, 0.5);
            }
            self.events.push(e);
        }
    }
}

impl Service for Camera {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if let MavMessage::CommandLong(c) = message
            && (c.command == MavCmd::REQUEST_CAMERA_IMAGE_CAPTURE
                || (c.command == MavCmd::REQUEST_MESSAGE && c.param1 == 263.0))
        {
            let index = if c.command == MavCmd::REQUEST_MESSAGE {
                c.param2
            } else {
                c.param1
            };
            self.asked.push((c.command, index as i32));
            if self.refuse_request_message && c.command == MavCmd::REQUEST_MESSAGE {
                let refused = CommandLong {
                    param1: 999_999.0,
                    ..*c
                };
                let used = self
                    .server
                    .handle_message(now, from, &MavMessage::CommandLong(refused));
                self.react(now);
                return used;
            }
        }
        let used = self.server.handle_message(now, from, message);
        self.react(now);
        used
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.server.handle_timeout(now);
        self.react(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        loop {
            let out = self.server.poll_transmit()?;
            if let MavMessage::CameraImageCaptured(m) = &out.message
                && let Some(i) = self.lose_first.iter().position(|&l| l == m.image_index)
            {
                self.lose_first.remove(i);
                continue;
            }
            return Some(out);
        }
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.server.poll_timeout()
    }
}

fn photo(
    camera: Camera,
    expected: Option<i32>,
    knobs: Knobs,
    seed: u64,
) -> (
    Pair<PhotoCapture, Camera>,
    Option<Result<mavstack_services::camera::ImageCaptured, CaptureError>>,
) {
    let capture = PhotoCapture::start(T0, GCS, CAMERA, expected, 1, CaptureConfig::default());
    let mut pair = Pair::new(capture, GCS, camera, CAMERA, knobs, seed);
    let mut result = None;
    pair.drive_until(Duration::from_secs(30), |c, _, _| {
        result = c.poll_result();
        result.is_some()
    });
    (pair, result)
}

#[test]
fn a_photo_and_its_announcement() {
    let (pair, result) = photo(
        Camera::new(CameraServer::new(T0, config())),
        Some(0),
        Knobs::clean(),
        1,
    );
    let image = result.unwrap().unwrap();
    assert_eq!(image.index, 0);
    assert!(image.success);
    assert_eq!(image.file_url, "file:///photos/IMG_0000.pgm");
    assert_eq!(pair.b.server.image_count(), 1);
    assert!(pair.b.asked.is_empty());
}

#[test]
fn a_lost_announcement_is_asked_for_by_its_index() {
    let mut camera = Camera::new(CameraServer::new(T0, config()));
    camera.lose_first = vec![0];
    let (pair, result) = photo(camera, Some(0), Knobs::clean(), 2);
    assert_eq!(result.unwrap().unwrap().index, 0);
    assert_eq!(pair.b.asked, [(MavCmd::REQUEST_MESSAGE, 0)]);
    assert_eq!(pair.a.asked_again(), 1);
}

#[test]
fn a_camera_refusing_request_message_is_asked_the_older_way() {
    let mut camera = Camera::new(CameraServer::new(T0, config()));
    camera.lose_first = vec![0];
    camera.refuse_request_message = true;
    let (pair, result) = photo(camera, Some(0), Knobs::clean(), 3);
    assert_eq!(result.unwrap().unwrap().index, 0);
    assert_eq!(
        pair.b.asked,
        [
            (MavCmd::REQUEST_MESSAGE, 0),
            (MavCmd::REQUEST_CAMERA_IMAGE_CAPTURE, 0)
        ]
    );
}

#[test]
fn an_announcement_that_never_comes_is_an_error() {
    let mut camera = Camera::new(CameraServer::new(T0, config()));
    camera.lose_first = vec![0, 0, 0, 0, 0];
    let (pair, result) = photo(camera, Some(0), Knobs::clean(), 4);
    assert_eq!(
        result.unwrap().unwrap_err(),
        CaptureError::NeverAnnounced {
            index: Some(0),
            asked: 3
        }
    );
    assert_eq!(pair.b.asked.len(), 3);
}

#[test]
fn photos_through_a_lossy_link() {
    let lossy = Knobs {
        loss: 0.2,
        duplicate: 0.05,
        latency: Duration::from_millis(50),
        jitter: Duration::from_millis(20),
    };
    let mut ok = 0;
    for seed in 0..40 {
        let (pair, result) = photo(
            Camera::new(CameraServer::new(T0, config())),
            Some(0),
            lossy,
            seed,
        );
        if let Some(Ok(image)) = result {
            assert_eq!(image.index, 0);
            ok += 1;
        }
        // A retried command never takes a second photo.
        assert!(pair.b.server.image_count() <= 1, "seed {seed}");
    }
    assert!(ok >= 38, "{ok} of 40");
}

#[test]
fn a_busy_camera_refuses() {
    let mut server = CameraServer::new(T0, config());
    // A photo its owner has not taken yet.
    let shot = MavMessage::CommandLong(CommandLong {
        target_system: 1,
        target_component: 100,
        command: MavCmd::IMAGE_START_CAPTURE,
        param3: 1.0,
        param4: 9.0,
        ..Default::default()
    });
    server.handle_message(T0, Address::new(254, 1), &shot);
    let mut camera = Camera::new(server);
    camera.asleep = true;
    let (_, result) = photo(camera, Some(1), Knobs::clean(), 5);
    let result = result.unwrap();
    assert!(
        matches!(result, Err(CaptureError::Refused { .. })),
        "{result:?}"
    );
}

fn settings_pair(knobs: Knobs, seed: u64) -> Pair<ParamExtClient, CameraServer> {
    Pair::new(
        ParamExtClient::new(CAMERA, ParamExtConfig::default()),
        GCS,
        CameraServer::new(T0, config()),
        CAMERA,
        knobs,
        seed,
    )
}

fn next_event(pair: &mut Pair<ParamExtClient, CameraServer>) -> ParamExtEvent {
    let mut event = None;
    pair.drive_until(Duration::from_secs(30), |c, _, _| {
        event = c.poll_event();
        event.is_some()
    });
    event.expect("an event")
}

#[test]
fn settings_listed_read_and_set() {
    for (knobs, seeds) in [
        (Knobs::clean(), 0..1),
        (
            Knobs {
                loss: 0.2,
                ..Knobs::clean()
            },
            0..20,
        ),
    ] {
        for seed in seeds {
            let mut pair = settings_pair(knobs, seed);
            pair.a.list(pair.now).unwrap();
            let ParamExtEvent::Listed(Ok(all)) = next_event(&mut pair) else {
                panic!("seed {seed}")
            };
            let names: Vec<&str> = all.iter().map(|(n, _)| n.as_str()).collect();
            assert_eq!(
                names[..3],
                ["CAM_MODE", "CAM_EXPMODE", "CAM_EV"],
                "seed {seed}"
            );
            assert_eq!(all.len(), 8);
        }
    }
    let mut pair = settings_pair(Knobs::clean(), 7);
    pair.a
        .set(pair.now, "CAM_WBMODE", ExtValue::U32(2))
        .unwrap();
    assert_eq!(
        next_event(&mut pair),
        ParamExtEvent::Set(Ok(("CAM_WBMODE".into(), ExtValue::U32(2))))
    );
    assert_eq!(
        pair.b.settings().unwrap().get("CAM_WBMODE"),
        Some(&ExtValue::U32(2))
    );
    assert!(matches!(
        pair.b.poll_event(),
        Some(CameraEvent::Setting { name, value: ExtValue::U32(2), .. }) if name == "CAM_WBMODE"
    ));
    pair.a.read(pair.now, "CAM_WBMODE").unwrap();
    assert_eq!(
        next_event(&mut pair),
        ParamExtEvent::Read(Ok(("CAM_WBMODE".into(), ExtValue::U32(2))))
    );
    // Setting the mode by its setting changes the camera's mode.
    pair.a.set(pair.now, "CAM_MODE", ExtValue::U32(1)).unwrap();
    assert!(matches!(next_event(&mut pair), ParamExtEvent::Set(Ok(_))));
    assert_eq!(pair.b.mode(), CameraMode::VIDEO);
}

#[test]
fn settings_the_definition_rules_out_are_refused() {
    let mut pair = settings_pair(Knobs::clean(), 8);
    // ISO is excluded while the exposure is automatic.
    pair.a.set(pair.now, "CAM_ISO", ExtValue::U32(400)).unwrap();
    let ParamExtEvent::Set(Err(e)) = next_event(&mut pair) else {
        panic!()
    };
    assert_eq!(
        e,
        ParamExtError::Refused {
            name: "CAM_ISO".into(),
            value: "400".into(),
            result: "VALUE_UNSUPPORTED",
            current: "100".into()
        }
    );
    pair.a.set(pair.now, "CAM_EV", ExtValue::F32(5.0)).unwrap();
    assert!(matches!(
        next_event(&mut pair),
        ParamExtEvent::Set(Err(ParamExtError::Refused { .. }))
    ));
    pair.a.set(pair.now, "CAM_NOPE", ExtValue::U8(1)).unwrap();
    assert!(matches!(
        next_event(&mut pair),
        ParamExtEvent::Set(Err(ParamExtError::Refused {
            result: "FAILED",
            ..
        }))
    ));
    assert_eq!(
        pair.b.settings().unwrap().get("CAM_ISO"),
        Some(&ExtValue::U32(100))
    );
    assert!(matches!(
        pair.a.set(pair.now, "", ExtValue::U8(1)),
        Err(ParamExtError::BadName(_))
    ));
}

/// Sends one command to the camera and gives its result and what came with it.
fn command(
    server: &mut CameraServer,
    now: Instant,
    c: CommandLong,
) -> (mavstack_dialects::common::MavResult, Vec<MavMessage>) {
    let c = CommandLong {
        target_system: 1,
        target_component: 100,
        ..c
    };
    server.handle_message(now, GCS, &MavMessage::CommandLong(c));
    let out: Vec<MavMessage> = core::iter::from_fn(|| server.poll_transmit())
        .map(|o| o.message)
        .collect();
    let result = out
        .iter()
        .find_map(|m| match m {
            MavMessage::CommandAck(a) if a.command == c.command => Some(a.result),
            _ => None,
        })
        .expect("an ACK");
    (result, out)
}

fn request(id: u32, p2: f32) -> CommandLong {
    CommandLong {
        command: MavCmd::REQUEST_MESSAGE,
        param1: id as f32,
        param2: p2,
        ..Default::default()
    }
}

#[test]
fn the_cameras_messages_on_request() {
    use mavstack_dialects::common::MavResult;
    let mut s = CameraServer::new(T0, config());
    let (r, out) = command(&mut s, T0, request(259, 0.0));
    assert_eq!(r, MavResult::ACCEPTED);
    assert!(matches!(out[0], MavMessage::CommandAck(_)), "the ACK first");
    let MavMessage::CameraInformation(info) = &out[1] else {
        panic!("{out:?}")
    };
    assert_eq!(
        CameraInfo::from_information(CAMERA, info).definition_uri,
        "mftp://camera.xml"
    );
    for id in [260, 261, 262] {
        assert_eq!(
            command(&mut s, T0, request(id, 0.0)).0,
            MavResult::ACCEPTED,
            "{id}"
        );
    }
    assert_eq!(command(&mut s, T0, request(261, 2.0)).0, MavResult::DENIED);
    // No image yet, no stream.
    assert_eq!(command(&mut s, T0, request(263, 0.0)).0, MavResult::DENIED);
    assert_eq!(command(&mut s, T0, request(269, 0.0)).0, MavResult::DENIED);
    // The older commands.
    let legacy = CommandLong {
        command: MavCmd::REQUEST_STORAGE_INFORMATION,
        param1: 0.0,
        param2: 1.0,
        ..Default::default()
    };
    let (r, out) = command(&mut s, T0, legacy);
    assert_eq!(r, MavResult::ACCEPTED);
    assert!(
        out.iter()
            .any(|m| matches!(m, MavMessage::StorageInformation(_)))
    );
    let arm = CommandLong {
        command: MavCmd::COMPONENT_ARM_DISARM,
        ..Default::default()
    };
    assert_eq!(command(&mut s, T0, arm).0, MavResult::UNSUPPORTED);
}

#[test]
fn video_intervals_and_format() {
    use mavstack_dialects::common::MavResult;
    let mut s = CameraServer::new(T0, config());
    let start = CommandLong {
        command: MavCmd::VIDEO_START_CAPTURE,
        param2: 1.0,
        ..Default::default()
    };
    assert_eq!(command(&mut s, T0, start).0, MavResult::ACCEPTED);
    assert!(s.recording());
    assert_eq!(s.poll_event(), Some(CameraEvent::VideoStart { stream: 0 }));
    // Capture status once a second while recording.
    s.handle_timeout(T0 + Duration::from_secs(1));
    let out: Vec<MavMessage> = core::iter::from_fn(|| s.poll_transmit())
        .map(|o| o.message)
        .collect();
    assert!(
        out.iter()
            .any(|m| matches!(m, MavMessage::CameraCaptureStatus(c) if c.video_status == 1))
    );
    let t = T0 + Duration::from_secs(3);
    let stop = CommandLong {
        command: MavCmd::VIDEO_STOP_CAPTURE,
        ..Default::default()
    };
    assert_eq!(command(&mut s, t, stop).0, MavResult::ACCEPTED);
    assert_eq!(
        s.poll_event(),
        Some(CameraEvent::VideoStop {
            recorded: Duration::from_secs(3)
        })
    );
    // Three photos two seconds apart.
    let interval = CommandLong {
        command: MavCmd::IMAGE_START_CAPTURE,
        param2: 2.0,
        param3: 3.0,
        ..Default::default()
    };
    assert_eq!(command(&mut s, t, interval).0, MavResult::ACCEPTED);
    let mut taken = Vec::new();
    let mut now = t;
    while let Some(next) = s.poll_timeout() {
        if next > t + Duration::from_secs(20) {
            break;
        }
        now = next;
        s.handle_timeout(now);
        while let Some(e) = s.poll_event() {
            if let CameraEvent::TakePhoto(p) = e {
                assert!(p.interval);
                s.photo_taken(now, p.index, Some("f"), 0, 0.0);
                taken.push((p.index, now.saturating_duration_since(t)));
            }
        }
        let _: Vec<Outgoing> = core::iter::from_fn(|| s.poll_transmit()).collect();
    }
    assert_eq!(
        taken,
        [
            (0, Duration::ZERO),
            (1, Duration::from_secs(2)),
            (2, Duration::from_secs(4))
        ]
    );
    assert_eq!(
        command(&mut s, now, request(263, -1.0)).1.len(),
        4,
        "the ACK and the three"
    );
    let format = CommandLong {
        command: MavCmd::STORAGE_FORMAT,
        param1: 1.0,
        param2: 1.0,
        ..Default::default()
    };
    assert_eq!(command(&mut s, now, format).0, MavResult::ACCEPTED);
    assert_eq!(s.image_count(), 0);
    let mode = CommandLong {
        command: MavCmd::SET_CAMERA_MODE,
        param2: 1.0,
        ..Default::default()
    };
    assert_eq!(command(&mut s, now, mode).0, MavResult::ACCEPTED);
    assert_eq!(s.mode(), CameraMode::VIDEO);
}

#[test]
fn requests_for_the_camera_through_a_command_client() {
    // The same answers a ground station's command client sees.
    let mut pair = Pair::new(
        CommandClient::new(GCS, Default::default()),
        GCS,
        CameraServer::new(T0, config()),
        CAMERA,
        Knobs::clean(),
        9,
    );
    let reset = mavstack_services::command::Command::long(
        MavCmd::RESET_CAMERA_SETTINGS,
        [1.0, 0., 0., 0., 0., 0., 0.],
    );
    let h = pair.a.send(pair.now, CAMERA, reset).unwrap();
    let mut done = None;
    pair.drive_until(Duration::from_secs(5), |c, _, _| {
        while let Some(e) = c.poll_event() {
            if let CommandEvent::Finished { handle, result } = e
                && handle == h
            {
                done = Some(result);
            }
        }
        done.is_some()
    });
    assert!(done.unwrap().is_ok());
}

/// A camera that refuses REQUEST_MESSAGE for everything but CAMERA_INFORMATION and
/// CAMERA_CAPTURE_STATUS, as MAVSDK's camera server does.
struct OldCamera(CameraServer);

impl Service for OldCamera {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if let MavMessage::CommandLong(c) = message
            && c.command == MavCmd::REQUEST_MESSAGE
            && !matches!(c.param1 as u32, 259 | 262)
        {
            let refused = CommandLong {
                param1: 999_999.0,
                ..*c
            };
            return self
                .0
                .handle_message(now, from, &MavMessage::CommandLong(refused));
        }
        self.0.handle_message(now, from, message)
    }
    fn handle_timeout(&mut self, now: Instant) {
        self.0.handle_timeout(now);
    }
    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.0.poll_transmit()
    }
    fn poll_timeout(&self) -> Option<Instant> {
        self.0.poll_timeout()
    }
}

#[test]
fn messages_asked_the_older_way_where_request_message_is_refused() {
    use mavstack_services::camera::MessageFetch;
    for (id, legacy) in [(261, true), (260, true), (262, false)] {
        let fetch = MessageFetch::start(T0, GCS, CAMERA, id, 0.0, Default::default());
        let mut pair = Pair::new(
            fetch,
            GCS,
            OldCamera(CameraServer::new(T0, config())),
            CAMERA,
            Knobs::clean(),
            10,
        );
        let mut result = None;
        pair.drive_until(Duration::from_secs(10), |f, _, _| {
            result = f.poll_result();
            result.is_some()
        });
        let got = result.unwrap().unwrap();
        assert_eq!(got.len(), 1, "{id}");
        assert_eq!(mavstack_core::MessageSet::id(&got[0]), id);
        // The older command is one more exchange.
        let exchanges = if legacy { 4 } else { 2 };
        assert_eq!(pair.ab.sent, exchanges / 2, "{id}");
    }
}

#[test]
fn cameras_of_a_system_found() {
    use mavstack_services::camera::CameraDiscovery;
    use mavstack_services::gimbal::DiscoveryConfig;
    let discovery = CameraDiscovery::new(T0, 1, &[1, 100], DiscoveryConfig::default());
    let mut pair = Pair::new(
        discovery,
        GCS,
        CameraServer::new(T0, config()),
        CAMERA,
        Knobs::clean(),
        11,
    );
    let mut found = None;
    pair.drive_until(Duration::from_secs(10), |d, _, _| {
        found = d.poll_result();
        found.is_some()
    });
    let found = found.unwrap();
    assert_eq!(found.len(), 1);
    assert_eq!(found[0].component, CAMERA);
    assert_eq!(found[0].model, "Simulated camera");
}

/// An announcement in another form (ArduPilot's CAMERA_FEEDBACK, converted by the caller):
/// taken from the camera with an index not below the one expected, once.
#[test]
fn an_announcement_in_another_form_is_taken_by_the_same_rule() {
    let mut capture = PhotoCapture::start(T0, GCS, CAMERA, Some(3), 1, CaptureConfig::default());
    let image = |index| mavstack_services::camera::ImageCaptured {
        index,
        time_utc_us: 0,
        lat: -35.36,
        lon: 149.16,
        alt_m: 584.0,
        relative_alt_m: 0.0,
        q: [1.0, 0.0, 0.0, 0.0],
        file_url: String::new(),
        success: true,
    };
    assert!(!capture.handle_announcement(Address::new(1, 1), image(3)));
    assert!(!capture.handle_announcement(CAMERA, image(2)));
    assert!(capture.poll_result().is_none());
    assert!(capture.handle_announcement(CAMERA, image(3)));
    assert_eq!(capture.poll_result(), Some(Ok(image(3))));
    assert!(!capture.handle_announcement(CAMERA, image(4)));
}
