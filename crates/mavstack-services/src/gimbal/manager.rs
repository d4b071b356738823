//! [`GimbalManager`]: the server role of the gimbal protocol, a manager in front of a
//! device its owner drives (a companion computer's servos, the simulator's gimbal).

use alloc::collections::VecDeque;
use alloc::string::String;
use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_core::time::Instant;
use mavstack_dialects::common::{
    GimbalDeviceAttitudeStatus, GimbalDeviceCapFlags, GimbalDeviceErrorFlags, GimbalDeviceFlags,
    GimbalDeviceInformation, GimbalManagerCapFlags, GimbalManagerFlags, GimbalManagerInformation,
    GimbalManagerStatus, Heartbeat, MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag,
    MavResult, MavState, MavType,
};

use super::angles::{Euler, YawFrame, euler_from_quaternion, look_at, quaternion_from_euler};
use super::{MAX_NON_MAVLINK_DEVICE, Range, manager_flags};
use crate::command::{Command, CommandHandler, CommandServer, Request, Response};
use crate::{Address, Outgoing, Service};

/// Radians to degrees.
const DEG_PER_RAD: f32 = 180.0 / core::f32::consts::PI;

/// What a [`GimbalManager`] is and says about its device.
#[derive(Clone, Debug, PartialEq)]
pub struct ManagerConfig {
    /// The manager's address (the autopilot's, or a companion's component of its own).
    pub own: Address,
    /// The device's id, 1 to 6 (a device without a component of its own: the manager
    /// reports its attitude).
    pub device_id: u8,
    /// What it can do (GIMBAL_MANAGER_CAP_FLAGS, also the device's capability flags).
    pub cap_flags: GimbalManagerCapFlags,
    /// Roll limits, in degrees.
    pub roll: Range,
    /// Pitch limits, in degrees.
    pub pitch: Range,
    /// Yaw limits, in degrees.
    pub yaw: Range,
    /// The device's vendor, in GIMBAL_DEVICE_INFORMATION.
    pub vendor: String,
    /// The device's model.
    pub model: String,
    /// Whether it is a component of its own (a companion's): then it sends its own
    /// HEARTBEAT (MAV_TYPE_GIMBAL) and answers every other command UNSUPPORTED. Inside an
    /// autopilot, the autopilot does both.
    pub own_component: bool,
    /// How often GIMBAL_MANAGER_STATUS goes out (default 200 ms, the protocol's 5 Hz).
    pub status_every: Duration,
    /// How often GIMBAL_DEVICE_ATTITUDE_STATUS goes out once the device's attitude is
    /// known (default 100 ms).
    pub attitude_every: Duration,
}

impl ManagerConfig {
    /// A manager at `own` of device `device_id` (1 to 6): pitch −90…30°, yaw −180…180°,
    /// roll −45…45°, pitch and yaw axes that follow or lock, pointing at locations.
    #[must_use]
    pub fn new(own: Address, device_id: u8) -> Self {
        type F = GimbalManagerCapFlags;
        let caps = F::HAS_PITCH_AXIS.0
            | F::HAS_PITCH_FOLLOW.0
            | F::HAS_PITCH_LOCK.0
            | F::HAS_YAW_AXIS.0
            | F::HAS_YAW_FOLLOW.0
            | F::HAS_YAW_LOCK.0
            | F::HAS_NEUTRAL.0
            | F::SUPPORTS_YAW_IN_EARTH_FRAME.0
            | F::CAN_POINT_LOCATION_GLOBAL.0;
        Self {
            own,
            device_id: device_id.clamp(1, MAX_NON_MAVLINK_DEVICE),
            cap_flags: GimbalManagerCapFlags(caps),
            roll: Range {
                min: -45.0,
                max: 45.0,
            },
            pitch: Range {
                min: -90.0,
                max: 30.0,
            },
            yaw: Range {
                min: -180.0,
                max: 180.0,
            },
            vendor: String::from("mavstack"),
            model: String::from("gimbal"),
            own_component: false,
            status_every: Duration::from_millis(200),
            attitude_every: Duration::from_millis(100),
        }
    }
}

