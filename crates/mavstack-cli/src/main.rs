//! `mavstack`: the command-line face of the mavstack MAVLink stack.
//!
//! Errors are one line on stderr starting with `error:`; the exit code is 0 on success, 1 on
//! failure and 2 on bad usage or bad input (`docs/contracts/cli.md`). Diagnostics of every
//! layer go to stderr through the `tracing` subscriber of `logging`.
//!
//! Architecture: `docs/architecture.md` in the repository.

mod camera_cmd;
mod codec_cmd;
mod command_cmd;
mod conform_cmd;
mod demo_cmd;
mod dialect_cmd;
mod fast_count;
mod fly_cmd;
mod ftp_cmd;
mod gimbal_cmd;
mod json_line;
mod link_cmd;
mod listen_rates;
mod log_cmd;
mod log_download_cmd;
mod log_plot;
mod log_reader;
mod logging;
mod mission_cmd;
mod mission_file;
mod param_cmd;
mod probe_cmd;
mod progress;
mod radio_cmd;
mod remote;
mod router_cmd;
mod rtk_cmd;
mod shell_cmd;
mod signing_cmd;
mod vehicle_cmd;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// mavstack: a complete MAVLink stack.
#[derive(Debug, Parser)]
#[command(name = "mavstack", version, about, propagate_version = true)]
struct Cli {
    #[command(flatten)]
    log: logging::LogArgs,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The main job: vehicle, radio and ground station on loopback run the MAVLink 2
    /// handshake, set up signing, fend off a replay and a forgery, exchange parameters and a
    /// mission, as a timeline.
    Demo(demo_cmd::DemoArgs),
    /// List the built-in dialects, or show one dialect's messages and enums.
    Dialect {
        #[command(subcommand)]
        action: dialect_cmd::DialectAction,
    },
    /// Generate Rust code for a dialect XML file (and every file it includes).
    Codegen(dialect_cmd::CodegenArgs),
    /// Decode a raw MAVLink stream or a tlog into JSON lines, one frame per line.
    Decode(codec_cmd::DecodeArgs),
    /// Encode JSON lines (as `decode` prints them) into raw MAVLink frames.
    Encode(codec_cmd::EncodeArgs),
    /// Print the frames arriving on a link as JSON lines (or a live table with `--table`).
    Listen(link_cmd::ListenArgs),
    /// Record a link into a tlog (flushed at least once a second).
    Record(link_cmd::RecordArgs),
    /// Send a tlog (original timing) or a raw capture onto a link.
    Replay(link_cmd::ReplayArgs),
    /// A simulated vehicle that follows the MAVLink version rules (runs until interrupted).
    Vehicle(vehicle_cmd::VehicleArgs),
    /// Find the systems on a link, run the MAVLink 2 handshake, report each as JSON.
    Probe(probe_cmd::ProbeArgs),
    /// A semi-transparent radio between a ground station (A) and a vehicle (B).
    Radio(radio_cmd::RadioArgs),
    /// Grade a remote vehicle (or, with `--role gcs`, a ground station) against the rules of
    /// the MAVLink versions documents: a table, or one JSON object with `--json`.
    Conform(conform_cmd::ConformArgs),
    /// Parameters of a remote system: list (and save), get, set.
    Param {
        #[command(subcommand)]
        action: param_cmd::ParamAction,
    },
    /// Mission, fence and rally plans of a remote system: download, upload, clear.
    Mission {
        #[command(subcommand)]
        action: mission_cmd::MissionAction,
    },
    /// Send a command (arm, takeoff, mode, any MAV_CMD) and print its acknowledgement.
    #[command(name = "command")]
    Cmd(command_cmd::CommandArgs),
    /// A vehicle's flight modes (AVAILABLE_MODES where offered, else the autopilot's
    /// table), the current one marked.
    Modes(fly_cmd::ModesArgs),
    /// Fly a vehicle: takeoff, land, rtl, hold, goto, velocity; progress on stderr, done
    /// when it is there.
    Fly(fly_cmd::FlyArgs),
    /// Forward between many links, each with its own MAVLink version and signing, converting
    /// where they differ (runs until interrupted).
    Router(router_cmd::RouterArgs),
    /// Logs: a summary, plots of fields, a smaller log of the frames selected; a vehicle's
    /// logs listed and downloaded.
    Log {
        #[command(subcommand)]
        action: log_cmd::LogAction,
    },
    /// Message signing with a remote system: set up (SETUP_SIGNING, then proven by a signed
    /// answer) or remove.
    Signing {
        #[command(subcommand)]
        action: signing_cmd::SigningAction,
    },
    /// Files on a system's MAVFTP server: list, download (checked by CRC32), upload, remove,
    /// make and remove directories, rename, CRC32.
    Ftp {
        #[command(subcommand)]
        action: ftp_cmd::FtpAction,
    },
    /// A system's shell over MAVLink (PX4's nsh): interactive, or one `--command` and its
    /// output.
    Shell(shell_cmd::ShellArgs),
    /// Forward an RTCM3 stream (TCP, serial or a file) to a vehicle as RTK corrections.
    Rtk(rtk_cmd::RtkArgs),
    /// A system's gimbals (gimbal protocol v2): list, point by angles, rates or at a
    /// location, read where they look.
    Gimbal(gimbal_cmd::GimbalArgs),
    /// A system's cameras (camera protocol v2): list, take a photo, record, intervals,
    /// modes, settings.
    Camera(camera_cmd::CameraArgs),
}

