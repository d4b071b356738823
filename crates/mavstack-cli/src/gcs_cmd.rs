//! `mavstack param`, `mission` and `command`: ground-station operations against a remote
//! system, over `mavstack::system::System` on a ground-station `Node`.
//!
//! Each command starts the node (our HEARTBEAT every second), waits for the target's
//! HEARTBEAT (the first autopilot heard, or `--target-system`; the MAVLink 2 handshake when
//! it still speaks MAVLink 1), runs one operation and prints its result for people, or as
//! JSON with `--json`.

use std::io::Write as _;

use anyhow::anyhow;
use clap::{Args, Subcommand, ValueEnum};
use mavstack::system::{ParamsVia, System, SystemError, Wanted};
use mavstack::{LinkSpec, Node};
use mavstack_channel::SigningConfig;
use mavstack_dialects::common::{
    CommandInt, MavCmd, MavFrame, MavMissionType, MavParamType, MavResult,
};
use mavstack_services::Address;
use mavstack_services::command::{Command, CommandError};
use mavstack_services::param::{Name, Param, Value};
use serde_json::json;
use tokio::time::Instant;

use crate::link_cmd::runtime;
use crate::mission_file;
use crate::vehicle_cmd::secret_key;
use crate::{Failure, other};
use mavstack::modes::{self, Flavour};
use mavstack_services::plan::{self, Convention};

/// How to reach the remote system (shared by `param`, `mission` and `command`).
#[derive(Clone, Debug, Args)]
pub(crate) struct RemoteArgs {
    /// The ground station's side of the link: udpin:HOST:PORT waits for the vehicle,
    /// udpout:HOST:PORT reaches one listening there, tcp:HOST:PORT, serial:DEV:BAUD.
    conn: String,
    /// The system to talk to (default: the first autopilot heard).
    #[arg(long)]
    target_system: Option<u8>,
    /// The component to talk to (default: the one whose HEARTBEAT was heard).
    #[arg(long)]
    target_component: Option<u8>,
    /// Seconds to wait for the target's HEARTBEAT (from 0.001 to 86400).
    #[arg(long, default_value_t = 10.0, value_parser = crate::link_cmd::timeout_arg)]
    timeout: f64,
    /// Our system id.
    #[arg(long, default_value_t = 255)]
    sysid: u8,
    /// Our component id.
    #[arg(long, default_value_t = 190)]
    compid: u8,
    /// Sign with this key (64 hex digits), for vehicles that accept only signed frames
    /// (`signing setup`: the key to set up; `signing remove`: the key in use).
    #[arg(long)]
    pub(crate) key: Option<String>,
    /// Signing link id (with `--key`).
    #[arg(long, default_value_t = 0)]
    pub(crate) link_id: u8,
    /// Print results as JSON (one object per line).
    #[arg(long)]
    pub(crate) json: bool,
}

#[derive(Debug, Subcommand)]
pub(crate) enum ParamAction {
    /// Fetch every parameter: over MAVFTP (`@PARAM/param.pck`) when the target offers it,
    /// else PARAM_REQUEST_LIST (missing ones re-requested); the same output either way.
    List {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Also save them as `NAME VALUE` lines (what `mavstack vehicle --params` reads).
        #[arg(long, value_name = "FILE")]
        save: Option<String>,
        /// How: `auto` (MAVFTP when AUTOPILOT_VERSION advertises MAV_PROTOCOL_CAPABILITY_FTP,
        /// PARAM_REQUEST_LIST when it does not or the download fails), `ftp` or `list`.
        #[arg(long, value_enum, default_value_t = Via::Auto)]
        via: Via,
    },
    /// Read parameters by name.
    Get {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Parameter names.
        #[arg(required = true)]
        names: Vec<String>,
    },
    /// Set the values of a parameter file (`NAME VALUE` lines, as `list --save` writes) that
    /// differ from the target's, converted to each parameter's type, and check them read
    /// back; names the target does not have are skipped with a warning.
    Load {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The parameter file.
        file: String,
        /// How: `auto` (one MAVFTP upload of `@PARAM/param.pck` to an ArduPilot that
        /// advertises MAVFTP, else PARAM_SET), `ftp` or `set`.
        #[arg(long, value_enum, default_value_t = crate::param_load::LoadVia::Auto)]
        via: crate::param_load::LoadVia,
    },
    /// Set a parameter (its type is read from the target first) and confirm the new value.
    Set {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Parameter name.
        name: String,
        /// New value.
        #[arg(allow_negative_numbers = true)]
        value: f64,
    },
}