/// Where the device is asked to look: angles and rates, each `None` where the request
/// leaves it as it is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Pitch, degrees, positive up.
    pub pitch_deg: Option<f32>,
    /// Yaw, degrees, positive right, in [`frame`](Self::frame).
    pub yaw_deg: Option<f32>,
    /// Pitch rate, degrees per second.
    pub pitch_rate_dps: Option<f32>,
    /// Yaw rate, degrees per second.
    pub yaw_rate_dps: Option<f32>,
    /// What the yaw is measured from.
    pub frame: YawFrame,
}

impl Setpoint {
    /// Straight ahead and level: where the device goes with DO_SET_ROI_NONE.
    pub const NEUTRAL: Self = Self {
        pitch_deg: Some(0.0),
        yaw_deg: Some(0.0),
        pitch_rate_dps: None,
        yaw_rate_dps: None,
        frame: YawFrame::Vehicle,
    };
}

/// What a [`GimbalManager`] tells its owner.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub enum ManagerEvent {
    /// Move the device: a request from `from` (or, while pointing at a location, the
    /// manager itself as the vehicle moves).
    Setpoint {
        /// Where to look.
        setpoint: Setpoint,
        /// Who asked (the manager's own address for location pointing).
        from: Address,
    },
    /// Who is in control changed.
    Control {
        /// The component in primary control.
        primary: Option<Address>,
        /// The component in secondary control.
        secondary: Option<Address>,
    },
    /// Pointing at a location (latitude, longitude in degrees, altitude above mean sea level
    /// in metres) began, or ended (`None`).
    Roi(Option<(f64, f64, f64)>),
}

/// The device's attitude as its owner measures it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceAttitude {
    /// Roll, pitch and yaw in degrees; the yaw in [`frame`](Self::frame).
    pub euler: Euler,
    /// What the yaw is measured from.
    pub frame: YawFrame,
    /// Angular rates (roll, pitch, yaw) in degrees per second, NaN where unknown.
    pub rates_dps: [f32; 3],
    /// GIMBAL_DEVICE_ERROR_FLAGS.
    pub failure_flags: GimbalDeviceErrorFlags,
}

/// The vehicle's position and heading, for pointing at a location and for reporting the
/// device's yaw in both frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleState {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Altitude above mean sea level, metres.
    pub alt_amsl: f64,
    /// Heading, degrees from north.
    pub heading_deg: f32,
}

/// The manager's state, which also answers its commands.
#[derive(Debug)]
struct State {
    config: ManagerConfig,
    started: Instant,
    primary: Option<Address>,
    secondary: Option<Address>,
    /// The last request's flags (for GIMBAL_MANAGER_STATUS).
    flags: GimbalManagerFlags,
    roi: Option<(f64, f64, f64)>,
    vehicle: Option<VehicleState>,
    /// Home's altitude above mean sea level, for locations given above home.
    home_amsl: Option<f64>,
    device: Option<DeviceAttitude>,
    replies: VecDeque<Outgoing>,
    events: VecDeque<ManagerEvent>,
}

impl State {
    fn boot_ms(&self, now: Instant) -> u32 {
        now.saturating_duration_since(self.started).as_millis() as u32
    }

    /// Whether `from` may move the gimbal: anyone while nobody is in control, else the
    /// components in control.
    fn may_control(&self, from: Address) -> bool {
        self.primary.is_none() || self.primary == Some(from) || self.secondary == Some(from)
    }

    /// Whether a request for device `id` is ours (0 is every device).
    fn our_device(&self, id: f32) -> bool {
        id == 0.0 || (id.is_finite() && id == f32::from(self.config.device_id))
    }

    fn setpoint(&mut self, setpoint: Setpoint, from: Address, flags: GimbalManagerFlags) {
        self.flags = flags;
        self.events
            .push_back(ManagerEvent::Setpoint { setpoint, from });
    }

    /// Aims at the location being pointed at, if any and the vehicle's position is known.
    fn aim(&mut self) {
        let (Some(target), Some(v)) = (self.roi, self.vehicle) else {
            return;
        };
        let (pitch, yaw) = look_at((v.lat, v.lon, v.alt_amsl), target);
        let setpoint = Setpoint {
            pitch_deg: Some(pitch.clamp(self.config.pitch.min, self.config.pitch.max)),
            yaw_deg: Some(yaw),
            pitch_rate_dps: None,
            yaw_rate_dps: None,
            frame: YawFrame::Earth,
        };
        let own = self.config.own;
        self.setpoint(setpoint, own, manager_flags(YawFrame::Earth));
    }

