//! [`CameraServer`]: the server role of the camera protocol, a camera whose owner takes the
//! photos and records (a companion's camera, the simulator's).

use alloc::collections::VecDeque;
use alloc::string::String;
use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CameraCapFlags, CameraCaptureStatus, CameraImageCaptured, CameraInformation, CameraMode,
    CameraSettings, Heartbeat, MavAutopilot, MavCmd, MavMessage, MavModeFlag, MavResult, MavState,
    MavType, StorageInformation, StorageStatus, StorageType, VideoStreamInformation,
    VideoStreamStatus, VideoStreamStatusFlags,
};

use super::definition::CameraDefinition;
use super::messages::{CameraInfo, CaptureStatus, ImageCaptured, StorageInfo, VideoStream};
use super::param_ext::ParamExtServer;
use super::value::ExtValue;
use crate::command::{Command, CommandHandler, CommandServer, Request, Response};
use crate::{Address, Outgoing, Service};

/// Announcements kept for asking again (the oldest forgotten first).
const IMAGES_KEPT: usize = 10_000;

/// The setting that mirrors MAV_CMD_SET_CAMERA_MODE, when a definition has it.
const MODE_SETTING: &str = "CAM_MODE";

/// What a [`CameraServer`] is.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraConfig {
    /// What it says in CAMERA_INFORMATION (its `component` is the camera's address).
    pub info: CameraInfo,
    /// Its storage.
    pub storage: StorageInfo,
    /// Its video streams.
    pub streams: Vec<VideoStream>,
    /// Its settings (PARAM_EXT_*), when it has a definition file.
    pub definition: Option<CameraDefinition>,
    /// Whether it sends its own HEARTBEAT (MAV_TYPE_CAMERA, once a second).
    pub heartbeat: bool,
    /// How long its owner may take to take a photo before the photo counts as failed
    /// (default 5 s).
    pub photo_timeout: Duration,
}

impl CameraConfig {
    /// A photo and video camera at `own` called `vendor` `model`: firmware unknown,
    /// one storage of `storage_mib` MiB, no video stream, no definition, its own HEARTBEAT.
    #[must_use]
    pub fn new(own: Address, vendor: &str, model: &str, storage_mib: f32) -> Self {
        let flags = CameraCapFlags::CAPTURE_IMAGE.0
            | CameraCapFlags::CAPTURE_VIDEO.0
            | CameraCapFlags::HAS_MODES.0
            | CameraCapFlags::CAN_CAPTURE_IMAGE_IN_VIDEO_MODE.0;
        Self {
            info: CameraInfo {
                component: own,
                vendor: String::from(vendor),
                model: String::from(model),
                firmware: None,
                focal_length_mm: None,
                sensor_mm: None,
                resolution: None,
                flags: CameraCapFlags(flags),
                definition_uri: String::new(),
                definition_version: 0,
                gimbal_device_id: 0,
            },
            storage: StorageInfo {
                id: 1,
                count: 1,
                status: StorageStatus::READY,
                total_mib: storage_mib,
                used_mib: 0.0,
                available_mib: storage_mib,
                kind: StorageType::OTHER,
                name: String::from("files"),
            },
            streams: Vec::new(),
            definition: None,
            heartbeat: true,
            photo_timeout: Duration::from_secs(5),
        }
    }
}

/// A photo the owner is to take ([`CameraEvent::TakePhoto`]), then report with
/// [`CameraServer::photo_taken`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Photo {
    /// Its index.
    pub index: i32,
    /// Who asked (the camera's own address for an interval's photos after the first).
    pub from: Address,
    /// Part of an interval's series.
    pub interval: bool,
}

/// What a [`CameraServer`] asks of its owner, or tells it.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum CameraEvent {
    /// Take a photo, then call [`CameraServer::photo_taken`].
    TakePhoto(Photo),
    /// Start recording.
    VideoStart {
        /// The stream (0: all).
        stream: u8,
    },
    /// Stop recording; it was recording for this long.
    VideoStop {
        /// How long it recorded.
        recorded: Duration,
    },
    /// The mode changed (MAV_CMD_SET_CAMERA_MODE, or the CAM_MODE setting).
    Mode(CameraMode),
    /// A client set a setting (PARAM_EXT_SET, checked against the definition).
    Setting {
        /// Who set it.
        from: Address,
        /// Which.
        name: String,
        /// To what.
        value: ExtValue,
    },
    /// Format the storage (MAV_CMD_STORAGE_FORMAT); the image count is reset.
    Format,
}

