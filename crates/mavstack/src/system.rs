//! [`System`]: a remote MAVLink system as a ground station or companion sees it, through a
//! [`Node`](crate::Node): its parameters, missions, commands and telemetry (feature
//! `services`).
//!
//! ```no_run
//! # async fn run() -> Result<(), Box<dyn core::error::Error>> {
//! use core::time::Duration;
//! use mavstack::system::{System, Wanted};
//! use mavstack::{LinkSpec, Node};
//! let none = |_: &str| None;
//! let gcs = Node::ground_station(255, 190)
//!     .link(LinkSpec::parse("udpin:0.0.0.0:14550", &none)?)
//!     .start()
//!     .await?;
//! // The first autopilot heard; the MAVLink 2 handshake if it speaks MAVLink 1.
//! let mut vehicle = System::wait(&gcs.handle(), Wanted::AnyAutopilot, Duration::from_secs(10)).await?;
//! let table = vehicle.params().await?;
//! println!("{} parameters from {}", table.len(), vehicle.target());
//! # Ok(()) }
//! ```
//!
//! Every operation runs the `mavstack-services` state machine for it (retries, timeouts,
//! IN_PROGRESS) over the node's link to the system, and ends when its future resolves;
//! dropping the future abandons it.

use core::marker::PhantomData;
use core::time::Duration;

use mavstack_channel::{CommandEncoding, HandshakeMethod, HandshakeOutcome, Target};
use mavstack_core::wire::Version;
use mavstack_core::{Message, MessageSet as _};
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandLong, GlobalPositionInt, HomePosition, MavAutopilot,
    MavCmd, MavFrame, MavMessage, MavMissionType, MavProtocolCapability, MavType, MissionItemInt,
};
use mavstack_router::LinkId;
use mavstack_services::command::{
    Command, CommandClient, CommandConfig, CommandError, CommandEvent,
};
use mavstack_services::ftp::param_pck::{self, DecodeError, EncodeError};
use mavstack_services::ftp::{
    ClientConfig as FtpConfig, DirEntry, FtpClient, FtpError, FtpEvent, FtpOutput, StartError,
};
use mavstack_services::heartbeat::{HeartbeatConfig, HeartbeatEvent, Heartbeats, Peer};
use mavstack_services::log_transfer::{
    ClientConfig as LogConfig, LogClient, LogError, LogEvent, LogInfo, LogOutput,
    StartError as LogStartError,
};
use mavstack_services::mission::transfer::{Download, Upload};
use mavstack_services::mission::{MissionClient, MissionConfig, MissionError, MissionEvent};
use mavstack_services::param::list::ListFetch;
use mavstack_services::param::{
    Encoding, Name, Param, ParamClient, ParamConfig, ParamError, ParamEvent, ParamRef, Value,
};
use mavstack_services::statustext::Lines;
use mavstack_services::{Address, Service};
use mavstack_transport::clock;

mod said;

use crate::modes::Flavour;
use crate::node::{NodeHandle, Subscription};

/// Retries per message of parameter and mission operations by default: with 10, a 500-item
/// upload over a link that drops 20 % each way fails about once in 150 (with the services'
/// default 3, about once in two).
pub const PATIENT_RETRIES: u8 = 10;

/// Which system [`System::wait`] waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Wanted {
    /// The first HEARTBEAT of an autopilot (not a ground station, not MAV_AUTOPILOT_INVALID).
    AnyAutopilot,
    /// This system; any component, or this one.
    System(u8, Option<u8>),
}

/// Why an operation on a [`System`] failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SystemError {
    /// No HEARTBEAT of the wanted system in time.
    #[error("no vehicle heard within {seconds:.1} s")]
    NotFound {
        /// How long it waited.
        seconds: f64,
    },
    /// The operation did not end in time.
    #[error("no result within {seconds:.0} s")]
    Timeout {
        /// Its limit.
        seconds: f64,
    },
    /// A parameter operation failed.
    #[error("parameter {what}: {source}")]
    Param {
        /// Which (a name, or "list").
        what: String,
        /// Why.
        source: ParamError,
    },
    /// A mission operation failed.
    #[error("{what}: {source}")]
    Mission {
        /// Which (upload, download, clear, set current).
        what: &'static str,
        /// Why.
        source: MissionError,
    },
    /// A command was not accepted.
    #[error("command {command}: {source}{}", said(statustext))]
    Command {
        /// The command.
        command: String,
        /// Why.
        source: CommandError,
        /// What the system said between the request and 0.5 s after its answer, in
        /// STATUSTEXT (ArduPilot says why it refuses there: `PreArm: Need Position
        /// Estimate`) and in EVENT messages made into text with its event metadata (PX4:
        /// `Arming denied: Resolve system health failures first`).
        statustext: Vec<String>,
    },
    /// A mode name the system's autopilot does not have (or an autopilot whose modes are
    /// not known: `known` is empty).
    #[error("unknown mode {name:?}{}", if known.is_empty() { " (the autopilot's modes are not known)".to_owned() } else { format!("; one of {}", known.join(", ")) })]
    UnknownMode {
        /// The name asked for.
        name: String,
        /// The names the autopilot has.
        known: Vec<&'static str>,
    },
    /// A MAVFTP operation failed.
    #[error("ftp {what}: {source}")]
    Ftp {
        /// Which (the operation and its path).
        what: String,
        /// Why.
        source: FtpError,
    },
    /// A log download operation (LOG_*) failed.
    #[error("log {what}: {source}")]
    Log {
        /// Which (list, download of an id, erase).
        what: String,
        /// Why.
        source: LogError,
    },
    /// The vehicle lists no log with this id.
    #[error("the vehicle lists no log {id}")]
    NoSuchLog {
        /// The id asked for.
        id: u16,
    },
    /// The packed parameter file (`@PARAM/param.pck`) read over MAVFTP is not one.
    #[error("{path}: {source}")]
    ParamFile {
        /// The file's path.
        path: &'static str,
        /// What is wrong with it.
        source: DecodeError,
    },
    /// A parameter table that cannot be uploaded as a packed file.
    #[error("{path}: {source}")]
    ParamPack {
        /// The file's path.
        path: &'static str,
        /// Why it cannot be packed.
        source: EncodeError,
    },
    /// The request could not start (another like it is running).
    #[error("{0}")]
    Busy(String),
    /// The node stopped.
    #[error("the node has stopped")]
    Stopped,
}

/// How [`System::params_by`] fetches the parameter table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamsVia {
    /// MAVFTP (`@PARAM/param.pck`) when the system's AUTOPILOT_VERSION advertises
    /// MAV_PROTOCOL_CAPABILITY_FTP (asked for [`CAPABILITIES_WAIT`] at most), the file's
    /// open tried [`AUTO_FTP_RETRIES`] times more and the transfer once it answered with the
    /// usual retries; PARAM_REQUEST_LIST when it does not, or when the download fails.
    Auto,
    /// MAVFTP only.
    Ftp,
    /// PARAM_REQUEST_LIST only.
    List,
}

/// How long [`ParamsVia::Auto`] waits for AUTOPILOT_VERSION.
pub const CAPABILITIES_WAIT: Duration = Duration::from_secs(2);

/// How often [`System::find_capabilities`] asks again for AUTOPILOT_VERSION.
const CAPABILITIES_RESEND: Duration = Duration::from_millis(500);

