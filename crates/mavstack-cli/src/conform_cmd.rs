//! `mavstack conform`: grade a remote vehicle or ground station against the rules of the
//! MAVLink versions documents ([`mavstack::conform`]), as a table or one JSON object.

use anyhow::anyhow;
use clap::{Args, ValueEnum};
use mavstack::conform::{
    GcsOptions, Report, Status, VehicleMode, VehicleOptions, grade_ground_station, grade_vehicle,
};
use mavstack::{LinkSpec, Node};
use serde_json::json;

use crate::link_cmd::{runtime, seconds};
use crate::vehicle_cmd::secret_key;
use crate::{Failure, fail, other};

/// The side graded.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum RoleArg {
    /// A vehicle: conform plays the ground station.
    Vehicle,
    /// A ground station: conform plays the vehicle.
    Gcs,
}

/// How conform's vehicle treats the handshake (`--role gcs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum ModeArg {
    /// Answer with PROTOCOL_VERSION in MAVLink 2 (MAVLink 2 capable).
    Answer,
    /// NACK it (MAVLink 1 only).
    Nack,
    /// Ignore it (MAVLink 1 only).
    Silent,
}

#[derive(Debug, Args)]
pub(crate) struct ConformArgs {
    /// The link, from conform's side (udpin:HOST:PORT waits, udpout:HOST:PORT reaches a
    /// system listening there, tcp:..., serial:...). In `--role gcs`, conform is the vehicle.
    conn: String,
    /// The side graded.
    #[arg(long, value_enum, default_value = "vehicle")]
    role: RoleArg,
    /// With `--role gcs`: how conform's vehicle treats the handshake.
    #[arg(long, value_enum, default_value = "answer")]
    vehicle_mode: ModeArg,
    /// Seconds to wait for the first HEARTBEAT (the ground station's first frame with
    /// `--role gcs`; from 0.001 to 86400).
    #[arg(long, default_value_t = 10.0, value_parser = crate::link_cmd::timeout_arg)]
    timeout: f64,
    /// Sign with this key (64 hex digits); every frame of the vehicle must verify with it.
    #[arg(long)]
    key: Option<String>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

pub(crate) fn conform(args: &ConformArgs) -> Result<(), Failure> {
    let spec = LinkSpec::parse(&args.conn, &|_| None).map_err(|e| Failure::Input(e.into()))?;
    let timeout = seconds(args.timeout, "--timeout")?;
    let key = args
        .key
        .as_deref()
        .map(|k| secret_key(k, "--key"))
        .transpose()?;
    if args.role == RoleArg::Gcs && key.is_some() {
        return Err(Failure::Input(anyhow!(
            "--key grades a signing vehicle: it does not go with --role gcs"
        )));
    }
    let report = runtime()?.block_on(async {
        match args.role {
            RoleArg::Vehicle => {
                let node = Node::builder().link(spec).start().await.map_err(fail)?;
                let options = VehicleOptions {
                    timeout,
                    key,
                    dialect: mavstack_core::MessageTable::of::<
                        mavstack_dialects::ardupilotmega::MavMessage,
                    >(),
                    ..VehicleOptions::default()
                };
                let report = grade_vehicle(&node.handle(), &options).await;
                node.shutdown().await.map_err(fail)?;
                Ok::<_, Failure>(report)
            }
            RoleArg::Gcs => {
                let options = GcsOptions {
                    timeout,
                    mode: match args.vehicle_mode {
                        ModeArg::Answer => VehicleMode::Answer,
                        ModeArg::Nack => VehicleMode::Nack,
                        ModeArg::Silent => VehicleMode::Silent,
                    },
                    ..GcsOptions::default()
                };
                grade_ground_station(spec, &options).await.map_err(fail)
            }
        }
    })?;
    if args.json {
        crate::json_line::to_stdout(&report_json(&report)).map_err(fail)?;
    } else {
        print_table(&report, &mavstack::redacted(&args.conn));
    }
    if report.conforms() {
        Ok(())
    } else {
        let failed: Vec<&str> = report
            .verdicts
            .iter()
            .filter(|v| v.status == Status::Fail)
            .map(|v| v.rule.id())
            .collect();
        Err(other(format!(
            "the {} does not conform: {} failed",
            if args.role == RoleArg::Gcs {
                "ground station"
            } else {
                "vehicle"
            },
            failed.join(", ")
        )))
    }
}

/// The report as the JSON object of `docs/contracts/conformance.md`.
fn report_json(report: &Report) -> serde_json::Value {
    json!({
        "role": report.role.as_str(),
        "target": report.target.map(|(sysid, compid)| json!({"sysid": sysid, "compid": compid})),
        "rules": report.verdicts.iter().map(|v| json!({
            "id": v.rule.id(),
            "level": v.rule.level().as_str(),
            "status": v.status.as_str(),
            "evidence": v.evidence,
        })).collect::<Vec<_>>(),
        "summary": {
            "pass": report.count(Status::Pass),
            "fail": report.count(Status::Fail),
            "n/a": report.count(Status::NotApplicable),
        },
        "seconds": (report.seconds * 100.0).round() / 100.0,
    })
}

fn print_table(report: &Report, conn: &str) {
    let who = match report.target {
        Some((s, c)) => format!("{} {s}/{c}", report.role.as_str()),
        None => format!("no {} heard", report.role.as_str()),
    };
    println!(
        "mavstack conform: {who} on {}, {:.1} s",
        mavstack::redacted(conn),
        report.seconds
    );
    let width = report
        .verdicts
        .iter()
        .map(|v| v.rule.id().len())
        .max()
        .unwrap_or(0);
    for v in &report.verdicts {
        println!(
            "{:<width$}  {:<6}  {:<4}  {}",
            v.rule.id(),
            v.rule.level().as_str(),
            v.status.as_str(),
            v.evidence
        );
    }
    println!(
        "{} pass, {} fail, {} n/a",
        report.count(Status::Pass),
        report.count(Status::Fail),
        report.count(Status::NotApplicable)
    );
}
