//! [`Commands`]: commands to a system (COMMAND_LONG, COMMAND_INT) with the services'
//! retries, their answers, and what the system said when it refused; commands by name
//! (`arm`, `takeoff 10`, `MAV_CMD_NAV_LAND`, `176`) as the CLI and Python take them.

use core::time::Duration;
use std::time::Instant;

use mavstack_core::Message as _;
use mavstack_dialects::common::{
    AutopilotVersion, CommandAck, CommandInt, CommandLong, MavCmd, MavFrame, MavResult,
};
use mavstack_services::command::{
    Command, CommandClient, CommandConfig, CommandError, CommandEvent,
};
use mavstack_transport::clock;

use super::{System, SystemError, run};
use crate::modes::Flavour;

/// How long STATUSTEXT is still collected after a refusal.
const SAID_AFTER: Duration = Duration::from_millis(500);

/// How long a command may run (IN_PROGRESS included).
const COMMAND_LIMIT: Duration = Duration::from_secs(600);

/// How long [`Commands::build`] waits for home's altitude (PX4's takeoff needs it).
const HOME_WAIT: Duration = Duration::from_secs(3);

/// Param 2 of MAV_CMD_COMPONENT_ARM_DISARM that forces a disarm, even in the air.
pub const FORCE_DISARM: f32 = 21196.0;

/// The commands of a system (from [`System::commands`]).
#[derive(Clone, Debug)]
pub struct Commands {
    system: System,
}

/// What became of a command, refused or not, as a ground station shows it.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct CommandOutcome {
    /// The command.
    pub command: MavCmd,
    /// Its final result; `None` when no acknowledgement came.
    pub result: Option<MavResult>,
    /// The acknowledgement's `result_param2`.
    pub result_param2: i32,
    /// The final acknowledgement's `progress` (0 when none came).
    pub progress: u8,
    /// What the system said when it refused (STATUSTEXT, EVENT texts); empty when accepted.
    pub statustext: Vec<String>,
    /// From the request to the answer.
    pub seconds: f64,
}

impl CommandOutcome {
    /// An outcome as given.
    #[must_use]
    pub const fn new(
        command: MavCmd,
        result: Option<MavResult>,
        result_param2: i32,
        statustext: Vec<String>,
        seconds: f64,
    ) -> Self {
        Self {
            command,
            result,
            result_param2,
            progress: 0,
            statustext,
            seconds,
        }
    }

    /// Whether it was accepted.
    #[must_use]
    pub fn accepted(&self) -> bool {
        self.result == Some(MavResult::ACCEPTED)
    }

    /// Its result's name (`ACCEPTED`, `DENIED`...), or `TIMEOUT` when no answer came.
    #[must_use]
    pub fn result_name(&self) -> &'static str {
        self.result.map_or("TIMEOUT", result_name)
    }
}

/// A MAV_CMD's name without its prefix (`NAV_TAKEOFF`), or its number.
#[must_use]
pub fn command_name(c: MavCmd) -> String {
    c.name().map_or_else(
        || c.0.to_string(),
        |n| n.strip_prefix("MAV_CMD_").unwrap_or(n).to_owned(),
    )
}

/// A MAV_RESULT's name without its prefix (`ACCEPTED`), or `UNKNOWN` for a number no
/// dialect names.
#[must_use]
pub fn result_name(r: MavResult) -> &'static str {
    r.name()
        .and_then(|n| n.strip_prefix("MAV_RESULT_"))
        .unwrap_or("UNKNOWN")
}

/// The MAV_CMD called `name` (with or without `MAV_CMD_`, any case, `-` for `_`) or
/// numbered so.
///
/// # Errors
/// [`SystemError::Invalid`] naming it.
pub fn command_id(name: &str) -> Result<MavCmd, SystemError> {
    if let Ok(n) = name.trim().parse::<u16>() {
        return Ok(MavCmd(n));
    }
    let upper = name.trim().to_ascii_uppercase().replace('-', "_");
    MavCmd::from_name(&upper)
        .or_else(|| MavCmd::from_name(&format!("MAV_CMD_{upper}")))
        .ok_or_else(|| {
            SystemError::Invalid(format!(
                "unknown command {name:?}: not a MAV_CMD name or number"
            ))
        })
}

/// The shortcuts [`Commands::build`] knows besides MAV_CMD names.
pub const SHORTCUTS: &[&str] = &["arm", "disarm", "takeoff", "land", "rtl", "mission-start"];

/// `command` as COMMAND_INT in `frame`: params 5 and 6 (degrees) become x and y in degE7
/// (NaN, "not given", becomes i32::MAX as the protocol says), param 7 stays z.
#[must_use]
pub fn to_int(command: &Command, frame: MavFrame) -> Command {
    let c = match command {
        Command::Int(_) => return command.clone(),
        Command::Long(c) => c,
    };
    let deg_e7 = |v: f32| {
        if v.is_finite() {
            (f64::from(v) * 1e7).clamp(f64::from(i32::MIN), f64::from(i32::MAX - 1)) as i32
        } else {
            i32::MAX
        }
    };
    Command::Int(CommandInt {
        command: c.command,
        frame,
        param1: c.param1,
        param2: c.param2,
        param3: c.param3,
        param4: c.param4,
        x: deg_e7(c.param5),
        y: deg_e7(c.param6),
        z: c.param7,
        ..CommandInt::default()
    })
}

