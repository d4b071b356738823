//! A simulated MAVLink vehicle, sans-IO: the vehicle behind `mavstack vehicle` and
//! `mavstack demo`, and the one a ground station's tests can run in-process.
//!
//! Architecture: `docs/architecture.md` in the repository.
//!
//! [`Vehicle`] puts the server roles of `mavstack-services` together around a kinematic
//! craft ([`flight::Flight`]): a [`CommandServer`] whose handler flies the craft, a
//! [`ParamServer`] with the flavour's table (or a file's), a [`MissionServer`] whose plan the
//! craft flies in mission mode, a [`StreamScheduler`] for telemetry rates, TIMESYNC, MAVFTP,
//! and log download (LOG_*) of its [`logs`] (a directory's files, or generated ones). The
//! craft is also flown as each flight stack flies it from outside: ArduPilot's GUIDED
//! targets and PX4's OFFBOARD setpoints, sticks (MANUAL_CONTROL) in the pilot modes, and the
//! failsafes of their loss; its [`modes`] are listed (AVAILABLE_MODES), told (CURRENT_MODE)
//! and entered (MAV_CMD_DO_SET_MODE, MAV_CMD_DO_SET_STANDARD_MODE) with each stack's
//! answers. Like every service it takes decoded messages and the time, and hands out
//! messages to send: the caller moves them over its links (`mavstack vehicle` over a
//! `mavstack-channel` link).
//!
//! [`CommandServer`]: mavstack_services::command::CommandServer
//! [`ParamServer`]: mavstack_services::param::ParamServer
//! [`MissionServer`]: mavstack_services::mission::MissionServer
//! [`StreamScheduler`]: mavstack_services::stream::StreamScheduler
//!
//! ## Features
//! - `fuzzing`: for the fuzz targets and the seed-corpus tests only; not a stable API
//!   (`params::fuzz_param_file`).

pub mod events;
pub mod flight;
pub mod logs;
pub mod modes;
pub mod params;

mod control;
mod craft;
mod gimbal;
mod nsh;
mod vehicle;

pub use vehicle::Vehicle;

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

use mavstack_services::Address;
use mavstack_services::ftp::DirBackend;
use mavstack_services::param::{Name, Value};

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
