//! The craft and its telemetry: the command handler of the vehicle, the messages it
//! streams, and the vehicle's clock.

use core::time::Duration;
use std::collections::VecDeque;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, AutopilotVersion, AvailableModes, AvailableModesMonitor, BatteryStatus,
    ComponentMetadata, CurrentMode, ExtendedSysState, GlobalPositionInt, GpsFixType, GpsRawInt,
    Heartbeat, HomePosition, LocalPositionNed, MavAutopilot, MavBatteryChargeState,
    MavBatteryFunction, MavBatteryType, MavCmd, MavDataStream, MavMessage, MavModeFlag,
    MavProtocolCapability, MavResult, MavSeverity, MavState, MavSysStatusSensor, MavType,
    MavVtolState, MissionCurrent, MissionState, RequestDataStream, SysStatus, VfrHud,
};
use mavstack_services::command::{Command, CommandHandler, Request, Response};
use mavstack_services::stream::{self, Interval, StreamScheduler, request_message};
use mavstack_services::{Address, Outgoing};

use crate::control::Control;
use crate::flight::{Flight, HOME_AMSL, Position};
use crate::modes::{self, Behaviour, Mode};
use crate::{Autopilot, events};

/// The flight software version both flavours give (AUTOPILOT_VERSION, the shell's `ver`):
/// 4.1.0, a release.
pub(crate) const FLIGHT_SW_VERSION: u32 = 0x0401_00ff;

mod mode_commands;

/// The vehicle's clock: the time since it started, which it reads as a flight stack reads
/// the time since its boot. Every time field it sends comes from here, never from the
/// driver's [`Instant`] itself, whose epoch is the driver's choice (the transport's clock
/// counts from the Unix epoch).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Boot(pub(crate) Instant);

impl Boot {
    fn since(self, now: Instant) -> Duration {
        now.saturating_duration_since(self.0)
    }

    /// Milliseconds since boot for a `time_boot_ms` field: it wraps after 49.7 days, as
    /// ArduPilot's and PX4's 32-bit millisecond counters do.
    pub(crate) fn ms(self, now: Instant) -> u32 {
        // Truncation is the wrap.
        self.since(now).as_millis() as u32
    }

    /// Microseconds since boot for a `time_usec` field.
    pub(crate) fn us(self, now: Instant) -> u64 {
        u64::try_from(self.since(now).as_micros()).unwrap_or(u64::MAX)
    }

    /// What turns the driver's time in nanoseconds into nanoseconds since boot (TIMESYNC's
    /// [`clock_offset_ns`]): ArduPilot and PX4 answer TIMESYNC with their time since boot.
    ///
    /// [`clock_offset_ns`]: mavstack_services::timesync::TimesyncConfig::clock_offset_ns
    pub(crate) fn timesync_offset_ns(self) -> i64 {
        i64::try_from(self.0.as_micros())
            .unwrap_or(i64::MAX)
            .saturating_mul(1_000)
            .saturating_neg()
    }
}

/// The messages the vehicle of a flavour streams and their default intervals (`None`: on
/// request only): [`STREAMS`], and PX4's CURRENT_MODE every 2 s (`mavlink_main.cpp`
/// configures it at 0.5 Hz), ArduPilot's AVAILABLE_MODES_MONITOR once AVAILABLE_MODES was
/// asked for.
pub(crate) fn streams(autopilot: Autopilot) -> Vec<(u32, Option<Duration>)> {
    let mut all = STREAMS.to_vec();
    all.push(match autopilot {
        Autopilot::Ardupilot => (AvailableModesMonitor::ID, None),
        Autopilot::Px4 => (CurrentMode::ID, Some(Duration::from_secs(2))),
    });
    all
}