/// Retries of the first MAVFTP request (the open) of [`ParamsVia::Auto`], which can still
/// fall back. (Applied to every request, a transfer through 20 % loss each way gave up
/// half-way about every other time, and the fallback cost three times as long.)
pub const AUTO_FTP_RETRIES: u8 = 3;

/// The MAVFTP operations on one path that return nothing ([`System::ftp_simple`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FtpPathOp {
    /// Remove a file.
    Remove,
    /// Make a directory.
    Mkdir,
    /// Remove an empty directory.
    Rmdir,
}

impl FtpPathOp {
    /// The operation's name as `mavstack ftp` spells it.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Remove => "rm",
            Self::Mkdir => "mkdir",
            Self::Rmdir => "rmdir",
        }
    }
}

/// A number that differs between runs (the wall clock's nanoseconds), to start MAVFTP
/// sequence numbers where another process's client is unlikely to have stopped.
fn clock_seed() -> u16 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| (d.subsec_nanos() >> 8) as u16 ^ d.as_secs() as u16)
}

/// The STATUSTEXT lines after an error's message.
fn said(lines: &[String]) -> String {
    if lines.is_empty() {
        String::new()
    } else {
        format!(" ({})", lines.join("; "))
    }
}

/// What a signing change proved: requests sent in the link's new signing after it, and
/// the answers that came back. On a signed link only frames that verify with the key are
/// accepted, so an answer there is a signed one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SigningCheck {
    /// Requests sent.
    pub asked: u8,
    /// Requests answered.
    pub answered: u8,
}

impl SigningCheck {
    /// Every request was answered.
    #[must_use]
    pub const fn proven(&self) -> bool {
        self.asked > 0 && self.answered == self.asked
    }
}

/// How [`System::request_rate`] got the message going.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RateMethod {
    /// MAV_CMD_SET_MESSAGE_INTERVAL, accepted.
    MessageInterval,
    /// REQUEST_DATA_STREAM for this group, after SET_MESSAGE_INTERVAL was refused or ignored.
    DataStream(mavstack_dialects::common::MavDataStream),
}

/// What [`System::request_rate`] did and saw.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RateRequest {
    /// The request that was made last.
    pub how: RateMethod,
    /// Whether the message then arrived.
    pub arrived: bool,
}

/// STATUSTEXT lines and events kept while a command runs.
const MAX_SAID: usize = 32;

/// How long STATUSTEXT is still collected after a refusal.
const SAID_AFTER: Duration = Duration::from_millis(500);

/// A remote system reached through a node's link.
#[derive(Debug)]
pub struct System {
    node: NodeHandle,
    frames: Subscription,
    own: Address,
    target: Address,
    link: LinkId,
    link_name: String,
    autopilot: MavAutopilot,
    mav_type: MavType,
    found_in: Version,
    handshake: Option<HandshakeOutcome>,
    home_amsl: Option<f32>,
    /// Its HOME_POSITION, once seen.
    home: Option<HomePosition>,
    /// The capabilities of its AUTOPILOT_VERSION, once seen.
    capabilities: Option<MavProtocolCapability>,
    retries: u8,
    /// Retries of each MAVFTP operation's first request, when fewer than `retries`.
    ftp_probe_retries: Option<u8>,
    /// STATUSTEXT chunks put together.
    lines: Lines,
    /// What the target said (STATUSTEXT, EVENT) since the current command started, and its
    /// event metadata.
    listening: said::Listening,
    /// Its logs as last listed ([`System::log_list`]).
    logs: Option<Vec<LogInfo>>,
    /// Where the next MAVFTP client starts its sequence numbers (see
    /// [`FtpClient::starting_after`]): from the clock at first, then where the last stopped.
    ftp_seq: u16,
}

impl System {
    /// Waits up to `wait` for the `wanted` system's HEARTBEAT on any link of `node`; if it
    /// came in MAVLink 1 on a ground-station link
    /// ([`LinkRole::GroundStation`](crate::router::LinkRole::GroundStation)), runs the
    /// MAVLink 2 handshake (REQUEST_MESSAGE(300)) there: whatever its outcome, the link goes
    /// on in the version it settles on ([`handshake`](Self::handshake) tells).
    ///
    /// # Errors
    /// [`SystemError::NotFound`], [`SystemError::Stopped`].
    pub async fn wait(
        node: &NodeHandle,
        wanted: Wanted,
        wait: Duration,
    ) -> Result<Self, SystemError> {
        let mut frames = node.subscribe().await;
        let deadline = tokio::time::Instant::now() + wait;
        let found = tokio::time::timeout_at(deadline, async {
            while let Some(incoming) = frames.recv().await {
                let f = incoming.frame.frame.view();
                let Ok(MavMessage::Heartbeat(hb)) = MavMessage::decode(f.msg_id(), f.payload())
                else {
                    continue;
                };
                let ok = match wanted {
                    Wanted::AnyAutopilot => {
                        hb.autopilot != MavAutopilot::INVALID && hb.r#type != MavType::GCS
                    }
                    Wanted::System(s, c) => f.sysid() == s && c.is_none_or(|c| c == f.compid()),
                };
                if ok {
                    let component = match wanted {
                        Wanted::System(_, Some(c)) => c,
                        _ => f.compid(),
                    };
                    let (target, version) = (Address::new(f.sysid(), component), f.version());
                    return Some((incoming, target, hb, version));
                }
            }
            None
        })
        .await;
        let (incoming, target, hb, found_in) = match found {
            Ok(Some(found)) => found,
            Ok(None) => return Err(SystemError::Stopped),
            Err(_) => {
                return Err(SystemError::NotFound {
                    seconds: wait.as_secs_f64(),
                });
            }
        };
        let (sysid, compid) = node.identity();
        let mut system = Self {
            node: node.clone(),
            frames,
            own: Address::new(sysid, compid),
            target,
            link: incoming.link_id,
            link_name: incoming.link,
            autopilot: hb.autopilot,
            mav_type: hb.r#type,
            found_in,
            handshake: None,
            home_amsl: None,
            home: None,
            capabilities: None,
            retries: PATIENT_RETRIES,
            ftp_probe_retries: None,
            lines: Lines::default(),
            listening: said::Listening::default(),
            logs: None,
            ftp_seq: clock_seed(),
        };
        if found_in == Version::V1 {
            let outcome = system
                .node
                .handshake(
                    system.link,
                    Target::new(target.system, target.component),
                    HandshakeMethod::RequestMessage300,
                    CommandEncoding::Long,
                )
                .await;
            // A link that cannot handshake (not a ground-station link, version=1) stays as
            // it is.
            system.handshake = outcome.ok();
        }
        Ok(system)
    }

    /// Its address (system, and the component that answered or was asked for).
    #[must_use]
    pub const fn target(&self) -> Address {
        self.target
    }

    /// The autopilot its HEARTBEAT names.
    #[must_use]
    pub const fn autopilot(&self) -> MavAutopilot {
        self.autopilot
    }

    /// The vehicle type its HEARTBEAT names.
    #[must_use]
    pub const fn mav_type(&self) -> MavType {
        self.mav_type
    }

    /// The router link it was found on.
    #[must_use]
    pub const fn link(&self) -> LinkId {
        self.link
    }

    /// The name of that link.
    #[must_use]
    pub fn link_name(&self) -> &str {
        &self.link_name
    }

    /// The framing of the HEARTBEAT that found it.
    #[must_use]
    pub const fn found_in(&self) -> Version {
        self.found_in
    }

    /// The outcome of the handshake [`wait`](Self::wait) ran, if it ran one.
    #[must_use]
    pub const fn handshake(&self) -> Option<&HandshakeOutcome> {
        self.handshake.as_ref()
    }