/// How `param list` fetches the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Via {
    /// MAVFTP if the target advertises it, falling back to PARAM_REQUEST_LIST.
    Auto,
    /// MAVFTP only (`@PARAM/param.pck`).
    Ftp,
    /// PARAM_REQUEST_LIST only.
    List,
}

/// The table as `via` says, with progress on a terminal, and how it came.
pub(crate) async fn fetch_params(
    system: &mut System,
    via: Via,
) -> Result<(Vec<(Name, Value)>, &'static str), SystemError> {
    let via = match via {
        Via::Auto => ParamsVia::Auto,
        Via::Ftp => ParamsVia::Ftp,
        Via::List => ParamsVia::List,
    };
    let show = showing_progress();
    let got = system
        .params_by(via, |way, done, total| {
            if show {
                match way {
                    ParamsVia::Ftp => eprint!("\r{done}/{total} bytes of @PARAM/param.pck"),
                    _ => eprint!("\r\x1b[K{done}/{total} parameters"),
                }
            }
        })
        .await;
    end_progress();
    let (table, way) = got?;
    let how = if way == ParamsVia::Ftp {
        "MAVFTP"
    } else {
        "PARAM_REQUEST_LIST"
    };
    Ok((table, how))
}

/// Which plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum PlanType {
    /// The mission.
    Mission,
    /// The geofence.
    Fence,
    /// Rally points.
    Rally,
}

impl PlanType {
    fn mav(self) -> MavMissionType {
        match self {
            Self::Mission => MavMissionType::MISSION,
            Self::Fence => MavMissionType::FENCE,
            Self::Rally => MavMissionType::RALLY,
        }
    }
}

#[derive(Debug, Subcommand)]
pub(crate) enum MissionAction {
    /// Download a plan; write it to FILE (`.json`: JSON, else QGC WPL 110) or print it.
    Download {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Where to save it (printed when absent: WPL, or JSON with --json).
        file: Option<String>,
        /// Which plan.
        #[arg(long = "type", value_enum, default_value = "mission")]
        plan: PlanType,
    },
    /// Upload a plan from FILE (`.json`: JSON, else QGC WPL 110).
    Upload {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The plan.
        file: String,
        /// Which plan.
        #[arg(long = "type", value_enum, default_value = "mission")]
        plan: PlanType,
    },
    /// Clear a plan (`--type all` is not offered: clear each).
    Clear {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Which plan.
        #[arg(long = "type", value_enum, default_value = "mission")]
        plan: PlanType,
    },
}

#[derive(Debug, Args)]
pub(crate) struct CommandArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// `arm`, `disarm`, `takeoff [ALT]`, `land`, `rtl`, `mode NAME`, `mission-start`, or a
    /// MAV_CMD name (`NAV_TAKEOFF`, `MAV_CMD_NAV_TAKEOFF`) or number.
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
    /// With `disarm`: force it even in the air (param2 = 21196).
    #[arg(long)]
    force: bool,
}

/// An open link to the target: a ground-station [`Node`] and the [`System`] found on it.
pub(crate) struct Remote {
    node: Node,
    pub(crate) system: System,
    start: Instant,
}

