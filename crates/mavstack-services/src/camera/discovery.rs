//! [`CameraDiscovery`]: the cameras of one system, found by asking its components for
//! CAMERA_INFORMATION; [`MessageFetch`]: one of a camera's messages asked for, by
//! REQUEST_MESSAGE or, where the camera refuses that, by the older command for it.

use alloc::vec::Vec;
use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::MessageSet as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    CameraCaptureStatus, CameraInformation, CameraSettings, MavCmd, MavMessage, StorageInformation,
    VideoStreamInformation,
};

use super::messages::CameraInfo;
use crate::command::{
    Command, CommandClient, CommandConfig, CommandError, CommandEvent, CommandHandle,
};
use crate::search::{DiscoveryConfig, Search};
use crate::{Address, Outgoing, Service};

/// A search for the cameras of one system: MAV_CMD_REQUEST_MESSAGE(CAMERA_INFORMATION) to
/// the whole system (component 0) and to each of its components heard (a camera answers
/// for itself; an autopilot may answer for a camera it drives), again every
/// [`DiscoveryConfig::ask_every`] to those that have not answered, until [`DiscoveryConfig::settle`] after the last answer or
/// [`DiscoveryConfig::limit`]. A [`Service`]: drive it and read
/// [`poll_result`](Self::poll_result).
#[derive(Clone, Debug)]
pub struct CameraDiscovery {
    search: Search,
    found: Vec<CameraInfo>,
}

impl CameraDiscovery {
    /// Starts looking among `components` of `system`.
    #[must_use]
    pub fn new(now: Instant, system: u8, components: &[u8], config: DiscoveryConfig) -> Self {
        let mut d = Self {
            search: Search::new(now, system, components, config),
            found: Vec::new(),
        };
        d.handle_timeout(now);
        d
    }

    /// The cameras found (by component), once the search has ended; given once.
    pub fn poll_result(&mut self) -> Option<Vec<CameraInfo>> {
        if !self.search.take() {
            return None;
        }
        let mut found = core::mem::take(&mut self.found);
        found.sort_by_key(|c| c.component.component);
        Some(found)
    }
}

impl Service for CameraDiscovery {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        let MavMessage::CameraInformation(info) = message else {
            return false;
        };
        if self.search.done() || from.system != self.search.system {
            return false;
        }
        if !self.found.iter().any(|c| c.component == from) {
            self.found.push(CameraInfo::from_information(from, info));
            self.search.found(now);
        }
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        if !self.search.tick(now) {
            return;
        }
        // The whole system (component 0) too: a camera not heard yet answers that.
        for c in core::iter::once(0).chain(self.search.components.clone()) {
            if c != 0 && self.found.iter().any(|f| f.component.component == c) {
                continue;
            }
            self.search.request(c, CameraInformation::ID);
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.search.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        self.search.poll_timeout()
    }
}

/// The older command that asks a camera for message `msg_id` (with an instance or index
/// `param`), for cameras that refuse REQUEST_MESSAGE for it.
#[must_use]
pub fn legacy_request(msg_id: u32, param: f32) -> Option<Command> {
    let (command, p) = match msg_id {
        CameraInformation::ID => (MavCmd::REQUEST_CAMERA_INFORMATION, [1.0, 0.0]),
        CameraSettings::ID => (MavCmd::REQUEST_CAMERA_SETTINGS, [1.0, 0.0]),
        StorageInformation::ID => (MavCmd::REQUEST_STORAGE_INFORMATION, [param, 1.0]),
        CameraCaptureStatus::ID => (MavCmd::REQUEST_CAMERA_CAPTURE_STATUS, [1.0, 0.0]),
        VideoStreamInformation::ID => (MavCmd::REQUEST_VIDEO_STREAM_INFORMATION, [param, 0.0]),
        _ => return None,
    };
    Some(Command::long(
        command,
        [p[0], p[1], 0.0, 0.0, 0.0, 0.0, 0.0],
    ))
}

/// One kind of a camera's messages asked for: MAV_CMD_REQUEST_MESSAGE(`msg_id`, `param`);
/// where the camera refuses it, the older command for that message ([`legacy_request`]).
/// It ends with the messages of that kind from the camera once as many came as the first
/// of them says there are (`count`, for the instances of STORAGE_INFORMATION and
/// VIDEO_STREAM_INFORMATION; one for the rest), or with the refusal. A [`Service`]: drive it
/// and read [`poll_result`](Self::poll_result).
#[derive(Debug)]
pub struct MessageFetch {
    camera: Address,
    msg_id: u32,
    param: f32,
    commands: CommandClient,
    request: Option<CommandHandle>,
    legacy_tried: bool,
    got: Vec<MavMessage>,
    /// When a request that was accepted gives up waiting for its message.
    give_up: Option<Instant>,
    result: Option<Result<Vec<MavMessage>, CommandError>>,
    taken: bool,
}