    /// Its home altitude above mean sea level (m), once a GLOBAL_POSITION_INT or
    /// HOME_POSITION of it was seen during an operation.
    #[must_use]
    pub const fn home_amsl(&self) -> Option<f32> {
        self.home_amsl
    }

    /// Its home altitude above mean sea level: the known one, or else asked for (HOME_POSITION
    /// and GLOBAL_POSITION_INT requested once with REQUEST_MESSAGE, then awaited) for up to
    /// `wait`; `None` when it never came. A vehicle that streams nothing until asked
    /// (ArduPilot) still answers a one-shot request.
    pub async fn find_home_amsl(&mut self, wait: Duration) -> Option<f32> {
        self.update();
        if self.home_amsl.is_some() {
            return self.home_amsl;
        }
        for id in [HomePosition::ID, GlobalPositionInt::ID] {
            self.request_once(id).await;
        }
        self.take_until(wait, |s, _| s.home_amsl.is_some()).await;
        self.home_amsl
    }

    /// Its home as a plan's item 0 (a NAV_WAYPOINT in MAV_FRAME_GLOBAL at home's latitude,
    /// longitude and altitude above mean sea level): HOME_POSITION asked for when not seen
    /// yet, awaited up to `wait`; `None` when it never came.
    pub async fn home_item(&mut self, wait: Duration) -> Option<MissionItemInt> {
        self.update();
        if self.home.is_none() {
            self.request_once(HomePosition::ID).await;
            self.take_until(wait, |s, _| s.home.is_some()).await;
        }
        let home = self.home?;
        Some(MissionItemInt {
            frame: MavFrame::GLOBAL,
            command: MavCmd::NAV_WAYPOINT,
            autocontinue: 1,
            x: home.latitude,
            y: home.longitude,
            z: home.altitude as f32 / 1000.0,
            ..MissionItemInt::default()
        })
    }

    /// The capabilities its AUTOPILOT_VERSION advertised, once one was seen during an
    /// operation (see [`find_capabilities`](Self::find_capabilities)).
    #[must_use]
    pub const fn capabilities(&self) -> Option<MavProtocolCapability> {
        self.capabilities
    }

    /// Its capabilities: the known ones, or else AUTOPILOT_VERSION requested with
    /// REQUEST_MESSAGE (again every half second) and awaited for up to `wait`; `None` when
    /// it never came.
    pub async fn find_capabilities(&mut self, wait: Duration) -> Option<MavProtocolCapability> {
        self.update();
        let end = tokio::time::Instant::now() + wait;
        while self.capabilities.is_none() {
            let left = end.saturating_duration_since(tokio::time::Instant::now());
            if left.is_zero() {
                break;
            }
            // Asked again every half second: one request and its answer through a link
            // losing 20 % each way are both there only two times in three.
            self.request_once(AutopilotVersion::ID).await;
            let slice = left.min(CAPABILITIES_RESEND);
            self.take_until(slice, |s, _| s.capabilities.is_some())
                .await;
        }
        self.capabilities
    }

    /// Sends one REQUEST_MESSAGE for `id` (no retries, no wait for its answer).
    async fn request_once(&self, id: u32) {
        let request = MavMessage::CommandLong(CommandLong {
            target_system: self.target.system,
            target_component: self.target.component,
            command: MavCmd::REQUEST_MESSAGE,
            param1: id as f32,
            ..CommandLong::default()
        });
        self.node.send_on(self.link, &request).await;
    }

    /// Whose mode numbers it uses, from its HEARTBEAT's autopilot and type (`None` when
    /// they are not known here).
    #[must_use]
    pub fn flavour(&self) -> Option<Flavour> {
        Flavour::of(self.autopilot, self.mav_type)
    }

