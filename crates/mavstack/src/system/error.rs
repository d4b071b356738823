//! [`SystemError`]: why an operation on a remote system failed, with its cause kept as the
//! error's source so that a caller can print the chain down to the OS error.

use mavstack_services::camera::{CaptureError, DefinitionError, ParamExtError, SettingError};
use mavstack_services::command::CommandError;
use mavstack_services::ftp::FtpError;
use mavstack_services::ftp::param_pck::{DecodeError, EncodeError};
use mavstack_services::gimbal::GimbalError;
use mavstack_services::log_transfer::LogError;
use mavstack_services::mission::MissionError;
use mavstack_services::param::ParamError;
use mavstack_services::rtcm::RtcmError;
use mavstack_services::shell::ShellError;

/// Why an operation on a [`System`](super::System) failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SystemError {
    /// The link could not be opened.
    #[error("cannot open {link}")]
    Open {
        /// The link as shown to people (its key redacted).
        link: String,
        /// Why.
        #[source]
        source: crate::NodeError,
    },
    /// No HEARTBEAT of the wanted system in time.
    #[error("no vehicle heard on {link} within {seconds:.1} s")]
    NotFound {
        /// The link as shown to people (its key redacted).
        link: String,
        /// How long it waited.
        seconds: f64,
    },
    /// The operation did not end in time.
    #[error("no result within {seconds:.0} s")]
    Timeout {
        /// Its limit.
        seconds: f64,
    },
    /// A value the operation was given cannot be sent (NaN, out of range, a name too long):
    /// nothing was sent.
    #[error("{0}")]
    Invalid(String),
    /// A parameter operation failed.
    #[error("parameter {what}")]
    Param {
        /// Which (a name, or "list").
        what: String,
        /// Why.
        #[source]
        source: ParamError,
    },
    /// A mission operation failed.
    #[error("{what}")]
    Mission {
        /// Which (upload, download, clear, set current).
        what: &'static str,
        /// Why.
        #[source]
        source: MissionError,
    },
    /// A command was not accepted.
    #[error("command {command}: {reason}{}", said(statustext))]
    Command {
        /// The command's name.
        command: String,
        /// Why (shown in this error's message, not as its source).
        reason: CommandError,
        /// What the system said between the request and 0.5 s after its answer, in
        /// STATUSTEXT (ArduPilot says why it refuses there: `PreArm: Need Position
        /// Estimate`) and in EVENT messages made into text with its event metadata (PX4:
        /// `Arming denied: Resolve system health failures first`).
        statustext: Vec<String>,
    },
    /// A mode name the system does not have (or a system whose modes are not known: `known`
    /// is empty).
    #[error("unknown {}mode {name:?}{}", whose(autopilot), known_modes(known))]
    UnknownMode {
        /// Whose modes were looked in (`PX4`, `ArduPilot Copter`), when known.
        autopilot: Option<String>,
        /// The name asked for.
        name: String,
        /// The names the system has.
        known: Vec<String>,
    },
    /// A MAVFTP operation failed.
    #[error("ftp {what}")]
    Ftp {
        /// Which (the operation and its path).
        what: String,
        /// Why.
        #[source]
        source: FtpError,
    },
    /// A log download operation (LOG_*) failed.
    #[error("log {what}")]
    Log {
        /// Which (list, download of an id, erase).
        what: String,
        /// Why.
        #[source]
        source: LogError,
    },
    /// The vehicle lists no log with this id.
    #[error("the vehicle lists no log {id}")]
    NoSuchLog {
        /// The id asked for.
        id: u16,
    },
    /// The packed parameter file (`@PARAM/param.pck`) read over MAVFTP is not one.
    #[error("{path}")]
    ParamFile {
        /// The file's path.
        path: &'static str,
        /// What is wrong with it.
        #[source]
        source: DecodeError,
    },
    /// A parameter table that cannot be uploaded as a packed file.
    #[error("{path}")]
    ParamPack {
        /// The file's path.
        path: &'static str,
        /// Why it cannot be packed.
        #[source]
        source: EncodeError,
    },
    /// The system did what was asked, but not what it was for (a takeoff that never reached
    /// its height, a mode that did not become current), with what it said meanwhile.
    #[error("{what}{}", said(statustext))]
    NotDone {
        /// What did not happen.
        what: String,
        /// What the system said meanwhile (STATUSTEXT, EVENT texts).
        statustext: Vec<String>,
    },
    /// RTK corrections that cannot be sent: nothing was sent.
    #[error("RTCM corrections not sent")]
    Rtcm(#[from] RtcmError),
    /// The shell gave no output.
    #[error("shell")]
    Shell(#[from] ShellError),
    /// A gimbal request that cannot be sent (an angle outside the gimbal's limits, NaN):
    /// nothing was sent.
    #[error("gimbal request not sent")]
    Gimbal(#[from] GimbalError),
    /// A photo without its CAMERA_IMAGE_CAPTURED.
    #[error("photo")]
    Photo(#[from] CaptureError),
    /// A camera setting that was not read or written (PARAM_EXT_*).
    #[error("camera settings")]
    CameraSettings(#[from] ParamExtError),
    /// A camera setting value that the camera's definition does not allow: nothing was sent.
    #[error("camera setting not sent")]
    CameraSetting(#[from] SettingError),
    /// A camera definition file that cannot be read.
    #[error("camera definition {uri}")]
    CameraDefinition {
        /// Where it is.
        uri: String,
        /// What is wrong with it.
        #[source]
        source: DefinitionError,
    },
    /// Reading or writing something of ours failed (an RTCM source).
    #[error("{what}")]
    Io {
        /// What failed.
        what: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The request could not start (another like it is running, a link that cannot do it).
    #[error("{0}")]
    Busy(String),
    /// The node stopped.
    #[error("the node has stopped")]
    Stopped,
}

/// The STATUSTEXT lines after an error's message.
fn said(lines: &[String]) -> String {
    if lines.is_empty() {
        String::new()
    } else {
        format!(" ({})", lines.join("; "))
    }
}

fn whose(autopilot: &Option<String>) -> String {
    autopilot
        .as_ref()
        .map_or_else(String::new, |a| format!("{a} "))
}

fn known_modes(known: &[String]) -> String {
    if known.is_empty() {
        " (the system's modes are not known)".to_owned()
    } else {
        format!("; one of {}", known.join(", "))
    }
}
