//! `mavstack mission download|upload|clear`: plan files (QGC WPL 110, JSON) read and
//! written around what `System::mission()` does.

use anyhow::Context as _;
use clap::{Subcommand, ValueEnum};
use mavstack_dialects::common::MavMissionType;
use serde_json::json;

use crate::Failure;
use crate::link_cmd::runtime;
use crate::mission_file;
use crate::remote::{RemoteArgs, close, connect, end_progress, print_lines, progress, since};

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
    const fn mav(self) -> MavMissionType {
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

pub(crate) fn mission(action: MissionAction) -> Result<(), Failure> {
    runtime()?.block_on(async {
        match action {
            MissionAction::Download { remote, file, plan } => {
                download(&remote, file.as_deref(), plan).await
            }
            MissionAction::Upload { remote, file, plan } => upload(&remote, &file, plan).await,
            MissionAction::Clear { remote, plan } => clear(&remote, plan).await,
        }
    })
}

async fn download(args: &RemoteArgs, file: Option<&str>, plan: PlanType) -> Result<(), Failure> {
    let session = connect(args).await?;
    let target = session.system().target();
    let began = std::time::Instant::now();
    let json_out = file.map_or(args.json, |f| f.ends_with(".json"));
    let mission = session.system().mission();
    // A WPL file starts with home: the vehicle's convention undone. JSON is as it is.
    let result = if json_out {
        mission
            .download_with_progress(plan.mav(), progress("items"))
            .await
    } else {
        mission.download_plan(plan.mav(), progress("items")).await
    };
    end_progress();
    let seconds = since(began);
    close(session).await?;
    let items = result
        .with_context(|| format!("download from {target}"))
        .map_err(Failure::Other)?;
    let text = if json_out {
        format!("{:#}\n", mission_file::to_json(plan.mav(), &items))
    } else {
        mavstack_services::wpl::to_text(&items)
    };
    match file {
        Some(path) => std::fs::write(path, text)
            .with_context(|| format!("cannot write {path}"))
            .map_err(Failure::Other)?,
        None if args.json => print_lines(&[mission_file::to_json(plan.mav(), &items).to_string()])?,
        None => print_lines(&[text.trim_end().to_owned()])?,
    }
    eprintln!(
        "{} {} items from {target} in {seconds:.2} s",
        items.len(),
        mission_file::type_name(plan.mav())
    );
    Ok(())
}

async fn upload(args: &RemoteArgs, file: &str, plan: PlanType) -> Result<(), Failure> {
    let items = mission_file::load(file).map_err(Failure::Input)?;
    let session = connect(args).await?;
    let target = session.system().target();
    let began = std::time::Instant::now();
    let mission = session.system().mission();
    // A WPL file starts with home: the vehicle's convention applied. JSON goes as it is.
    let result = if file.ends_with(".json") {
        let count = items.len();
        mission
            .upload_with_progress(plan.mav(), items, progress("items"))
            .await
            .map(|()| count)
    } else {
        mission
            .upload_plan(plan.mav(), &items, progress("items"))
            .await
    };
    end_progress();
    let seconds = since(began);
    close(session).await?;
    let count = result
        .with_context(|| format!("upload to {target}"))
        .map_err(Failure::Other)?;
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

async fn clear(args: &RemoteArgs, plan: PlanType) -> Result<(), Failure> {
    let session = connect(args).await?;
    let target = session.system().target();
    let result = session.system().mission().clear(plan.mav()).await;
    close(session).await?;
    result
        .with_context(|| format!("clear on {target}"))
        .map_err(Failure::Other)?;
    let line = if args.json {
        json!({"cleared": mission_file::type_name(plan.mav())}).to_string()
    } else {
        format!(
            "{} cleared on {target}",
            mission_file::type_name(plan.mav())
        )
    };
    print_lines(&[line])
}