/// The messages both flavours stream and their default intervals (`None`: on request only).
const STREAMS: &[(u32, Option<Duration>)] = &[
    (Heartbeat::ID, Some(Duration::from_secs(1))),
    (SysStatus::ID, Some(Duration::from_secs(1))),
    (GpsRawInt::ID, Some(Duration::from_secs(1))),
    (Attitude::ID, Some(Duration::from_millis(250))),
    (GlobalPositionInt::ID, Some(Duration::from_millis(250))),
    (LocalPositionNed::ID, Some(Duration::from_millis(250))),
    (MissionCurrent::ID, Some(Duration::from_secs(1))),
    (VfrHud::ID, Some(Duration::from_millis(500))),
    (BatteryStatus::ID, Some(Duration::from_secs(1))),
    (AutopilotVersion::ID, None),
    (HomePosition::ID, Some(Duration::from_secs(5))),
    (ExtendedSysState::ID, Some(Duration::from_secs(1))),
];

/// The craft and its telemetry: the command handler of the vehicle.
#[derive(Debug)]
pub(crate) struct Craft {
    pub(crate) autopilot: Autopilot,
    pub(crate) mavlink2: bool,
    pub(crate) ftp: bool,
    pub(crate) flight: Flight,
    pub(crate) streams: StreamScheduler,
    /// Mission items made current by a command, for the mission server.
    pub(crate) new_current: Option<u16>,
    /// When the estimator is ready (arming is refused before).
    pub(crate) ready_at: Instant,
    /// SET_MESSAGE_INTERVAL refused: rates only through REQUEST_DATA_STREAM.
    pub(crate) data_streams_only: bool,
    /// EVENTs to send (the PX4 flavour says why it refuses in them).
    pub(crate) events: events::Events,
    /// Its clock, for the time fields of what it sends.
    pub(crate) boot: Boot,
    /// Setpoints and sticks, and the failsafes of their loss.
    pub(crate) control: Control,
    /// Messages answering a command, sent after its ACK (AVAILABLE_MODES).
    pub(crate) replies: VecDeque<Outgoing>,
    /// Messages sent before the ACK of the command that caused them (PX4's first ACK of
    /// MAV_CMD_DO_SET_MODE).
    pub(crate) early: VecDeque<Outgoing>,
    /// Lines for STATUSTEXT with their severity.
    pub(crate) said: Vec<(MavSeverity, String)>,
}

/// The numeric params of a command: p1–p4, latitude and longitude in degrees (`None` when
/// not given), and p7/z.
struct Params {
    p: [f32; 4],
    lat: Option<f64>,
    lon: Option<f64>,
    z: f32,
}

fn params_of(command: &Command) -> Params {
    match command {
        Command::Long(c) => {
            let deg = |v: f32| (v.is_finite() && v != 0.0).then_some(f64::from(v));
            Params {
                p: [c.param1, c.param2, c.param3, c.param4],
                lat: deg(c.param5),
                lon: deg(c.param6),
                z: c.param7,
            }
        }
        Command::Int(c) => {
            let deg = |v: i32| (v != 0 && v != i32::MAX).then_some(f64::from(v) / 1e7);
            Params {
                p: [c.param1, c.param2, c.param3, c.param4],
                lat: deg(c.x),
                lon: deg(c.y),
                z: c.z,
            }
        }
    }
}

impl Craft {
    /// The mode the user (a command, SET_MODE) asked for: it ends a failsafe.
    pub(crate) fn set_mode(&mut self, mode: Mode) {
        self.control.user_mode_change();
        self.flight.set_mode(mode);
    }

    /// A line for STATUSTEXT.
    fn tell(&mut self, severity: MavSeverity, text: String) {
        self.said.push((severity, text));
    }

    fn mode_with(&self, behaviour: Behaviour) -> Mode {
        modes::with_behaviour(self.autopilot, behaviour)
    }

    /// A take-off altitude from param7: relative for ArduPilot, above mean sea level for
    /// PX4 (which also takes NaN for "the configured height").
    fn takeoff_alt(&self, z: f32) -> Option<f32> {
        if !z.is_finite() {
            return None;
        }
        match self.autopilot {
            Autopilot::Ardupilot => Some(z),
            Autopilot::Px4 if z > HOME_AMSL - 100.0 => Some(z - HOME_AMSL),
            Autopilot::Px4 => Some(z),
        }
    }

    fn one_shot(&mut self, now: Instant, from: Address, msg_id: u32) -> Response {
        let request = Request {
            from,
            command: request_message(msg_id, [0.0; 5]),
        };
        self.streams
            .handle_command(now, &request)
            .unwrap_or(Response::done(MavResult::FAILED))
    }