/// Where the vehicle is, for the photos' announcements.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Where {
    lat: f64,
    lon: f64,
    alt_m: f32,
    relative_alt_m: f32,
    q: [f32; 4],
}

#[derive(Debug)]
struct State {
    config: CameraConfig,
    started: Instant,
    mode: CameraMode,
    status: CaptureStatus,
    /// The photo being taken: its index, who asked, and when it must be done by.
    pending: Option<(Photo, Instant)>,
    /// An interval series: every, photos left (`None`: until stopped), next.
    interval: Option<(Duration, Option<u32>, Instant)>,
    recording_since: Option<Instant>,
    /// CAMERA_CAPTURE_STATUS while recording, every so often (VIDEO_START_CAPTURE's param 2).
    status_every: Option<(Duration, Instant)>,
    streaming: bool,
    images: VecDeque<CameraImageCaptured>,
    position: Where,
    replies: VecDeque<Outgoing>,
    events: VecDeque<CameraEvent>,
}

impl State {
    fn boot_ms(&self, now: Instant) -> u32 {
        now.saturating_duration_since(self.started).as_millis() as u32
    }

    fn reply(&mut self, to: Address, message: MavMessage) {
        self.replies.push_back(Outgoing {
            target: to,
            message,
        });
    }

    fn capture_status(&self, now: Instant) -> MavMessage {
        let mut s = self.status;
        s.photo_busy = self.pending.is_some();
        s.interval_on = self.interval.is_some();
        s.video_on = self.recording_since.is_some();
        s.recording_s = self
            .recording_since
            .map_or(0.0, |t| now.saturating_duration_since(t).as_secs_f32());
        s.available_mib = self.config.storage.available_mib;
        MavMessage::CameraCaptureStatus(s.to_message(self.boot_ms(now)))
    }

    fn settings(&self, now: Instant) -> MavMessage {
        MavMessage::CameraSettings(CameraSettings {
            time_boot_ms: self.boot_ms(now),
            mode_id: self.mode,
            zoom_level: f32::NAN,
            focus_level: f32::NAN,
            camera_device_id: 0,
        })
    }

    fn stream_status(&self, s: &VideoStream) -> MavMessage {
        let mut flags = s.flags.0 & !VideoStreamStatusFlags::RUNNING.0;
        if self.streaming {
            flags |= VideoStreamStatusFlags::RUNNING.0;
        }
        MavMessage::VideoStreamStatus(VideoStreamStatus {
            stream_id: s.id,
            flags: VideoStreamStatusFlags(flags),
            framerate: s.framerate,
            resolution_h: s.resolution.0,
            resolution_v: s.resolution.1,
            bitrate: s.bitrate,
            rotation: 0,
            hfov: s.hfov_deg,
            camera_device_id: 0,
        })
    }

    fn heartbeat() -> MavMessage {
        MavMessage::Heartbeat(Heartbeat {
            r#type: MavType::CAMERA,
            autopilot: MavAutopilot::INVALID,
            base_mode: MavModeFlag(0),
            custom_mode: 0,
            system_status: MavState::ACTIVE,
            mavlink_version: 3,
        })
    }

    /// Asks the owner for a photo with the next index.
    fn shoot(&mut self, now: Instant, from: Address, interval: bool) {
        let photo = Photo {
            index: self.status.image_count,
            from,
            interval,
        };
        self.pending = Some((photo, now + self.config.photo_timeout));
        self.events.push_back(CameraEvent::TakePhoto(photo));
    }