impl Remote {
    /// Opens the link and waits for the target.
    pub(crate) async fn connect(args: &RemoteArgs) -> Result<Self, Failure> {
        let mut spec =
            LinkSpec::parse(&args.conn, &|_| None).map_err(|e| Failure::Input(anyhow!("{e}")))?;
        if let Some(key) = &args.key {
            spec.config.signing = Some(SigningConfig::new(secret_key(key, "--key")?, args.link_id));
        }
        let wait = crate::link_cmd::seconds(args.timeout, "--timeout")?;
        let start = Instant::now();
        let node = Node::ground_station(args.sysid, args.compid)
            .link(spec)
            .start()
            .await
            .map_err(other)?;
        let wanted = match args.target_system {
            Some(s) => Wanted::System(s, args.target_component),
            None => Wanted::AnyAutopilot,
        };
        let system = match System::wait(&node.handle(), wanted, wait).await {
            Ok(system) => system,
            Err(SystemError::NotFound { seconds }) => {
                let _ = node.shutdown().await;
                return Err(other(format!(
                    "no vehicle heard on {} within {seconds:.1} s",
                    args.conn
                )));
            }
            Err(e) => return Err(other(e)),
        };
        Ok(Self {
            node,
            system,
            start,
        })
    }

    /// The target's address.
    pub(crate) fn target(&self) -> Address {
        self.system.target()
    }

    fn flavour(&self) -> Option<Flavour> {
        self.system.flavour()
    }

    /// Seconds since the link opened.
    pub(crate) fn elapsed(&self) -> f64 {
        self.start.elapsed().as_secs_f64()
    }

    /// Seconds since `began` (an [`Remote::elapsed`] reading), to the millisecond.
    pub(crate) fn since(&self, began: f64) -> f64 {
        ((self.elapsed() - began) * 1000.0).round() / 1000.0
    }

    /// Closes the link.
    pub(crate) async fn close(self) -> Result<(), Failure> {
        drop(self.system);
        self.node.shutdown().await.map(drop).map_err(other)
    }
}

fn type_name(ty: MavParamType) -> &'static str {
    ty.name()
        .and_then(|n| n.strip_prefix("MAV_PARAM_TYPE_"))
        .unwrap_or("?")
}

/// A value as text: integers exactly, floats in their shortest form.
pub(crate) fn value_text(v: Value) -> String {
    match v {
        Value::F32(f) => format!("{f}"),
        other => format!("{}", other.as_f64()),
    }
}

pub(crate) fn value_json(v: Value) -> serde_json::Value {
    match v {
        Value::F32(f) if f.is_finite() => json!(f),
        Value::F32(_) => serde_json::Value::Null,
        other => json!(other.as_f64() as i64),
    }
}

fn param_json(index: usize, name: Name, value: Value) -> serde_json::Value {
    json!({
        "index": index,
        "name": name.as_str(),
        "value": value_json(value),
        "type": type_name(value.param_type()),
    })
}

/// Prints lines to stdout, turning a closed pipe into the failure `main` forgives.
pub(crate) fn print_lines(lines: &[String]) -> Result<(), Failure> {
    let mut out = std::io::stdout().lock();
    for line in lines {
        writeln!(out, "{line}").map_err(|e| Failure::Other(e.into()))?;
    }
    Ok(())
}

/// Whether progress is shown: on a terminal, not when piped.
pub(crate) fn showing_progress() -> bool {
    std::io::IsTerminal::is_terminal(&std::io::stderr())
}

/// Prints `done/total what` over itself on stderr, on a terminal only.
fn progress(what: &'static str) -> impl FnMut(usize, usize) {
    let show = showing_progress();
    move |done, total| {
        if show {
            eprint!("\r{done}/{total} {what}");
        }
    }
}

/// Clears the progress line.
pub(crate) fn end_progress() {
    if showing_progress() {
        eprint!("\r\x1b[K");
    }
}

/// Sets one parameter to `value` (converted to `current`'s type) and returns the value in
/// force.
pub(crate) async fn set_param(
    system: &mut System,
    name: Name,
    current: Value,
    value: f64,
) -> Result<Param, Failure> {
    let typed = typed_value(name, current, value)?;
    system.set_param(name, typed).await.map_err(other)
}