    fn reply(&mut self, to: Address, message: MavMessage) {
        self.replies.push_back(Outgoing {
            target: to,
            message,
        });
    }

    fn information(&self, now: Instant) -> MavMessage {
        let c = &self.config;
        let rad = |d: f32| d / DEG_PER_RAD;
        MavMessage::GimbalManagerInformation(GimbalManagerInformation {
            time_boot_ms: self.boot_ms(now),
            cap_flags: c.cap_flags,
            gimbal_device_id: c.device_id,
            roll_min: rad(c.roll.min),
            roll_max: rad(c.roll.max),
            pitch_min: rad(c.pitch.min),
            pitch_max: rad(c.pitch.max),
            yaw_min: rad(c.yaw.min),
            yaw_max: rad(c.yaw.max),
        })
    }

    fn device_information(&self, now: Instant) -> MavMessage {
        let c = &self.config;
        let rad = |d: f32| d / DEG_PER_RAD;
        let name = |s: &str| {
            let mut field = [0u8; 32];
            let n = s.len().min(32);
            field[..n].copy_from_slice(&s.as_bytes()[..n]);
            field
        };
        MavMessage::GimbalDeviceInformation(GimbalDeviceInformation {
            time_boot_ms: self.boot_ms(now),
            vendor_name: name(&c.vendor),
            model_name: name(&c.model),
            cap_flags: GimbalDeviceCapFlags(c.cap_flags.0 & 0xffff),
            cap_flags2: GimbalDeviceCapFlags(c.cap_flags.0),
            roll_min: rad(c.roll.min),
            roll_max: rad(c.roll.max),
            pitch_min: rad(c.pitch.min),
            pitch_max: rad(c.pitch.max),
            yaw_min: rad(c.yaw.min),
            yaw_max: rad(c.yaw.max),
            gimbal_device_id: c.device_id,
            ..GimbalDeviceInformation::default()
        })
    }

    fn status(&self, now: Instant) -> MavMessage {
        let addr = |a: Option<Address>| a.map_or((0, 0), |a| (a.system, a.component));
        let (ps, pc) = addr(self.primary);
        let (ss, sc) = addr(self.secondary);
        MavMessage::GimbalManagerStatus(GimbalManagerStatus {
            time_boot_ms: self.boot_ms(now),
            flags: self.flags,
            gimbal_device_id: self.config.device_id,
            primary_control_sysid: ps,
            primary_control_compid: pc,
            secondary_control_sysid: ss,
            secondary_control_compid: sc,
        })
    }

    fn attitude(&self, now: Instant) -> Option<MavMessage> {
        let d = self.device?;
        type F = GimbalDeviceFlags;
        let frame_flags = match d.frame {
            YawFrame::Earth => F::YAW_IN_EARTH_FRAME.0 | F::YAW_LOCK.0,
            YawFrame::Vehicle => F::YAW_IN_VEHICLE_FRAME.0,
        };
        let rad = |dps: f32| dps / DEG_PER_RAD;
        Some(MavMessage::GimbalDeviceAttitudeStatus(
            GimbalDeviceAttitudeStatus {
                time_boot_ms: self.boot_ms(now),
                flags: GimbalDeviceFlags(F::ROLL_LOCK.0 | F::PITCH_LOCK.0 | frame_flags),
                q: quaternion_from_euler(d.euler.roll_deg, d.euler.pitch_deg, d.euler.yaw_deg),
                angular_velocity_x: rad(d.rates_dps[0]),
                angular_velocity_y: rad(d.rates_dps[1]),
                angular_velocity_z: rad(d.rates_dps[2]),
                failure_flags: d.failure_flags,
                delta_yaw: self
                    .vehicle
                    .map_or(f32::NAN, |v| v.heading_deg / DEG_PER_RAD),
                delta_yaw_velocity: f32::NAN,
                gimbal_device_id: self.config.device_id,
                ..GimbalDeviceAttitudeStatus::default()
            },
        ))
    }