impl MessageFetch {
    /// Asks the camera at `camera` for message `msg_id` (REQUEST_MESSAGE's param 2 is
    /// `param`: an instance, 0 for all).
    #[must_use]
    pub fn start(
        now: Instant,
        own: Address,
        camera: Address,
        msg_id: u32,
        param: f32,
        config: CommandConfig,
    ) -> Self {
        let mut commands = CommandClient::new(own, config);
        let request = crate::stream::request_message(msg_id, [param, 0.0, 0.0, 0.0, 0.0]);
        let sent = commands.send(now, camera, request);
        let result = sent
            .is_err()
            .then_some(Err(CommandError::TimedOut { attempts: 0 }));
        Self {
            camera,
            msg_id,
            param,
            commands,
            request: sent.ok(),
            legacy_tried: false,
            got: Vec::new(),
            give_up: None,
            result,
            taken: false,
        }
    }

    /// The messages, or why none came; given once.
    pub fn poll_result(&mut self) -> Option<Result<Vec<MavMessage>, CommandError>> {
        if self.taken {
            return None;
        }
        let r = self.result.clone()?;
        self.taken = true;
        Some(r)
    }

    fn wanted(&self) -> usize {
        match self.got.first() {
            Some(MavMessage::StorageInformation(s)) if self.param == 0.0 => {
                usize::from(s.storage_count).max(1)
            }
            Some(MavMessage::VideoStreamInformation(v)) if self.param == 0.0 => {
                usize::from(v.count).max(1)
            }
            _ => 1,
        }
    }

    fn command_events(&mut self, now: Instant) {
        while let Some(e) = self.commands.poll_event() {
            let CommandEvent::Finished { handle, result } = e else {
                continue;
            };
            if Some(handle) != self.request {
                continue;
            }
            self.request = None;
            match result {
                Ok(_) => {
                    // The message follows its ACK at once: a round trip's grace.
                    self.give_up = Some(now + Duration::from_secs(2));
                }
                Err(e @ CommandError::Rejected { .. }) => {
                    match legacy_request(self.msg_id, self.param).filter(|_| !self.legacy_tried) {
                        Some(legacy) => {
                            self.legacy_tried = true;
                            self.request = self.commands.send(now, self.camera, legacy).ok();
                        }
                        None if self.got.is_empty() => self.result = Some(Err(e)),
                        None => {}
                    }
                }
                Err(e) if self.got.is_empty() => self.result = Some(Err(e)),
                Err(_) => {}
            }
        }
        self.check_done(now);
    }

    fn check_done(&mut self, now: Instant) {
        if self.result.is_some() {
            return;
        }
        let enough = !self.got.is_empty() && self.got.len() >= self.wanted();
        let late = self.give_up.is_some_and(|t| now >= t);
        if enough || (late && !self.got.is_empty()) {
            self.result = Some(Ok(core::mem::take(&mut self.got)));
        } else if late {
            // Accepted, yet nothing came.
            self.result = Some(Err(CommandError::TimedOut { attempts: 1 }));
        }
    }
}

impl Service for MessageFetch {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if from != self.camera || self.result.is_some() {
            return false;
        }
        if let MavMessage::CommandAck(_) = message {
            let used = self.commands.handle_message(now, from, message);
            self.command_events(now);
            return used;
        }
        if message.id() != self.msg_id {
            return false;
        }
        let instance = |m: &MavMessage| match m {
            MavMessage::StorageInformation(s) => Some(s.storage_id),
            MavMessage::VideoStreamInformation(v) => Some(v.stream_id),
            _ => None,
        };
        let seen =
            instance(message).is_some_and(|i| self.got.iter().any(|g| instance(g) == Some(i)));
        if !seen {
            self.got.push(message.clone());
        }
        self.check_done(now);
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.commands.handle_timeout(now);
        self.command_events(now);
        self.check_done(now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.commands.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        if self.result.is_some() {
            return None;
        }
        crate::earliest(self.commands.poll_timeout(), self.give_up)
    }
}
