//! A simulated MAVLink vehicle, sans-IO: the vehicle behind `mavstack vehicle` and
//! `mavstack demo`, and the one a ground station's tests can run in-process.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! [`Vehicle`] puts the server roles of `mavstack-services` together around a kinematic
//! craft ([`flight::Flight`]): a [`CommandServer`] whose handler flies the craft, a
//! [`ParamServer`] with the flavour's table (or a file's), a [`MissionServer`] whose plan the
//! craft flies in mission mode, a [`StreamScheduler`] for telemetry rates, TIMESYNC, MAVFTP,
//! and log download (LOG_*) of its [`logs`] (a directory's files, or generated ones). Like
//! every service it takes decoded messages and the time, and hands out messages to send:
//! the caller moves them over its links (`mavstack vehicle` over a `mavstack-channel` link).

pub mod events;
pub mod flight;
pub mod logs;
pub mod modes;
pub mod params;

/// The autopilot a simulated vehicle claims to be: its HEARTBEAT, parameter table and
/// encoding, flight modes and mission conventions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Autopilot {
    /// ArduPilot (MAV_AUTOPILOT_ARDUPILOTMEGA, 3).
    Ardupilot,
    /// PX4 (MAV_AUTOPILOT_PX4, 12).
    Px4,
}

impl core::fmt::Display for Autopilot {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::Ardupilot => "ArduPilot",
            Self::Px4 => "PX4",
        })
    }
}

impl core::str::FromStr for Autopilot {
    type Err = String;

    /// `ardupilot` or `px4` (any case).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "ardupilot" => Ok(Self::Ardupilot),
            "px4" => Ok(Self::Px4),
            _ => Err(format!("unknown autopilot {s:?}: ardupilot or px4")),
        }
    }
}

use core::time::Duration;
use std::collections::VecDeque;

use mavstack_core::Message;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    Attitude, AutopilotVersion, BatteryStatus, ComponentMetadata, ExtendedSysState,
    GlobalPositionInt, GpsFixType, GpsRawInt, Heartbeat, HomePosition, MavAutopilot,
    MavBatteryChargeState, MavBatteryFunction, MavBatteryType, MavCmd, MavDataStream, MavFrame,
    MavMessage, MavMissionType, MavModeFlag, MavProtocolCapability, MavResult, MavSeverity,
    MavState, MavSysStatusSensor, MavType, MavVtolState, MissionCurrent, MissionItemInt,
    MissionItemReached, MissionState, RequestDataStream, Statustext, SysStatus, VfrHud,
};
use mavstack_services::command::{Command, CommandHandler, CommandServer, Request, Response};
use mavstack_services::ftp::param_pck::TableFile;
use mavstack_services::ftp::{DirBackend, FtpServer, Overlay, ServerConfig};
use mavstack_services::log_transfer::{LogServer, LogServerEvent};
use mavstack_services::mission::{
    MissionConfig, MissionServer, MissionServerEvent, StrayItems, UploadPacing,
};
use mavstack_services::param::{Encoding, Name, ParamServer, ParamServerEvent, Value};
use mavstack_services::stream::{self, Interval, StreamScheduler, request_message};
use mavstack_services::timesync::{Timesync, TimesyncConfig};
use mavstack_services::{Address, Outgoing, Service};

use self::flight::{Flight, FlightEvent, HOME_AMSL, Position, Tuning};
use self::modes::{Behaviour, Mode};

/// The vehicle's clock: the time since it started, which it reads as a flight stack reads
/// the time since its boot. Every time field it sends comes from here, never from the
/// driver's [`Instant`] itself, whose epoch is the driver's choice (the transport's clock
/// counts from the Unix epoch).
#[derive(Clone, Copy, Debug)]
struct Boot(Instant);

impl Boot {
    fn since(self, now: Instant) -> Duration {
        now.saturating_duration_since(self.0)
    }

    /// Milliseconds since boot for a `time_boot_ms` field: it wraps after 49.7 days, as
    /// ArduPilot's and PX4's 32-bit millisecond counters do.
    fn ms(self, now: Instant) -> u32 {
        // Truncation is the wrap.
        self.since(now).as_millis() as u32
    }