    /// Answers REQUEST_MESSAGE (and its older commands) for message `id` with `p2`/`p3`
    /// (an instance or index, a range).
    fn request(&mut self, now: Instant, from: Address, id: u32, p2: f32, p3: f32) -> MavResult {
        let boot = self.boot_ms(now);
        match id {
            CameraInformation::ID => {
                let m = self.config.info.to_information(boot);
                self.reply(from, MavMessage::CameraInformation(m));
            }
            CameraSettings::ID => {
                let m = self.settings(now);
                self.reply(from, m);
            }
            StorageInformation::ID => {
                let id = p2 as u8;
                if id != 0 && id != self.config.storage.id {
                    return MavResult::DENIED;
                }
                let m = self.config.storage.to_message(boot);
                self.reply(from, MavMessage::StorageInformation(m));
            }
            CameraCaptureStatus::ID => {
                let m = self.capture_status(now);
                self.reply(from, m);
            }
            CameraImageCaptured::ID => {
                let first = p2 as i32;
                let last = match p3 as i32 {
                    0 => first,
                    -1 => i32::MAX,
                    l => l,
                };
                let all = first == -1;
                let found: Vec<CameraImageCaptured> = self
                    .images
                    .iter()
                    .filter(|m| all || (m.image_index >= first && m.image_index <= last))
                    .copied()
                    .collect();
                if found.is_empty() {
                    return MavResult::DENIED;
                }
                for m in found {
                    self.reply(from, MavMessage::CameraImageCaptured(m));
                }
            }
            VideoStreamInformation::ID | VideoStreamStatus::ID => {
                let wanted = p2 as u8;
                let streams: Vec<VideoStream> = self
                    .config
                    .streams
                    .iter()
                    .filter(|s| wanted == 0 || s.id == wanted)
                    .cloned()
                    .collect();
                if streams.is_empty() {
                    return MavResult::DENIED;
                }
                for s in &streams {
                    let m = if id == VideoStreamInformation::ID {
                        MavMessage::VideoStreamInformation(s.to_message())
                    } else {
                        self.stream_status(s)
                    };
                    self.reply(from, m);
                }
            }
            Heartbeat::ID if self.config.heartbeat => self.reply(from, Self::heartbeat()),
            _ => return MavResult::UNSUPPORTED,
        }
        MavResult::ACCEPTED
    }
}

impl CommandHandler for State {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        let Command::Long(c) = &request.command else {
            return Response::done(MavResult::UNSUPPORTED);
        };
        let from = request.from;
        let done = Response::done;
        match c.command {
            MavCmd::REQUEST_MESSAGE => {
                done(self.request(now, from, c.param1 as u32, c.param2, c.param3))
            }
            MavCmd::REQUEST_CAMERA_INFORMATION => {
                done(self.request(now, from, CameraInformation::ID, 0.0, 0.0))
            }
            MavCmd::REQUEST_CAMERA_SETTINGS => {
                done(self.request(now, from, CameraSettings::ID, 0.0, 0.0))
            }
            MavCmd::REQUEST_STORAGE_INFORMATION => {
                done(self.request(now, from, StorageInformation::ID, c.param1, 0.0))
            }
            MavCmd::REQUEST_CAMERA_CAPTURE_STATUS => {
                done(self.request(now, from, CameraCaptureStatus::ID, 0.0, 0.0))
            }
            MavCmd::REQUEST_CAMERA_IMAGE_CAPTURE => {
                done(self.request(now, from, CameraImageCaptured::ID, c.param1, 0.0))
            }
            MavCmd::REQUEST_VIDEO_STREAM_INFORMATION => {
                done(self.request(now, from, VideoStreamInformation::ID, c.param1, 0.0))
            }
            MavCmd::REQUEST_VIDEO_STREAM_STATUS => {
                done(self.request(now, from, VideoStreamStatus::ID, c.param1, 0.0))
            }
            MavCmd::IMAGE_START_CAPTURE => self.start_capture(now, from, c.param2, c.param3),
            MavCmd::IMAGE_STOP_CAPTURE => {
                self.interval = None;
                done(MavResult::ACCEPTED)
            }
            MavCmd::VIDEO_START_CAPTURE => {
                if self.recording_since.is_none() {
                    self.recording_since = Some(now);
                    self.events.push_back(CameraEvent::VideoStart {
                        stream: c.param1 as u8,
                    });
                }
                self.status_every = (c.param2.is_finite() && c.param2 > 0.0).then(|| {
                    let every = Duration::from_secs_f32((1.0 / c.param2).max(0.05));
                    (every, now + every)
                });
                done(MavResult::ACCEPTED)
            }
            MavCmd::VIDEO_STOP_CAPTURE => {
                if let Some(since) = self.recording_since.take() {
                    let recorded = now.saturating_duration_since(since);
                    self.events.push_back(CameraEvent::VideoStop { recorded });
                }
                self.status_every = None;
                done(MavResult::ACCEPTED)
            }
            MavCmd::VIDEO_START_STREAMING | MavCmd::VIDEO_STOP_STREAMING => {
                if self.config.streams.is_empty() {
                    return done(MavResult::UNSUPPORTED);
                }
                self.streaming = c.command == MavCmd::VIDEO_START_STREAMING;
                done(MavResult::ACCEPTED)
            }
            MavCmd::SET_CAMERA_MODE => {
                let mode = CameraMode(c.param2 as u8);
                if !matches!(mode, CameraMode::IMAGE | CameraMode::VIDEO) {
                    return done(MavResult::DENIED);
                }
                self.set_mode(now, mode);
                done(MavResult::ACCEPTED)
            }
            MavCmd::STORAGE_FORMAT => {
                self.status.image_count = 0;
                self.images.clear();
                let s = &mut self.config.storage;
                s.available_mib = s.total_mib;
                s.used_mib = 0.0;
                self.events.push_back(CameraEvent::Format);
                let m = self.config.storage.to_message(self.boot_ms(now));
                self.reply(Address::BROADCAST, MavMessage::StorageInformation(m));
                done(MavResult::ACCEPTED)
            }
            _ => done(MavResult::UNSUPPORTED),
        }
    }
}