    fn heartbeat() -> MavMessage {
        MavMessage::Heartbeat(Heartbeat {
            r#type: MavType::GIMBAL,
            autopilot: MavAutopilot::INVALID,
            base_mode: MavModeFlag(0),
            custom_mode: 0,
            system_status: MavState::ACTIVE,
            mavlink_version: 3,
        })
    }

    fn pitch_yaw(&mut self, from: Address, p: [f32; 4], flags: u32, device: f32) -> MavResult {
        if !self.our_device(device) {
            return MavResult::DENIED;
        }
        if !self.may_control(from) {
            return MavResult::DENIED;
        }
        let given = |v: f32| v.is_finite().then_some(v);
        let (pitch, yaw) = (given(p[0]), given(p[1]));
        let (pitch_rate, yaw_rate) = (given(p[2]), given(p[3]));
        if [pitch, yaw, pitch_rate, yaw_rate]
            .iter()
            .all(Option::is_none)
        {
            return MavResult::DENIED;
        }
        if pitch.is_some_and(|v| !self.config.pitch.contains(v))
            || yaw.is_some_and(|v| !self.config.yaw.contains(v))
        {
            return MavResult::DENIED;
        }
        let flags = GimbalManagerFlags(flags);
        if self.roi.take().is_some() {
            self.events.push_back(ManagerEvent::Roi(None));
        }
        let setpoint = Setpoint {
            pitch_deg: pitch,
            yaw_deg: yaw,
            pitch_rate_dps: pitch_rate,
            yaw_rate_dps: yaw_rate,
            frame: YawFrame::of_manager(flags),
        };
        self.setpoint(setpoint, from, flags);
        MavResult::ACCEPTED
    }

    fn configure(&mut self, now: Instant, from: Address, p: [f32; 4], device: f32) -> MavResult {
        if !self.our_device(device) {
            return MavResult::DENIED;
        }
        let pick = |current: Option<Address>, sys: f32, comp: f32| -> Option<Option<Address>> {
            match (sys as i32, comp as i32) {
                (-1, _) | (_, -1) => Some(current),
                (-2, _) | (_, -2) => Some(Some(from)),
                (-3, _) | (_, -3) => Some(current.filter(|&c| c != from)),
                (0, _) => Some(None),
                (s, c) if (1..=255).contains(&s) && (0..=255).contains(&c) => {
                    Some(Some(Address::new(s as u8, c as u8)))
                }
                _ => None,
            }
        };
        let (Some(primary), Some(secondary)) = (
            pick(self.primary, p[0], p[1]),
            pick(self.secondary, p[2], p[3]),
        ) else {
            return MavResult::DENIED;
        };
        if (primary, secondary) != (self.primary, self.secondary) {
            (self.primary, self.secondary) = (primary, secondary);
            self.events
                .push_back(ManagerEvent::Control { primary, secondary });
        }
        // Told at once, not at the next tick.
        let status = self.status(now);
        self.reply(Address::BROADCAST, status);
        MavResult::ACCEPTED
    }

    fn roi(&mut self, from: Address, target: Option<(f64, f64, f64)>, device: f32) -> MavResult {
        if !self.our_device(device) || !self.may_control(from) {
            return MavResult::DENIED;
        }
        match target {
            Some(t) => {
                self.roi = Some(t);
                self.events.push_back(ManagerEvent::Roi(Some(t)));
                self.aim();
            }
            None => {
                if self.roi.take().is_some() {
                    self.events.push_back(ManagerEvent::Roi(None));
                }
                self.setpoint(Setpoint::NEUTRAL, from, manager_flags(YawFrame::Vehicle));
            }
        }
        MavResult::ACCEPTED
    }

    /// The location of DO_SET_ROI_LOCATION: COMMAND_INT in a global frame (above mean sea
    /// level, or above home with home's altitude known), COMMAND_LONG above home as
    /// ArduPilot reads it.
    fn roi_location(&self, command: &Command) -> Option<(f64, f64, f64)> {
        let (lat, lon, alt, above_home) = match command {
            Command::Int(c) => {
                let above_home = match c.frame {
                    MavFrame::GLOBAL | MavFrame::GLOBAL_INT => false,
                    MavFrame::GLOBAL_RELATIVE_ALT | MavFrame::GLOBAL_RELATIVE_ALT_INT => true,
                    _ => return None,
                };
                (
                    f64::from(c.x) / 1e7,
                    f64::from(c.y) / 1e7,
                    f64::from(c.z),
                    above_home,
                )
            }
            Command::Long(c) => (
                f64::from(c.param5),
                f64::from(c.param6),
                f64::from(c.param7),
                true,
            ),
        };
        let valid = lat.is_finite() && lon.is_finite() && lat.abs() <= 90.0 && lon.abs() <= 180.0;
        if !valid || !alt.is_finite() {
            return None;
        }
        let alt = if above_home {
            alt + self.home_amsl?
        } else {
            alt
        };
        Some((lat, lon, alt))
    }