/// `value` in `current`'s type, as PARAM_SET will carry it.
pub(crate) fn typed_value(name: Name, current: Value, value: f64) -> Result<Value, Failure> {
    // A REAL32 holds what f32 holds: no infinity, no NaN (an integer type clamps instead).
    if current.param_type() == MavParamType::REAL32 && !(value as f32).is_finite() {
        return Err(Failure::Input(anyhow!(
            "{name}: {value} is not a REAL32 value (beyond ±3.4e38, or not a number)"
        )));
    }
    let typed = Value::F32(value as f32)
        .converted_to(current.param_type())
        .map(|v| match (v, current) {
            // Integers straight from the f64, not through f32 (exact to 2^53).
            (Value::I32(_), _) if value.fract() == 0.0 => {
                Value::I32(value.clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32)
            }
            (Value::U32(_), _) if value.fract() == 0.0 => {
                Value::U32(value.clamp(0.0, f64::from(u32::MAX)) as u32)
            }
            (v, _) => v,
        })
        .ok_or_else(|| other(format!("{name} has a type PARAM_SET cannot carry")))?;
    Ok(typed)
}

fn name_arg(text: &str) -> Result<Name, Failure> {
    Name::new(text).map_err(|e| Failure::Input(anyhow!("parameter name {text:?}: {e}")))
}

pub(crate) fn param(action: ParamAction) -> Result<(), Failure> {
    runtime()?.block_on(async {
        match action {
            ParamAction::List {
                remote: args,
                save,
                via,
            } => {
                let mut remote = Remote::connect(&args).await?;
                let began = remote.elapsed();
                let (table, how) = fetch_params(&mut remote.system, via).await.map_err(other)?;
                end_progress();
                let seconds = remote.since(began);
                let target = remote.target();
                remote.close().await?;
                if let Some(path) = &save {
                    let text: String = table
                        .iter()
                        .map(|(n, v)| format!("{n} {}\n", value_text(*v)))
                        .collect();
                    std::fs::write(path, text)
                        .map_err(|e| other(format!("cannot write {path}: {e}")))?;
                }
                let lines: Vec<String> = if args.json {
                    table
                        .iter()
                        .enumerate()
                        .map(|(i, (n, v))| param_json(i, *n, *v).to_string())
                        .collect()
                } else {
                    let width = table
                        .iter()
                        .map(|(n, _)| n.as_str().len())
                        .max()
                        .unwrap_or(0);
                    table
                        .iter()
                        .map(|(n, v)| {
                            format!(
                                "{:<width$}  {:>14}  {}",
                                n.as_str(),
                                value_text(*v),
                                type_name(v.param_type())
                            )
                        })
                        .collect()
                };
                print_lines(&lines)?;
                eprintln!(
                    "{} parameters from {target} in {seconds:.2} s ({how})",
                    table.len()
                );
                Ok(())
            }
            ParamAction::Get {
                remote: args,
                names,
            } => {
                let names = names
                    .iter()
                    .map(|n| name_arg(n))
                    .collect::<Result<Vec<_>, _>>()?;
                let mut remote = Remote::connect(&args).await?;
                let mut lines = Vec::new();
                for name in names {
                    let p = remote.system.param(name).await.map_err(other)?;
                    lines.push(if args.json {
                        param_json(usize::from(p.index), p.name, p.value).to_string()
                    } else {
                        format!(
                            "{} = {} ({})",
                            p.name,
                            value_text(p.value),
                            type_name(p.value.param_type())
                        )
                    });
                }
                remote.close().await?;
                print_lines(&lines)
            }
            ParamAction::Load {
                remote: args,
                file,
                via,
            } => crate::param_load::load(&args, &file, via).await,
            ParamAction::Set {
                remote: args,
                name,
                value,
            } => {
                let name = name_arg(&name)?;
                let mut remote = Remote::connect(&args).await?;
                let before = remote.system.param(name).await.map_err(other)?;
                let after = set_param(&mut remote.system, name, before.value, value).await?;
                remote.close().await?;
                let line = if args.json {
                    let mut j = param_json(usize::from(after.index), after.name, after.value);
                    j["previous"] = value_json(before.value);
                    j.to_string()
                } else {
                    format!(
                        "{} = {} ({}, was {})",
                        after.name,
                        value_text(after.value),
                        type_name(after.value.param_type()),
                        value_text(before.value)
                    )
                };
                print_lines(&[line])
            }
        }
    })
}

