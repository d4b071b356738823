//! Diagnostics of every layer on stderr: the `tracing` subscriber every command installs
//! (`docs/contracts/cli.md`, Logging).
//!
//! Warnings and errors are shown by default, one line each with the level, the target and
//! the event's fields (a link's events carry `link = NAME`). `-q` keeps errors only, `-v`
//! adds info and `-vv` debug (for mavstack's own crates; other crates stay at info), and
//! `RUST_LOG`, when set, replaces all of that. `--log-format json` writes one JSON object a
//! line for daemons whose stderr is collected.

use clap::{Args, ValueEnum};
use tracing_subscriber::EnvFilter;

/// How the diagnostics are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub(crate) enum LogFormat {
    /// One human-readable line per event.
    #[default]
    Text,
    /// One JSON object per line: `timestamp`, `level`, `target`, `fields`.
    Json,
}

/// The logging options, given before the command (`mavstack -v router ...`): after it,
/// `-v` is the command's own where it has one (`vehicle -v`, `radio -v`).
#[derive(Debug, Args)]
pub(crate) struct LogArgs {
    /// More diagnostics on stderr: `-v` info, `-vv` debug (`RUST_LOG` overrides).
    #[arg(short = 'v', long = "log-verbose", action = clap::ArgAction::Count)]
    verbose: u8,
    /// Errors only on stderr (`RUST_LOG` overrides).
    #[arg(short = 'q', long = "quiet", conflicts_with = "verbose")]
    quiet: bool,
    /// How diagnostics are written: `text`, or `json` (one object per line).
    #[arg(long = "log-format", value_enum, default_value_t = LogFormat::Text)]
    format: LogFormat,
}

impl LogArgs {
    /// The filter the flags ask for, without `RUST_LOG`.
    fn directives(&self) -> &'static str {
        match (self.quiet, self.verbose) {
            (true, _) => "error",
            (false, 0) => "warn",
            (false, 1) => "info",
            (false, 2) => "info,mavstack=debug",
            (false, _) => "info,mavstack=trace",
        }
    }
}

/// Installs the subscriber for the whole process. `RUST_LOG`, when set and not empty, is the
/// filter; a `RUST_LOG` that does not parse is reported and the flags' filter used instead.
pub(crate) fn init(args: &LogArgs) {
    let from_env = std::env::var("RUST_LOG")
        .ok()
        .filter(|v| !v.trim().is_empty());
    let mut bad_env = None;
    let filter = match from_env {
        Some(text) => EnvFilter::try_new(&text).unwrap_or_else(|e| {
            bad_env = Some(format!("RUST_LOG={text:?} ignored: {e}"));
            EnvFilter::new(args.directives())
        }),
        None => EnvFilter::new(args.directives()),
    };
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr);
    // Another subscriber already installed (never in the binary) is left in place.
    let _ = match args.format {
        LogFormat::Text => builder.with_ansi(ansi).try_init(),
        LogFormat::Json => builder.json().with_ansi(false).try_init(),
    };
    if let Some(warning) = bad_env {
        tracing::warn!("{warning}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(verbose: u8, quiet: bool) -> LogArgs {
        LogArgs {
            verbose,
            quiet,
            format: LogFormat::Text,
        }
    }

    #[test]
    fn flags_pick_the_level() {
        assert_eq!(args(0, false).directives(), "warn");
        assert_eq!(args(0, true).directives(), "error");
        assert_eq!(args(1, false).directives(), "info");
        assert_eq!(args(2, false).directives(), "info,mavstack=debug");
        for d in ["warn", "error", "info", "info,mavstack=debug"] {
            assert!(EnvFilter::try_new(d).is_ok(), "{d}");
        }
    }
}