    fn request_message(&mut self, now: Instant, from: Address, id: f32) -> MavResult {
        let message = match id as u32 {
            GimbalManagerInformation::ID => self.information(now),
            GimbalManagerStatus::ID => self.status(now),
            GimbalDeviceInformation::ID => self.device_information(now),
            GimbalDeviceAttitudeStatus::ID => match self.attitude(now) {
                Some(m) => m,
                None => return MavResult::TEMPORARILY_REJECTED,
            },
            Heartbeat::ID if self.config.own_component => Self::heartbeat(),
            _ => return MavResult::UNSUPPORTED,
        };
        self.reply(from, message);
        MavResult::ACCEPTED
    }
}

impl CommandHandler for State {
    fn handle_command(&mut self, now: Instant, request: &Request) -> Response {
        let from = request.from;
        let command = &request.command;
        let (p, device_long) = match command {
            Command::Long(c) => ([c.param1, c.param2, c.param3, c.param4], c.param7),
            Command::Int(c) => ([c.param1, c.param2, c.param3, c.param4], c.z),
        };
        let result = match command.id() {
            MavCmd::DO_GIMBAL_MANAGER_PITCHYAW => {
                let flags = match command {
                    Command::Long(c) => c.param5 as u32,
                    Command::Int(c) => c.x as u32,
                };
                self.pitch_yaw(from, p, flags, device_long)
            }
            MavCmd::DO_GIMBAL_MANAGER_CONFIGURE => self.configure(now, from, p, device_long),
            MavCmd::DO_SET_ROI_LOCATION => match self.roi_location(command) {
                Some(t) => self.roi(from, Some(t), p[0]),
                None => MavResult::DENIED,
            },
            MavCmd::DO_SET_ROI_NONE => self.roi(from, None, p[0]),
            MavCmd::REQUEST_MESSAGE => self.request_message(now, from, p[0]),
            _ => MavResult::UNSUPPORTED,
        };
        Response::done(result)
    }
}

/// A gimbal manager (the protocol's server role) for one device that its owner drives: it
/// answers REQUEST_MESSAGE for GIMBAL_MANAGER_INFORMATION, GIMBAL_MANAGER_STATUS,
/// GIMBAL_DEVICE_INFORMATION and GIMBAL_DEVICE_ATTITUDE_STATUS; takes
/// MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE (who is in control: −1 unchanged, −2 the sender, −3
/// the sender out, 0 nobody), MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW (COMMAND_LONG, or
/// COMMAND_INT with the flags in x and the device in z, as MAVSDK sends rates),
/// GIMBAL_MANAGER_SET_PITCHYAW and GIMBAL_MANAGER_SET_ATTITUDE, and
/// MAV_CMD_DO_SET_ROI_LOCATION / _NONE, turning them into [`ManagerEvent::Setpoint`]s for
/// its owner; and reports GIMBAL_MANAGER_STATUS (5 Hz) and, from what its owner measures
/// ([`set_device_attitude`](Self::set_device_attitude)), GIMBAL_DEVICE_ATTITUDE_STATUS
/// (10 Hz) on the device's behalf.
///
/// Requests from a component that is not in control while another is are DENIED, and so
/// are angles outside its limits: nothing reaches the device. While pointing at a location
/// it aims again whenever the vehicle's position or heading changes (from
/// GLOBAL_POSITION_INT and ATTITUDE of its own system, or
/// [`set_vehicle`](Self::set_vehicle)).
#[derive(Debug)]
pub struct GimbalManager {
    commands: CommandServer<State>,
    next_status: Instant,
    next_attitude: Instant,
    next_heartbeat: Option<Instant>,
}