impl State {
    fn start_capture(
        &mut self,
        now: Instant,
        from: Address,
        interval: f32,
        total: f32,
    ) -> Response {
        if self.pending.is_some() {
            return Response::done(MavResult::TEMPORARILY_REJECTED);
        }
        if !interval.is_finite() || interval < 0.0 || !total.is_finite() || total < 0.0 {
            return Response::done(MavResult::DENIED);
        }
        if total as u32 == 1 {
            self.shoot(now, from, false);
            // ACCEPTED (or FAILED) once the owner has taken it.
            return Response::in_progress(0);
        }
        if interval <= 0.0 {
            return Response::done(MavResult::DENIED);
        }
        let every = Duration::from_secs_f32(interval);
        let left = (total as u32 != 0).then_some(total as u32);
        self.interval = Some((every, left, now));
        self.status.interval_s = interval;
        Response::done(MavResult::ACCEPTED)
    }

    fn set_mode(&mut self, now: Instant, mode: CameraMode) {
        if self.mode != mode {
            self.mode = mode;
            self.events.push_back(CameraEvent::Mode(mode));
        }
        let m = self.settings(now);
        self.reply(Address::BROADCAST, m);
    }
}

/// A camera (the protocol's server role) whose owner takes the photos and records. It
/// answers REQUEST_MESSAGE for CAMERA_INFORMATION, CAMERA_SETTINGS, STORAGE_INFORMATION,
/// CAMERA_CAPTURE_STATUS, CAMERA_IMAGE_CAPTURED (by index, a range, or all: every
/// announcement is kept), VIDEO_STREAM_INFORMATION and VIDEO_STREAM_STATUS, and the older
/// MAV_CMD_REQUEST_CAMERA_* commands for them; takes MAV_CMD_IMAGE_START_CAPTURE (one photo:
/// IN_PROGRESS, then ACCEPTED and CAMERA_IMAGE_CAPTURED once the owner has taken it; or a
/// series at an interval, until IMAGE_STOP_CAPTURE or its count), VIDEO_START_CAPTURE /
/// _STOP_CAPTURE, SET_CAMERA_MODE, STORAGE_FORMAT, RESET_CAMERA_SETTINGS and
/// VIDEO_START_STREAMING / _STOP_STREAMING; serves its settings with PARAM_EXT_* when it has
/// a definition; and sends HEARTBEAT (MAV_TYPE_CAMERA). The photos' position and attitude
/// are those of its own system's GLOBAL_POSITION_INT and ATTITUDE.
///
/// The definition file itself is served by whoever serves MAVFTP for the camera's
/// component (`mftp://` in the URI), not by this type.
#[derive(Debug)]
pub struct CameraServer {
    commands: CommandServer<State>,
    settings: Option<ParamExtServer>,
    next_heartbeat: Option<Instant>,
}