    /// Switches it to the mode called `name` (see [`crate::modes::by_name`]) with
    /// MAV_CMD_DO_SET_MODE, and waits for the answer (STATUSTEXT with a refusal, as
    /// [`command`](Self::command)).
    ///
    /// # Errors
    /// [`SystemError::UnknownMode`] (the name, or the autopilot's modes, are not known),
    /// and those of [`command`](Self::command).
    pub async fn set_mode(&mut self, name: &str) -> Result<CommandAck, SystemError> {
        let unknown = |known: Vec<&'static str>| SystemError::UnknownMode {
            name: name.to_owned(),
            known,
        };
        let flavour = self.flavour().ok_or_else(|| unknown(Vec::new()))?;
        let mode = crate::modes::by_name(flavour, name).ok_or_else(|| {
            unknown(
                crate::modes::modes(flavour)
                    .iter()
                    .map(|m| m.name)
                    .collect(),
            )
        })?;
        let (param1, param2, param3) = flavour.command_params(mode.custom_mode);
        let command = Command::Long(CommandLong {
            command: MavCmd::DO_SET_MODE,
            param1,
            param2,
            param3,
            ..CommandLong::default()
        });
        self.command(command, |_| {}).await
    }

    /// Takes in what the system sent since the last operation (its home altitude, for
    /// [`home_amsl`](Self::home_amsl)).
    pub fn update(&mut self) {
        while let Ok(incoming) = self.frames.try_recv() {
            let f = incoming.frame.frame.view();
            if let Ok(msg) = MavMessage::decode(f.msg_id(), f.payload()) {
                self.note(Address::new(f.sysid(), f.compid()), &msg);
            }
        }
    }

    /// Retries per message of later parameter and mission operations (default
    /// [`PATIENT_RETRIES`]).
    pub const fn set_retries(&mut self, retries: u8) {
        self.retries = retries;
    }

    /// Its parameter encoding (ArduPilot's C cast, everyone else's bytewise).
    #[must_use]
    pub fn encoding(&self) -> Encoding {
        Encoding::for_autopilot(self.autopilot)
    }

    fn param_client(&self) -> ParamClient {
        let config = ParamConfig {
            retries: self.retries,
            ..ParamConfig::default()
        };
        ParamClient::new(config, self.encoding())
    }

    fn mission_client(&self) -> MissionClient {
        let config = MissionConfig {
            retries: self.retries,
            ..MissionConfig::default()
        };
        MissionClient::new(self.own, config)
    }

    // ----- parameters --------------------------------------------------------------------

    /// The whole parameter table, by index.
    ///
    /// # Errors
    /// [`SystemError::Param`] (entries still missing after the retries), [`SystemError::Busy`],
    /// [`SystemError::Timeout`] (10 minutes), [`SystemError::Stopped`].
    pub async fn params(&mut self) -> Result<Vec<(Name, Value)>, SystemError> {
        self.params_with_progress(|_, _| {}).await
    }

    /// Like [`params`](Self::params), telling `progress` (values received, count) each time
    /// more have come.
    ///
    /// # Errors
    /// As [`params`](Self::params).
    pub async fn params_with_progress(
        &mut self,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let mut client = self.param_client();
        let target = self.target;
        client
            .fetch_all(clock::now(), target)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let mut told = (0, 0);
        let result = self
            .run(&mut client, Duration::from_secs(600), |c| {
                if let Some(ListFetch::Collecting(list)) = c.list_state(target) {
                    let now = (list.count() - list.missing(), list.count());
                    if now != told {
                        told = now;
                        progress(now.0, now.1);
                    }
                }
                let result = core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    ParamEvent::List { result, .. } => Some(result),
                    _ => None,
                });
                if let Some(Ok(table)) = &result
                    && told != (table.len(), table.len())
                {
                    progress(table.len(), table.len());
                }
                result
            })
            .await?;
        result.map_err(|source| SystemError::Param {
            what: "list".to_owned(),
            source,
        })
    }

    /// The whole parameter table in one MAVFTP download of ArduPilot's packed file,
    /// `@PARAM/param.pck` ([`param_pck`]): the order and types of the file, the same table
    /// as [`params`](Self::params) gives, in a fraction of the time on a long table. Only
    /// systems whose MAVFTP server has that file (ArduPilot, `mavstack vehicle`) can answer;
    /// [`find_capabilities`](Self::find_capabilities) tells whether there is a MAVFTP server.
    ///
    /// # Errors
    /// Those of [`ftp_read`](Self::ftp_read) (no such file: [`SystemError::Ftp`]), and
    /// [`SystemError::ParamFile`] for a file that is not a packed table.
    pub async fn params_via_ftp(&mut self) -> Result<Vec<(Name, Value)>, SystemError> {
        self.params_via_ftp_with_progress(|_, _| {}).await
    }

    /// Like [`params_via_ftp`](Self::params_via_ftp), telling `progress` (bytes so far,
    /// size) as the file comes.
    ///
    /// # Errors
    /// As [`params_via_ftp`](Self::params_via_ftp).
    pub async fn params_via_ftp_with_progress(
        &mut self,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let bytes = self.ftp_read(param_pck::PATH, progress).await?;
        param_pck::decode(&bytes).map_err(|source| SystemError::ParamFile {
            path: param_pck::PATH,
            source,
        })
    }

    /// Sets the parameters of `table` with one MAVFTP upload of ArduPilot's packed file
    /// ([`param_pck::encode_upload`]), then reads the file back and returns the table as the
    /// system has it now. The upload itself has no answer per parameter: ArduPilot converts
    /// each value to its parameter's type and skips names it does not have, silently, so
    /// compare what comes back. At most [`param_pck::MAX_UPLOAD`] bytes (about 5,000
    /// changes); `progress` hears (bytes so far, size) of the upload.
    ///
    /// # Errors
    /// [`SystemError::ParamPack`] for a table too large to pack; those of
    /// [`ftp_write`](Self::ftp_write) and [`params_via_ftp`](Self::params_via_ftp).
    pub async fn set_params_via_ftp(
        &mut self,
        table: &[(Name, Value)],
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<(Name, Value)>, SystemError> {
        let bytes = param_pck::encode_upload(table).map_err(|source| SystemError::ParamPack {
            path: param_pck::PATH,
            source,
        })?;
        self.ftp_write(param_pck::PATH, &bytes, progress).await?;
        self.params_via_ftp().await
    }

    /// The whole parameter table as `via` says, and the way it came ([`ParamsVia::Ftp`] or
    /// [`ParamsVia::List`]): the same table either way (names, values, types). `progress`
    /// hears the way, and (done, total) in bytes of the file or in parameters. A fallback
    /// of [`ParamsVia::Auto`] is logged as a warning with the reason.
    ///
    /// # Errors
    /// Those of [`params_via_ftp`](Self::params_via_ftp) for [`ParamsVia::Ftp`], of
    /// [`params`](Self::params) otherwise.
    pub async fn params_by(
        &mut self,
        via: ParamsVia,
        mut progress: impl FnMut(ParamsVia, u64, u64),
    ) -> Result<(Vec<(Name, Value)>, ParamsVia), SystemError> {
        let ftp = match via {
            ParamsVia::Ftp => true,
            ParamsVia::List => false,
            ParamsVia::Auto => self
                .find_capabilities(CAPABILITIES_WAIT)
                .await
                .is_some_and(|c| c.contains(MavProtocolCapability::FTP)),
        };
        if ftp {
            if via == ParamsVia::Auto {
                self.ftp_probe_retries = Some(AUTO_FTP_RETRIES);
            }
            let got = self
                .params_via_ftp_with_progress(|done, total| {
                    progress(ParamsVia::Ftp, done, total);
                })
                .await;
            self.ftp_probe_retries = None;
            match got {
                Ok(table) => return Ok((table, ParamsVia::Ftp)),
                Err(e) if via == ParamsVia::Ftp || matches!(e, SystemError::Stopped) => {
                    return Err(e);
                }
                Err(e) => {
                    tracing::warn!("MAVFTP failed ({e}): PARAM_REQUEST_LIST instead");
                }
            }
        }
        let table = self
            .params_with_progress(|done, total| {
                progress(ParamsVia::List, done as u64, total as u64);
            })
            .await?;
        Ok((table, ParamsVia::List))
    }

    /// One parameter, read by name.
    ///
    /// # Errors
    /// [`SystemError::Param`] (no answer, or no such parameter), [`SystemError::Stopped`].
    pub async fn param(&mut self, name: Name) -> Result<Param, SystemError> {
        let mut client = self.param_client();
        let handle = client.read(clock::now(), self.target, ParamRef::Name(name));
        self.param_result(&mut client, handle, name).await
    }

    /// Sets a parameter and waits for the system's confirmation; returns the value in force
    /// (the system may have clamped or refused it).
    ///
    /// # Errors
    /// [`SystemError::Param`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn set_param(&mut self, name: Name, value: Value) -> Result<Param, SystemError> {
        let mut client = self.param_client();
        let handle = client
            .set(clock::now(), self.target, name, value)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        self.param_result(&mut client, handle, name).await
    }

    async fn param_result(
        &mut self,
        client: &mut ParamClient,
        handle: mavstack_services::param::ParamHandle,
        name: Name,
    ) -> Result<Param, SystemError> {
        let result = self
            .run(client, Duration::from_secs(30), |c| {
                core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    ParamEvent::Finished { handle: h, result } if h == handle => Some(result),
                    _ => None,
                })
            })
            .await?;
        result.map_err(|source| SystemError::Param {
            what: name.to_string(),
            source,
        })
    }

    // ----- missions ------------------------------------------------------------------------

    /// Uploads `items` as the system's plan of `kind` (mission, fence or rally).
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn upload_mission(
        &mut self,
        kind: MavMissionType,
        items: Vec<MissionItemInt>,
    ) -> Result<(), SystemError> {
        self.upload_mission_with_progress(kind, items, |_, _| {})
            .await
    }

    /// Like [`upload_mission`](Self::upload_mission), telling `progress` (items sent,
    /// count) each time the system has asked for more.
    ///
    /// # Errors
    /// As [`upload_mission`](Self::upload_mission).
    pub async fn upload_mission_with_progress(
        &mut self,
        kind: MavMissionType,
        items: Vec<MissionItemInt>,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<(), SystemError> {
        let mut client = self.mission_client();
        let sent = items.clone();
        client
            .upload(clock::now(), self.target, kind, items)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let mut told = (0, 0);
        let event = self
            .run(&mut client, Duration::from_secs(3600), |c| {
                let now = match c.upload_state() {
                    Some(Upload::AwaitingRequest(u)) => (u.sent(), u.count()),
                    Some(Upload::AwaitingAck(u)) => (u.count(), u.count()),
                    None => told,
                };
                if now != told {
                    told = now;
                    progress(now.0, now.1);
                }
                c.poll_event()
            })
            .await?;
        match event {
            MissionEvent::Uploaded {
                result: Err(MissionError::Unconfirmed { result }),
                ..
            } => {
                // The final ACK was lost; what the vehicle holds tells whether it took the
                // plan.
                tracing::info!(
                    "mission upload: the final MISSION_ACK was lost ({result:?} to the last \
                     item sent again): reading the plan back"
                );
                let back = self.download_mission(kind).await?;
                if mavstack_services::plan::same(&sent, &back) {
                    Ok(())
                } else {
                    Err(SystemError::Mission {
                        what: "upload",
                        source: MissionError::Rejected { result },
                    })
                }
            }
            MissionEvent::Uploaded { result, .. } => {
                result.map_err(|source| SystemError::Mission {
                    what: "upload",
                    source,
                })
            }
            _ => Err(unexpected("upload")),
        }
    }

    /// Downloads the system's plan of `kind`.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn download_mission(
        &mut self,
        kind: MavMissionType,
    ) -> Result<Vec<MissionItemInt>, SystemError> {
        self.download_mission_with_progress(kind, |_, _| {}).await
    }

    /// Like [`download_mission`](Self::download_mission), telling `progress` (items
    /// received, count) as they come.
    ///
    /// # Errors
    /// As [`download_mission`](Self::download_mission).
    pub async fn download_mission_with_progress(
        &mut self,
        kind: MavMissionType,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<Vec<MissionItemInt>, SystemError> {
        let mut client = self.mission_client();
        client
            .download(clock::now(), self.target, kind)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let mut told = (0, 0);
        let event = self
            .run(&mut client, Duration::from_secs(3600), |c| {
                if let Some(Download::AwaitingItem(d)) = c.download_state() {
                    let now = (usize::from(d.seq), usize::from(d.count()));
                    if now != told {
                        told = now;
                        progress(now.0, now.1);
                    }
                }
                c.poll_event()
            })
            .await?;
        match event {
            MissionEvent::Downloaded { result, .. } => {
                if let Ok(items) = &result
                    && told != (items.len(), items.len())
                {
                    progress(items.len(), items.len());
                }
                result.map_err(|source| SystemError::Mission {
                    what: "download",
                    source,
                })
            }
            _ => Err(unexpected("download")),
        }
    }

    /// Clears the system's plan of `kind`.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn clear_mission(&mut self, kind: MavMissionType) -> Result<(), SystemError> {
        let mut client = self.mission_client();
        client
            .clear(clock::now(), self.target, kind)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        self.mission_result(&mut client, "clear", |e| match e {
            MissionEvent::Cleared { result, .. } => Some(result),
            _ => None,
        })
        .await
    }

    /// Makes mission item `seq` the current one.
    ///
    /// # Errors
    /// [`SystemError::Mission`], [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn set_current_mission_item(&mut self, seq: u16) -> Result<(), SystemError> {
        let mut client = self.mission_client();
        client
            .set_current(clock::now(), self.target, seq)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        self.mission_result(&mut client, "set current", |e| match e {
            MissionEvent::CurrentSet { result, .. } => Some(result),
            _ => None,
        })
        .await
    }

    /// Runs the started operation `what` of `client` to its event; `pick` takes its result.
    async fn mission_result(
        &mut self,
        client: &mut MissionClient,
        what: &'static str,
        pick: impl FnOnce(MissionEvent) -> Option<Result<(), MissionError>>,
    ) -> Result<(), SystemError> {
        let event = self
            .run(client, Duration::from_secs(3600), MissionClient::poll_event)
            .await?;
        pick(event)
            .ok_or_else(|| unexpected(what))?
            .map_err(|source| SystemError::Mission { what, source })
    }

    // ----- commands ------------------------------------------------------------------------

    /// Sends a command (COMMAND_LONG or COMMAND_INT; its target fields are the system's) with
    /// the services' retries and waits for the final COMMAND_ACK; `progress` hears each
    /// IN_PROGRESS (0–100, 255 unknown). When the command is refused or unanswered, the
    /// error carries the STATUSTEXT lines the system sent from the request until 0.5 s after
    /// its answer (the reason flight stacks give).
    ///
    /// # Errors
    /// [`SystemError::Command`] (refused, or no acknowledgement), [`SystemError::Busy`],
    /// [`SystemError::Stopped`].
    pub async fn command(
        &mut self,
        command: Command,
        mut progress: impl FnMut(u8),
    ) -> Result<CommandAck, SystemError> {
        let id = command.id();
        self.update();
        self.listening.said.clear();
        let mut client = CommandClient::new(self.own, CommandConfig::default());
        let handle = client
            .send(clock::now(), self.target, command)
            .map_err(|e| SystemError::Busy(e.to_string()))?;
        let result = self
            .run(&mut client, Duration::from_secs(600), |c| {
                core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    CommandEvent::Progress {
                        handle: h,
                        progress: p,
                    } if h == handle => {
                        progress(p);
                        None
                    }
                    CommandEvent::Finished { handle: h, result } if h == handle => Some(result),
                    _ => None,
                })
            })
            .await?;
        match result {
            Ok(ack) => Ok(ack),
            Err(source) => {
                // STATUSTEXT or EVENTs that say why may follow the refusal.
                self.take_until(SAID_AFTER, |_, _| false).await;
                let said = core::mem::take(&mut self.listening.said);
                Err(SystemError::Command {
                    command: command_name(id),
                    source,
                    statustext: self.said_texts(said).await,
                })
            }
        }
    }

    /// Takes in what the system sends (noting what it tells about itself) until `done` holds
    /// after a frame — given the frame's (sysid, msg_id) — or `wait` has passed; says whether
    /// `done` held.
    async fn take_until(
        &mut self,
        wait: Duration,
        mut done: impl FnMut(&Self, (u8, u32)) -> bool,
    ) -> bool {
        let until = tokio::time::Instant::now() + wait;
        while let Ok(Some(incoming)) = tokio::time::timeout_at(until, self.frames.recv()).await {
            let f = incoming.frame.frame.view();
            if let Ok(msg) = MavMessage::decode(f.msg_id(), f.payload()) {
                self.note(Address::new(f.sysid(), f.compid()), &msg);
            }
            if done(self, (f.sysid(), f.msg_id())) {
                return true;
            }
        }
        false
    }

    /// Asks the system to send message `id` once (MAV_CMD_REQUEST_MESSAGE); returns its
    /// acknowledgement (the message itself arrives on the node's subscriptions).
    ///
    /// # Errors
    /// As [`command`](Self::command).
    pub async fn request_message(&mut self, id: u32) -> Result<CommandAck, SystemError> {
        let command = Command::Long(CommandLong {
            command: MavCmd::REQUEST_MESSAGE,
            param1: id as f32,
            ..CommandLong::default()
        });
        self.command(command, |_| {}).await
    }

    /// Asks the system to stream message `id` every `interval` (MAV_CMD_SET_MESSAGE_INTERVAL;
    /// `None` stops it).
    ///
    /// # Errors
    /// As [`command`](Self::command).
    pub async fn set_message_interval(
        &mut self,
        id: u32,
        interval: Option<Duration>,
    ) -> Result<CommandAck, SystemError> {
        let us = interval.map_or(-1.0, |d| d.as_micros() as f32);
        let command = Command::Long(CommandLong {
            command: MavCmd::SET_MESSAGE_INTERVAL,
            param1: id as f32,
            param2: us,
            ..CommandLong::default()
        });
        self.command(command, |_| {}).await
    }

    // ----- the link --------------------------------------------------------------------------

    /// What the link to the system carries now: `"1"`, `"2"`, `"signed"` or `"auto"` (see
    /// [`LinkReport::version`](crate::LinkReport)); `None` once the node has stopped or the
    /// peer went away.
    pub async fn link_version(&self) -> Option<&'static str> {
        let report = self.node.report().await?;
        report
            .links
            .iter()
            .find(|l| l.link_id == Some(self.link))
            .map(|l| l.version)
    }

    /// Sets up signing with the system: sends SETUP_SIGNING with `key` and a timestamp of
    /// now over the link (which should be a secure one: a wire, or a link already signed),
    /// signs the link with `key` and link id `link_id`, then proves it: the system confirms
    /// nothing, so one request (REQUEST_MESSAGE for AUTOPILOT_VERSION, with the command
    /// protocol's retries) goes out signed, and only a signed answer that verifies with `key`
    /// can reach us on the signed link ([`SigningCheck::answered`]).
    ///
    /// # Errors
    /// [`SystemError::Busy`] on a link that cannot sign (`version=1`),
    /// [`SystemError::Stopped`].
    pub async fn setup_signing(
        &mut self,
        key: mavstack_core::signing::SecretKey,
        link_id: u8,
    ) -> Result<SigningCheck, SystemError> {
        let timestamp =
            mavstack_core::signing::timestamp_from_unix_micros(clock::now().as_micros());
        self.send_setup_signing(*key.as_bytes(), timestamp).await?;
        let mut signing = mavstack_channel::SigningConfig::new(key, link_id);
        signing.initial_timestamp = timestamp;
        self.sign_link(Some(signing)).await?;
        Ok(self.check_answers().await)
    }

    /// Turns signing off with the system: sends SETUP_SIGNING with the all-zero key and
    /// timestamp (signed with the link's current key, as the system requires), stops signing
    /// the link, then proves it with one unsigned request ([`SigningCheck::answered`]: the
    /// system answered it, so it accepts unsigned frames again).
    ///
    /// # Errors
    /// As [`setup_signing`](Self::setup_signing).
    pub async fn remove_signing(&mut self) -> Result<SigningCheck, SystemError> {
        self.send_setup_signing([0; 32], 0).await?;
        self.sign_link(None).await?;
        Ok(self.check_answers().await)
    }

    async fn send_setup_signing(
        &self,
        secret_key: [u8; 32],
        timestamp: u64,
    ) -> Result<(), SystemError> {
        let setup = MavMessage::SetupSigning(mavstack_dialects::common::SetupSigning {
            target_system: self.target.system,
            target_component: self.target.component,
            secret_key,
            initial_timestamp: timestamp,
        });
        if self.node.send_on(self.link, &setup).await == 0 {
            return Err(SystemError::Stopped);
        }
        Ok(())
    }

    async fn sign_link(
        &self,
        signing: Option<mavstack_channel::SigningConfig>,
    ) -> Result<(), SystemError> {
        self.node
            .set_signing(self.link, signing)
            .await
            .map_err(|e| match e {
                crate::node::RequestError::Stopped => SystemError::Stopped,
                e => SystemError::Busy(e.to_string()),
            })
    }

    /// One request in the link's current signing; whether it was answered.
    async fn check_answers(&mut self) -> SigningCheck {
        let answered = self.request_message(AutopilotVersion::ID).await.is_ok();
        SigningCheck {
            asked: 1,
            answered: u8::from(answered),
        }
    }

    // ----- telemetry -----------------------------------------------------------------------

    /// Asks the system to send message `msg_id` `hz` times a second, and checks that it
    /// comes: SET_MESSAGE_INTERVAL first; where the system refuses it, or accepts it and the
    /// message still does not come within a few of its intervals (at least 1.5 s), the older
    /// REQUEST_DATA_STREAM for the group that carries it (ArduPilot before 4.0, some links).
    ///
    /// # Errors
    /// [`SystemError::Stopped`]; a system that sends the message neither way is not an error
    /// ([`RateRequest::arrived`] is false).
    pub async fn request_rate(&mut self, msg_id: u32, hz: f32) -> Result<RateRequest, SystemError> {
        let hz = if hz.is_finite() {
            hz.clamp(0.01, 1000.0)
        } else {
            1.0
        };
        let interval = Duration::from_secs_f32(1.0 / hz);
        let wait = (interval * 3).max(Duration::from_millis(1500));
        let answer = self.set_message_interval(msg_id, Some(interval)).await;
        let accepted = match answer {
            Ok(_) => true,
            Err(SystemError::Stopped) => return Err(SystemError::Stopped),
            Err(_) => false,
        };
        if accepted && self.comes(msg_id, wait).await {
            return Ok(RateRequest {
                how: RateMethod::MessageInterval,
                arrived: true,
            });
        }
        let Some(group) = mavstack_services::stream::data_stream_of(msg_id) else {
            return Ok(RateRequest {
                how: RateMethod::MessageInterval,
                arrived: false,
            });
        };
        let request = mavstack_services::stream::request_data_stream(self.target, group, hz);
        if self
            .node
            .send_on(self.link, &MavMessage::RequestDataStream(request))
            .await
            == 0
        {
            return Err(SystemError::Stopped);
        }
        let arrived = self.comes(msg_id, wait).await;
        Ok(RateRequest {
            how: RateMethod::DataStream(group),
            arrived,
        })
    }

    /// Whether message `msg_id` from the system arrives within `wait`.
    async fn comes(&mut self, msg_id: u32, wait: Duration) -> bool {
        self.take_until(wait, |s, (sysid, id)| {
            id == msg_id && sysid == s.target.system
        })
        .await
    }

    /// Messages `T` from this system from now on, decoded (see [`Telemetry`]).
    pub async fn subscribe<T: Message>(&self) -> Telemetry<T> {
        Telemetry {
            frames: self.node.subscribe().await,
            system: self.target.system,
            message: PhantomData,
        }
    }

    // ----- files (MAVFTP) -------------------------------------------------------------------

    /// A directory's entries on the system's MAVFTP server.
    ///
    /// # Errors
    /// [`SystemError::Ftp`] (refused, or no answer after the retries), [`SystemError::Busy`]
    /// (a path too long), [`SystemError::Stopped`].
    pub async fn ftp_list(&mut self, path: &str) -> Result<Vec<DirEntry>, SystemError> {
        match self
            .ftp(format!("ls {path}"), |c, now| c.list(now, path), |_, _| {})
            .await?
        {
            FtpOutput::Listing(entries) => Ok(entries),
            _ => Err(self.ftp_protocol(format!("ls {path}"))),
        }
    }

    /// A file's contents, telling `progress` (bytes so far, size) as they come.
    ///
    /// # Errors
    /// As [`ftp_list`](Self::ftp_list).
    pub async fn ftp_read(
        &mut self,
        path: &str,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<u8>, SystemError> {
        match self
            .ftp(format!("get {path}"), |c, now| c.read(now, path), progress)
            .await?
        {
            FtpOutput::Data(bytes) => Ok(bytes),
            _ => Err(self.ftp_protocol(format!("get {path}"))),
        }
    }

    /// Writes `contents` as the file `path` (created; an existing file is refused by most
    /// servers), telling `progress` (bytes so far, size).
    ///
    /// # Errors
    /// As [`ftp_list`](Self::ftp_list).
    pub async fn ftp_write(
        &mut self,
        path: &str,
        contents: &[u8],
        progress: impl FnMut(u64, u64),
    ) -> Result<(), SystemError> {
        self.ftp(
            format!("put {path}"),
            |c, now| c.write(now, path, contents),
            progress,
        )
        .await
        .map(drop)
    }

    /// Removes a file (`rm`), makes or removes a directory (`mkdir`, `rmdir`).
    ///
    /// # Errors
    /// As [`ftp_list`](Self::ftp_list).
    pub async fn ftp_simple(&mut self, op: FtpPathOp, path: &str) -> Result<(), SystemError> {
        let what = format!("{} {path}", op.name());
        self.ftp(
            what,
            |c, now| match op {
                FtpPathOp::Remove => c.remove(now, path),
                FtpPathOp::Mkdir => c.mkdir(now, path),
                FtpPathOp::Rmdir => c.rmdir(now, path),
            },
            |_, _| {},
        )
        .await
        .map(drop)
    }

    /// Renames `from` to `to`.
    ///
    /// # Errors
    /// As [`ftp_list`](Self::ftp_list).
    pub async fn ftp_rename(&mut self, from: &str, to: &str) -> Result<(), SystemError> {
        self.ftp(
            format!("mv {from} {to}"),
            |c, now| c.rename(now, from, to),
            |_, _| {},
        )
        .await
        .map(drop)
    }

    /// A file's CRC32 as MAVFTP servers compute it (`mavstack_services::ftp::crc32`).
    ///
    /// # Errors
    /// As [`ftp_list`](Self::ftp_list).
    pub async fn ftp_crc32(&mut self, path: &str) -> Result<u32, SystemError> {
        match self
            .ftp(
                format!("crc {path}"),
                |c, now| c.crc32(now, path),
                |_, _| {},
            )
            .await?
        {
            FtpOutput::Crc32(crc) => Ok(crc),
            _ => Err(self.ftp_protocol(format!("crc {path}"))),
        }
    }

    fn ftp_protocol(&self, what: String) -> SystemError {
        SystemError::Ftp {
            what,
            source: FtpError::Protocol,
        }
    }

    /// Runs one MAVFTP operation, started by `start`, to its end.
    async fn ftp(
        &mut self,
        what: String,
        start: impl FnOnce(&mut FtpClient, mavstack_core::time::Instant) -> Result<(), StartError>,
        mut progress: impl FnMut(u64, u64),
    ) -> Result<FtpOutput, SystemError> {
        let config = FtpConfig {
            attempts: self.retries.saturating_add(1),
            first_attempts: self.ftp_probe_retries.map_or(0, |r| r.saturating_add(1)),
            ..FtpConfig::default()
        };
        let mut client = FtpClient::new(self.own, self.target, config).starting_after(self.ftp_seq);
        start(&mut client, clock::now())
            .map_err(|e| SystemError::Busy(format!("ftp {what}: {e}")))?;
        let result = self
            .run(&mut client, Duration::from_secs(3600), |c| {
                core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    FtpEvent::Progress { done, total } => {
                        progress(done, total);
                        None
                    }
                    FtpEvent::Finished(result) => Some(result),
                })
            })
            .await;
        // The next operation's client starts past this one's numbers.
        self.ftp_seq = client.last_seq().wrapping_add(1);
        result?.map_err(|source| SystemError::Ftp { what, source })
    }

    // ----- logs (LOG_*) ---------------------------------------------------------------------

    fn log_client(&self) -> LogClient {
        let config = LogConfig {
            attempts: self.retries.max(1),
            ..LogConfig::default()
        };
        LogClient::new(self.target, config)
    }

    /// Runs one log operation, started by `start`, to its end (`limit` at most).
    async fn log_op(
        &mut self,
        what: String,
        limit: Duration,
        start: impl FnOnce(&mut LogClient, mavstack_core::time::Instant) -> Result<(), LogStartError>,
        mut progress: impl FnMut(u64, u64),
    ) -> Result<LogOutput, SystemError> {
        let mut client = self.log_client();
        start(&mut client, clock::now())
            .map_err(|e| SystemError::Busy(format!("log {what}: {e}")))?;
        let result = self
            .run(&mut client, limit, |c| {
                core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                    LogEvent::Progress { done, total } => {
                        progress(done, total);
                        None
                    }
                    LogEvent::Finished(result) => Some(result),
                })
            })
            .await;
        // Given up on (the limit, the node stopping): the vehicle is told to stop sending.
        if client.is_busy() {
            client.cancel();
        }
        while let Some(out) = client.poll_transmit() {
            self.node.send_on(self.link, &out.message).await;
        }
        result?.map_err(|source| SystemError::Log { what, source })
    }

    /// The system's logs (LOG_REQUEST_LIST), by id; remembered for
    /// [`log_download`](Self::log_download). Entries lost on the way are asked for again.
    ///
    /// # Errors
    /// [`SystemError::Log`] (no answer, or entries still missing, after the retries),
    /// [`SystemError::Timeout`] (2 minutes), [`SystemError::Stopped`].
    pub async fn log_list(&mut self) -> Result<Vec<LogInfo>, SystemError> {
        let output = self
            .log_op(
                "list".to_owned(),
                Duration::from_secs(120),
                |c, now| c.list(now),
                |_, _| {},
            )
            .await?;
        let LogOutput::Entries(entries) = output else {
            return Err(SystemError::Busy(
                "log list: the log client reported another operation".to_owned(),
            ));
        };
        self.logs = Some(entries.clone());
        Ok(entries)
    }

    /// Log `id`'s bytes (LOG_REQUEST_DATA, gaps asked for again), telling `progress` (bytes so
    /// far, size) as they come. Its size is the one of the last [`log_list`](Self::log_list)
    /// (listed first if there was none, or it did not have `id`); never more than that is
    /// kept, and less when the vehicle ends the log earlier (sizes may be approximate).
    ///
    /// # Errors
    /// [`SystemError::NoSuchLog`], [`SystemError::Log`] (nothing new for the retries'
    /// time), [`SystemError::Busy`] (a log above 512 MiB), [`SystemError::Timeout`]
    /// (6 hours), [`SystemError::Stopped`].
    pub async fn log_download(
        &mut self,
        id: u16,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<u8>, SystemError> {
        let listed = |logs: &Option<Vec<LogInfo>>| {
            logs.as_ref()
                .and_then(|l| l.iter().find(|e| e.id == id).copied())
        };
        let entry = match listed(&self.logs) {
            Some(entry) => entry,
            None => {
                self.log_list().await?;
                listed(&self.logs).ok_or(SystemError::NoSuchLog { id })?
            }
        };
        let output = self
            .log_op(
                format!("download {id}"),
                Duration::from_secs(6 * 3600),
                |c, now| c.download(now, entry.id, entry.size),
                progress,
            )
            .await?;
        match output {
            LogOutput::Data(bytes) => Ok(bytes),
            _ => Err(SystemError::Busy(format!(
                "log download {id}: the log client reported another operation"
            ))),
        }
    }

    /// Erases every log (LOG_ERASE), then lists them to see that none is left (LOG_ERASE
    /// has no answer), sending LOG_ERASE again while some are.
    ///
    /// # Errors
    /// [`SystemError::Log`] (logs still listed: [`LogError::NotErased`]; no answer to the
    /// list), [`SystemError::Timeout`] (2 minutes), [`SystemError::Stopped`].
    pub async fn log_erase(&mut self) -> Result<(), SystemError> {
        self.logs = None;
        self.log_op(
            "erase".to_owned(),
            Duration::from_secs(120),
            |c, now| c.erase(now),
            |_, _| {},
        )
        .await
        .map(drop)
    }

    // ----- the driver ----------------------------------------------------------------------

    /// Drives `service` (any `mavstack-services` state machine) over the system's link until
    /// `done` returns a result, or fails after `limit`.
    ///
    /// # Errors
    /// [`SystemError::Timeout`], [`SystemError::Stopped`].
    pub async fn run<S: Service, R>(
        &mut self,
        service: &mut S,
        limit: Duration,
        mut done: impl FnMut(&mut S) -> Option<R>,
    ) -> Result<R, SystemError> {
        // What waited in the queue came before this operation: not its answers.
        self.update();
        let deadline = tokio::time::Instant::now() + limit;
        loop {
            while let Some(out) = service.poll_transmit() {
                if self.node.send_on(self.link, &out.message).await == 0
                    && self.node.report().await.is_none()
                {
                    return Err(SystemError::Stopped);
                }
            }
            if let Some(result) = done(service) {
                return Ok(result);
            }
            let now = tokio::time::Instant::now();
            if now >= deadline {
                return Err(SystemError::Timeout {
                    seconds: limit.as_secs_f64(),
                });
            }
            let wake = service
                .poll_timeout()
                .map_or(deadline, |t| clock::to_tokio(t).min(deadline));
            tokio::select! {
                () = tokio::time::sleep_until(wake) => service.handle_timeout(clock::now()),
                incoming = self.frames.recv() => {
                    let incoming = incoming.ok_or(SystemError::Stopped)?;
                    let f = incoming.frame.frame.view();
                    if let Ok(msg) = MavMessage::decode(f.msg_id(), f.payload()) {
                        let from = Address::new(f.sysid(), f.compid());
                        self.note(from, &msg);
                        service.handle_message(clock::now(), from, &msg);
                    }
                }
            }
        }
    }

    /// Keeps what the system tells about itself in passing.
    fn note(&mut self, from: Address, msg: &MavMessage) {
        if let MavMessage::Statustext(text) = msg
            && from.system == self.target.system
            && let Some(line) = self.lines.push((from.system, from.component), text)
        {
            self.listening.push(said::Said::Text(line.text));
        }
        if from.system != self.target.system {
            return;
        }
        match msg {
            MavMessage::Event(e) => self.listening.event(from, self.own, e),
            MavMessage::ComponentMetadata(m) if from.component == self.target.component => {
                self.listening.component_metadata(m);
            }
            MavMessage::GlobalPositionInt(GlobalPositionInt {
                alt, relative_alt, ..
            }) => self.home_amsl = Some((alt - relative_alt) as f32 / 1000.0),
            MavMessage::HomePosition(home) => {
                self.home_amsl = Some(home.altitude as f32 / 1000.0);
                self.home = Some(*home);
            }
            MavMessage::AutopilotVersion(v) if from.component == self.target.component => {
                self.capabilities = Some(v.capabilities);
            }
            _ => {}
        }
    }
}