impl GimbalManager {
    /// A manager as `config` says, started at `now`.
    #[must_use]
    pub fn new(now: Instant, config: ManagerConfig) -> Self {
        let own = config.own;
        let heartbeat = config.own_component.then_some(now);
        let state = State {
            config,
            started: now,
            primary: None,
            secondary: None,
            flags: manager_flags(YawFrame::Vehicle),
            roi: None,
            vehicle: None,
            home_amsl: None,
            device: None,
            replies: VecDeque::new(),
            events: VecDeque::new(),
        };
        Self {
            commands: CommandServer::new(own, Default::default(), state),
            next_status: now,
            next_attitude: now,
            next_heartbeat: heartbeat,
        }
    }

    fn state(&self) -> &State {
        self.commands.handler()
    }

    fn state_mut(&mut self) -> &mut State {
        self.commands.handler_mut()
    }

    /// Its settings.
    #[must_use]
    pub fn config(&self) -> &ManagerConfig {
        &self.state().config
    }

    /// The next thing to tell its owner.
    pub fn poll_event(&mut self) -> Option<ManagerEvent> {
        self.state_mut().events.pop_front()
    }

    /// Who is in primary and secondary control.
    #[must_use]
    pub fn control(&self) -> (Option<Address>, Option<Address>) {
        (self.state().primary, self.state().secondary)
    }

    /// The location being pointed at, if any.
    #[must_use]
    pub fn roi(&self) -> Option<(f64, f64, f64)> {
        self.state().roi
    }

    /// The device's attitude as last measured.
    #[must_use]
    pub fn device_attitude(&self) -> Option<DeviceAttitude> {
        self.state().device
    }

    /// What the owner measured of the device (sent on its behalf from now on).
    pub fn set_device_attitude(&mut self, attitude: DeviceAttitude) {
        self.state_mut().device = Some(attitude);
    }

    /// The vehicle's position and heading (when the manager is not told them by messages
    /// of its own system: inside an autopilot). Re-aims while pointing at a location.
    pub fn set_vehicle(&mut self, vehicle: VehicleState, home_amsl: Option<f64>) {
        let s = self.state_mut();
        s.vehicle = Some(vehicle);
        if home_amsl.is_some() {
            s.home_amsl = home_amsl;
        }
        s.aim();
    }

    /// Whether `message` is a command for this manager: its own commands (and
    /// REQUEST_MESSAGE for its messages) addressed to it, or any command addressed to it
    /// when it is a component of its own.
    fn is_ours(&self, message: &MavMessage) -> bool {
        let (target, command, p1) = match message {
            MavMessage::CommandLong(c) => (
                Address::new(c.target_system, c.target_component),
                c.command,
                c.param1,
            ),
            MavMessage::CommandInt(c) => (
                Address::new(c.target_system, c.target_component),
                c.command,
                c.param1,
            ),
            _ => return false,
        };
        let config = &self.state().config;
        if !config.own.is_reached_by(target) {
            return false;
        }
        if config.own_component && target.component != 0 {
            return true;
        }
        match command {
            MavCmd::DO_GIMBAL_MANAGER_PITCHYAW
            | MavCmd::DO_GIMBAL_MANAGER_CONFIGURE
            | MavCmd::DO_SET_ROI_LOCATION
            | MavCmd::DO_SET_ROI_NONE => true,
            MavCmd::REQUEST_MESSAGE => matches!(
                p1 as u32,
                GimbalManagerInformation::ID
                    | GimbalManagerStatus::ID
                    | GimbalDeviceInformation::ID
                    | GimbalDeviceAttitudeStatus::ID
            ),
            _ => false,
        }
    }

    /// A streamed request (GIMBAL_MANAGER_SET_PITCHYAW, GIMBAL_MANAGER_SET_ATTITUDE):
    /// taken when addressed to it, for its device, from a component that may control it,
    /// within its limits; otherwise dropped.
    fn stream(
        &mut self,
        from: Address,
        target: Address,
        device: u8,
        setpoint: Setpoint,
        flags: u32,
    ) {
        let s = self.state_mut();
        let ours = s.config.own.is_reached_by(target)
            && target.component != 0
            && (device == 0 || device == s.config.device_id);
        let within = setpoint
            .pitch_deg
            .is_none_or(|v| s.config.pitch.contains(v))
            && setpoint.yaw_deg.is_none_or(|v| s.config.yaw.contains(v));
        if ours && within && s.may_control(from) {
            if s.roi.take().is_some() {
                s.events.push_back(ManagerEvent::Roi(None));
            }
            s.setpoint(setpoint, from, GimbalManagerFlags(flags));
        }
    }

