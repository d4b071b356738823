//! Modes asked for and told about, as each flight stack answers (seen on ArduPilot Copter
//! 4.7-dev SITL and PX4 1.16 SITL):
//!
//! | | ArduPilot | PX4 |
//! | --- | --- | --- |
//! | REQUEST_MESSAGE(AVAILABLE_MODES, 0) | ACCEPTED, then only the first mode (the others are sent only while the message is due again, which it is not on SITL's SERIAL0); AVAILABLE_MODES_MONITOR every 5 s from then on | ACCEPTED, every mode |
//! | REQUEST_MESSAGE(AVAILABLE_MODES, i) | that mode; beyond the list ACCEPTED and nothing | that mode; beyond the list DENIED |
//! | CURRENT_MODE | never (REQUEST_MESSAGE: FAILED) | streamed every 2 s and on request, with the intended mode |
//! | MAV_CMD_DO_SET_STANDARD_MODE | UNSUPPORTED | ACCEPTED, FAILED for a standard mode it has none for, TEMPORARILY_REJECTED when the mode cannot run |
//! | MAV_CMD_DO_SET_MODE | FAILED for an unknown number ("No such mode N") or a mode that fails to start (its reasons) | two ACKs: ACCEPTED from the MAVLink receiver at once, then the commander's, ACCEPTED or TEMPORARILY_REJECTED with "Switching to X is currently not available" |

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    AvailableModes, AvailableModesMonitor, CommandAck, CurrentMode, MavCmd, MavMessage, MavResult,
    MavSeverity, MavStandardMode,
};
use mavstack_services::command::{Request, Response};
use mavstack_services::stream::Interval;
use mavstack_services::{Address, Outgoing};

use super::Craft;
use crate::Autopilot;
use crate::modes::{self, Entry, Mode, Px4Request};

/// How often ArduPilot sends AVAILABLE_MODES_MONITOR once AVAILABLE_MODES was asked for.
const MONITOR_EVERY: Duration = Duration::from_secs(5);

/// MAV_COMP_ID_MISSIONPLANNER: PX4 says why it refuses a mode only to this component.
const MISSIONPLANNER: u8 = 190;

/// AVAILABLE_MODES for mode `index` (from 1) of a flavour.
pub(crate) fn available_mode(autopilot: Autopilot, index: u8) -> Option<AvailableModes> {
    let all = modes::modes(autopilot);
    let mode = all.get(usize::from(index).checked_sub(1)?)?;
    let mut mode_name = [0u8; 35];
    let n = mode.listed.len().min(34);
    mode_name[..n].copy_from_slice(&mode.listed.as_bytes()[..n]);
    Some(AvailableModes {
        number_modes: u8::try_from(all.len()).unwrap_or(u8::MAX),
        mode_index: index,
        standard_mode: mode.standard,
        custom_mode: mode.custom_mode,
        properties: mode.properties,
        mode_name,
    })
}

/// CURRENT_MODE of a craft in `mode`, which the user asked for `intended`.
pub(crate) fn current_mode(mode: Mode, intended: Mode) -> CurrentMode {
    CurrentMode {
        standard_mode: mode.standard,
        custom_mode: mode.custom_mode,
        intended_custom_mode: intended.custom_mode,
    }
}

/// PX4's name of a mode in its messages (`mode_util::nav_state_names`).
fn px4_ui_name(mode: Mode) -> String {
    match mode.name {
        "AUTO.LOITER" => "Hold".to_owned(),
        "ALTCTL" => "Altitude".to_owned(),
        "POSCTL" => "Position".to_owned(),
        "AUTO.MISSION" => "Mission".to_owned(),
        "AUTO.RTL" => "Return".to_owned(),
        "AUTO.TAKEOFF" => "Takeoff".to_owned(),
        "AUTO.LAND" => "Land".to_owned(),
        "POSCTL.ORBIT" => "Orbit".to_owned(),
        name => match name.strip_prefix("AUTO.EXTERNAL") {
            Some(n) => format!("External {n}"),
            None => mode.listed.to_owned(),
        },
    }
}

impl Craft {
    /// MAV_CMD_REQUEST_MESSAGE(AVAILABLE_MODES, `index`): the modes go out after the ACK.
    pub(super) fn request_available_modes(
        &mut self,
        now: Instant,
        from: Address,
        index: f32,
    ) -> Response {
        let count = modes::modes(self.autopilot).len();
        let index = if index.is_finite() && index >= 0.0 {
            index.round() as usize
        } else {
            usize::MAX
        };
        let wanted: Vec<u8> = match (self.autopilot, index) {
            // ArduPilot 4.7 sends the first and goes on only while the message is due again.
            (Autopilot::Ardupilot, 0) => vec![1],
            (Autopilot::Px4, 0) => (1..=count).filter_map(|i| u8::try_from(i).ok()).collect(),
            (_, i) if i <= count => u8::try_from(i).map(|i| vec![i]).unwrap_or_default(),
            (Autopilot::Ardupilot, _) => Vec::new(),
            (Autopilot::Px4, _) => return Response::done(MavResult::DENIED),
        };
        for i in wanted {
            if let Some(m) = available_mode(self.autopilot, i) {
                self.replies.push_back(Outgoing {
                    target: from,
                    message: MavMessage::AvailableModes(m),
                });
            }
        }
        if self.autopilot == Autopilot::Ardupilot {
            let _ = self.streams.set_interval(
                now,
                AvailableModesMonitor::ID,
                Interval::Every(MONITOR_EVERY),
            );
        }
        Response::done(MavResult::ACCEPTED)
    }

