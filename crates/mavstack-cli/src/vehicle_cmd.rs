//! `mavstack vehicle`: a simulated vehicle (`mavstack::sim`: parameters, missions, commands,
//! telemetry streams, a kinematic craft) on a [`mavstack::Node`] with one or more links, each
//! with its own version and signing (`docs/contracts/cli.md`, "`mavstack vehicle`").
//!
//! The version rules live in the links' channels and the router; the vehicle is
//! `mavstack::sim_vehicle::SimVehicle`. This command parses arguments and prints.

use core::time::Duration;

use anyhow::{Context as _, anyhow};
use clap::Args;
use mavstack::router::{LinkRole, ProtocolVersionSupport, VersionMode};
use mavstack::services::ftp::DirBackend;
use mavstack::sim_camera::SimCamera;
use mavstack::sim_vehicle::SimVehicle;
use mavstack::{LinkSpec, Node, NodeBuilder};
use mavstack_channel::SigningConfig;
use mavstack_core::signing::SecretKey;
use mavstack_core::wire::Version;
use mavstack_services::Address;
use tokio::sync::mpsc;

use crate::link_cmd::{interrupted, runtime};
use crate::{Failure, fail};
use mavstack_sim::logs::LogDir;
use mavstack_sim::{Autopilot, SimConfig, params};

/// `--autopilot NAME` (the names [`Autopilot`]'s `FromStr` takes).
fn autopilot_arg(name: &str) -> Result<Autopilot, String> {
    name.parse()
}

#[derive(Debug, Args)]
pub(crate) struct VehicleArgs {
    /// The vehicle's links, from its side: udpout:HOST:PORT sends to a ground station
    /// listening there, udpin:HOST:PORT waits for one, tcpin:HOST:PORT serves TCP, serial
    /// ports; each optionally followed by link options
    /// ('udpin:0.0.0.0:14550?version=1&name=legacy').
    #[arg(required = true, value_name = "LINK")]
    links: Vec<String>,
    /// System id.
    #[arg(long, default_value_t = 1)]
    sysid: u8,
    /// Component id.
    #[arg(long, default_value_t = 1)]
    compid: u8,
    /// Which autopilot to claim: ardupilot or px4.
    #[arg(long, default_value = "ardupilot", value_parser = autopilot_arg)]
    autopilot: Autopilot,
    /// MAVLink 1 only (on links that set neither `version` nor `key`): refuse the handshake
    /// (failure COMMAND_ACK), never switch.
    #[arg(long, conflicts_with_all = ["start_mavlink2", "sign_key"])]
    mavlink1_only: bool,
    /// Send MAVLink 2 from the start (on links that set neither `version` nor `key`;
    /// default: MAVLink 1 until a MAVLink 2 frame arrives).
    #[arg(long)]
    start_mavlink2: bool,
    /// Sign every frame with this key (64 hex digits) and accept only signed frames
    /// (RADIO_STATUS excepted), on links that set neither `version` nor `key`; signed
    /// MAVLink 2 from the first frame.
    #[arg(long)]
    sign_key: Option<String>,
    /// Signing link id (with --sign-key).
    #[arg(long, default_value_t = 0)]
    link_id: u8,
    /// Never answer the handshake (no PROTOCOL_VERSION support): neither ACK nor answer.
    /// The same as `--protocol-version silent`.
    #[arg(long, conflicts_with = "protocol_version")]
    no_protocol_version: bool,
    /// How a request for PROTOCOL_VERSION is answered: `answer` (PROTOCOL_VERSION in
    /// MAVLink 2, as the versions documents describe), `refuse` (as ArduPilot does:
    /// COMMAND_ACK FAILED for REQUEST_MESSAGE(300), UNSUPPORTED for command 519; ground
    /// stations then request AUTOPILOT_VERSION instead) or `silent`.
    #[arg(long, value_name = "HOW", default_value = "answer", value_parser = protocol_version_arg)]
    protocol_version: ProtocolVersionSupport,
    /// Treat the links that set neither `version` nor `key` as secure (a USB cable): accept
    /// SETUP_SIGNING on them.
    #[arg(long)]
    secure: bool,
    /// Parameter table to serve instead of the flavour's defaults: one `NAME VALUE`,
    /// `NAME,VALUE` or QGroundControl `SYSID COMPID NAME VALUE TYPE` line per parameter.
    #[arg(long, value_name = "FILE")]
    params: Option<String>,
    /// Seconds after start during which arming is refused with a STATUSTEXT saying why, as
    /// a flight stack's estimator settles (ArduPilot SITL: about 40 s). Default 0.
    #[arg(long, value_name = "S", default_value_t = 0.0, value_parser = settle_seconds)]
    estimator_settle: f64,
    /// Stream only HEARTBEAT until rates are asked for (SET_MESSAGE_INTERVAL or
    /// REQUEST_DATA_STREAM), as ArduPilot does on SITL's SERIAL0 and after a restart.
    #[arg(long)]
    streams_on_request: bool,
    /// Serve this directory over MAVFTP beside `@PARAM/param.pck` (the vehicle always
    /// serves that and advertises MAV_PROTOCOL_CAPABILITY_FTP); read-only unless
    /// --ftp-writable; no path, `..` or symlink leaves it.
    #[arg(long, value_name = "DIR")]
    ftp_root: Option<std::path::PathBuf>,
    /// With --ftp-root: let clients create, write, rename and remove files and directories.
    #[arg(long, requires = "ftp_root")]
    ftp_writable: bool,
    /// Serve this directory's files as the vehicle's logs (log download: LOG_REQUEST_LIST,
    /// LOG_REQUEST_DATA), numbered from 1 in name order, and over MAVFTP as
    /// /APM/LOGS/00000001.BIN, ... as ArduPilot keeps them; without it, two generated logs
    /// (LOG_* only). LOG_ERASE hides them; the files stay.
    #[arg(long, value_name = "DIR")]
    log_dir: Option<std::path::PathBuf>,
    /// A camera beside the vehicle, as a component of its own (component 100): the camera
    /// protocol with the simulated camera's definition file (over MAVFTP); each photo is an
    /// image file written into DIR.
    #[arg(long, value_name = "DIR")]
    camera: Option<std::path::PathBuf>,
    /// Print what happens (link versions, handshakes, rejections, modes, parameter sets,
    /// plans) to stderr.
    #[arg(long, short)]
    verbose: bool,
    #[command(flatten)]
    http: crate::router_cmd::HttpArgs,
}