impl CameraServer {
    /// A camera as `config` says, at the address of its `info.component`, started at
    /// `now` with no photos taken.
    #[must_use]
    pub fn new(now: Instant, config: CameraConfig) -> Self {
        let own = config.info.component;
        let settings = config
            .definition
            .clone()
            .map(|d| ParamExtServer::new(own, d));
        let mode = settings
            .as_ref()
            .and_then(|s| s.get(MODE_SETTING))
            .and_then(ExtValue::as_f64)
            .map_or(CameraMode::IMAGE, |m| CameraMode(m as u8));
        let heartbeat = config.heartbeat.then_some(now);
        let state = State {
            config,
            started: now,
            mode,
            status: CaptureStatus {
                photo_busy: false,
                interval_on: false,
                interval_s: 0.0,
                video_on: false,
                recording_s: 0.0,
                available_mib: 0.0,
                image_count: 0,
            },
            pending: None,
            interval: None,
            recording_since: None,
            status_every: None,
            streaming: false,
            images: VecDeque::new(),
            position: Where {
                q: [1.0, 0.0, 0.0, 0.0],
                ..Where::default()
            },
            replies: VecDeque::new(),
            events: VecDeque::new(),
        };
        Self {
            commands: CommandServer::new(own, Default::default(), state),
            settings,
            next_heartbeat: heartbeat,
        }
    }

    fn state(&self) -> &State {
        self.commands.handler()
    }

    fn state_mut(&mut self) -> &mut State {
        self.commands.handler_mut()
    }

    /// Its address.
    #[must_use]
    pub fn own(&self) -> Address {
        self.state().config.info.component
    }

    /// The next thing the owner is to do or know.
    pub fn poll_event(&mut self) -> Option<CameraEvent> {
        self.state_mut().events.pop_front()
    }

    /// Its settings, when it has a definition.
    #[must_use]
    pub const fn settings(&self) -> Option<&ParamExtServer> {
        self.settings.as_ref()
    }

    /// Photos announced so far.
    #[must_use]
    pub fn image_count(&self) -> i32 {
        self.state().status.image_count
    }

    /// Whether it is recording.
    #[must_use]
    pub fn recording(&self) -> bool {
        self.state().recording_since.is_some()
    }

    /// Its mode.
    #[must_use]
    pub fn mode(&self) -> CameraMode {
        self.state().mode
    }

    /// The owner's account of the photo it was asked for ([`CameraEvent::TakePhoto`]):
    /// where the file is (or `None`: it failed), when (µs since the UNIX epoch, 0 when not
    /// known), and how much storage it used (MiB). The photo is announced
    /// (CAMERA_IMAGE_CAPTURED to everyone, kept for asking again) and a single photo's
    /// command is answered: ACCEPTED, or FAILED. Returns whether that photo was pending.
    pub fn photo_taken(
        &mut self,
        now: Instant,
        index: i32,
        file_url: Option<&str>,
        time_utc_us: u64,
        size_mib: f32,
    ) -> bool {
        let s = self.state_mut();
        let Some((photo, _)) = s.pending.filter(|(p, _)| p.index == index) else {
            return false;
        };
        s.pending = None;
        s.status.image_count = s.status.image_count.max(index.saturating_add(1));
        if file_url.is_some() && size_mib.is_finite() && size_mib > 0.0 {
            let st = &mut s.config.storage;
            st.used_mib += size_mib;
            st.available_mib = (st.available_mib - size_mib).max(0.0);
        }
        let p = s.position;
        let image = ImageCaptured {
            index,
            time_utc_us,
            lat: p.lat,
            lon: p.lon,
            alt_m: p.alt_m,
            relative_alt_m: p.relative_alt_m,
            q: p.q,
            file_url: String::from(file_url.unwrap_or("")),
            success: file_url.is_some(),
        };
        let m = image.to_message(s.boot_ms(now));
        if s.images.len() == IMAGES_KEPT {
            s.images.pop_front();
        }
        s.images.push_back(m);
        if !photo.interval {
            let result = if image.success {
                MavResult::ACCEPTED
            } else {
                MavResult::FAILED
            };
            self.commands.finish(
                now,
                photo.from,
                MavCmd::IMAGE_START_CAPTURE,
                Response::done(result),
            );
        }
        self.state_mut()
            .reply(Address::BROADCAST, MavMessage::CameraImageCaptured(m));
        true
    }

