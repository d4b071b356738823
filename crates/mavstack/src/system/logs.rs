//! [`Logs`]: a system's logs over LOG_* — listed (missing entries asked for again),
//! downloaded (gaps asked for again), erased — or, where the vehicle keeps them as files
//! (ArduPilot: `APM/LOGS/00000001.BIN`, `logs/` in SITL), over MAVFTP.

use core::time::Duration;

use mavstack_dialects::common::MavProtocolCapability;
use mavstack_services::ftp::EntryKind;
use mavstack_services::log_transfer::{
    ClientConfig as LogConfig, LogClient, LogEvent, LogInfo, LogOutput, StartError as LogStartError,
};
use mavstack_transport::clock;

use super::{AUTO_FTP_RETRIES, CAPABILITIES_WAIT, PATIENT_RETRIES, System, SystemError, lock, run};

/// Where ArduPilot keeps its logs on its MAVFTP server: `APM/LOGS` on a board, `logs` in
/// the working directory of SITL; the first that lists is used.
pub const FTP_LOG_DIRS: [&str; 2] = ["/APM/LOGS", "/logs"];

/// How logs are fetched ([`Logs::download_via`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LogsVia {
    /// LOG_REQUEST_DATA, then MAVFTP if that fails and the vehicle offers the log as a file
    /// of the listed size.
    Auto,
    /// LOG_* only.
    Log,
    /// MAVFTP only (ids and sizes from the directory's listing).
    Ftp,
}

/// A log's MAVFTP path in `dir`: `/APM/LOGS/00000001.BIN` for 1.
#[must_use]
pub fn ftp_log_path(dir: &str, id: u16) -> String {
    format!("{dir}/{id:08}.BIN")
}

/// The logs of a system (from [`System::logs`]).
#[derive(Clone, Debug)]
pub struct Logs {
    system: System,
}

impl Logs {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// The system's logs (LOG_REQUEST_LIST), by id; remembered for
    /// [`download`](Self::download). Entries lost on the way are asked for again.
    ///
    /// # Errors
    /// [`SystemError::Log`] (no answer, or entries still missing, after the retries),
    /// [`SystemError::Timeout`] (2 minutes), [`SystemError::Stopped`].
    pub async fn list(&self) -> Result<Vec<LogInfo>, SystemError> {
        let output = self
            .op(
                "list",
                Duration::from_secs(120),
                |c, now| c.list(now),
                |_, _| {},
            )
            .await?;
        let LogOutput::Entries(entries) = output else {
            return Err(SystemError::Busy(
                "log list: the log client reported another operation".to_owned(),
            ));
        };
        *lock(&self.system.inner.logs) = Some(entries.clone());
        Ok(entries)
    }