pub(crate) fn mission(action: MissionAction) -> Result<(), Failure> {
    runtime()?.block_on(async {
        match action {
            MissionAction::Download {
                remote: args,
                file,
                plan,
            } => {
                let mut remote = Remote::connect(&args).await?;
                let target = remote.target();
                let began = remote.elapsed();
                let result = remote
                    .system
                    .download_mission_with_progress(plan.mav(), progress("items"))
                    .await;
                end_progress();
                let seconds = remote.since(began);
                let json_out = file.as_deref().map_or(args.json, |f| f.ends_with(".json"));
                // A plan file starts with home (QGC WPL): the vehicle's convention undone.
                let convention = plan_convention(&remote, plan, !json_out);
                let home = if convention == Convention::Px4 {
                    remote.system.home_item(core::time::Duration::from_secs(3)).await
                } else {
                    None
                };
                remote.close().await?;
                let items = result.map_err(|e| other(format!("download from {target}: {e}")))?;
                let items = plan::from_vehicle(convention, &items, home);
                let text = match &file {
                    Some(path) if path.ends_with(".json") => {
                        format!("{:#}\n", mission_file::to_json(plan.mav(), &items))
                    }
                    Some(_) => mavstack_services::wpl::to_text(&items),
                    None if args.json => {
                        format!("{}\n", mission_file::to_json(plan.mav(), &items))
                    }
                    None => mavstack_services::wpl::to_text(&items),
                };
                match &file {
                    Some(path) => std::fs::write(path, text)
                        .map_err(|e| other(format!("cannot write {path}: {e}")))?,
                    None => print_lines(&[text.trim_end().to_owned()])?,
                }
                eprintln!(
                    "{} {} items from {target} in {seconds:.2} s",
                    items.len(),
                    mission_file::type_name(plan.mav())
                );
                Ok(())
            }
            MissionAction::Upload {
                remote: args,
                file,
                plan,
            } => {
                let items = mission_file::load(&file).map_err(Failure::Input)?;
                let mut remote = Remote::connect(&args).await?;
                let target = remote.target();
                let began = remote.elapsed();
                // A plan file starts with home (QGC WPL): the vehicle's convention applied.
                let convention = plan_convention(&remote, plan, !file.ends_with(".json"));
                let items = plan::to_vehicle(convention, &items);
                let count = items.len();
                let result = remote
                    .system
                    .upload_mission_with_progress(plan.mav(), items, progress("items"))
                    .await;
                end_progress();
                let seconds = remote.since(began);
                remote.close().await?;
                result.map_err(|e| other(format!("upload to {target}: {e}")))?;
                let line = if args.json {
                    json!({"uploaded": count, "mission_type": mission_file::type_name(plan.mav()), "seconds": seconds}).to_string()
                } else {
                    format!(
                        "{count} {} items uploaded to {target} in {seconds:.2} s",
                        mission_file::type_name(plan.mav())
                    )
                };
                print_lines(&[line])
            }
            MissionAction::Clear { remote: args, plan } => {
                let mut remote = Remote::connect(&args).await?;
                let target = remote.target();
                let result = remote.system.clear_mission(plan.mav()).await;
                remote.close().await?;
                result.map_err(|e| other(format!("clear on {target}: {e}")))?;
                let line = if args.json {
                    json!({"cleared": mission_file::type_name(plan.mav())}).to_string()
                } else {
                    format!("{} cleared on {target}", mission_file::type_name(plan.mav()))
                };
                print_lines(&[line])
            }
        }
    })
}

