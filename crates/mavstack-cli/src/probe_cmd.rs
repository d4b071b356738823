//! `mavstack probe`: the ground station's side of the version rules: find the systems on a
//! link, ask for AUTOPILOT_VERSION, run the MAVLink 2 handshake, print one JSON report per
//! system. The conversation is the library's (`mavstack::probe`); this file parses the
//! arguments and prints.

use anyhow::anyhow;
use clap::{Args, ValueEnum};
use mavstack::LinkSpec;
use mavstack::probe::{self, ProbeOptions, ProbedSystem};
use mavstack_channel::{CommandEncoding, HandshakeMethod, SigningConfig};

use crate::link_cmd::{runtime, seconds};
use crate::vehicle_cmd::secret_key;
use crate::{Failure, fail};

/// How the probe runs the handshake.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Method {
    /// MAV_CMD_REQUEST_MESSAGE with param1 = 300 (PROTOCOL_VERSION).
    #[value(name = "request-message-300")]
    RequestMessage300,
    /// MAV_CMD_REQUEST_PROTOCOL_VERSION.
    RequestProtocolVersion,
    /// MAV_CMD_REQUEST_MESSAGE for another message the target sends (`--other-id`, ≥ 256).
    RequestMessageOther,
}

#[derive(Debug, Args)]
pub(crate) struct ProbeArgs {
    /// The ground station's side of the link (udpin:HOST:PORT waits for vehicles,
    /// udpout:HOST:PORT reaches one listening there, tcp:HOST:PORT, serial:...).
    conn: String,
    /// Seconds to wait for the first system (from 0.001 to 86400).
    #[arg(long, default_value_t = 5.0, value_parser = crate::link_cmd::timeout_arg)]
    timeout: f64,
    /// Handshake request.
    #[arg(long, value_enum, default_value = "request-message-300")]
    method: Method,
    /// With `--method request-message-other`: the message to ask for (id from 256 to
    /// 16777215, a MAVLink 2 id).
    #[arg(long, default_value_t = 397, value_parser = clap::value_parser!(u32).range(256..=16_777_215))]
    other_id: u32,
    /// Send the requests as COMMAND_INT instead of COMMAND_LONG.
    #[arg(long)]
    command_int: bool,
    /// Sign with this key (64 hex digits): talk to vehicles that accept only signed frames.
    #[arg(long)]
    key: Option<String>,
    /// Signing link id (with `--key`).
    #[arg(long, default_value_t = 0)]
    link_id: u8,
    /// Our system id.
    #[arg(long, default_value_t = 255)]
    sysid: u8,
    /// Our component id.
    #[arg(long, default_value_t = 190)]
    compid: u8,
}

/// The JSON object of one system (`docs/contracts/cli.md`).
fn report(s: &ProbedSystem) -> String {
    let capability = s
        .mavlink2_capability
        .map_or_else(|| "null".to_owned(), |c| c.to_string());
    let supported = if s.protocol_version_supported == Some(false) {
        ",\"protocol_version_supported\":false"
    } else {
        ""
    };
    format!(
        "{{\"sysid\":{},\"compid\":{},\"autopilot\":{},\"type\":{},\"version_before\":{},\"version_after\":{},\"handshake\":{{\"method\":\"{}\",\"result\":\"{}\"}},\"mavlink2_capability\":{capability},\"signed\":{}{supported}}}",
        s.system_id,
        s.component_id,
        s.autopilot.0,
        s.kind.0,
        s.version_before.number(),
        s.version_after.number(),
        s.handshake_method.name(),
        s.handshake_result(),
        s.signed
    )
}

pub(crate) fn probe(args: &ProbeArgs) -> Result<(), Failure> {
    let mut spec = LinkSpec::parse(&args.conn, &|_| None).map_err(|e| Failure::Input(e.into()))?;
    let wait = seconds(args.timeout, "--timeout")?;
    if args.method == Method::RequestMessageOther && args.other_id < 256 {
        return Err(Failure::Input(anyhow!(
            "--other-id: {} is below 256",
            args.other_id
        )));
    }
    let method = match args.method {
        Method::RequestMessage300 => HandshakeMethod::RequestMessage300,
        Method::RequestProtocolVersion => HandshakeMethod::RequestProtocolVersion,
        Method::RequestMessageOther => HandshakeMethod::RequestMessageOther {
            msg_id: args.other_id,
        },
    };
    let encoding = if args.command_int {
        CommandEncoding::Int
    } else {
        CommandEncoding::Long
    };
    spec.config.signing = args
        .key
        .as_deref()
        .map(|k| secret_key(k, "--key").map(|key| SigningConfig::new(key, args.link_id)))
        .transpose()?;
    if args.sysid == 0 || args.compid == 0 {
        return Err(Failure::Input(anyhow!(
            "probe: --sysid and --compid must be 1 to 255"
        )));
    }
    let options = ProbeOptions::default()
        .identity(args.sysid, args.compid)
        .wait(wait)
        .handshake(method, encoding);
    let systems = runtime()?
        .block_on(probe::run(spec, &options))
        .map_err(fail)?;
    for system in &systems {
        println!("{}", report(system));
    }
    Ok(())
}