    /// Log `id`'s bytes (LOG_REQUEST_DATA, gaps asked for again), telling `progress` (bytes so
    /// far, size) as they come. Its size is the one of the last [`list`](Self::list) (listed
    /// first if there was none, or it did not have `id`); never more than that is kept, and
    /// less when the vehicle ends the log earlier (sizes may be approximate).
    ///
    /// # Errors
    /// [`SystemError::NoSuchLog`], [`SystemError::Log`] (nothing new for the retries'
    /// time), [`SystemError::Busy`] (a log above 512 MiB), [`SystemError::Timeout`]
    /// (6 hours), [`SystemError::Stopped`].
    pub async fn download(
        &self,
        id: u16,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<u8>, SystemError> {
        let listed = || {
            lock(&self.system.inner.logs)
                .as_ref()
                .and_then(|l| l.iter().find(|e| e.id == id).copied())
        };
        let entry = match listed() {
            Some(entry) => entry,
            None => {
                self.list().await?;
                listed().ok_or(SystemError::NoSuchLog { id })?
            }
        };
        let output = self
            .op(
                &format!("download {id}"),
                Duration::from_secs(6 * 3600),
                |c, now| c.download(now, entry.id, entry.size),
                progress,
            )
            .await?;
        match output {
            LogOutput::Data(bytes) => Ok(bytes),
            _ => Err(SystemError::Busy(format!(
                "log download {id}: the log client reported another operation"
            ))),
        }
    }

    /// Erases every log (LOG_ERASE), then lists them to see that none is left (LOG_ERASE
    /// has no answer), sending LOG_ERASE again while some are.
    ///
    /// # Errors
    /// [`SystemError::Log`] (logs still listed; no answer to the list),
    /// [`SystemError::Timeout`] (2 minutes), [`SystemError::Stopped`].
    pub async fn erase(&self) -> Result<(), SystemError> {
        *lock(&self.system.inner.logs) = None;
        self.op(
            "erase",
            Duration::from_secs(120),
            |c, now| c.erase(now),
            |_, _| {},
        )
        .await
        .map(drop)
    }

    /// The logs MAVFTP shows in the first of [`FTP_LOG_DIRS`] that lists (files named
    /// `<8 digits>.BIN`), as entries (time 0), and that directory.
    ///
    /// # Errors
    /// Those of [`Ftp::list`](super::Ftp::list) for the last directory tried.
    pub async fn list_files(&self) -> Result<(&'static str, Vec<LogInfo>), SystemError> {
        let ftp = self.system.ftp();
        let mut listed = Err(SystemError::Busy(String::new()));
        let mut dir = FTP_LOG_DIRS[0];
        for d in FTP_LOG_DIRS {
            listed = ftp.list(d).await;
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

    /// The logs as `via` lists them: LOG_ENTRY for [`LogsVia::Auto`] and [`LogsVia::Log`],
    /// the MAVFTP files for [`LogsVia::Ftp`].
    ///
    /// # Errors
    /// Those of [`list`](Self::list) or [`list_files`](Self::list_files).
    pub async fn list_via(&self, via: LogsVia) -> Result<Vec<LogInfo>, SystemError> {
        match via {
            LogsVia::Ftp => self.list_files().await.map(|(_, logs)| logs),
            LogsVia::Auto | LogsVia::Log => self.list().await,
        }
    }

    /// The log `entry` (as listed) as `via` says, and how it came ([`LogsVia::Log`] or
    /// [`LogsVia::Ftp`]); a fallback is logged with its reason. A file over MAVFTP is
    /// checked against the server's CRC32.
    ///
    /// # Errors
    /// Those of [`download`](Self::download) and [`Ftp::read_checked`](super::Ftp::read_checked);
    /// [`SystemError::NotDone`] when the vehicle does not offer the log as a file of its
    /// listed size.
    pub async fn download_via(
        &self,
        entry: LogInfo,
        via: LogsVia,
        mut progress: impl FnMut(u64, u64),
    ) -> Result<(Vec<u8>, LogsVia), SystemError> {
        let id = entry.id;
        if via != LogsVia::Ftp {
            match self.download(id, &mut progress).await {
                Ok(bytes) => return Ok((bytes, LogsVia::Log)),
                Err(e) if via == LogsVia::Log || matches!(e, SystemError::Stopped) => {
                    return Err(e);
                }
                Err(e) => tracing::warn!(
                    "log {id}: LOG_REQUEST_DATA failed ({}): MAVFTP instead",
                    crate::error_chain(&e)
                ),
            }
        }
        let (dir, files) = if via == LogsVia::Ftp {
            self.list_files().await?
        } else {
            self.offered_files().await
        };
        if !files.iter().any(|f| f.id == id && f.size == entry.size) {
            return Err(SystemError::NotDone {
                what: format!(
                    "log {id}: not offered as a file of {} bytes over MAVFTP",
                    entry.size
                ),
                statustext: Vec::new(),
            });
        }
        let (bytes, _) = self
            .system
            .ftp()
            .read_checked(&ftp_log_path(dir, id), progress)
            .await?;
        Ok((bytes, LogsVia::Ftp))
    }

    /// The log files MAVFTP offers when AUTOPILOT_VERSION advertises it (none otherwise,
    /// or when listing fails), and their directory; asked with few retries, since the
    /// caller has already failed once.
    async fn offered_files(&self) -> (&'static str, Vec<LogInfo>) {
        let offered = self
            .system
            .capabilities(CAPABILITIES_WAIT)
            .await
            .is_some_and(|c| c.contains(MavProtocolCapability::FTP));
        if !offered {
            return (FTP_LOG_DIRS[0], Vec::new());
        }
        self.system.set_retries(AUTO_FTP_RETRIES);
        let files = self
            .list_files()
            .await
            .unwrap_or((FTP_LOG_DIRS[0], Vec::new()));
        self.system.set_retries(PATIENT_RETRIES);
        files
    }

    /// Runs one log operation, started by `start`, to its end (`limit` at most).
    async fn op(
        &self,
        what: &str,
        limit: Duration,
        start: impl FnOnce(&mut LogClient, mavstack_core::time::Instant) -> Result<(), LogStartError>,
        mut progress: impl FnMut(u64, u64),
    ) -> Result<LogOutput, SystemError> {
        let inner = &self.system.inner;
        let _one = inner.locks.logs.lock().await;
        let config = LogConfig {
            attempts: self.system.retries().max(1),
            ..LogConfig::default()
        };
        let mut client = LogClient::new(inner.target, config);
        let mut frames = self.system.frames().await;
        start(&mut client, clock::now())
            .map_err(|e| SystemError::Busy(format!("log {what}: {e}")))?;
        let result = run::drive(inner, &mut frames, &mut client, limit, |c| {
            core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                LogEvent::Progress { done, total } => {
                    progress(done, total);
                    None
                }
                LogEvent::Finished(result) => Some(result),
            })
        })
        .await;
        // Given up on (the limit, the node stopping): the vehicle is told to stop sending.
        if client.is_busy() {
            client.cancel();
        }
        run::flush(inner, &mut client).await.ok();
        result?.map_err(|source| SystemError::Log {
            what: what.to_owned(),
            source,
        })
    }
}
