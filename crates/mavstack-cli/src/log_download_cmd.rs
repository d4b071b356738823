//! `mavstack log list | download | erase`: a vehicle's logs, over
//! `mavstack::system::System::logs()` (LOG_REQUEST_LIST / LOG_REQUEST_DATA, gaps asked for
//! again, or MAVFTP where the vehicle keeps them as files; `docs/contracts/cli.md`, "Log
//! download").

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, anyhow};
use clap::{ArgGroup, Args, ValueEnum};
use mavstack::services::log_transfer::LogInfo;
use mavstack::system::{LogsVia, System, SystemError};
use serde_json::json;

use crate::link_cmd::runtime;
use crate::progress::Progress;
use crate::remote::{RemoteArgs, close, connect, print_lines, since};
use crate::{Failure, fail, other};

/// `mavstack log list`.
#[derive(Debug, Args)]
pub(crate) struct ListArgs {
    #[command(flatten)]
    remote: RemoteArgs,
}

/// `mavstack log erase`.
#[derive(Debug, Args)]
pub(crate) struct EraseArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// Erase them: every log the vehicle keeps is lost (without it nothing is sent).
    #[arg(long)]
    yes: bool,
}

/// `mavstack log download`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("which").required(true).args(["ids", "latest", "all"])))]
pub(crate) struct DownloadArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// The logs to download, by id (as `log list` shows them).
    ids: Vec<u16>,
    /// The newest log (the highest id).
    #[arg(long)]
    latest: bool,
    /// Every log.
    #[arg(long)]
    all: bool,
    /// The directory to write them to, as `log_<ID>.bin` (made if missing).
    #[arg(long, value_name = "DIR", default_value = ".")]
    out: PathBuf,
    /// How: `auto` (LOG_REQUEST_DATA, then MAVFTP if that fails and the vehicle keeps the
    /// log as a file, `APM/LOGS/<ID>.BIN` or `logs/` in SITL, of the listed size), `ftp` or
    /// `log`. (ArduPilot SITL sent a 578 KB log at 5 MB/s by LOG_DATA, 40 KiB/s by MAVFTP.)
    #[arg(long, value_enum, default_value_t = Via::Auto)]
    via: Via,
}

impl Via {
    const fn library(self) -> LogsVia {
        match self {
            Self::Auto => LogsVia::Auto,
            Self::Ftp => LogsVia::Ftp,
            Self::Log => LogsVia::Log,
        }
    }
}

/// How `log download` fetches a log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub(crate) enum Via {
    /// LOG_REQUEST_DATA, then MAVFTP where the vehicle offers the file.
    Auto,
    /// MAVFTP only (`/APM/LOGS/<ID>.BIN`, or `/logs/` as SITL keeps them; ids and sizes from its listing).
    Ftp,
    /// LOG_REQUEST_DATA only.
    Log,
}

/// `(year, month, day)` of a day counted from 1970-01-01 (the proleptic Gregorian
/// calendar; H. Hinnant's `civil_from_days`).
fn civil(days: i64) -> (i64, u32, u32) {
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (year, month, day)
}

/// A LOG_ENTRY time as `2023-11-14T22:13:20Z`; `None` for 0 (not known).
fn utc_text(secs: u32) -> Option<String> {
    if secs == 0 {
        return None;
    }
    let secs = i64::from(secs);
    let (y, mo, d) = civil(secs.div_euclid(86_400));
    let t = secs.rem_euclid(86_400);
    Some(format!(
        "{y:04}-{mo:02}-{d:02}T{:02}:{:02}:{:02}Z",
        t / 3600,
        t / 60 % 60,
        t % 60
    ))
}

/// Erases every log (LOG_ERASE), then lists them to see none is left.
pub(crate) fn erase(args: &EraseArgs) -> Result<(), Failure> {
    if !args.yes {
        return Err(Failure::Input(anyhow!(
            "log erase deletes every log on the vehicle: add --yes to do it"
        )));
    }
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let began = Instant::now();
        let result = session.system().logs().erase().await;
        let seconds = since(began);
        close(session).await?;
        result.map_err(fail)?;
        if args.remote.json {
            print_lines(&[json!({"erased": true, "seconds": seconds}).to_string()])?;
        } else {
            eprintln!("log erase: no logs left, {seconds:.2} s");
        }
        Ok(())
    })
}

