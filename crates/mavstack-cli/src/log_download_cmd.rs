//! `mavstack log list | download | erase`: a vehicle's logs, over `mavstack::system::System`
//! (`log_list`, `log_download`: LOG_REQUEST_LIST / LOG_REQUEST_DATA, gaps asked for again)
//! or, where the vehicle keeps them as files (`APM/LOGS/00000001.BIN`, as ArduPilot), over
//! MAVFTP (`docs/contracts/cli.md`, "Log download").

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::anyhow;
use clap::{ArgGroup, Args, ValueEnum};
use mavstack::services::ftp::EntryKind;
use mavstack::services::log_transfer::LogInfo;
use mavstack::system::{PATIENT_RETRIES, System, SystemError};
use mavstack_dialects::common::MavProtocolCapability;
use serde_json::json;

use crate::ftp_cmd::read_checked;
use crate::gcs_cmd::{Remote, RemoteArgs, print_lines};
use crate::link_cmd::runtime;
use crate::progress::Progress;
use crate::{Failure, other};

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

/// Where ArduPilot keeps its logs on its MAVFTP server: `APM/LOGS` on a board, `logs` in
/// the working directory of SITL; the first that lists is used.
const FTP_DIRS: [&str; 2] = ["/APM/LOGS", "/logs"];

/// How long `--via auto` waits for AUTOPILOT_VERSION.
const CAPABILITIES_WAIT: core::time::Duration = core::time::Duration::from_secs(2);

/// Retries per MAVFTP request when `--via auto` can still fall back.
const AUTO_FTP_RETRIES: u8 = 3;