    /// Microseconds since boot for a `time_usec` field.
    fn us(self, now: Instant) -> u64 {
        u64::try_from(self.since(now).as_micros()).unwrap_or(u64::MAX)
    }

    /// What turns the driver's time in nanoseconds into nanoseconds since boot (TIMESYNC's
    /// [`TimesyncConfig::clock_offset_ns`]): ArduPilot and PX4 answer TIMESYNC with their
    /// time since boot.
    fn timesync_offset_ns(self) -> i64 {
        i64::try_from(self.0.as_micros())
            .unwrap_or(i64::MAX)
            .saturating_mul(1_000)
            .saturating_neg()
    }
}

/// Peers that appear later than this after the start get a HEARTBEAT of their own.
const GREETING_AFTER: Duration = Duration::from_millis(100);

/// How often the craft's model advances.
const STEP: Duration = Duration::from_millis(50);

/// What the vehicle is.
#[derive(Clone, Debug)]
pub struct SimConfig {
    /// Its address.
    pub own: Address,
    /// Which autopilot it behaves like.
    pub autopilot: Autopilot,
    /// Whether it advertises MAVLink 2 in AUTOPILOT_VERSION.
    pub mavlink2: bool,
    /// Its parameter table.
    pub params: Vec<(Name, Value)>,
    /// How long after start its estimator is not ready: arming is refused with a STATUSTEXT
    /// saying why, as flight stacks do (ArduPilot SITL takes about 40 s: `PreArm: Need
    /// Position Estimate`). Zero: ready at once.
    pub estimator_settle: Duration,
    /// Refuse SET_MESSAGE_INTERVAL (MAV_RESULT_UNSUPPORTED) and take rates only through
    /// REQUEST_DATA_STREAM, as ArduPilot before 4.0 did.
    pub data_streams_only: bool,
    /// Stream only HEARTBEAT until a rate is asked for (SET_MESSAGE_INTERVAL or
    /// REQUEST_DATA_STREAM), as ArduPilot does on a link whose stream rates are 0 (SITL's
    /// SERIAL0, and again after every restart); `false`: the default streams.
    pub streams_on_request: bool,
    /// Serve MAVFTP as the vehicle's own component, and advertise
    /// MAV_PROTOCOL_CAPABILITY_FTP: ArduPilot's packed parameter file `@PARAM/param.pck`
    /// (made from the parameter table when a client opens it; defaults: the table the
    /// vehicle started with), over [`ftp_files`](Self::ftp_files).
    pub ftp: bool,
    /// With [`ftp`](Self::ftp): the directory served beside `@PARAM` (`mavstack vehicle
    /// --ftp-root`); `None`, an empty read-only root.
    pub ftp_files: Option<DirBackend>,
    /// The logs it serves by log download (LOG_*): a directory's files (`mavstack vehicle
    /// --log-dir`), also over MAVFTP as `APM/LOGS/00000001.BIN`, ... when [`ftp`](Self::ftp)
    /// is on; `None`, the [`logs::GENERATED`] logs (LOG_* only).
    pub log_dir: Option<logs::LogDir>,
}

/// The messages the vehicle streams and their default intervals (`None`: on request only).
const STREAMS: &[(u32, Option<Duration>)] = &[
    (Heartbeat::ID, Some(Duration::from_secs(1))),
    (SysStatus::ID, Some(Duration::from_secs(1))),
    (GpsRawInt::ID, Some(Duration::from_secs(1))),
    (Attitude::ID, Some(Duration::from_millis(250))),
    (GlobalPositionInt::ID, Some(Duration::from_millis(250))),
    (MissionCurrent::ID, Some(Duration::from_secs(1))),
    (VfrHud::ID, Some(Duration::from_millis(500))),
    (BatteryStatus::ID, Some(Duration::from_secs(1))),
    (AutopilotVersion::ID, None),
    (HomePosition::ID, Some(Duration::from_secs(5))),
    (ExtendedSysState::ID, Some(Duration::from_secs(1))),
];

