//! [`PhotoCapture`]: one photo, from MAV_CMD_IMAGE_START_CAPTURE to its
//! CAMERA_IMAGE_CAPTURED, asking again for the announcement when it is lost.

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{CameraImageCaptured, MavCmd, MavMessage, MavResult};

use super::messages::ImageCaptured;
use crate::command::{
    Command, CommandClient, CommandConfig, CommandError, CommandEvent, CommandHandle,
};
use crate::{Address, Outgoing, Service};

/// Timings of a [`PhotoCapture`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CaptureConfig {
    /// The commands' retries and timeouts.
    pub command: CommandConfig,
    /// How long after the camera accepted the photo its CAMERA_IMAGE_CAPTURED may take
    /// before it is asked for again (default 1 s).
    pub resend_after: Duration,
    /// How many times it is asked for again (default 3).
    pub resends: u8,
}

impl Default for CaptureConfig {
    fn default() -> Self {
        Self {
            command: CommandConfig::default(),
            resend_after: Duration::from_secs(1),
            resends: 3,
        }
    }
}

/// Why a photo has no CAMERA_IMAGE_CAPTURED.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CaptureError {
    /// The camera refused to take it.
    #[error("the camera refused the photo: {}", result_name(*.result))]
    Refused {
        /// Its MAV_RESULT.
        result: MavResult,
    },
    /// The camera never acknowledged the command.
    #[error("the camera did not answer IMAGE_START_CAPTURE ({0})")]
    NoAnswer(CommandError),
    /// The photo was taken (acknowledged), but its CAMERA_IMAGE_CAPTURED never came, even
    /// asked for again.
    #[error("the camera took the photo but never announced it{}", match .index {
        Some(i) => alloc::format!(" (image {i}, asked for again {} times)", .asked),
        None => alloc::string::String::new(),
    })]
    NeverAnnounced {
        /// The index it should have had, when known.
        index: Option<i32>,
        /// How many times it was asked for.
        asked: u8,
    },
}

fn result_name(r: MavResult) -> &'static str {
    r.name()
        .and_then(|n| n.strip_prefix("MAV_RESULT_"))
        .unwrap_or("UNKNOWN")
}

/// How a lost announcement is asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Resend {
    /// MAV_CMD_REQUEST_MESSAGE(CAMERA_IMAGE_CAPTURED, index).
    RequestMessage,
    /// MAV_CMD_REQUEST_CAMERA_IMAGE_CAPTURE(index), for cameras that refuse the first
    /// (MAVSDK's camera server answers REQUEST_MESSAGE only for a few messages).
    Legacy,
    /// Neither is taken: only waiting.
    Wait,
}

/// One photo: MAV_CMD_IMAGE_START_CAPTURE (one image, a sequence number so that a retry
/// does not take a second), then its CAMERA_IMAGE_CAPTURED. The photo's index is the
/// camera's image count before the shot (CAMERA_CAPTURE_STATUS, read by the caller); an
/// announcement with that index or a later one ends it. When the camera accepted the photo
/// but no announcement came within [`CaptureConfig::resend_after`], it is asked for again
/// by its index — MAV_CMD_REQUEST_MESSAGE, and where the camera refuses that,
/// MAV_CMD_REQUEST_CAMERA_IMAGE_CAPTURE — up to [`CaptureConfig::resends`] times. A
/// [`Service`]: drive it and read [`poll_result`](Self::poll_result).
#[derive(Debug)]
pub struct PhotoCapture {
    camera: Address,
    config: CaptureConfig,
    commands: CommandClient,
    shot: Option<CommandHandle>,
    expected: Option<i32>,
    resend: Resend,
    resend_command: Option<CommandHandle>,
    next_resend: Option<Instant>,
    asked: u8,
    result: Option<Result<ImageCaptured, CaptureError>>,
    taken: bool,
}

impl PhotoCapture {
    /// Takes a photo with the camera at `camera`, as `own`; `expected` is the index it will
    /// have (the camera's image count before it), `sequence` the command's sequence number
    /// (from 1, a new one per photo).
    #[must_use]
    pub fn start(
        now: Instant,
        own: Address,
        camera: Address,
        expected: Option<i32>,
        sequence: u32,
        config: CaptureConfig,
    ) -> Self {
        let mut commands = CommandClient::new(own, config.command);
        let shot = Command::long(
            MavCmd::IMAGE_START_CAPTURE,
            [0.0, 0.0, 1.0, sequence as f32, 0.0, 0.0, f32::NAN],
        );
        let sent = commands.send(now, camera, shot);
        let result = sent
            .is_err()
            .then_some(Err(CaptureError::NoAnswer(CommandError::TimedOut {
                attempts: 0,
            })));
        Self {
            camera,
            config,
            commands,
            shot: sent.ok(),
            expected,
            resend: Resend::RequestMessage,
            resend_command: None,
            next_resend: None,
            asked: 0,
            result,
            taken: false,
        }
    }