    fn note_vehicle(&mut self, from: Address, message: &MavMessage) {
        let s = self.state_mut();
        if from.system != s.config.info.component.system {
            return;
        }
        match message {
            MavMessage::GlobalPositionInt(g) => {
                s.position.lat = f64::from(g.lat) / 1e7;
                s.position.lon = f64::from(g.lon) / 1e7;
                s.position.alt_m = g.alt as f32 / 1000.0;
                s.position.relative_alt_m = g.relative_alt as f32 / 1000.0;
            }
            MavMessage::Attitude(a) => {
                let deg = 180.0 / core::f32::consts::PI;
                s.position.q =
                    crate::gimbal::quaternion_from_euler(a.roll * deg, a.pitch * deg, a.yaw * deg);
            }
            _ => {}
        }
    }

    /// Carries the settings' changes over: events, and CAM_MODE to the mode.
    fn settings_changed(&mut self, now: Instant) {
        let Some(settings) = &mut self.settings else {
            return;
        };
        let mut changed = Vec::new();
        while let Some(c) = settings.poll_changed() {
            changed.push(c);
        }
        for (from, name, value) in changed {
            if name == MODE_SETTING
                && let Some(m) = value.as_f64()
            {
                self.state_mut().set_mode(now, CameraMode(m as u8));
            }
            self.state_mut()
                .events
                .push_back(CameraEvent::Setting { from, name, value });
        }
    }
}

impl Service for CameraServer {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::CommandLong(c)
                if c.command == MavCmd::RESET_CAMERA_SETTINGS
                    && self
                        .own()
                        .is_reached_by(Address::new(c.target_system, c.target_component)) =>
            {
                // The settings are not the command handler's: answered here.
                if let Some(s) = &mut self.settings {
                    s.reset();
                }
                let result = if self.settings.is_some() {
                    MavResult::ACCEPTED
                } else {
                    MavResult::UNSUPPORTED
                };
                let ack = mavstack_dialects::common::CommandAck {
                    command: c.command,
                    result,
                    target_system: from.system,
                    target_component: from.component,
                    ..Default::default()
                };
                self.state_mut().reply(from, MavMessage::CommandAck(ack));
                true
            }
            MavMessage::CommandLong(_) | MavMessage::CommandInt(_) => {
                self.commands.handle_message(now, from, message)
            }
            MavMessage::ParamExtRequestList(_)
            | MavMessage::ParamExtRequestRead(_)
            | MavMessage::ParamExtSet(_) => {
                let used = self
                    .settings
                    .as_mut()
                    .is_some_and(|s| s.handle_message(now, from, message));
                self.settings_changed(now);
                used
            }
            MavMessage::GlobalPositionInt(_) | MavMessage::Attitude(_) => {
                self.note_vehicle(from, message);
                false
            }
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.commands.handle_timeout(now);
        if let Some(due) = self.next_heartbeat
            && now >= due
        {
            self.state_mut()
                .reply(Address::BROADCAST, State::heartbeat());
            self.next_heartbeat = Some(now + Duration::from_secs(1));
        }
        // A photo its owner never reported failed.
        if let Some((photo, by)) = self.state().pending
            && now >= by
        {
            self.photo_taken(now, photo.index, None, 0, 0.0);
        }
        let s = self.state_mut();
        if let Some((every, left, next)) = s.interval
            && now >= next
        {
            if s.pending.is_none() {
                let own = s.config.info.component;
                s.shoot(now, own, true);
            }
            let left = left.map(|n| n.saturating_sub(1));
            s.interval = match left {
                Some(0) => None,
                left => Some((every, left, next + every.max(Duration::from_millis(10)))),
            };
        }
        if let Some((every, next)) = s.status_every
            && now >= next
        {
            let m = s.capture_status(now);
            s.reply(Address::BROADCAST, m);
            s.status_every = Some((every, now + every));
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        // An ACK before what it answers.
        self.commands
            .poll_transmit()
            .or_else(|| self.state_mut().replies.pop_front())
            .or_else(|| {
                self.settings
                    .as_mut()
                    .and_then(ParamExtServer::poll_transmit)
            })
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let s = self.state();
        [
            self.next_heartbeat,
            s.pending.map(|(_, by)| by),
            s.interval.map(|(_, _, next)| next),
            s.status_every.map(|(_, next)| next),
        ]
        .into_iter()
        .flatten()
        .min()
    }
}