fn unexpected(what: &'static str) -> SystemError {
    SystemError::Busy(format!(
        "{what}: the mission client reported another operation"
    ))
}

/// A MAV_CMD's name without its prefix, or its number.
fn command_name(c: MavCmd) -> String {
    c.name().map_or_else(
        || c.0.to_string(),
        |n| n.strip_prefix("MAV_CMD_").unwrap_or(n).to_owned(),
    )
}

/// The systems and components a node hears, as they appear, change and go (from
/// [`Discovery::new`]): a table kept from their HEARTBEATs (and AUTOPILOT_VERSIONs); a
/// component silent for 3 s is lost, one heard again is new again.
///
/// ```no_run
/// # async fn run(node: &mavstack::NodeHandle) {
/// use mavstack::services::heartbeat::HeartbeatEvent;
/// use mavstack::system::Discovery;
/// let mut discovery = Discovery::new(node).await;
/// while let Some(event) = discovery.next().await {
///     match event {
///         HeartbeatEvent::New(peer) => println!("{} appeared: {:?}", peer.address, peer.autopilot),
///         HeartbeatEvent::Lost(address) => println!("{address} lost"),
///         _ => {}
///     }
/// }
/// # }
/// ```
#[derive(Debug)]
pub struct Discovery {
    frames: Subscription,
    table: Heartbeats,
}