    /// Notes the vehicle's position and heading from its own system's messages.
    fn note_vehicle(&mut self, from: Address, message: &MavMessage) {
        let s = self.state_mut();
        if from.system != s.config.own.system || from == s.config.own {
            return;
        }
        match message {
            MavMessage::GlobalPositionInt(p) => {
                let heading = s.vehicle.map_or(0.0, |v| v.heading_deg);
                s.vehicle = Some(VehicleState {
                    lat: f64::from(p.lat) / 1e7,
                    lon: f64::from(p.lon) / 1e7,
                    alt_amsl: f64::from(p.alt) / 1e3,
                    heading_deg: heading,
                });
                if s.home_amsl.is_none() {
                    s.home_amsl = Some(f64::from(p.alt - p.relative_alt) / 1e3);
                }
                s.aim();
            }
            MavMessage::HomePosition(h) => s.home_amsl = Some(f64::from(h.altitude) / 1e3),
            MavMessage::Attitude(a) => {
                if let Some(v) = &mut s.vehicle {
                    v.heading_deg = a.yaw * DEG_PER_RAD;
                }
            }
            _ => {}
        }
    }
}

impl Service for GimbalManager {
    fn handle_message(&mut self, now: Instant, from: Address, message: &MavMessage) -> bool {
        match message {
            MavMessage::CommandLong(_) | MavMessage::CommandInt(_) => {
                self.is_ours(message) && self.commands.handle_message(now, from, message)
            }
            MavMessage::GimbalManagerSetPitchyaw(m) => {
                let deg = |r: f32| (r.is_finite()).then_some(r * DEG_PER_RAD);
                let setpoint = Setpoint {
                    pitch_deg: deg(m.pitch),
                    yaw_deg: deg(m.yaw),
                    pitch_rate_dps: deg(m.pitch_rate),
                    yaw_rate_dps: deg(m.yaw_rate),
                    frame: YawFrame::of_manager(m.flags),
                };
                let target = Address::new(m.target_system, m.target_component);
                self.stream(from, target, m.gimbal_device_id, setpoint, m.flags.0);
                true
            }
            MavMessage::GimbalManagerSetAttitude(m) => {
                let angles = euler_from_quaternion(m.q);
                let deg = |r: f32| (r.is_finite()).then_some(r * DEG_PER_RAD);
                let setpoint = Setpoint {
                    pitch_deg: angles.map(|e| e.pitch_deg),
                    yaw_deg: angles.map(|e| e.yaw_deg),
                    pitch_rate_dps: deg(m.angular_velocity_y),
                    yaw_rate_dps: deg(m.angular_velocity_z),
                    frame: YawFrame::of_manager(m.flags),
                };
                let target = Address::new(m.target_system, m.target_component);
                self.stream(from, target, m.gimbal_device_id, setpoint, m.flags.0);
                true
            }
            MavMessage::GlobalPositionInt(_)
            | MavMessage::Attitude(_)
            | MavMessage::HomePosition(_) => {
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
        if now >= self.next_status {
            let status = self.state().status(now);
            self.state_mut().reply(Address::BROADCAST, status);
            self.next_status = now + self.state().config.status_every;
        }
        if now >= self.next_attitude {
            if let Some(m) = self.state().attitude(now) {
                self.state_mut().reply(Address::BROADCAST, m);
            }
            self.next_attitude = now + self.state().config.attitude_every;
        }
    }

    fn poll_transmit(&mut self) -> Option<Outgoing> {
        // The ACK first, then what it answers.
        self.commands
            .poll_transmit()
            .or_else(|| self.state_mut().replies.pop_front())
    }

    fn poll_timeout(&self) -> Option<Instant> {
        let next = self.next_status.min(self.next_attitude);
        Some(self.next_heartbeat.map_or(next, |h| h.min(next)))
    }
}

#[cfg(test)]
mod tests;