/// ArduPilot asks again for a mission item it has not received 1 s after its last request
/// (`wp_recv_timeout_ms = 1000U + link->get_stream_slowdown_ms()`, the slow-down 0 on a
/// network link: libraries/GCS_MAVLink/MissionItemProtocol.cpp:407-411, ArduPilot master as
/// of October 2025).
const ARDUPILOT_REREQUEST: Duration = Duration::from_secs(1);

/// ArduPilot gives an upload up 8 s after the last item (or count) it received, and sends
/// MISSION_ACK MAV_MISSION_OPERATION_CANCELLED (`upload_timeout_ms = 8000`:
/// libraries/GCS_MAVLink/MissionItemProtocol.h:95, used in MissionItemProtocol.cpp:391-404).
const ARDUPILOT_UPLOAD_TIMEOUT: Duration = Duration::from_secs(8);

/// The mission server as each flavour's autopilot runs it. The ArduPilot flavour's answers to
/// items it did not ask for are ArduPilot's (INVALID_SEQUENCE during an upload,
/// MissionItemProtocol.cpp:272-275; ERROR outside one), and so are its timings: a
/// ground station slower than the measured round trip is not asked twice (MAVProxy answers
/// both requests, and the copy is refused). The PX4 flavour keeps the round-trip pacing (PX4
/// asks again after 250 ms).
fn mission_config(autopilot: Autopilot) -> MissionConfig {
    let (stray_items, pacing) = match autopilot {
        Autopilot::Ardupilot => (
            StrayItems::ArduPilot,
            UploadPacing::Fixed {
                every: ARDUPILOT_REREQUEST,
                give_up_after: ARDUPILOT_UPLOAD_TIMEOUT,
            },
        ),
        Autopilot::Px4 => (StrayItems::Reask, UploadPacing::Adaptive),
    };
    MissionConfig {
        stray_items,
        pacing,
        ..MissionConfig::default()
    }
}

/// A plan's name in the log: "mission", "fence" or "rally".
fn plan_name(mission_type: MavMissionType) -> &'static str {
    match mission_type {
        MavMissionType::FENCE => "fence",
        MavMissionType::RALLY => "rally",
        _ => "mission",
    }
}

/// The craft and its telemetry: the command handler of the vehicle.
#[derive(Debug)]
struct Craft {
    autopilot: Autopilot,
    mavlink2: bool,
    ftp: bool,
    flight: Flight,
    streams: StreamScheduler,
    /// Mission items made current by a command, for the mission server.
    new_current: Option<u16>,
    /// When the estimator is ready (arming is refused before).
    ready_at: Instant,
    /// SET_MESSAGE_INTERVAL refused: rates only through REQUEST_DATA_STREAM.
    data_streams_only: bool,
    /// EVENTs to send (the PX4 flavour says why it refuses in them).
    events: events::Events,
    /// Its clock, for the time fields of what it sends.
    boot: Boot,
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
    fn set_mode(&mut self, mode: Mode) {
        self.flight.set_mode(mode);
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

    fn heartbeat(&self) -> Heartbeat {
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
            flight_sw_version: 0x0401_00ff,
            vendor_id: 0x1209,
            product_id: 0x5741,
            uid: 0x6d61_7673_7461_636b,
            ..AutopilotVersion::default()
        }
    }