    /// The photo's announcement once it came (its `success` says whether the camera took
    /// it), or why none will; given once.
    pub fn poll_result(&mut self) -> Option<Result<ImageCaptured, CaptureError>> {
        if self.taken {
            return None;
        }
        let r = self.result.clone()?;
        self.taken = true;
        Some(r)
    }

    /// How many times the announcement was asked for again.
    #[must_use]
    pub const fn asked_again(&self) -> u8 {
        self.asked
    }

    fn finish(&mut self, result: Result<ImageCaptured, CaptureError>) {
        if self.result.is_none() {
            self.result = Some(result);
            self.next_resend = None;
        }
    }

    fn ask_again(&mut self, now: Instant) {
        self.asked += 1;
        self.next_resend = Some(now + self.config.resend_after);
        let Some(index) = self.expected else { return };
        let command = match self.resend {
            Resend::RequestMessage => Command::long(
                MavCmd::REQUEST_MESSAGE,
                [
                    CameraImageCaptured::ID as f32,
                    index as f32,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                    0.0,
                ],
            ),
            Resend::Legacy => Command::long(
                MavCmd::REQUEST_CAMERA_IMAGE_CAPTURE,
                [
                    index as f32,
                    f32::NAN,
                    f32::NAN,
                    f32::NAN,
                    0.0,
                    0.0,
                    f32::NAN,
                ],
            ),
            Resend::Wait => return,
        };
        if let Some(h) = self.resend_command.take() {
            self.commands.cancel(h);
        }
        self.resend_command = self.commands.send(now, self.camera, command).ok();
    }

    /// The photo announced in another form than CAMERA_IMAGE_CAPTURED, converted by the
    /// caller: ArduPilot announces a photo only with CAMERA_FEEDBACK (its own dialect's
    /// message, which this crate's messages lack). Taken as the announcement under the
    /// same rule (from the camera, an index not below the one expected). Whether it was.
    pub fn handle_announcement(&mut self, from: Address, image: ImageCaptured) -> bool {
        if from != self.camera
            || self.result.is_some()
            || self.expected.is_some_and(|e| image.index < e)
        {
            return false;
        }
        self.finish(Ok(image));
        true
    }

    fn command_events(&mut self, now: Instant) {
        while let Some(e) = self.commands.poll_event() {
            let CommandEvent::Finished { handle, result } = e else {
                continue;
            };
            if Some(handle) == self.shot {
                match result {
                    Ok(_) => {
                        if self.result.is_none() && self.next_resend.is_none() {
                            self.next_resend = Some(now + self.config.resend_after);
                        }
                    }
                    Err(CommandError::Rejected { result, .. }) => {
                        self.finish(Err(CaptureError::Refused { result }));
                    }
                    Err(e) => self.finish(Err(CaptureError::NoAnswer(e))),
                }
            } else if Some(handle) == self.resend_command {
                self.resend_command = None;
                if let Err(CommandError::Rejected { .. }) = result {
                    // The next request goes the other way.
                    self.resend = match self.resend {
                        Resend::RequestMessage => Resend::Legacy,
                        _ => Resend::Wait,
                    };
                }
            }
        }
    }
}

impl Service for PhotoCapture {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        if from != self.camera {
            return false;
        }
        match message {
            MavMessage::CommandAck(_) => {
                let used = self.commands.handle_message(now, from, message);
                self.command_events(now);
                used
            }
            MavMessage::CameraImageCaptured(m) => {
                if self.result.is_none() && self.expected.is_none_or(|e| m.image_index >= e) {
                    self.finish(Ok(ImageCaptured::from_message(m)));
                }
                true
            }
            _ => false,
        }
    }

    fn handle_timeout(&mut self, now: Instant) {
        self.commands.handle_timeout(now);
        self.command_events(now);
        if let Some(due) = self.next_resend
            && now >= due
            && self.result.is_none()
        {
            if self.asked >= self.config.resends {
                let asked = self.asked;
                let index = self.expected;
                self.finish(Err(CaptureError::NeverAnnounced { index, asked }));
            } else {
                self.ask_again(now);
            }
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        self.commands.poll_transmit()
    }

    fn poll_timeout(&self) -> Option<Instant> {
        if self.result.is_some() {
            return None;
        }
        crate::earliest(self.commands.poll_timeout(), self.next_resend)
    }
}