    /// MAV_CMD_DO_REPOSITION with the change-mode flags `flags` (param2) to `lat`, `lon` and
    /// `z` metres above mean sea level. ArduPilot: armed, it flies there in GUIDED. PX4 1.16
    /// (`Commander`, `Navigator`): flag 1 switches to Hold (ACCEPTED, also disarmed); without
    /// it UNSUPPORTED; armed, the point is flown to in Hold either way, disarmed it is not
    /// kept.
    fn reposition(&mut self, flags: f32, lat: Option<f64>, lon: Option<f64>, z: f32) -> Response {
        let alt = z.is_finite().then_some(z - HOME_AMSL);
        let armed = self.flight.is_armed();
        match self.autopilot {
            Autopilot::Ardupilot => {
                if !armed {
                    return Response::done(MavResult::DENIED);
                }
                self.control.user_mode_change();
                self.flight.go_to(lat, lon, alt);
                Response::done(MavResult::ACCEPTED)
            }
            Autopilot::Px4 => {
                let change_mode = flags.is_finite() && flags as u32 == 1;
                let in_hold = self.flight.mode().behaviour == Behaviour::Hold;
                if armed && (change_mode || in_hold) {
                    self.control.user_mode_change();
                    self.flight.go_to(lat, lon, alt);
                } else if change_mode {
                    let hold = self.mode_with(Behaviour::Hold);
                    self.set_mode(hold);
                }
                Response::done(if change_mode {
                    MavResult::ACCEPTED
                } else {
                    MavResult::UNSUPPORTED
                })
            }
        }
    }

    pub(crate) fn heartbeat(&self) -> Heartbeat {
        let mode = self.flight.mode();
        let mut base = MavModeFlag::CUSTOM_MODE_ENABLED | MavModeFlag::STABILIZE_ENABLED;
        if self.flight.is_armed() {
            base |= MavModeFlag::SAFETY_ARMED;
        }
        if mode.behaviour != Behaviour::Manual {
            base |= MavModeFlag::GUIDED_ENABLED;
        }
        if matches!(
            mode.behaviour,
            Behaviour::Mission | Behaviour::ReturnToLaunch | Behaviour::Land | Behaviour::Takeoff
        ) {
            base |= MavModeFlag::AUTO_ENABLED;
        }
        Heartbeat {
            r#type: MavType::QUADROTOR,
            autopilot: match self.autopilot {
                Autopilot::Ardupilot => MavAutopilot::ARDUPILOTMEGA,
                Autopilot::Px4 => MavAutopilot::PX4,
            },
            base_mode: base,
            custom_mode: mode.custom_mode,
            system_status: if self.flight.is_armed() {
                MavState::ACTIVE
            } else {
                MavState::STANDBY
            },
            mavlink_version: 3,
        }
    }

    fn autopilot_version(&self) -> AutopilotVersion {
        let mut capabilities = MavProtocolCapability::MISSION_INT
            | MavProtocolCapability::COMMAND_INT
            | MavProtocolCapability::MISSION_FENCE
            | MavProtocolCapability::MISSION_RALLY
            | MavProtocolCapability::SET_POSITION_TARGET_GLOBAL_INT;
        capabilities |= match self.autopilot {
            Autopilot::Ardupilot => MavProtocolCapability::PARAM_ENCODE_C_CAST,
            Autopilot::Px4 => MavProtocolCapability::PARAM_ENCODE_BYTEWISE,
        };
        if self.mavlink2 {
            capabilities |= MavProtocolCapability::MAVLINK2;
        }
        if self.ftp {
            capabilities |= MavProtocolCapability::FTP;
        }
        AutopilotVersion {
            capabilities,
            flight_sw_version: FLIGHT_SW_VERSION,
            vendor_id: 0x1209,
            product_id: 0x5741,
            uid: 0x6d61_7673_7461_636b,
            ..AutopilotVersion::default()
        }
    }