/// The mission convention between a plan and the vehicle: QGC WPL plans (item 0: home) of
/// the MISSION type follow the autopilot's; JSON plans and fences and rally points go as
/// they are.
fn plan_convention(remote: &Remote, plan: PlanType, wpl: bool) -> Convention {
    if wpl && plan.mav() == MavMissionType::MISSION {
        Convention::of(remote.system.autopilot())
    } else {
        Convention::Plain
    }
}

fn number(text: &str, what: &str) -> Result<f32, Failure> {
    text.parse::<f32>()
        .map_err(|_| Failure::Input(anyhow!("{what} {text:?} is not a number")))
}

/// The MAV_CMD named `name` (with or without the `MAV_CMD_` prefix) or numbered so.
fn command_id(name: &str) -> Result<MavCmd, Failure> {
    if let Ok(n) = name.parse::<u16>() {
        return Ok(MavCmd(n));
    }
    let upper = name.to_ascii_uppercase().replace('-', "_");
    MavCmd::from_name(&upper)
        .or_else(|| MavCmd::from_name(&format!("MAV_CMD_{upper}")))
        .ok_or_else(|| {
            Failure::Input(anyhow!(
                "unknown command {name:?}: not a MAV_CMD name or number"
            ))
        })
}

pub(crate) fn result_name(r: MavResult) -> &'static str {
    r.name()
        .and_then(|n| n.strip_prefix("MAV_RESULT_"))
        .unwrap_or("UNKNOWN")
}

pub(crate) fn command_name(c: MavCmd) -> String {
    c.name().map_or_else(
        || c.0.to_string(),
        |n| n.strip_prefix("MAV_CMD_").unwrap_or(n).to_owned(),
    )
}

/// The command `args` ask for: id and params 1–7.
fn build_command(args: &CommandArgs, remote: &Remote) -> Result<(MavCmd, [f32; 7]), Failure> {
    let given = |i: usize, what: &str| -> Result<Option<f32>, Failure> {
        args.params.get(i).map(|p| number(p, what)).transpose()
    };
    let only = |n: usize| -> Result<(), Failure> {
        if args.params.len() > n {
            return Err(Failure::Input(anyhow!(
                "`{}` takes at most {n} argument(s)",
                args.name
            )));
        }
        Ok(())
    };
    let mut p = [0.0f32; 7];
    let id = match args.name.to_ascii_lowercase().as_str() {
        "arm" | "disarm" => {
            only(0)?;
            p[0] = if args.name.eq_ignore_ascii_case("arm") {
                1.0
            } else {
                0.0
            };
            if args.force {
                p[1] = 21196.0;
            }
            MavCmd::COMPONENT_ARM_DISARM
        }
        "takeoff" => {
            only(1)?;
            let alt = given(0, "altitude")?;
            p[3] = f32::NAN;
            p[4] = f32::NAN;
            p[5] = f32::NAN;
            p[6] = match (remote.flavour(), alt) {
                // PX4 takes an altitude above mean sea level.
                (Some(Flavour::Px4), Some(a)) => match remote.system.home_amsl() {
                    Some(home) => home + a,
                    None => f32::NAN,
                },
                (_, Some(a)) => a,
                (_, None) => f32::NAN,
            };
            MavCmd::NAV_TAKEOFF
        }
        "land" => {
            only(0)?;
            p[3] = f32::NAN;
            p[4] = f32::NAN;
            p[5] = f32::NAN;
            p[6] = f32::NAN;
            MavCmd::NAV_LAND
        }
        "rtl" => {
            only(0)?;
            MavCmd::NAV_RETURN_TO_LAUNCH
        }
        "mission-start" => {
            only(2)?;
            p[0] = given(0, "first item")?.unwrap_or(0.0);
            p[1] = given(1, "last item")?.unwrap_or(0.0);
            MavCmd::MISSION_START
        }
        "mode" => {
            let Some(name) = args.params.first() else {
                return Err(Failure::Input(anyhow!("`mode` needs a mode name")));
            };
            only(1)?;
            let flavour = remote.flavour().ok_or_else(|| {
                other("the target's modes are not known (neither ArduPilot nor PX4): give DO_SET_MODE's params")
            })?;
            let mode = modes::by_name(flavour, name).ok_or_else(|| {
                let names: Vec<&str> = modes::modes(flavour).iter().map(|m| m.name).collect();
                Failure::Input(anyhow!(
                    "unknown {flavour} mode {name:?}; one of {}",
                    names.join(", ")
                ))
            })?;
            (p[0], p[1], p[2]) = flavour.command_params(mode.custom_mode);
            MavCmd::DO_SET_MODE
        }
        _ => {
            if args.params.len() > 7 {
                return Err(Failure::Input(anyhow!("a command has at most 7 params")));
            }
            for (i, slot) in p.iter_mut().enumerate() {
                if let Some(v) = given(i, &format!("param{}", i + 1))? {
                    *slot = v;
                }
            }
            command_id(&args.name)?
        }
    };
    Ok((id, p))
}