/// A failure with the exit code it maps to.
#[derive(Debug)]
pub(crate) enum Failure {
    /// Bad input (a malformed dialect, an unknown name): exit code 2.
    Input(anyhow::Error),
    /// Anything else: exit code 1.
    Other(anyhow::Error),
}

/// A failure (exit code 1) that is only a message.
pub(crate) fn other(message: impl core::fmt::Display) -> Failure {
    Failure::Other(anyhow::anyhow!("{message}"))
}

/// An error as a failure (exit code 1), its chain of causes kept for the message.
pub(crate) fn fail(e: impl core::error::Error + Send + Sync + 'static) -> Failure {
    Failure::Other(anyhow::Error::new(e))
}

impl From<anyhow::Error> for Failure {
    fn from(e: anyhow::Error) -> Self {
        Self::Other(e)
    }
}

fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            || c.downcast_ref::<serde_json::Error>()
                .is_some_and(|j| j.io_error_kind() == Some(std::io::ErrorKind::BrokenPipe))
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    logging::init(&cli.log);
    let result = match cli.command {
        Command::Demo(args) => demo_cmd::demo(&args),
        Command::Dialect { action } => dialect_cmd::run(action),
        Command::Codegen(args) => dialect_cmd::codegen(&args),
        Command::Decode(args) => codec_cmd::decode(&args),
        Command::Encode(args) => codec_cmd::encode(&args),
        Command::Listen(args) => link_cmd::listen(&args),
        Command::Record(args) => link_cmd::record(&args),
        Command::Replay(args) => link_cmd::replay(&args),
        Command::Vehicle(args) => vehicle_cmd::vehicle(&args),
        Command::Probe(args) => probe_cmd::probe(&args),
        Command::Radio(args) => radio_cmd::radio(&args),
        Command::Conform(args) => conform_cmd::conform(&args),
        Command::Param { action } => param_cmd::param(action),
        Command::Mission { action } => mission_cmd::mission(action),
        Command::Cmd(args) => command_cmd::command(&args),
        Command::Modes(args) => fly_cmd::modes(&args),
        Command::Fly(args) => fly_cmd::fly(&args),
        Command::Router(args) => router_cmd::router(&args),
        Command::Log { action } => log_cmd::run(action),
        Command::Signing { action } => signing_cmd::signing(&action),
        Command::Ftp { action } => ftp_cmd::ftp(&action),
        Command::Shell(args) => shell_cmd::shell(&args),
        Command::Rtk(args) => rtk_cmd::rtk(&args),
        Command::Gimbal(args) => gimbal_cmd::gimbal(&args),
        Command::Camera(args) => camera_cmd::camera(&args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            let (e, code) = match failure {
                // The reader went away (`| head`): not an error worth a message.
                Failure::Other(e) if is_broken_pipe(&e) => return ExitCode::SUCCESS,
                Failure::Input(e) => (e, 2),
                Failure::Other(e) => (e, 1),
            };
            eprintln!("error: {}", one_line(&e));
            ExitCode::from(code)
        }
    }
}

/// An error and its chain of causes as one line, joined by `": "` without repeating a
/// cause the line already ends with (`mavstack::error_chain`).
fn one_line(e: &anyhow::Error) -> String {
    let e: &(dyn core::error::Error + 'static) = e.as_ref();
    mavstack::error_chain(e).replace('\n', " ")
}

#[cfg(test)]
mod tests {
    use super::one_line;

    /// An error that prints its source in its own message too.
    #[derive(Debug)]
    struct Repeats {
        source: std::io::Error,
    }

    impl core::fmt::Display for Repeats {
        fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
            write!(f, "link \"x\": {}", self.source)
        }
    }

    impl core::error::Error for Repeats {
        fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
            Some(&self.source)
        }
    }

    #[test]
    fn the_chain_is_joined_without_repeating_a_cause() {
        let os = || std::io::Error::from_raw_os_error(21);
        let e = anyhow::Error::new(os()).context("cannot read x.tlog");
        assert_eq!(
            one_line(&e),
            "cannot read x.tlog: Is a directory (os error 21)"
        );
        let e = anyhow::Error::new(Repeats { source: os() }).context("cannot open x");
        assert_eq!(
            one_line(&e),
            "cannot open x: link \"x\": Is a directory (os error 21)"
        );
        let e = anyhow::anyhow!("two\nlines");
        assert_eq!(one_line(&e), "two lines");
    }
}