    /// The message `msg_id` as the craft is now.
    pub(crate) fn message(&self, now: Instant, msg_id: u32) -> Option<MavMessage> {
        let f = &self.flight;
        let (boot_us, boot_ms) = (self.boot.us(now), self.boot.ms(now));
        let here = f.position();
        let [vn, ve, vd] = f.velocity();
        let ground_speed = vn.hypot(ve);
        let degrees = |rad: f32| rad.to_degrees().rem_euclid(360.0);
        let e7 = |deg: f64| (deg * 1e7) as i32;
        let amsl_mm = |rel: f32| ((rel + HOME_AMSL) * 1000.0) as i32;
        let (left, volts, amps, used) = f.battery();
        let percent = (left * 100.0).round() as i8;
        Some(match msg_id {
            Heartbeat::ID => MavMessage::Heartbeat(self.heartbeat()),
            ComponentMetadata::ID => {
                MavMessage::ComponentMetadata(events::component_metadata(boot_ms))
            }
            SysStatus::ID => {
                let sensors = MavSysStatusSensor(
                    MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_MAG.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_GPS.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_AHRS.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY.0
                        | MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK.0,
                );
                MavMessage::SysStatus(SysStatus {
                    onboard_control_sensors_present: sensors,
                    onboard_control_sensors_enabled: sensors,
                    onboard_control_sensors_health: sensors,
                    load: 250,
                    voltage_battery: (volts * 1000.0) as u16,
                    current_battery: (amps * 100.0) as i16,
                    battery_remaining: percent,
                    ..SysStatus::default()
                })
            }
            GpsRawInt::ID => MavMessage::GpsRawInt(GpsRawInt {
                time_usec: boot_us,
                fix_type: GpsFixType::GPS_FIX_TYPE_3D_FIX,
                lat: e7(here.lat),
                lon: e7(here.lon),
                alt: amsl_mm(here.alt),
                eph: 70,
                epv: 120,
                vel: (ground_speed * 100.0) as u16,
                cog: (degrees(ve.atan2(vn)) * 100.0) as u16,
                satellites_visible: 14,
                ..GpsRawInt::default()
            }),
            Attitude::ID => {
                let heading = f.heading();
                // Lean into the direction of travel: pitch down for forward speed.
                let (sin, cos) = heading.sin_cos();
                let forward = vn * cos + ve * sin;
                let right = -vn * sin + ve * cos;
                MavMessage::Attitude(Attitude {
                    time_boot_ms: boot_ms,
                    roll: (right * 0.03).clamp(-0.5, 0.5),
                    pitch: (-forward * 0.03).clamp(-0.5, 0.5),
                    yaw: if heading > core::f32::consts::PI {
                        heading - 2.0 * core::f32::consts::PI
                    } else {
                        heading
                    },
                    ..Attitude::default()
                })
            }
            GlobalPositionInt::ID => MavMessage::GlobalPositionInt(GlobalPositionInt {
                time_boot_ms: boot_ms,
                lat: e7(here.lat),
                lon: e7(here.lon),
                alt: amsl_mm(here.alt),
                relative_alt: (here.alt * 1000.0) as i32,
                vx: (vn * 100.0) as i16,
                vy: (ve * 100.0) as i16,
                vz: (vd * 100.0) as i16,
                hdg: (degrees(f.heading()) * 100.0) as u16,
            }),
            VfrHud::ID => MavMessage::VfrHud(VfrHud {
                airspeed: ground_speed,
                groundspeed: ground_speed,
                heading: degrees(f.heading()) as i16,
                throttle: if f.is_airborne() { 45 } else { 0 },
                alt: here.alt + HOME_AMSL,
                climb: -vd,
            }),
            MissionCurrent::ID => {
                let total = u16::try_from(f.mission_len()).unwrap_or(u16::MAX);
                let state = if total == 0 {
                    MissionState::NO_MISSION
                } else if f.mission_done() {
                    MissionState::COMPLETE
                } else if f.mode().behaviour == Behaviour::Mission && f.is_armed() {
                    MissionState::ACTIVE
                } else {
                    MissionState::NOT_STARTED
                };
                MavMessage::MissionCurrent(MissionCurrent {
                    seq: f.current_item(),
                    total,
                    mission_state: state,
                    mission_mode: u8::from(f.mode().behaviour == Behaviour::Mission),
                })
            }
            BatteryStatus::ID => {
                let mut voltages = [u16::MAX; 10];
                for cell in &mut voltages[..4] {
                    *cell = (volts / 4.0 * 1000.0) as u16;
                }
                MavMessage::BatteryStatus(BatteryStatus {
                    id: 0,
                    battery_function: MavBatteryFunction::ALL,
                    r#type: MavBatteryType::LIPO,
                    temperature: i16::MAX,
                    voltages,
                    current_battery: (amps * 100.0) as i16,
                    current_consumed: used as i32,
                    energy_consumed: -1,
                    battery_remaining: percent,
                    charge_state: MavBatteryChargeState::OK,
                    ..BatteryStatus::default()
                })
            }
            AutopilotVersion::ID => MavMessage::AutopilotVersion(self.autopilot_version()),
            HomePosition::ID => {
                let home = f.home();
                MavMessage::HomePosition(HomePosition {
                    latitude: e7(home.lat),
                    longitude: e7(home.lon),
                    altitude: amsl_mm(home.alt),
                    q: [1.0, 0.0, 0.0, 0.0],
                    time_usec: boot_us,
                    ..HomePosition::default()
                })
            }
            // ArduPilot Copter says MC; PX4 on a multicopter UNDEFINED.
            ExtendedSysState::ID => MavMessage::ExtendedSysState(ExtendedSysState {
                vtol_state: match self.autopilot {
                    Autopilot::Ardupilot => MavVtolState::MC,
                    Autopilot::Px4 => MavVtolState::UNDEFINED,
                },
                landed_state: f.landed_state(),
            }),
            LocalPositionNed::ID => {
                let [x, y, z] = f.local_position();
                MavMessage::LocalPositionNed(LocalPositionNed {
                    time_boot_ms: boot_ms,
                    x,
                    y,
                    z,
                    vx: vn,
                    vy: ve,
                    vz: vd,
                })
            }
            CurrentMode::ID if self.autopilot == Autopilot::Px4 => {
                MavMessage::CurrentMode(self.current_mode())
            }
            AvailableModesMonitor::ID if self.autopilot == Autopilot::Ardupilot => {
                MavMessage::AvailableModesMonitor(AvailableModesMonitor { seq: 0 })
            }
            _ => return None,
        })
    }