pub(crate) fn command(args: &CommandArgs) -> Result<(), Failure> {
    // Name errors before the link opens (the shortcuts are checked against the target).
    let shortcut = [
        "arm",
        "disarm",
        "takeoff",
        "land",
        "rtl",
        "mission-start",
        "mode",
    ]
    .iter()
    .any(|s| s.eq_ignore_ascii_case(&args.name));
    if !shortcut {
        command_id(&args.name)?;
    }
    runtime()?.block_on(async {
        let mut remote = Remote::connect(&args.remote).await?;
        remote.system.update();
        if args.name.eq_ignore_ascii_case("takeoff") && remote.flavour() == Some(Flavour::Px4) {
            // PX4 reads NAV_TAKEOFF's altitude as above mean sea level: the user's "10" is
            // 10 m above home, which needs home's altitude first.
            remote
                .system
                .find_home_amsl(core::time::Duration::from_secs(3))
                .await;
        }
        let (id, p) = build_command(args, &remote)?;
        let target = remote.target();
        let command = if args.int {
            let deg_e7 = |v: f32| {
                if v.is_finite() {
                    (f64::from(v) * 1e7) as i32
                } else {
                    i32::MAX
                }
            };
            Command::Int(CommandInt {
                command: id,
                frame: MavFrame(args.frame),
                param1: p[0],
                param2: p[1],
                param3: p[2],
                param4: p[3],
                x: deg_e7(p[4]),
                y: deg_e7(p[5]),
                z: p[6],
                ..CommandInt::default()
            })
        } else {
            Command::long(id, p)
        };
        let began = remote.elapsed();
        let json = args.remote.json;
        let result = remote
            .system
            .command(command, |progress| {
                if !json {
                    eprintln!("{}: in progress {progress}%", command_name(id));
                }
            })
            .await;
        let seconds = remote.since(began);
        remote.close().await?;
        let none: &[String] = &[];
        let (result, code, param2, said) = match &result {
            Ok(ack) => (Some(ack.result), 0, ack.result_param2, none),
            Err(SystemError::Command {
                source:
                    CommandError::Rejected {
                        result,
                        result_param2,
                    },
                statustext,
                ..
            }) => (Some(*result), 1, *result_param2, statustext.as_slice()),
            Err(SystemError::Command { statustext, .. }) => (None, 1, 0, statustext.as_slice()),
            Err(e) => return Err(other(e)),
        };
        let line = if json {
            json!({
                "command": id.0,
                "name": command_name(id),
                "target": target.to_string(),
                "result": result.map_or("TIMEOUT", result_name),
                "result_code": result.map(|r| r.0),
                "result_param2": param2,
                "seconds": seconds,
                "statustext": said,
            })
            .to_string()
        } else {
            let why = if said.is_empty() {
                String::new()
            } else {
                format!(": {}", said.join("; "))
            };
            format!(
                "{} → {} ({seconds:.2} s){why}",
                command_name(id),
                result.map_or("no acknowledgement (timed out)", result_name)
            )
        };
        print_lines(&[line])?;
        if code == 0 {
            Ok(())
        } else {
            Err(other(format!(
                "{} was not accepted by {target}",
                command_name(id)
            )))
        }
    })
}