    /// The message `msg_id` as the craft is now.
    fn message(&self, now: Instant, msg_id: u32) -> Option<MavMessage> {
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
            ExtendedSysState::ID => MavMessage::ExtendedSysState(ExtendedSysState {
                vtol_state: MavVtolState::UNDEFINED,
                landed_state: f.landed_state(),
            }),
            _ => return None,
        })
    }

    fn request_data_stream(&mut self, now: Instant, r: &RequestDataStream) {
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
            MavCmd::DO_SET_MODE => {
                let custom = modes::custom_mode_of_command(self.autopilot, p[1], p[2]);
                match modes::by_custom_mode(self.autopilot, custom) {
                    Some(mode) => {
                        self.set_mode(mode);
                        accepted
                    }
                    None => done(MavResult::DENIED),
                }
            }
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
            MavCmd::DO_REPOSITION => {
                if !self.flight.is_armed() {
                    return done(MavResult::DENIED);
                }
                let alt = z.is_finite().then_some(z - HOME_AMSL);
                self.flight.go_to(lat, lon, alt);
                accepted
            }
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

/// The vehicle's MAVFTP server: `@PARAM/param.pck` over the served directory, if any.
/// Under it, the PX4 flavour's event metadata ([`events::MetadataFiles`]), and under that
/// the logs of a [`logs::LogDir`].
type Files = FtpServer<
    Overlay<Overlay<Overlay<DirBackend, logs::LogFiles>, events::MetadataFiles>, TableFile>,
>;

/// The simulated vehicle; see the [module docs](self).
#[derive(Debug)]
pub struct Vehicle {
    own: Address,
    commands: CommandServer<Craft>,
    params: ParamServer,
    /// MAVFTP (with [`SimConfig::ftp`]).
    files: Option<Files>,
    /// Log download (LOG_*).
    logs: LogServer<logs::SimLogs>,
    missions: MissionServer,
    timesync: Timesync,
    out: VecDeque<Outgoing>,
    log: VecDeque<String>,
    next_step: Instant,
    /// When the vehicle started.
    started: Instant,
}

impl Vehicle {
    /// A vehicle on the ground at home, disarmed, at time `now`.
    pub fn new(config: SimConfig, now: Instant) -> Self {
        let encoding = match config.autopilot {
            Autopilot::Ardupilot => Encoding::CCast,
            Autopilot::Px4 => Encoding::Bytewise,
        };
        let mut params = ParamServer::new(config.own, encoding);
        for &(name, value) in &config.params {
            // A table from `params::load` has fewer than 65,535 entries.
            let _ = params.insert(name, value);
        }
        let logs = logs::SimLogs::new(config.log_dir);
        let log_files = logs.ftp_view();
        // PX4 serves its component metadata over MAVFTP whether or not a directory is served.
        let px4 = config.autopilot == Autopilot::Px4;
        let files = (config.ftp || px4).then(|| {
            let table: Vec<(Name, Value)> = params.iter().copied().collect();
            let provider = TableFile::new(&table);
            let under = match config.ftp_files {
                Some(dir) => Overlay::new(dir, log_files),
                None => Overlay::alone(log_files),
            };
            let metadata = if px4 {
                events::MetadataFiles::px4()
            } else {
                events::MetadataFiles::none()
            };
            let overlay = Overlay::new(Overlay::new(under, metadata), provider);
            FtpServer::new(config.own, ServerConfig::default(), overlay)
        });
        let mut streams = StreamScheduler::new();
        for &(id, interval) in STREAMS {
            let unasked = config.streams_on_request && id != Heartbeat::ID;
            streams.support(id, interval.filter(|_| !unasked));
        }
        if config.autopilot == Autopilot::Px4 {
            streams.support(ComponentMetadata::ID, None);
        }
        let craft = Craft {
            autopilot: config.autopilot,
            mavlink2: config.mavlink2,
            ftp: config.ftp,
            flight: Flight::new(config.autopilot, Tuning::default()),
            streams,
            new_current: None,
            ready_at: now + config.estimator_settle,
            data_streams_only: config.data_streams_only,
            events: events::Events::default(),
            boot: Boot(now),
        };
        let mut vehicle = Self {
            own: config.own,
            commands: CommandServer::new(config.own, Default::default(), craft),
            params,
            files,
            logs: LogServer::new(config.own, Default::default(), logs),
            missions: MissionServer::new(config.own, mission_config(config.autopilot)),
            timesync: Timesync::new(TimesyncConfig {
                interval: None,
                clock_offset_ns: Boot(now).timesync_offset_ns(),
                ..TimesyncConfig::default()
            }),
            out: VecDeque::new(),
            log: VecDeque::new(),
            next_step: now,
            started: now,
        };
        vehicle.retune();
        vehicle.restore_home_item();
        vehicle
    }

    /// ArduPilot keeps home as mission item 0: a new or cleared mission has that one item,
    /// so a ground station's download always finds at least it (MAVProxy's `wp list` and
    /// `wp save` rely on it).
    fn restore_home_item(&mut self) {
        if self.commands.handler().autopilot != Autopilot::Ardupilot
            || !self.missions.plan(MavMissionType::MISSION).is_empty()
        {
            return;
        }
        let home = self.commands.handler().flight.home();
        let item = MissionItemInt {
            seq: 0,
            command: MavCmd::NAV_WAYPOINT,
            frame: MavFrame::GLOBAL,
            x: (home.lat * 1e7) as i32,
            y: (home.lon * 1e7) as i32,
            z: HOME_AMSL + home.alt,
            autocontinue: 1,
            mission_type: MavMissionType::MISSION,
            ..MissionItemInt::default()
        };
        self.missions.set_plan(MavMissionType::MISSION, vec![item]);
        let plan = self.missions.plan(MavMissionType::MISSION).to_vec();
        self.craft().flight.set_mission(&plan);
    }

    fn craft(&mut self) -> &mut Craft {
        self.commands.handler_mut()
    }

    /// A parameter's value as `f32`, if the table has it.
    fn param(&self, name: &str) -> Option<f32> {
        let name = Name::new(name).ok()?;
        self.params.get(name).map(|v| v.as_f64() as f32)
    }

    /// Takes the craft's speeds, altitudes and battery size from the parameter table.
    fn retune(&mut self) {
        let mut t = Tuning::default();
        let positive = |v: Option<f32>| v.filter(|v| v.is_finite() && *v > 0.0);
        let autopilot = self.commands.handler().autopilot;
        match autopilot {
            Autopilot::Ardupilot => {
                let cm = |v: Option<f32>| positive(v).map(|v| v / 100.0);
                t.cruise = cm(self.param("WPNAV_SPEED")).unwrap_or(t.cruise);
                t.climb = cm(self.param("WPNAV_SPEED_UP")).unwrap_or(t.climb);
                t.descent = cm(self.param("WPNAV_SPEED_DN")).unwrap_or(t.descent);
                t.land = cm(self.param("LAND_SPEED")).unwrap_or(t.land);
                t.rtl_alt = cm(self.param("RTL_ALT")).unwrap_or(t.rtl_alt);
                t.takeoff_alt = cm(self.param("PILOT_TKOFF_ALT")).unwrap_or(t.takeoff_alt);
                t.capacity_mah = positive(self.param("BATT_CAPACITY")).unwrap_or(t.capacity_mah);
            }
            Autopilot::Px4 => {
                t.cruise = positive(self.param("MPC_XY_CRUISE")).unwrap_or(t.cruise);
                t.climb = positive(self.param("MPC_Z_VEL_MAX_UP")).unwrap_or(t.climb);
                t.descent = positive(self.param("MPC_Z_VEL_MAX_DN")).unwrap_or(t.descent);
                t.land = positive(self.param("MPC_LAND_SPEED")).unwrap_or(t.land);
                t.rtl_alt = positive(self.param("RTL_RETURN_ALT")).unwrap_or(t.rtl_alt);
                t.takeoff_alt = positive(self.param("MIS_TAKEOFF_ALT")).unwrap_or(t.takeoff_alt);
                t.capacity_mah = positive(self.param("BAT1_CAPACITY")).unwrap_or(t.capacity_mah);
            }
        }
        self.craft().flight.set_tuning(t);
    }

    /// Feeds one decoded message from `from`.
    pub fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) {
        let own = self.own;
        match message {
            MavMessage::SetMode(m) if m.target_system == own.system => {
                let autopilot = self.commands.handler().autopilot;
                if let Some(mode) = modes::by_custom_mode(autopilot, m.custom_mode) {
                    self.craft().set_mode(mode);
                }
            }
            MavMessage::RequestDataStream(r)
                if own.is_reached_by(Address::new(r.target_system, r.target_component)) =>
            {
                self.craft().request_data_stream(now, r);
            }
            _ => {}
        }
        self.commands.handle_message(now, from, message);
        self.params.handle_message(now, from, message);
        self.missions.handle_message(now, from, message);
        self.timesync.handle_message(now, from, message);
        if self.logs.handle_message(now, from, message) {
            self.note_logs();
        }
        if let Some(files) = &mut self.files {
            files.handle_message(now, from, message);
        }
        self.settle(now);
    }

    /// Advances the model and every timer to `now`.
    pub fn handle_timeout(&mut self, now: Instant) {
        while self.next_step <= now {
            self.craft().flight.step(STEP.as_secs_f64());
            self.next_step += STEP;
        }
        self.commands.handle_timeout(now);
        self.params.handle_timeout(now);
        self.missions.handle_timeout(now);
        self.timesync.handle_timeout(now);
        self.logs.handle_timeout(now);
        if let Some(files) = &mut self.files {
            files.handle_timeout(now);
        }
        self.settle(now);
    }

    /// Applies the parameter files uploaded to `@PARAM/param.pck`, as ArduPilot does: each
    /// known name set (converted to its type), unknown ones skipped, nothing broadcast.
    fn apply_uploads(&mut self) {
        let Some(files) = &mut self.files else { return };
        let provider = files.backend_mut().provider_mut();
        let mut changed = false;
        while let Some(upload) = provider.take_upload() {
            let table = match upload {
                Ok(table) => table,
                Err(e) => {
                    self.log.push_back(format!("param.pck upload refused: {e}"));
                    continue;
                }
            };
            let (mut set, mut unknown) = (0usize, 0usize);
            for (name, value) in table {
                match self.params.set_quietly(name, value) {
                    Ok(now) => {
                        provider.set(name, now);
                        set += 1;
                    }
                    Err(_) => unknown += 1,
                }
            }
            self.log.push_back(format!(
                "param.pck upload: {set} parameters set, {unknown} unknown skipped"
            ));
            changed |= set > 0;
        }
        if changed {
            self.retune();
        }
    }

    /// Carries what one part did over to the others, and queues what is due.
    fn settle(&mut self, now: Instant) {
        self.apply_uploads();
        while let Some(e) = self.params.poll_event() {
            if let ParamServerEvent::Changed { from, name, value } = e {
                self.log
                    .push_back(format!("param {name} = {} (set by {from})", value.as_f64()));
                // The packed file is made from the table as it is when opened.
                if let (Some(files), Some(now)) = (&mut self.files, self.params.get(name)) {
                    files.backend_mut().provider_mut().set(name, now);
                }
                self.retune();
            }
        }
        while let Some(e) = self.missions.poll_event() {
            match e {
                MissionServerEvent::PlanChanged {
                    mission_type,
                    count,
                } => {
                    self.log.push_back(format!(
                        "{} plan stored: {count} items",
                        plan_name(mission_type)
                    ));
                    if mission_type == MavMissionType::MISSION {
                        let plan = self.missions.plan(MavMissionType::MISSION).to_vec();
                        self.craft().flight.set_mission(&plan);
                        self.restore_home_item();
                    }
                }
                MissionServerEvent::CurrentChanged { seq } => {
                    self.craft().flight.set_current(seq);
                }
                MissionServerEvent::UploadAbandoned { mission_type } => {
                    self.log
                        .push_back(format!("{} upload abandoned", plan_name(mission_type)));
                }
                _ => {}
            }
        }
        if let Some(seq) = self.craft().new_current.take() {
            self.missions.set_current(seq);
        }
        for e in self.craft().events.take() {
            self.broadcast(MavMessage::Event(e));
        }
        while let Some(e) = self.craft().flight.poll_event() {
            match e {
                FlightEvent::ItemReached(seq) => {
                    self.broadcast(MavMessage::MissionItemReached(MissionItemReached { seq }))
                }
                FlightEvent::CurrentChanged(seq) => {
                    self.missions.set_current(seq);
                }
                FlightEvent::Text(text) => self.say(MavSeverity::INFO, text),
                FlightEvent::Warning(text) => self.say(MavSeverity::CRITICAL, text),
            }
        }
        loop {
            let craft = self.commands.handler_mut();
            let Some(due) = craft.streams.poll_due(now) else {
                break;
            };
            if let Some(message) = craft.message(now, due.msg_id) {
                self.out.push_back(Outgoing {
                    target: due.target,
                    message,
                });
            }
        }
    }

    /// A line in STATUSTEXT (cut to its 50 bytes) and in the log.
    fn say(&mut self, severity: MavSeverity, text: String) {
        let mut field = [0u8; 50];
        let n = text.len().min(50);
        field[..n].copy_from_slice(&text.as_bytes()[..n]);
        self.broadcast(MavMessage::Statustext(Statustext {
            severity,
            text: field,
            ..Statustext::default()
        }));
        self.log.push_back(text);
    }

    /// Says what the log server did (a download's first request, not each gap's).
    fn note_logs(&mut self) {
        while let Some(e) = self.logs.poll_event() {
            let line = match e {
                LogServerEvent::Listing { to, entries } => {
                    format!("log list: {entries} entries to {to}")
                }
                LogServerEvent::Sending {
                    to,
                    id,
                    ofs: 0,
                    bytes,
                } => {
                    format!("log {id}: sending {bytes} bytes to {to}")
                }
                LogServerEvent::NoSuchLog { from, id } => {
                    format!("log {id} asked by {from}: there is none")
                }
                LogServerEvent::Erased { by } => format!("logs erased by {by}"),
                _ => continue,
            };
            self.log.push_back(line);
        }
    }

    fn broadcast(&mut self, message: MavMessage) {
        self.out.push_back(Outgoing {
            target: Address::BROADCAST,
            message,
        });
    }

    /// The next message to send.
    pub fn poll_transmit(&mut self) -> Option<Outgoing> {
        if let Some(o) = self.commands.poll_transmit() {
            return Some(o);
        }
        if let Some(o) = self.commands.handler_mut().streams.poll_transmit() {
            return Some(o);
        }
        self.out
            .pop_front()
            .or_else(|| self.params.poll_transmit())
            .or_else(|| self.missions.poll_transmit())
            .or_else(|| self.timesync.poll_transmit())
            .or_else(|| self.files.as_mut().and_then(Service::poll_transmit))
            .or_else(|| self.logs.poll_transmit())
    }

    /// When [`Vehicle::handle_timeout`] is next due.
    pub fn poll_timeout(&self) -> Instant {
        [
            self.commands.handler().streams.poll_timeout(),
            self.commands.poll_timeout(),
            self.params.poll_timeout(),
            self.missions.poll_timeout(),
            self.timesync.poll_timeout(),
            self.files.as_ref().and_then(Service::poll_timeout),
            self.logs.poll_timeout(),
        ]
        .into_iter()
        .flatten()
        .fold(self.next_step, Instant::min)
    }

    /// The next line of what happened (mode changes, parameter sets, plans stored).
    pub fn poll_log(&mut self) -> Option<String> {
        self.log.pop_front()
    }

    /// What to send a peer that just appeared: our HEARTBEAT at once, so that it need not
    /// wait up to a second to find us — except in the first moments, when the stream's own
    /// first HEARTBEAT reaches the peers a link starts with (a `udpout` destination).
    pub fn greeting(&self, now: Instant) -> Option<MavMessage> {
        (now.saturating_duration_since(self.started) >= GREETING_AFTER)
            .then(|| MavMessage::Heartbeat(self.commands.handler().heartbeat()))
    }

    /// The parameter table's size.
    pub fn param_count(&self) -> usize {
        self.params.len()
    }
}

/// The vehicle as one [`Service`]: what runs it on a node (`mavstack::serve`) runs it like
/// any other component.
impl Service for Vehicle {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        Self::handle_message(self, now, from, message);
        true
    }

    fn handle_timeout(&mut self, now: Instant) {
        Self::handle_timeout(self, now);
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        Self::poll_transmit(self)
    }

    fn poll_timeout(&self) -> Option<Instant> {
        Some(Self::poll_timeout(self))
    }
}
