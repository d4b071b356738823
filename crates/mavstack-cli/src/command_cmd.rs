//! `mavstack command`: one command (a shortcut, a MAV_CMD name or number, or `mode NAME`)
//! sent through `System::commands()` (or `System::modes()`), its outcome printed.

use clap::Args;
use mavstack::system::{CommandOutcome, SHORTCUTS, SystemError, command_id, command_name, to_int};
use mavstack_dialects::common::{MavCmd, MavFrame, MavResult};
use mavstack_services::command::CommandError;
use serde_json::json;

use crate::link_cmd::runtime;
use crate::remote::{RemoteArgs, close, connect, input, print_lines};
use crate::{Failure, fail, other};

#[derive(Debug, Args)]
pub(crate) struct CommandArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// `arm`, `disarm`, `takeoff [HEIGHT]` (above home on every autopilot), `land`, `rtl`,
    /// `mode NAME`, `mission-start`, or a MAV_CMD name (`NAV_TAKEOFF`, `MAV_CMD_NAV_TAKEOFF`)
    /// or number.
    name: String,
    /// The command's parameters in order (`nan` allowed); the shortcuts take their own.
    #[arg(allow_negative_numbers = true)]
    params: Vec<String>,
    /// Send COMMAND_INT (params 5 and 6 given in degrees, sent as degE7) instead of
    /// COMMAND_LONG.
    #[arg(long)]
    int: bool,
    /// With `--int`: the MAV_FRAME of params 5–7.
    #[arg(long, default_value_t = 6)]
    frame: u8,
    /// With `arm`: past the pre-arm checks; with `disarm`: even in the air (param2 = 21196).
    #[arg(long)]
    force: bool,
}

fn number(text: &str, what: &str) -> Result<f32, Failure> {
    text.parse::<f32>()
        .map_err(|_| input(format!("{what} {text:?} is not a number")))
}

pub(crate) fn command(args: &CommandArgs) -> Result<(), Failure> {
    let is_mode = args.name.eq_ignore_ascii_case("mode");
    let shortcut = SHORTCUTS.iter().any(|s| s.eq_ignore_ascii_case(&args.name));
    // Name errors before the link opens.
    if !is_mode && !shortcut {
        command_id(&args.name).map_err(|e| Failure::Input(e.into()))?;
    }
    let mut params = Vec::new();
    if !is_mode {
        for (i, p) in args.params.iter().enumerate() {
            params.push(number(p, &format!("param{}", i + 1))?);
        }
        let arming = ["arm", "disarm"]
            .iter()
            .any(|a| a.eq_ignore_ascii_case(&args.name));
        if args.force && arming {
            params.push(mavstack::system::FORCE_DISARM);
        }
    }
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let system = session.system().clone();
        let target = system.target();
        let json = args.remote.json;
        let outcome = if is_mode {
            let [name] = args.params.as_slice() else {
                close(session).await?;
                return Err(input("`mode` takes one mode name"));
            };
            let began = std::time::Instant::now();
            let set = system.modes().set(name).await;
            mode_outcome(set.map(drop), began)
        } else {
            match system.commands().build(&args.name, &params).await {
                Ok(mut command) => {
                    if args.int {
                        command = to_int(&command, MavFrame(args.frame));
                    }
                    let id = command.id();
                    system
                        .commands()
                        .outcome(command, |progress| {
                            if !json {
                                eprintln!("{}: in progress {progress}%", command_name(id));
                            }
                        })
                        .await
                }
                Err(e) => Err(e),
            }
        };
        close(session).await?;
        let outcome = outcome.map_err(|e| match e {
            SystemError::Invalid(_) | SystemError::UnknownMode { .. } => Failure::Input(e.into()),
            e => fail(e),
        })?;
        print_lines(&[line(&outcome, &target.to_string(), json)])?;
        if outcome.accepted() {
            Ok(())
        } else {
            Err(other(format!(
                "{} was not accepted by {target}",
                command_name(outcome.command)
            )))
        }
    })
}

/// A mode change as a command's outcome (what `command mode` prints).
fn mode_outcome(
    set: Result<(), SystemError>,
    began: std::time::Instant,
) -> Result<CommandOutcome, SystemError> {
    let seconds = crate::remote::since(began);
    let (result, result_param2, statustext) = match set {
        Ok(()) => (Some(MavResult::ACCEPTED), 0, Vec::new()),
        Err(SystemError::Command {
            reason:
                CommandError::Rejected {
                    result,
                    result_param2,
                },
            statustext,
            ..
        }) => (Some(result), result_param2, statustext),
        Err(SystemError::Command { statustext, .. }) => (None, 0, statustext),
        Err(e) => return Err(e),
    };
    Ok(CommandOutcome::new(
        MavCmd::DO_SET_MODE,
        result,
        result_param2,
        statustext,
        seconds,
    ))
}

fn line(o: &CommandOutcome, target: &str, json: bool) -> String {
    if json {
        json!({
            "command": o.command.0,
            "name": command_name(o.command),
            "target": target,
            "result": o.result_name(),
            "result_code": o.result.map(|r| r.0),
            "result_param2": o.result_param2,
            "seconds": o.seconds,
            "statustext": o.statustext,
        })
        .to_string()
    } else {
        let why = if o.statustext.is_empty() {
            String::new()
        } else {
            format!(": {}", o.statustext.join("; "))
        };
        let result = if o.result.is_some() {
            o.result_name()
        } else {
            "no acknowledgement (timed out)"
        };
        format!(
            "{} → {} ({:.2} s){why}",
            command_name(o.command),
            result,
            o.seconds
        )
    }
}