impl Discovery {
    /// Starts listening on `node`.
    pub async fn new(node: &NodeHandle) -> Self {
        Self {
            frames: node.subscribe().await,
            table: Heartbeats::new(HeartbeatConfig::default()),
        }
    }

    /// The next appearance, change or loss; `None` once the node has stopped.
    pub async fn next(&mut self) -> Option<HeartbeatEvent> {
        loop {
            if let Some(event) = self.table.poll_event() {
                return Some(event);
            }
            let wake = self.table.poll_timeout().map(clock::to_tokio);
            let sleep = async {
                match wake {
                    Some(t) => tokio::time::sleep_until(t).await,
                    None => core::future::pending().await,
                }
            };
            tokio::select! {
                () = sleep => self.table.handle_timeout(clock::now()),
                incoming = self.frames.recv() => {
                    let incoming = incoming?;
                    let f = incoming.frame.frame.view();
                    let from = Address::new(f.sysid(), f.compid());
                    match MavMessage::decode(f.msg_id(), f.payload()) {
                        Ok(MavMessage::Heartbeat(hb)) => self.table.handle_heartbeat(
                            clock::now(),
                            from,
                            &hb,
                            Some(f.version().number()),
                        ),
                        Ok(MavMessage::AutopilotVersion(v)) => {
                            self.table.handle_autopilot_version(from, &v);
                        }
                        _ => {}
                    }
                }
            }
        }
    }

