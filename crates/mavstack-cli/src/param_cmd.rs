//! `mavstack param list|get|set|load`: printing and saving what `System::params()` does.

use anyhow::Context as _;
use clap::{Subcommand, ValueEnum};
use mavstack::system::ParamsVia;
use mavstack_dialects::common::MavParamType;
use mavstack_services::param::{Name, Value};
use serde_json::json;

use crate::link_cmd::runtime;
use crate::remote::{
    RemoteArgs, close, connect, end_progress, print_lines, showing_progress, since, value_json,
    value_text,
};
use crate::{Failure, fail, other};

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
        #[arg(long, value_enum, default_value_t = LoadVia::Auto)]
        via: LoadVia,
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

/// How `param load` sets the values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum LoadVia {
    /// One MAVFTP upload when the target is ArduPilot and advertises MAVFTP, PARAM_SET
    /// otherwise or when the upload fails.
    Auto,
    /// One MAVFTP upload of `@PARAM/param.pck` only.
    Ftp,
    /// PARAM_SET, one parameter at a time.
    Set,
}

impl Via {
    const fn library(self) -> ParamsVia {
        match self {
            Self::Auto => ParamsVia::Auto,
            Self::Ftp => ParamsVia::Ftp,
            Self::List => ParamsVia::List,
        }
    }
}

impl LoadVia {
    const fn library(self) -> ParamsVia {
        match self {
            Self::Auto => ParamsVia::Auto,
            Self::Ftp => ParamsVia::Ftp,
            Self::Set => ParamsVia::List,
        }
    }
}

fn type_name(ty: MavParamType) -> &'static str {
    ty.name()
        .and_then(|n| n.strip_prefix("MAV_PARAM_TYPE_"))
        .unwrap_or("?")
}

fn param_json(index: usize, name: Name, value: Value) -> serde_json::Value {
    json!({
        "index": index,
        "name": name.as_str(),
        "value": value_json(value),
        "type": type_name(value.param_type()),
    })
}

fn name_arg(text: &str) -> Result<Name, Failure> {
    Name::new(text)
        .with_context(|| format!("parameter name {text:?}"))
        .map_err(Failure::Input)
}

pub(crate) fn param(action: ParamAction) -> Result<(), Failure> {
    runtime()?.block_on(async {
        match action {
            ParamAction::List { remote, save, via } => list(&remote, save.as_deref(), via).await,
            ParamAction::Get { remote, names } => get(&remote, &names).await,
            ParamAction::Load { remote, file, via } => load(&remote, &file, via).await,
            ParamAction::Set {
                remote,
                name,
                value,
            } => set(&remote, &name, value).await,
        }
    })
}

async fn list(args: &RemoteArgs, save: Option<&str>, via: Via) -> Result<(), Failure> {
    let session = connect(args).await?;
    let began = std::time::Instant::now();
    let target = session.system().target();
    let show = showing_progress();
    let got = session
        .system()
        .params()
        .get_all_via(via.library(), |way, done, total| {
            if show {
                match way {
                    ParamsVia::Ftp => eprint!("\r{done}/{total} bytes of @PARAM/param.pck"),
                    _ => eprint!("\r\x1b[K{done}/{total} parameters"),
                }
            }
        })
        .await;
    end_progress();
    let seconds = since(began);
    close(session).await?;
    let (table, way) = got.map_err(fail)?;
    let how = if way == ParamsVia::Ftp {
        "MAVFTP"
    } else {
        "PARAM_REQUEST_LIST"
    };
    if let Some(path) = save {
        let text: String = table
            .iter()
            .map(|(n, v)| format!("{n} {}\n", value_text(*v)))
            .collect();
        std::fs::write(path, text)
            .with_context(|| format!("cannot write {path}"))
            .map_err(Failure::Other)?;
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

async fn get(args: &RemoteArgs, names: &[String]) -> Result<(), Failure> {
    let names = names
        .iter()
        .map(|n| name_arg(n))
        .collect::<Result<Vec<_>, _>>()?;
    let session = connect(args).await?;
    let params = session.system().params();
    let mut lines = Vec::new();
    let mut failed = None;
    for name in names {
        match params.get(name).await {
            Ok(p) => lines.push(if args.json {
                param_json(usize::from(p.index), p.name, p.value).to_string()
            } else {
                format!(
                    "{} = {} ({})",
                    p.name,
                    value_text(p.value),
                    type_name(p.value.param_type())
                )
            }),
            Err(e) => {
                failed = Some(e);
                break;
            }
        }
    }
    close(session).await?;
    print_lines(&lines)?;
    failed.map_or(Ok(()), |e| Err(fail(e)))
}

async fn set(args: &RemoteArgs, name: &str, value: f64) -> Result<(), Failure> {
    let name = name_arg(name)?;
    let session = connect(args).await?;
    let result = session.system().params().set_typed(name, value).await;
    close(session).await?;
    let (before, after) = result.map_err(|e| match e {
        mavstack::system::SystemError::Invalid(_) => Failure::Input(e.into()),
        e => fail(e),
    })?;
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

async fn load(args: &RemoteArgs, file: &str, via: LoadVia) -> Result<(), Failure> {
    let wanted = mavstack_sim::params::load(file).map_err(|e| Failure::Input(e.into()))?;
    let session = connect(args).await?;
    let report = session
        .system()
        .params()
        .load(
            &wanted,
            via.library(),
            crate::remote::progress("parameters"),
        )
        .await;
    end_progress();
    close(session).await?;
    let report = report.map_err(|e| match e {
        mavstack::system::SystemError::Invalid(_) => Failure::Input(e.into()),
        e => fail(e),
    })?;
    let mut lines = Vec::new();
    for c in &report.changes {
        lines.push(if args.json {
            json!({
                "name": c.name.as_str(),
                "value": value_json(c.value),
                "previous": value_json(c.was),
                "now": c.now.map(value_json),
                "ok": c.set(),
            })
            .to_string()
        } else {
            let state = match c.now {
                Some(_) if c.set() => String::new(),
                Some(v) => format!(", NOT SET: the vehicle has {}", value_text(v)),
                None => ", NOT SET: no longer listed".to_owned(),
            };
            format!(
                "{} = {} (was {}{state})",
                c.name,
                value_text(c.value),
                value_text(c.was)
            )
        });
    }
    let failed = report.changes.iter().filter(|c| !c.set()).count();
    if !args.json {
        lines.push(format!(
            "{} of {} changed values set ({}), {} unchanged, {} not on the vehicle",
            report.changes.len() - failed,
            report.changes.len(),
            report.how,
            report.unchanged,
            report.unknown.len()
        ));
    }
    print_lines(&lines)?;
    if failed > 0 {
        return Err(other(format!("{failed} values were not set")));
    }
    Ok(())
}
