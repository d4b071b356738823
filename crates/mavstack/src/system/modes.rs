//! [`Modes`]: a system's flight modes — listed from AVAILABLE_MODES where the vehicle offers
//! them (PX4 1.15+, ArduPilot 4.6+), else from the built-in tables ([`crate::modes`]); the
//! current one from CURRENT_MODE or HEARTBEAT; set by the vehicle's name or a standard name
//! (MAV_CMD_DO_SET_STANDARD_MODE where the vehicle lists the mode as standard, else
//! MAV_CMD_DO_SET_MODE with the custom mode), and awaited until current.

use core::time::Duration;

use mavstack_core::Message as _;
use mavstack_dialects::common::{AvailableModes, MavCmd, MavResult, MavStandardMode};

use mavstack_services::command::{Command, CommandError};

use super::state::ModeSeen;
use super::{System, SystemError};
use crate::modes::{self as tables, Flavour};

/// How long AVAILABLE_MODES may take to come after a request.
const LIST_WAIT: Duration = Duration::from_secs(2);

/// Rounds of asking one by one for the AVAILABLE_MODES that did not come.
const LIST_ROUNDS: usize = 3;

/// How long a mode set may take to show in HEARTBEAT (or CURRENT_MODE).
const CURRENT_WAIT: Duration = Duration::from_secs(5);

/// How long what a vehicle says after refusing a mode is still collected.
const SAID_AFTER: Duration = Duration::from_millis(500);

/// MAV_MODE_PROPERTY_NOT_USER_SELECTABLE.
const NOT_USER_SELECTABLE: u32 = 2;

/// One flight mode of a system.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct Mode {
    /// Its name, as the vehicle gives it (AVAILABLE_MODES) or as the built-in tables have it.
    pub name: String,
    /// The standard mode it is (from the vehicle where it says, else from our table).
    pub standard: Option<MavStandardMode>,
    /// The autopilot's own number (HEARTBEAT's `custom_mode`).
    pub custom_mode: u32,
    /// Whether a user may select it (failsafe-only modes are not).
    pub selectable: bool,
    /// Whether the vehicle itself marks it standard (then MAV_CMD_DO_SET_STANDARD_MODE can
    /// set it).
    pub vehicle_standard: bool,
}

impl Mode {
    /// Its standard name (`position_hold`, `safe_recovery`...), if it is one.
    #[must_use]
    pub fn standard_name(&self) -> Option<String> {
        self.standard.and_then(tables::standard_name)
    }
}

/// The flight modes of a system (from [`System::modes`]).
#[derive(Clone, Debug)]
pub struct Modes {
    system: System,
}

impl Modes {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Its modes: from AVAILABLE_MODES when the vehicle answers a request for them, else from
    /// the built-in table of its autopilot (empty when there is none). All of them are asked
    /// for at once (param 2 = 0); those that did not come are then asked for one by one
    /// (ArduPilot 4.7 answers the request for all with the first mode only).
    pub async fn list(&self) -> Vec<Mode> {
        if let Some(listed) = self.listed() {
            return listed;
        }
        let asked_before = {
            let s = self.system.state();
            s.stopped || s.modes_refused
        };
        if !asked_before && !self.ask_all().await {
            self.system
                .inner
                .state
                .send_modify(|s| s.modes_refused = true);
        }
        self.listed().unwrap_or_else(|| self.built_in())
    }

    /// Asks for every AVAILABLE_MODES; whether the vehicle gave them all.
    async fn ask_all(&self) -> bool {
        let commands = self.system.commands();
        // param2 = 0: every mode.
        if commands
            .request_message_with(AvailableModes::ID, 0.0)
            .await
            .is_err()
        {
            return false;
        }
        let complete = |s: &super::state::State| {
            s.modes_count
                .is_some_and(|n| usize::from(n) == s.available_modes.len())
        };
        if !self
            .system
            .wait_state(LIST_WAIT, |s| s.modes_count.is_some())
            .await
        {
            return false;
        }
        for _ in 0..LIST_ROUNDS {
            if self.system.wait_state(LIST_WAIT, complete).await {
                return true;
            }
            let missing: Vec<u8> = {
                let s = self.system.state();
                (1..=s.modes_count.unwrap_or(0))
                    .filter(|i| !s.available_modes.contains_key(i))
                    .collect()
            };
            for i in missing {
                if commands
                    .request_message_with(AvailableModes::ID, f32::from(i))
                    .await
                    .is_err()
                {
                    return false;
                }
            }
        }
        self.system.wait_state(LIST_WAIT, complete).await
    }

