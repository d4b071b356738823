//! What the ground-station commands (`param`, `mission`, `command`, `modes`, `ftp`, `log
//! list|download`, `signing`) share: how the remote system is reached (its arguments, then
//! `mavstack::system::System::connect`), and how results are printed.

use std::io::Write as _;

use anyhow::anyhow;
use clap::Args;
use mavstack::LinkSpec;
use mavstack::system::{ConnectOptions, Session, System, Wanted};
use mavstack_channel::SigningConfig;
use mavstack_services::param::Value;
use serde_json::json;

use crate::vehicle_cmd::secret_key;
use crate::{Failure, fail};

/// How to reach the remote system. The options are accepted after a subcommand too
/// (`camera CONN photo --json --timeout 3`).
#[derive(Clone, Debug, Args)]
pub(crate) struct RemoteArgs {
    /// The ground station's side of the link, with link options after `?` (quote it):
    /// udpin:HOST:PORT waits for the vehicle, udpout:HOST:PORT reaches one listening there,
    /// tcp:HOST:PORT, serial:DEV:BAUD; `?key=HEX` signs, `?name=...` names it.
    pub(crate) conn: String,
    /// The system to talk to (default: the first autopilot heard).
    #[arg(long, global = true)]
    pub(crate) target_system: Option<u8>,
    /// The component to talk to (default: the one whose HEARTBEAT was heard).
    #[arg(long, global = true)]
    pub(crate) target_component: Option<u8>,
    /// Seconds to wait for the target's HEARTBEAT (from 0.001 to 86400).
    #[arg(long, global = true, default_value_t = 10.0, value_parser = crate::link_cmd::timeout_arg)]
    pub(crate) timeout: f64,
    /// Our system id.
    #[arg(long, global = true, default_value_t = 255)]
    pub(crate) sysid: u8,
    /// Our component id.
    #[arg(long, global = true, default_value_t = 190)]
    pub(crate) compid: u8,
    /// Sign with this key (64 hex digits), for vehicles that accept only signed frames
    /// (`signing setup`: the key to set up; `signing remove`: the key in use). The same as
    /// the link option `key`.
    #[arg(long, global = true)]
    pub(crate) key: Option<String>,
    /// Signing link id (with `--key`).
    #[arg(long, global = true, default_value_t = 0)]
    pub(crate) link_id: u8,
    /// Print results as JSON (one object per line).
    #[arg(long, global = true)]
    pub(crate) json: bool,
}

impl RemoteArgs {
    /// The link to open: the connection string and its options, `--key` added.
    pub(crate) fn spec(&self) -> Result<LinkSpec, Failure> {
        let mut spec =
            LinkSpec::parse(&self.conn, &|_| None).map_err(|e| Failure::Input(e.into()))?;
        if let Some(key) = &self.key {
            spec.config.signing = Some(SigningConfig::new(secret_key(key, "--key")?, self.link_id));
        }
        Ok(spec)
    }

    /// The system asked for.
    pub(crate) const fn wanted(&self) -> Wanted {
        match self.target_system {
            Some(s) => Wanted::System(s, self.target_component),
            None => Wanted::AnyAutopilot,
        }
    }
}

/// Opens the link of `args` and waits for the target (see `System::connect`).
pub(crate) async fn connect(args: &RemoteArgs) -> Result<Session, Failure> {
    let spec = args.spec()?;
    let wait = crate::link_cmd::seconds(args.timeout, "--timeout")?;
    let options = ConnectOptions::default().identity(args.sysid, args.compid);
    System::connect_with(spec, args.wanted(), wait, &options)
        .await
        .map_err(fail)
}

/// Closes `session`'s link.
pub(crate) async fn close(session: Session) -> Result<(), Failure> {
    session.close().await.map(drop).map_err(fail)
}

/// Seconds since `began`, to the millisecond.
pub(crate) fn since(began: std::time::Instant) -> f64 {
    (began.elapsed().as_secs_f64() * 1000.0).round() / 1000.0
}

/// A value as text: integers exactly, floats in their shortest form.
pub(crate) fn value_text(v: Value) -> String {
    match v {
        Value::F32(f) => format!("{f}"),
        other => format!("{}", other.as_f64()),
    }
}

/// A value as JSON: integers exactly, a float (null when not finite).
pub(crate) fn value_json(v: Value) -> serde_json::Value {
    match v {
        Value::F32(f) if f.is_finite() => json!(f),
        Value::F32(_) => serde_json::Value::Null,
        other => json!(other.as_f64() as i64),
    }
}

/// Prints lines to stdout, turning a closed pipe into the failure `main` forgives.
pub(crate) fn print_lines(lines: &[String]) -> Result<(), Failure> {
    let mut out = std::io::stdout().lock();
    for line in lines {
        writeln!(out, "{line}").map_err(fail)?;
    }
    Ok(())
}

/// Whether progress is shown: on a terminal, not when piped.
pub(crate) fn showing_progress() -> bool {
    std::io::IsTerminal::is_terminal(&std::io::stderr())
}

/// Prints `done/total what` over itself on stderr, on a terminal only.
pub(crate) fn progress<N: core::fmt::Display>(what: &'static str) -> impl FnMut(N, N) {
    let show = showing_progress();
    move |done, total| {
        if show {
            eprint!("\r\x1b[K{done}/{total} {what}");
        }
    }
}

/// Clears the progress line.
pub(crate) fn end_progress() {
    if showing_progress() {
        eprint!("\r\x1b[K");
    }
}

/// A bad-input failure (exit 2) with `message`.
pub(crate) fn input(message: impl core::fmt::Display) -> Failure {
    Failure::Input(anyhow!("{message}"))
}
