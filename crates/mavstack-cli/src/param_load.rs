//! `mavstack param load`: a parameter file onto a vehicle, the values that differ only.
//!
//! The file (`NAME VALUE` lines, as `param list --save` writes and `vehicle --params`
//! reads) is compared with the vehicle's table; each value is converted to its
//! parameter's type, and those that differ are set: with one MAVFTP upload of
//! `@PARAM/param.pck` (ArduPilot's way, seconds for a whole table) or PARAM_SET one by
//! one. Either way the result is read back and every value checked, because an upload
//! has no answer per parameter.

use anyhow::anyhow;
use clap::ValueEnum;
use mavstack::modes::Flavour;
use mavstack::system::System;
use mavstack_dialects::common::MavProtocolCapability;
use mavstack_services::param::{Name, Value};
use serde_json::json;

use mavstack::system::CAPABILITIES_WAIT;

use crate::gcs_cmd::{
    Remote, RemoteArgs, Via, end_progress, fetch_params, print_lines, showing_progress,
    typed_value, value_json, value_text,
};
use crate::{Failure, other};

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

/// One value to change.
struct Change {
    name: Name,
    value: Value,
    was: Value,
}

/// Loads `file` onto the target of `args` and prints what changed.
pub(crate) async fn load(args: &RemoteArgs, file: &str, via: LoadVia) -> Result<(), Failure> {
    let wanted = mavstack_sim::params::load(file).map_err(|e| Failure::Input(anyhow!("{e}")))?;
    let mut remote = Remote::connect(args).await?;
    let (current, _) = fetch_params(&mut remote.system, Via::Auto)
        .await
        .map_err(other)?;
    end_progress();
    let mut changes = Vec::new();
    let (mut unchanged, mut unknown) = (0usize, Vec::new());
    for &(name, value) in &wanted {
        let Some(&(_, was)) = current.iter().find(|(n, _)| *n == name) else {
            unknown.push(name);
            continue;
        };
        let value = typed_value(name, was, value.as_f64())?;
        if value.same_as(was) {
            unchanged += 1;
        } else {
            changes.push(Change { name, value, was });
        }
    }
    if !unknown.is_empty() {
        let names: Vec<&str> = unknown.iter().map(Name::as_str).collect();
        eprintln!("warning: not on the vehicle, skipped: {}", names.join(", "));
    }
    let (now, how) = if changes.is_empty() {
        (Vec::new(), "nothing to set")
    } else {
        set_all(&mut remote.system, &changes, via).await?
    };
    remote.close().await?;
    let mut failed = 0usize;
    let mut lines = Vec::new();
    for c in &changes {
        let got = now.iter().find(|(n, _)| *n == c.name).map(|&(_, v)| v);
        let ok = got.is_some_and(|v| v.same_as(c.value));
        failed += usize::from(!ok);
        lines.push(if args.json {
            json!({
                "name": c.name.as_str(),
                "value": value_json(c.value),
                "previous": value_json(c.was),
                "now": got.map(value_json),
                "ok": ok,
            })
            .to_string()
        } else {
            let state = match got {
                Some(_) if ok => String::new(),
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
    if !args.json {
        lines.push(format!(
            "{} of {} changed values set ({how}), {unchanged} unchanged, {} not on the vehicle",
            changes.len() - failed,
            changes.len(),
            unknown.len()
        ));
    }
    print_lines(&lines)?;
    if failed > 0 {
        return Err(other(format!("{failed} values were not set")));
    }
    Ok(())
}

/// Sets `changes` as `via` says; returns the table read back and how it went.
async fn set_all(
    system: &mut System,
    changes: &[Change],
    via: LoadVia,
) -> Result<(Vec<(Name, Value)>, &'static str), Failure> {
    let by_ftp = match via {
        LoadVia::Ftp => true,
        LoadVia::Set => false,
        LoadVia::Auto => {
            let ardupilot = matches!(
                system.flavour(),
                Some(
                    Flavour::ArduCopter
                        | Flavour::ArduPlane
                        | Flavour::ArduRover
                        | Flavour::ArduSub
                        | Flavour::ArduTracker
                )
            );
            ardupilot
                && system
                    .find_capabilities(CAPABILITIES_WAIT)
                    .await
                    .is_some_and(|c| c.contains(MavProtocolCapability::FTP))
        }
    };
    if by_ftp {
        let table: Vec<(Name, Value)> = changes.iter().map(|c| (c.name, c.value)).collect();
        let show = showing_progress();
        let uploaded = system
            .set_params_via_ftp(&table, |done, total| {
                if show {
                    eprint!("\r{done}/{total} bytes of @PARAM/param.pck");
                }
            })
            .await;
        end_progress();
        match uploaded {
            Ok(now) if via == LoadVia::Ftp => return Ok((now, "one MAVFTP upload")),
            Ok(mut now) => {
                // An upload has no answer per parameter, and a vehicle may skip some
                // (ArduPilot 4.7 SITL left RTL_ALT alone in a one-entry file, whoever sent
                // it): what did not take goes by PARAM_SET.
                let missed: Vec<&Change> = changes
                    .iter()
                    .filter(|c| !now.iter().any(|&(n, v)| n == c.name && v.same_as(c.value)))
                    .collect();
                if missed.is_empty() {
                    return Ok((now, "one MAVFTP upload"));
                }
                eprintln!(
                    "the MAVFTP upload did not set {} of {} values: PARAM_SET for those",
                    missed.len(),
                    changes.len()
                );
                for (name, value) in param_set(system, &missed).await? {
                    match now.iter_mut().find(|(n, _)| *n == name) {
                        Some(slot) => slot.1 = value,
                        None => now.push((name, value)),
                    }
                }
                return Ok((now, "MAVFTP upload, then PARAM_SET for what it did not set"));
            }
            Err(e) if via == LoadVia::Ftp => return Err(other(e)),
            Err(e) => eprintln!("MAVFTP upload failed ({e}): PARAM_SET instead"),
        }
    }
    let all: Vec<&Change> = changes.iter().collect();
    Ok((param_set(system, &all).await?, "PARAM_SET"))
}

/// Sets each of `changes` by PARAM_SET; returns the values the vehicle confirmed.
async fn param_set(
    system: &mut System,
    changes: &[&Change],
) -> Result<Vec<(Name, Value)>, Failure> {
    let mut now = Vec::with_capacity(changes.len());
    for (i, c) in changes.iter().enumerate() {
        if showing_progress() {
            eprint!("\r{}/{} parameters", i + 1, changes.len());
        }
        let p = system.set_param(c.name, c.value).await.map_err(other)?;
        now.push((p.name, p.value));
    }
    end_progress();
    Ok(now)
}