    /// The list AVAILABLE_MODES gave, once every mode of it came.
    fn listed(&self) -> Option<Vec<Mode>> {
        let state = self.system.state();
        let count = usize::from(state.modes_count?);
        if count == 0 || state.available_modes.len() < count {
            return None;
        }
        let flavour = self.system.flavour();
        Some(
            state
                .available_modes
                .values()
                .map(|m| from_vehicle(flavour, m))
                .collect(),
        )
    }

    /// The built-in table of its autopilot.
    fn built_in(&self) -> Vec<Mode> {
        let Some(flavour) = self.system.flavour() else {
            return Vec::new();
        };
        tables::modes(flavour)
            .into_iter()
            .map(|m| Mode {
                name: m.name.to_owned(),
                standard: tables::standard_of(flavour, m.custom_mode),
                custom_mode: m.custom_mode,
                selectable: true,
                vehicle_standard: false,
            })
            .collect()
    }

    /// The mode it is in now: the `custom_mode` of its newest CURRENT_MODE or HEARTBEAT,
    /// named from [`list`](Self::list) (a mode not listed is named by its
    /// number).
    pub async fn current(&self) -> Option<Mode> {
        let custom = self.current_custom()?;
        let list = self.list().await;
        Some(
            list.into_iter()
                .find(|m| m.custom_mode == custom)
                .unwrap_or_else(|| {
                    let flavour = self.system.flavour();
                    Mode {
                        name: flavour
                            .and_then(|f| tables::name_of(f, custom))
                            .map_or_else(|| format!("custom mode {custom}"), str::to_owned),
                        standard: flavour.and_then(|f| tables::standard_of(f, custom)),
                        custom_mode: custom,
                        selectable: true,
                        vehicle_standard: false,
                    }
                }),
        )
    }

    /// The `custom_mode` it reports now (the newer of CURRENT_MODE and HEARTBEAT).
    fn current_custom(&self) -> Option<u32> {
        self.system.state().custom_mode()
    }

    /// The mode called `name`: a name of [`list`](Self::list) (any case; PX4's also as
    /// QGroundControl writes them), or a standard name (`position_hold`, `orbit`, `cruise`,
    /// `altitude_hold`, `safe_recovery`, `mission`, `land`, `takeoff`).
    ///
    /// # Errors
    /// [`SystemError::UnknownMode`] with the names it has.
    pub async fn find(&self, name: &str) -> Result<Mode, SystemError> {
        let list = self.list().await;
        let same = |a: &str, b: &str| {
            let norm = |c: char| match c {
                '-' | ' ' => '_',
                c => c.to_ascii_uppercase(),
            };
            a.chars().map(norm).eq(b.chars().map(norm))
        };
        if let Some(m) = list.iter().find(|m| same(&m.name, name)) {
            return Ok(m.clone());
        }
        // The built-in names (PX4's `AUTO.` prefix and QGroundControl's names).
        if let Some(flavour) = self.system.flavour()
            && let Some(m) = tables::by_name(flavour, name)
            && let Some(listed) = list.iter().find(|l| l.custom_mode == m.custom_mode)
        {
            return Ok(listed.clone());
        }
        if let Some(standard) = tables::standard_by_name(name)
            && let Some(m) = list.iter().find(|m| m.standard == Some(standard))
        {
            return Ok(m.clone());
        }
        Err(SystemError::UnknownMode {
            autopilot: self.system.flavour().map(|f| f.to_string()),
            name: name.to_owned(),
            known: list.iter().map(|m| m.name.clone()).collect(),
        })
    }

    /// Switches it to the mode called `name` (see [`find`](Self::find)) and waits until it
    /// reports that mode (5 s at most): with MAV_CMD_DO_SET_STANDARD_MODE when the vehicle
    /// lists the mode as standard (and DO_SET_MODE if it refuses that command), else with
    /// MAV_CMD_DO_SET_MODE.
    ///
    /// # Errors
    /// [`SystemError::UnknownMode`]; [`SystemError::Command`] (refused, with what the
    /// vehicle said); [`SystemError::NotDone`] when it accepted but did not change.
    pub async fn set(&self, name: &str) -> Result<Mode, SystemError> {
        let mode = self.find(name).await?;
        self.set_mode(&mode).await?;
        Ok(mode)
    }