impl Commands {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Sends `command` (its target fields are the system's) with the services' retries and
    /// waits for the final COMMAND_ACK.
    ///
    /// # Errors
    /// [`SystemError::Command`] (refused, or no acknowledgement; with what the system said
    /// from the request until 0.5 s after its answer), [`SystemError::Busy`],
    /// [`SystemError::Stopped`].
    pub async fn send(&self, command: Command) -> Result<CommandAck, SystemError> {
        self.send_with_progress(command, |_| {}).await
    }

    /// Like [`send`](Self::send); `progress` hears each IN_PROGRESS (0–100, 255 unknown).
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn send_with_progress(
        &self,
        command: Command,
        progress: impl FnMut(u8),
    ) -> Result<CommandAck, SystemError> {
        self.exchange(command, progress, true).await
    }

    /// Like [`send_with_progress`](Self::send_with_progress), with a refusal or a timeout
    /// given as an outcome rather than an error: what a ground station prints.
    ///
    /// # Errors
    /// [`SystemError::Busy`], [`SystemError::Stopped`].
    pub async fn outcome(
        &self,
        command: Command,
        progress: impl FnMut(u8),
    ) -> Result<CommandOutcome, SystemError> {
        let began = Instant::now();
        let id = command.id();
        let result = self.send_with_progress(command, progress).await;
        let seconds = (began.elapsed().as_secs_f64() * 1000.0).round() / 1000.0;
        let outcome = |result, result_param2, statustext| {
            CommandOutcome::new(id, result, result_param2, statustext, seconds)
        };
        match result {
            Ok(ack) => {
                let mut o = outcome(Some(ack.result), ack.result_param2, Vec::new());
                o.progress = ack.progress;
                Ok(o)
            }
            Err(SystemError::Command {
                reason:
                    CommandError::Rejected {
                        result,
                        result_param2,
                    },
                statustext,
                ..
            }) => Ok(outcome(Some(result), result_param2, statustext)),
            Err(SystemError::Command { statustext, .. }) => Ok(outcome(None, 0, statustext)),
            Err(e) => Err(e),
        }
    }

    /// Runs one command exchange; `explain`: collect what the system said with a refusal.
    async fn exchange(
        &self,
        command: Command,
        mut progress: impl FnMut(u8),
        explain: bool,
    ) -> Result<CommandAck, SystemError> {
        let system = &self.system;
        let id = command.id();
        let said_before = system.said_count();
        let result = {
            let mut echoes = system.inner.locks.commands.lock().await;
            let mut frames = system.frames().await;
            let mut client = CommandClient::new(system.inner.own, CommandConfig::default())
                .with_echoes(core::mem::take(&mut *echoes));
            let handle = client
                .send(clock::now(), system.inner.target, command)
                .map_err(|e| SystemError::Busy(e.to_string()))?;
            let result = run::drive(
                &system.inner,
                &mut frames,
                &mut client,
                COMMAND_LIMIT,
                |c| {
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
                },
            )
            .await;
            *echoes = client.take_echoes();
            result?
        };
        match result {
            Ok(ack) => Ok(ack),
            Err(reason) => {
                let statustext = if explain {
                    // STATUSTEXT or EVENTs that say why may follow the refusal.
                    tokio::time::sleep(SAID_AFTER).await;
                    system.said_since(said_before).await
                } else {
                    Vec::new()
                };
                Err(SystemError::Command {
                    command: command_name(id),
                    reason,
                    statustext,
                })
            }
        }
    }

    /// Asks the system to send message `id` once (MAV_CMD_REQUEST_MESSAGE); returns its
    /// acknowledgement (the message itself arrives on the node's subscriptions).
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn request_message(&self, id: u32) -> Result<CommandAck, SystemError> {
        self.request_message_with(id, 0.0).await
    }

    /// Like [`request_message`](Self::request_message), with the request's param 2 (what
    /// some messages take: AVAILABLE_MODES' mode index, MESSAGE_INTERVAL's message id).
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn request_message_with(
        &self,
        id: u32,
        param2: f32,
    ) -> Result<CommandAck, SystemError> {
        let command = Command::long(
            MavCmd::REQUEST_MESSAGE,
            [id as f32, param2, 0., 0., 0., 0., 0.],
        );
        self.exchange(command, |_| {}, false).await
    }

    /// Asks the system to stream message `id` every `interval` (MAV_CMD_SET_MESSAGE_INTERVAL;
    /// `None` stops it). [`Telemetry::request_rate`](super::Telemetry::request_rate) also
    /// checks that the message comes, and falls back to REQUEST_DATA_STREAM.
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn set_message_interval(
        &self,
        id: u32,
        interval: Option<Duration>,
    ) -> Result<CommandAck, SystemError> {
        let us = interval.map_or(-1.0, |d| d.as_micros() as f32);
        let command = Command::long(
            MavCmd::SET_MESSAGE_INTERVAL,
            [id as f32, us, 0., 0., 0., 0., 0.],
        );
        self.exchange(command, |_| {}, false).await
    }

    /// Arms it (MAV_CMD_COMPONENT_ARM_DISARM).
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn arm(&self) -> Result<CommandAck, SystemError> {
        self.send(Command::long(
            MavCmd::COMPONENT_ARM_DISARM,
            [1., 0., 0., 0., 0., 0., 0.],
        ))
        .await
    }

    /// Disarms it; `force`: even in the air.
    ///
    /// # Errors
    /// As [`send`](Self::send).
    pub async fn disarm(&self, force: bool) -> Result<CommandAck, SystemError> {
        let magic = if force { FORCE_DISARM } else { 0.0 };
        self.send(Command::long(
            MavCmd::COMPONENT_ARM_DISARM,
            [0., magic, 0., 0., 0., 0., 0.],
        ))
        .await
    }

    /// One request in the link's current signing, without explanation; whether it was
    /// answered (what [`Signing`](super::Signing) proves itself with).
    pub(super) async fn answered(&self) -> bool {
        self.request_message(AutopilotVersion::ID).await.is_ok()
    }

    /// The command `name` asks for with `params` (params 1–7 in order; NaN for "not
    /// given"): a MAV_CMD name or number, or a shortcut: `arm [21196]`, `disarm [21196]`
    /// (the number forces it: arming past the checks, disarming in the air), `takeoff [HEIGHT]` (above home on every autopilot: PX4, which
    /// reads an altitude above mean sea level, gets home's altitude added, asked for first
    /// when not known), `land`, `rtl`, `mission-start [FIRST [LAST]]`.
    ///
    /// # Errors
    /// [`SystemError::Invalid`]: an unknown name, too many params, or a takeoff height
    /// that PX4 cannot be given because its home is not known.
    pub async fn build(&self, name: &str, params: &[f32]) -> Result<Command, SystemError> {
        let at_most = |n: usize| {
            if params.len() > n {
                Err(SystemError::Invalid(format!(
                    "`{name}` takes at most {n} parameter(s), not {}",
                    params.len()
                )))
            } else {
                Ok(())
            }
        };
        let given = |i: usize| params.get(i).copied();
        let nan = f32::NAN;
        let shortcut = name.to_ascii_lowercase();
        let (id, p) = match shortcut.as_str() {
            "arm" => {
                at_most(1)?;
                let magic = given(0).unwrap_or(0.0);
                (
                    MavCmd::COMPONENT_ARM_DISARM,
                    [1., magic, 0., 0., 0., 0., 0.],
                )
            }
            "disarm" => {
                at_most(1)?;
                let magic = given(0).unwrap_or(0.0);
                (
                    MavCmd::COMPONENT_ARM_DISARM,
                    [0., magic, 0., 0., 0., 0., 0.],
                )
            }
            "takeoff" => {
                at_most(1)?;
                let alt = match given(0) {
                    Some(h) if !h.is_finite() => {
                        return Err(SystemError::Invalid(format!(
                            "takeoff height {h} is not a number"
                        )));
                    }
                    Some(h) => self.takeoff_altitude(h).await?,
                    None => nan,
                };
                (MavCmd::NAV_TAKEOFF, [0., 0., 0., nan, nan, nan, alt])
            }
            "land" => {
                at_most(0)?;
                (MavCmd::NAV_LAND, [0., 0., 0., nan, nan, nan, nan])
            }
            "rtl" => {
                at_most(0)?;
                (MavCmd::NAV_RETURN_TO_LAUNCH, [0.; 7])
            }
            "mission-start" => {
                at_most(2)?;
                let first = given(0).unwrap_or(0.0);
                let last = given(1).unwrap_or(0.0);
                (MavCmd::MISSION_START, [first, last, 0., 0., 0., 0., 0.])
            }
            _ => {
                at_most(7)?;
                let mut p = [0.0f32; 7];
                p[..params.len()].copy_from_slice(params);
                (command_id(name)?, p)
            }
        };
        Ok(Command::Long(CommandLong {
            command: id,
            param1: p[0],
            param2: p[1],
            param3: p[2],
            param4: p[3],
            param5: p[4],
            param6: p[5],
            param7: p[6],
            ..CommandLong::default()
        }))
    }

    /// NAV_TAKEOFF's param 7 for `height` m above home: PX4 takes an altitude above mean sea
    /// level, ArduPilot (and the rest) a height above home.
    pub(super) async fn takeoff_altitude(&self, height: f32) -> Result<f32, SystemError> {
        if self.system.flavour() != Some(Flavour::Px4) {
            return Ok(height);
        }
        let home = self.system.telemetry().home_amsl(HOME_WAIT).await;
        home.map(|h| h + height).ok_or_else(|| {
            SystemError::Invalid(format!(
                "takeoff to {height} m above home: PX4 wants an altitude above mean sea level, \
                 and its home altitude did not come within {} s",
                HOME_WAIT.as_secs()
            ))
        })
    }
}