pub(crate) fn list(args: &ListArgs) -> Result<(), Failure> {
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let began = Instant::now();
        let result = session.system().logs().list().await;
        let seconds = since(began);
        close(session).await?;
        let entries = result.map_err(fail)?;
        let lines: Vec<String> = if args.remote.json {
            entries
                .iter()
                .map(|e| {
                    json!({"id": e.id, "size": e.size, "time_utc": e.time_utc, "time": utc_text(e.time_utc)})
                        .to_string()
                })
                .collect()
        } else if entries.is_empty() {
            Vec::new()
        } else {
            core::iter::once(format!("{:>5}  {:>12}  time (UTC)", "id", "size"))
                .chain(entries.iter().map(|e| {
                    let time = utc_text(e.time_utc).unwrap_or_else(|| "-".to_owned());
                    format!("{:>5}  {:>12}  {time}", e.id, e.size)
                }))
                .collect()
        };
        print_lines(&lines)?;
        if !args.remote.json {
            eprintln!("log list: {} logs in {seconds:.2} s", entries.len());
        }
        Ok(())
    })
}

/// Writes `data` as `dir/log_<id>.bin`, through a `.part` file renamed when complete.
fn write_log(dir: &Path, id: u16, data: &[u8]) -> Result<PathBuf, Failure> {
    let to = dir.join(format!("log_{id}.bin"));
    let part = dir.join(format!("log_{id}.bin.part"));
    std::fs::write(&part, data)
        .and_then(|()| std::fs::rename(&part, &to))
        .with_context(|| format!("cannot write {}", to.display()))
        .map_err(Failure::Other)?;
    Ok(to)
}

pub(crate) fn download(args: &DownloadArgs) -> Result<(), Failure> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("--out {}", args.out.display()))
        .map_err(Failure::Input)?;
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let began = Instant::now();
        let result = download_all(session.system(), args).await;
        let seconds = since(began);
        close(session).await?;
        let (lines, count) = result?;
        print_lines(&lines)?;
        if !args.remote.json {
            eprintln!("log download: {count} logs in {seconds:.2} s");
        }
        Ok(())
    })
}

/// Lists, picks and downloads; the lines to print and the number of logs.
async fn download_all(
    system: &System,
    args: &DownloadArgs,
) -> Result<(Vec<String>, usize), Failure> {
    let logs = system.logs();
    let via = args.via.library();
    // What the vehicle has: its LOG_ENTRY list, or with --via ftp its log files.
    let listed = logs.list_via(via).await.map_err(fail)?;
    let wanted: Vec<LogInfo> = if args.all {
        listed.clone()
    } else if args.latest {
        let newest = listed
            .iter()
            .max_by_key(|e| e.id)
            .ok_or_else(|| other("the vehicle has no logs"))?;
        vec![*newest]
    } else {
        args.ids
            .iter()
            .map(|&id| {
                listed
                    .iter()
                    .find(|e| e.id == id)
                    .copied()
                    .ok_or_else(|| fail(SystemError::NoSuchLog { id }))
            })
            .collect::<Result<_, _>>()?
    };
    let mut lines = Vec::new();
    for entry in &wanted {
        let id = entry.id;
        let mut bar = Progress::transfer(&format!("log {id}"), u64::from(entry.size));
        let start = Instant::now();
        let got = logs
            .download_via(*entry, via, |done, _| bar.set(done))
            .await;
        bar.finish();
        let (data, how) = got.map_err(fail)?;
        let seconds = start.elapsed().as_secs_f64();
        let to = write_log(&args.out, id, &data)?;
        let kib_s = if seconds > 0.0 {
            data.len() as f64 / 1024.0 / seconds
        } else {
            0.0
        };
        let ftp = how == LogsVia::Ftp;
        lines.push(if args.remote.json {
            json!({"id": id, "file": to.display().to_string(), "bytes": data.len(),
                   "seconds": (seconds * 1e6).round() / 1e6,
                   "kib_per_s": (kib_s * 10.0).round() / 10.0, "via": if ftp { "ftp" } else { "log" }})
            .to_string()
        } else {
            format!(
                "log {id} → {}: {} bytes in {seconds:.2} s ({kib_s:.1} KiB/s) by {}",
                to.display(),
                data.len(),
                if ftp { "MAVFTP" } else { "LOG_REQUEST_DATA" }
            )
        });
    }
    Ok((lines, wanted.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_are_utc_dates() {
        assert_eq!(utc_text(0), None);
        assert_eq!(utc_text(1).as_deref(), Some("1970-01-01T00:00:01Z"));
        assert_eq!(
            utc_text(1_700_000_000).as_deref(),
            Some("2023-11-14T22:13:20Z")
        );
        assert_eq!(
            utc_text(951_782_400).as_deref(),
            Some("2000-02-29T00:00:00Z")
        );
        assert_eq!(utc_text(u32::MAX).as_deref(), Some("2106-02-07T06:28:15Z"));
    }
}