    /// The components heard and not lost.
    pub fn peers(&self) -> impl Iterator<Item = &Peer> {
        self.table.peers()
    }
}

/// One message of a [`Telemetry`] subscription.
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Sample<T> {
    /// The sending component.
    pub from: Address,
    /// Its framing.
    pub version: Version,
    /// Its sequence number.
    pub seq: u8,
    /// The message.
    pub message: T,
}

/// Messages of type `T` from one system (from [`System::subscribe`]): a bounded queue like
/// the node's subscriptions, read with [`recv`](Self::recv) or as a
/// [`Stream`](futures_core::Stream) of [`Sample`]s; dropping it unsubscribes.
#[derive(Debug)]
pub struct Telemetry<T> {
    frames: Subscription,
    system: u8,
    message: PhantomData<fn() -> T>,
}

impl<T: Message> Telemetry<T> {
    /// The next one; `None` once the node has stopped.
    pub async fn recv(&mut self) -> Option<Sample<T>> {
        core::future::poll_fn(|cx| self.poll_sample(cx)).await
    }

    fn poll_sample(
        &mut self,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<Option<Sample<T>>> {
        use core::task::Poll;
        loop {
            let incoming = match self.frames.poll_recv(cx) {
                Poll::Ready(Some(incoming)) => incoming,
                Poll::Ready(None) => return Poll::Ready(None),
                Poll::Pending => return Poll::Pending,
            };
            let f = incoming.frame.frame.view();
            if f.msg_id() == T::ID && f.sysid() == self.system {
                return Poll::Ready(Some(Sample {
                    from: Address::new(f.sysid(), f.compid()),
                    version: f.version(),
                    seq: f.seq(),
                    message: T::decode(f.payload()),
                }));
            }
        }
    }
}

impl<T: Message> futures_core::Stream for Telemetry<T> {
    type Item = Sample<T>;

    fn poll_next(
        self: core::pin::Pin<&mut Self>,
        cx: &mut core::task::Context<'_>,
    ) -> core::task::Poll<Option<Sample<T>>> {
        self.get_mut().poll_sample(cx)
    }
}