    /// CURRENT_MODE as the craft is now (PX4).
    pub(super) fn current_mode(&self) -> CurrentMode {
        let mode = self.flight.mode();
        current_mode(mode, self.control.intended().unwrap_or(mode))
    }

    /// MAV_CMD_DO_SET_MODE.
    pub(super) fn do_set_mode(&mut self, now: Instant, request: &Request, p: [f32; 4]) -> Response {
        match self.autopilot {
            Autopilot::Ardupilot => {
                let number = modes::custom_mode_of_command(self.autopilot, p[1], p[2]);
                match modes::by_custom_mode(self.autopilot, number) {
                    Some(mode) => self.ardupilot_enter(mode),
                    None => {
                        self.tell(MavSeverity::WARNING, format!("No such mode {number}"));
                        Response::done(MavResult::FAILED)
                    }
                }
            }
            Autopilot::Px4 => {
                // PX4's MAVLink receiver acknowledges the command before its commander runs it.
                self.early.push_back(Outgoing {
                    target: request.from,
                    message: MavMessage::CommandAck(CommandAck {
                        command: MavCmd::DO_SET_MODE,
                        result: MavResult::ACCEPTED,
                        target_system: request.from.system,
                        target_component: request.from.component,
                        ..CommandAck::default()
                    }),
                });
                match modes::px4_request(p[0], p[1], p[2]) {
                    Px4Request::Mode(mode) => {
                        if self.control.px4_can_enter(now, &self.flight, mode) {
                            self.set_mode(mode);
                            return Response::done(MavResult::ACCEPTED);
                        }
                        if request.from.component == MISSIONPLANNER {
                            let name = px4_ui_name(mode);
                            self.tell(
                                MavSeverity::CRITICAL,
                                format!("Switching to {name} is currently not available\t"),
                            );
                        }
                        Response::done(MavResult::TEMPORARILY_REJECTED)
                    }
                    Px4Request::UnsupportedAuto => {
                        self.tell(MavSeverity::CRITICAL, "Unsupported auto mode\t".to_owned());
                        Response::done(MavResult::TEMPORARILY_REJECTED)
                    }
                    Px4Request::Nothing => Response::done(MavResult::ACCEPTED),
                }
            }
        }
    }

    /// SET_MODE (the message): the mode entered as by MAV_CMD_DO_SET_MODE, nothing answered.
    pub(crate) fn set_mode_message(&mut self, now: Instant, custom_mode: u32) {
        let Some(mode) = modes::by_custom_mode(self.autopilot, custom_mode) else {
            return;
        };
        let allowed = match self.autopilot {
            Autopilot::Ardupilot => !matches!(mode.entry, Entry::Refused(_)),
            Autopilot::Px4 => self.control.px4_can_enter(now, &self.flight, mode),
        };
        if allowed {
            self.set_mode(mode);
        }
    }

    /// ArduPilot entering `mode`: FAILED with its reasons where it fails to start.
    fn ardupilot_enter(&mut self, mode: Mode) -> Response {
        if let Entry::Refused(lines) = mode.entry {
            for line in lines {
                self.tell(MavSeverity::WARNING, (*line).to_owned());
            }
            return Response::done(MavResult::FAILED);
        }
        self.set_mode(mode);
        Response::done(MavResult::ACCEPTED)
    }

    /// MAV_CMD_DO_SET_STANDARD_MODE(`standard`).
    pub(super) fn do_set_standard_mode(&mut self, now: Instant, standard: f32) -> Response {
        if self.autopilot == Autopilot::Ardupilot {
            return Response::done(MavResult::UNSUPPORTED);
        }
        let standard = if standard.is_finite() && (0.0..=255.0).contains(&standard) {
            MavStandardMode(standard.round() as u8)
        } else {
            MavStandardMode::NON_STANDARD
        };
        let Some(mode) = modes::by_standard(self.autopilot, standard) else {
            return Response::done(MavResult::FAILED);
        };
        if !self.control.px4_can_enter(now, &self.flight, mode) {
            return Response::done(MavResult::TEMPORARILY_REJECTED);
        }
        self.set_mode(mode);
        Response::done(MavResult::ACCEPTED)
    }
}