fn settle_seconds(text: &str) -> Result<f64, String> {
    crate::link_cmd::number_within(text, 0.0, 3600.0, "seconds")
}

fn protocol_version_arg(text: &str) -> Result<ProtocolVersionSupport, String> {
    match text {
        "answer" => Ok(ProtocolVersionSupport::Answer),
        "refuse" => Ok(ProtocolVersionSupport::Refuse),
        "silent" => Ok(ProtocolVersionSupport::Silent),
        _ => Err(format!("'{text}' is not one of answer, refuse, silent")),
    }
}

pub(crate) fn secret_key(hex: &str, what: &str) -> Result<SecretKey, Failure> {
    SecretKey::from_hex(hex)
        .with_context(|| what.to_owned())
        .map_err(Failure::Input)
}

/// One line of what happened, for `--verbose` and the demo's timeline.
pub(crate) type Log = Option<mpsc::UnboundedSender<String>>;

pub(crate) fn say(log: &Log, line: impl FnOnce() -> String) {
    if let Some(tx) = log {
        let _ = tx.send(line());
    }
}

pub(crate) fn version_name(v: Version) -> &'static str {
    match v {
        Version::V1 => "MAVLink 1",
        Version::V2 => "MAVLink 2",
    }
}

/// Prints `--verbose` lines to stderr as they come.
pub(crate) fn stderr_log(on: bool) -> Log {
    on.then(|| {
        let (tx, mut rx) = mpsc::unbounded_channel::<String>();
        tokio::spawn(async move {
            while let Some(line) = rx.recv().await {
                eprintln!("{line}");
            }
        });
        tx
    })
}

/// Whether a link string sets `version` or `key` itself (the single-link options then leave
/// it alone).
fn sets_version_or_key(text: &str) -> bool {
    text.split_once('?').is_some_and(|(_, opts)| {
        opts.split('&')
            .any(|o| matches!(o.split_once('=').map(|(k, _)| k), Some("version" | "key")))
    })
}