/// A log's MAVFTP path in `dir`: `/APM/LOGS/00000001.BIN` for 1.
fn ftp_path(dir: &str, id: u16) -> String {
    format!("{dir}/{id:08}.BIN")
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
        let mut remote = Remote::connect(&args.remote).await?;
        let began = remote.elapsed();
        let result = remote.system.log_erase().await;
        let seconds = remote.since(began);
        remote.close().await?;
        result.map_err(other)?;
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
        let mut remote = Remote::connect(&args.remote).await?;
        let began = remote.elapsed();
        let result = remote.system.log_list().await;
        let seconds = remote.since(began);
        remote.close().await?;
        let entries = result.map_err(other)?;
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

/// The logs MAVFTP shows in the first of [`FTP_DIRS`] that lists (files named
/// `<8 digits>.BIN`), as entries (time 0), and that directory.
async fn ftp_logs(system: &mut System) -> Result<(&'static str, Vec<LogInfo>), SystemError> {
    let mut listed = Err(SystemError::Busy(String::new()));
    let mut dir = FTP_DIRS[0];
    for d in FTP_DIRS {
        listed = system.ftp_list(d).await;
        dir = d;
        if listed.is_ok() {
            break;
        }
    }
    let mut logs: Vec<LogInfo> = listed?
        .into_iter()
        .filter_map(|e| {
            let EntryKind::File { size } = e.kind else {
                return None;
            };
            let digits = e.name.strip_suffix(".BIN")?;
            if digits.len() != 8 || !digits.bytes().all(|b| b.is_ascii_digit()) {
                return None;
            }
            Some(LogInfo {
                id: digits.parse().ok()?,
                time_utc: 0,
                size: u32::try_from(size).ok()?,
            })
        })
        .collect();
    logs.sort_by_key(|l| l.id);
    Ok((dir, logs))
}

/// The log files MAVFTP offers when AUTOPILOT_VERSION advertises it (none otherwise, or
/// when listing fails), noting their directory in `dir`.
async fn offered_files(system: &mut System, dir: &mut &'static str) -> Vec<LogInfo> {
    let offered = system
        .find_capabilities(CAPABILITIES_WAIT)
        .await
        .is_some_and(|c| c.contains(MavProtocolCapability::FTP));
    if !offered {
        return Vec::new();
    }
    system.set_retries(AUTO_FTP_RETRIES);
    let files = match ftp_logs(system).await {
        Ok((d, files)) => {
            *dir = d;
            files
        }
        Err(_) => Vec::new(),
    };
    system.set_retries(PATIENT_RETRIES);
    files
}

/// Writes `data` as `dir/log_<id>.bin`, through a `.part` file renamed when complete.
fn write_log(dir: &Path, id: u16, data: &[u8]) -> Result<PathBuf, Failure> {
    let to = dir.join(format!("log_{id}.bin"));
    let part = dir.join(format!("log_{id}.bin.part"));
    std::fs::write(&part, data)
        .and_then(|()| std::fs::rename(&part, &to))
        .map_err(|e| other(format!("cannot write {}: {e}", to.display())))?;
    Ok(to)
}

pub(crate) fn download(args: &DownloadArgs) -> Result<(), Failure> {
    std::fs::create_dir_all(&args.out)
        .map_err(|e| Failure::Input(anyhow!("--out {}: {e}", args.out.display())))?;
    runtime()?.block_on(async {
        let mut remote = Remote::connect(&args.remote).await?;
        let began = remote.elapsed();
        let result = download_all(&mut remote.system, args).await;
        let seconds = remote.since(began);
        remote.close().await?;
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
    system: &mut System,
    args: &DownloadArgs,
) -> Result<(Vec<String>, usize), Failure> {
    // What the vehicle has: its LOG_ENTRY list, or with --via ftp its log files.
    let mut ftp_dir = FTP_DIRS[0];
    let listed = match args.via {
        Via::Ftp => {
            let (dir, logs) = ftp_logs(system).await.map_err(other)?;
            ftp_dir = dir;
            logs
        }
        Via::Auto | Via::Log => system.log_list().await.map_err(other)?,
    };
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
                    .ok_or_else(|| other(SystemError::NoSuchLog { id }))
            })
            .collect::<Result<_, _>>()?
    };
    // The files MAVFTP offers, by id and size: listed already for --via ftp, looked for by
    // --via auto only when LOG_REQUEST_DATA fails.
    let mut ftp_files: Option<Vec<LogInfo>> = match args.via {
        Via::Ftp => Some(listed),
        Via::Log | Via::Auto => None,
    };
    let mut lines = Vec::new();
    for entry in &wanted {
        let id = entry.id;
        let mut bar = Progress::transfer(&format!("log {id}"), u64::from(entry.size));
        let start = Instant::now();
        let mut via = "log";
        let mut data = None;
        if args.via != Via::Ftp {
            match system.log_download(id, |done, _| bar.set(done)).await {
                Ok(bytes) => data = Some(bytes),
                Err(e) if args.via == Via::Log => {
                    bar.finish();
                    return Err(other(e));
                }
                Err(e) => {
                    bar.finish();
                    eprintln!("log {id}: LOG_REQUEST_DATA failed ({e}): MAVFTP instead");
                }
            }
        }
        if data.is_none() {
            if ftp_files.is_none() {
                ftp_files = Some(offered_files(system, &mut ftp_dir).await);
            }
            let as_file = ftp_files
                .iter()
                .flatten()
                .any(|f| f.id == id && f.size == entry.size);
            if !as_file {
                bar.finish();
                return Err(other(format!(
                    "log {id}: not offered as a file of {} bytes over MAVFTP",
                    entry.size
                )));
            }
            let got = read_checked(system, &ftp_path(ftp_dir, id), |done, _| bar.set(done)).await;
            bar.finish();
            data = Some(got.map_err(Failure::Other)?.0);
            via = "ftp";
        }
        let Some(data) = data else {
            return Err(other(format!("log {id}: nothing downloaded")));
        };
        bar.finish();
        let seconds = start.elapsed().as_secs_f64();
        let to = write_log(&args.out, id, &data)?;
        let kib_s = if seconds > 0.0 {
            data.len() as f64 / 1024.0 / seconds
        } else {
            0.0
        };
        lines.push(if args.remote.json {
            json!({"id": id, "file": to.display().to_string(), "bytes": data.len(),
                   "seconds": (seconds * 1e6).round() / 1e6,
                   "kib_per_s": (kib_s * 10.0).round() / 10.0, "via": via})
            .to_string()
        } else {
            format!(
                "log {id} → {}: {} bytes in {seconds:.2} s ({kib_s:.1} KiB/s) by {}",
                to.display(),
                data.len(),
                if via == "ftp" {
                    "MAVFTP"
                } else {
                    "LOG_REQUEST_DATA"
                }
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
        assert_eq!(ftp_path(FTP_DIRS[0], 1), "/APM/LOGS/00000001.BIN");
    }
}