    /// Switches it to `mode` and waits until it reports it (see [`set`](Self::set)).
    ///
    /// # Errors
    /// As [`set`](Self::set).
    pub async fn set_mode(&self, mode: &Mode) -> Result<(), SystemError> {
        let said_before = self.system.said_count();
        let acks_before = self.system.state().ack_count;
        let commands = self.system.commands();
        let mut sent = None;
        if mode.vehicle_standard
            && let Some(standard) = mode.standard
        {
            let command = Command::long(
                MavCmd::DO_SET_STANDARD_MODE,
                [f32::from(standard.0), 0., 0., 0., 0., 0., 0.],
            );
            match commands.send(command).await {
                Ok(_) => sent = Some(MavCmd::DO_SET_STANDARD_MODE),
                Err(SystemError::Command {
                    reason:
                        CommandError::Rejected {
                            result: MavResult::UNSUPPORTED,
                            ..
                        },
                    ..
                }) => {}
                Err(e) => return Err(e),
            }
        }
        let sent = match sent {
            Some(command) => command,
            None => {
                commands
                    .send(self.set_mode_command(mode.custom_mode)?)
                    .await?;
                MavCmd::DO_SET_MODE
            }
        };
        // PX4 acknowledges twice: ACCEPTED from its MAVLink receiver at once, then its
        // commander's verdict. A refusal after the first answer ends the wait.
        let custom = mode.custom_mode;
        let reported = self
            .system
            .wait_state(CURRENT_WAIT, |s| {
                s.custom_mode() == Some(custom) || s.refusal_after(sent, acks_before).is_some()
            })
            .await;
        let refusal = self.system.state().refusal_after(sent, acks_before);
        if let Some(ack) = refusal {
            tokio::time::sleep(SAID_AFTER).await;
            return Err(SystemError::Command {
                command: super::command_name(sent),
                reason: CommandError::Rejected {
                    result: ack.result,
                    result_param2: ack.result_param2,
                },
                statustext: self.system.said_since(said_before).await,
            });
        }
        if !reported {
            return Err(SystemError::NotDone {
                what: format!(
                    "mode {}: accepted, but the vehicle did not report it within {} s",
                    mode.name,
                    CURRENT_WAIT.as_secs()
                ),
                statustext: self.system.said_since(said_before).await,
            });
        }
        Ok(())
    }

    /// MAV_CMD_DO_SET_MODE for `custom_mode` in the autopilot's encoding.
    fn set_mode_command(&self, custom_mode: u32) -> Result<Command, SystemError> {
        let flavour = self
            .system
            .flavour()
            .ok_or_else(|| SystemError::UnknownMode {
                autopilot: None,
                name: format!("custom mode {custom_mode}"),
                known: Vec::new(),
            })?;
        let (p1, p2, p3) = flavour.command_params(custom_mode);
        Ok(Command::long(
            MavCmd::DO_SET_MODE,
            [p1, p2, p3, 0., 0., 0., 0.],
        ))
    }
}

/// A mode as AVAILABLE_MODES gave it, its standard mapping from the vehicle or our table.
fn from_vehicle(flavour: Option<Flavour>, m: &ModeSeen) -> Mode {
    let vehicle_standard = m.standard != MavStandardMode::NON_STANDARD.0;
    let standard = if vehicle_standard {
        Some(MavStandardMode(m.standard))
    } else {
        flavour.and_then(|f| tables::standard_of(f, m.custom_mode))
    };
    let name = if m.name.is_empty() {
        flavour
            .and_then(|f| tables::name_of(f, m.custom_mode))
            .map(str::to_owned)
            .or_else(|| standard.and_then(tables::standard_name))
            .unwrap_or_else(|| format!("custom mode {}", m.custom_mode))
    } else {
        m.name.clone()
    };
    Mode {
        name,
        standard,
        custom_mode: m.custom_mode,
        selectable: m.properties & NOT_USER_SELECTABLE == 0,
        vehicle_standard,
    }
}