/// The vehicle's node: its links, with the single-link options applied where a link sets
/// neither `version` nor `key`.
pub(crate) fn vehicle_node(args: &VehicleArgs) -> Result<NodeBuilder, Failure> {
    let signing = args
        .sign_key
        .as_deref()
        .map(|k| secret_key(k, "--sign-key").map(|key| SigningConfig::new(key, args.link_id)))
        .transpose()?;
    let mut builder = Node::builder().role(LinkRole::Vehicle {
        protocol_version: if args.no_protocol_version {
            ProtocolVersionSupport::Silent
        } else {
            args.protocol_version
        },
    });
    // Message names in link options resolve in the node's dialect (`common`).
    let dialect = mavstack::core::MessageTable::of::<mavstack::dialects::common::MavMessage>();
    builder = builder.dialect(dialect);
    for text in &args.links {
        let mut spec = LinkSpec::parse_in(text, &dialect).map_err(|e| Failure::Input(e.into()))?;
        if !sets_version_or_key(text) {
            if args.mavlink1_only {
                spec.config.version = VersionMode::Mavlink1;
            } else if args.start_mavlink2 {
                spec.config.version = VersionMode::Mavlink2;
            }
            spec.config.signing.clone_from(&signing);
            spec.config.secure |= args.secure;
        }
        builder = builder.link(spec);
    }
    Ok(builder)
}

pub(crate) fn vehicle(args: &VehicleArgs) -> Result<(), Failure> {
    if args.sysid == 0 || args.compid == 0 {
        return Err(Failure::Input(anyhow!(
            "--sysid and --compid must be 1 to 255"
        )));
    }
    let mut builder = vehicle_node(args)?;
    // The API speaks ardupilotmega, as mavlink2rest does (a superset of the node's common).
    builder = args.http.apply(builder, "ardupilotmega")?;
    let params = match &args.params {
        Some(path) => params::load(path).map_err(|e| Failure::Input(e.into()))?,
        None => params::defaults(args.autopilot),
    };
    let files = args
        .ftp_root
        .as_ref()
        .map(|root| {
            let backend = DirBackend::new(root)
                .with_context(|| format!("--ftp-root {}", root.display()))
                .map_err(Failure::Input)?;
            Ok::<_, Failure>(if args.ftp_writable {
                backend.writable()
            } else {
                backend
            })
        })
        .transpose()?;
    let log_dir = args
        .log_dir
        .as_ref()
        .map(|dir| {
            LogDir::new(dir)
                .with_context(|| format!("--log-dir {}", dir.display()))
                .map_err(Failure::Input)
        })
        .transpose()?;
    // The vehicle's own MAVFTP server serves them beside `@PARAM/param.pck`.
    let config = SimConfig {
        own: Address::new(args.sysid, args.compid),
        autopilot: args.autopilot,
        mavlink2: true,
        params,
        estimator_settle: Duration::from_secs_f64(args.estimator_settle),
        data_streams_only: false,
        streams_on_request: args.streams_on_request,
        ftp: true,
        ftp_files: files,
        log_dir,
    };
    if let Some(dir) = &args.camera
        && !dir.is_dir()
    {
        return Err(Failure::Input(anyhow!(
            "--camera {}: not a directory",
            dir.display()
        )));
    }
    runtime()?.block_on(async {
        let log = stderr_log(args.verbose);
        // The camera's node, joined to the vehicle's.
        let (builder, to_vehicle) = match &args.camera {
            Some(_) => {
                let (to_camera, to_vehicle) = mavstack::serve::joined("vehicle", "camera");
                (
                    builder.opened_link(to_camera.0, to_camera.1),
                    Some(to_vehicle),
                )
            }
            None => (builder, None),
        };
        let vehicle = SimVehicle::start_logged(builder, config, log.clone())
            .await
            .map_err(fail)?;
        let camera = match (to_vehicle, &args.camera) {
            (Some(link), Some(dir)) => {
                let own = Address::new(args.sysid, mavstack::sim_camera::CAMERA_COMPONENT);
                Some(SimCamera::start(link, own, dir, log).await.map_err(fail)?)
            }
            _ => None,
        };
        if let Some(addr) = vehicle.node().http_addr() {
            eprintln!("mavstack vehicle: status page on http://{addr}/");
        }
        tokio::select! {
            () = interrupted() => {}
            () = vehicle.node().closed() => {}
        }
        if let Some(camera) = camera {
            camera.shutdown().await.map_err(fail)?;
        }
        vehicle.shutdown().await.map(drop).map_err(fail)
    })
}