    pub(crate) fn request_data_stream(&mut self, now: Instant, r: &RequestDataStream) {
        let interval = if r.start_stop == 0 || r.req_message_rate == 0 {
            Interval::Disabled
        } else {
            Interval::Every(Duration::from_secs(1) / u32::from(r.req_message_rate))
        };
        let groups: Vec<MavDataStream> = if r.req_stream_id == MavDataStream::ALL {
            (1..=12).map(MavDataStream).collect()
        } else {
            vec![r.req_stream_id]
        };
        for group in groups {
            for &id in stream::data_stream_members(group) {
                // ArduPilot 4.7 has EXTENDED_SYS_STATE in no group (on request only).
                if self.autopilot == Autopilot::Ardupilot && id == ExtendedSysState::ID {
                    continue;
                }
                // Ids of a group the simulator does not send are refused: nothing to do.
                let _ = self.streams.set_interval(now, id, interval);
            }
        }
    }
}

impl CommandHandler for Craft {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        let done = Response::done;
        let accepted = done(MavResult::ACCEPTED);
        let Params { p, lat, lon, z } = params_of(&request.command);
        match request.command.id() {
            MavCmd::SET_MESSAGE_INTERVAL if self.data_streams_only => done(MavResult::UNSUPPORTED),
            // PX4 answers REQUEST_MESSAGE only for messages it has a stream of: not for
            // MESSAGE_INTERVAL (244), which it gives for GET_MESSAGE_INTERVAL alone.
            MavCmd::REQUEST_MESSAGE if self.autopilot == Autopilot::Px4 && p[0] == 244.0 => {
                done(MavResult::DENIED)
            }
            MavCmd::REQUEST_MESSAGE if p[0] == AvailableModes::ID as f32 => {
                self.request_available_modes(now, request.from, p[1])
            }
            // ArduPilot has no CURRENT_MODE: a message it does not know is FAILED.
            MavCmd::REQUEST_MESSAGE
                if self.autopilot == Autopilot::Ardupilot && p[0] == CurrentMode::ID as f32 =>
            {
                done(MavResult::FAILED)
            }
            MavCmd::SET_MESSAGE_INTERVAL
            | MavCmd::REQUEST_MESSAGE
            | MavCmd::GET_MESSAGE_INTERVAL => self
                .streams
                .handle_command(now, request)
                .unwrap_or(done(MavResult::FAILED)),
            MavCmd::REQUEST_AUTOPILOT_CAPABILITIES => {
                self.one_shot(now, request.from, AutopilotVersion::ID)
            }
            MavCmd::GET_HOME_POSITION => self.one_shot(now, request.from, HomePosition::ID),
            MavCmd::COMPONENT_ARM_DISARM => {
                // 21196 in param2 forces, as both autopilots define it.
                let (arm, force) = (p[0] >= 0.5, p[1] == 21196.0);
                if arm && !force && !self.flight.is_armed() && now < self.ready_at {
                    // As the flight stacks refuse (seen on their SITL): ArduPilot answers
                    // FAILED and says why in STATUSTEXT; PX4 v1.16 answers
                    // TEMPORARILY_REJECTED and says why in EVENT messages (libevents), not
                    // in STATUSTEXT.
                    return match self.autopilot {
                        Autopilot::Ardupilot => {
                            self.flight.warn("PreArm: Need Position Estimate");
                            done(MavResult::FAILED)
                        }
                        Autopilot::Px4 => {
                            let left = self.ready_at.saturating_duration_since(now);
                            self.events
                                .arm_refused(self.boot.ms(now), left.as_secs_f32());
                            done(MavResult::TEMPORARILY_REJECTED)
                        }
                    };
                }
                match self.flight.arm(arm, force) {
                    Ok(()) => accepted,
                    Err(_) => done(MavResult::DENIED),
                }
            }
            MavCmd::NAV_TAKEOFF => match self.flight.takeoff(self.takeoff_alt(z)) {
                Ok(()) => accepted,
                Err(_) => done(MavResult::FAILED),
            },
            MavCmd::NAV_LAND => {
                let land = self.mode_with(Behaviour::Land);
                self.set_mode(land);
                accepted
            }
            MavCmd::NAV_RETURN_TO_LAUNCH => {
                let rtl = self.mode_with(Behaviour::ReturnToLaunch);
                self.set_mode(rtl);
                accepted
            }
            MavCmd::DO_SET_MODE => self.do_set_mode(now, request, p),
            MavCmd::DO_SET_STANDARD_MODE => self.do_set_standard_mode(now, p[0]),
            MavCmd::MISSION_START => {
                let len = self.flight.mission_len();
                if len == 0 {
                    return done(MavResult::DENIED);
                }
                let first = if p[0] >= 1.0 && (p[0] as usize) < len {
                    p[0] as u16
                } else {
                    u16::from(self.autopilot == Autopilot::Ardupilot && len > 1)
                };
                self.flight.set_current(first);
                self.new_current = Some(first);
                let mission = self.mode_with(Behaviour::Mission);
                self.set_mode(mission);
                accepted
            }
            MavCmd::DO_SET_MISSION_CURRENT => {
                let seq = p[0];
                if seq >= 0.0 && (seq as usize) < self.flight.mission_len() {
                    self.flight.set_current(seq as u16);
                    self.new_current = Some(seq as u16);
                    accepted
                } else {
                    done(MavResult::DENIED)
                }
            }
            MavCmd::DO_CHANGE_SPEED => {
                self.flight.set_speed(p[1]);
                accepted
            }
            MavCmd::DO_REPOSITION => self.reposition(p[1], lat, lon, z),
            MavCmd::DO_SET_HOME => {
                let here = self.flight.position();
                let home = if p[0] >= 0.5 {
                    here
                } else {
                    Position {
                        lat: lat.unwrap_or(here.lat),
                        lon: lon.unwrap_or(here.lon),
                        alt: if z.is_finite() { z - HOME_AMSL } else { 0.0 },
                    }
                };
                self.flight.set_home(home);
                accepted
            }
            _ => done(MavResult::UNSUPPORTED),
        }
    }
}
