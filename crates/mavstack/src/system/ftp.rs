//! [`Ftp`]: files on a system's MAVFTP server — list, read, write, remove, make and remove
//! directories, rename, CRC32.

use core::time::Duration;

use mavstack_services::ftp::{
    ClientConfig as FtpConfig, DirEntry, FtpClient, FtpError, FtpEvent, FtpOutput, StartError,
    crc32,
};
use mavstack_transport::clock;

use super::{System, SystemError, lock, run};

/// How long one MAVFTP operation may take.
const FTP_LIMIT: Duration = Duration::from_secs(3600);

/// The MAVFTP operations on one path that return nothing ([`Ftp::simple`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FtpPathOp {
    /// Remove a file.
    Remove,
    /// Make a directory.
    Mkdir,
    /// Remove an empty directory.
    Rmdir,
}

impl FtpPathOp {
    /// The operation's name as `mavstack ftp` spells it.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Remove => "rm",
            Self::Mkdir => "mkdir",
            Self::Rmdir => "rmdir",
        }
    }
}

/// The MAVFTP server of a system (from [`System::ftp`]).
#[derive(Clone, Debug)]
pub struct Ftp {
    system: System,
}

impl Ftp {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// A directory's entries.
    ///
    /// # Errors
    /// [`SystemError::Ftp`] (refused, or no answer after the retries), [`SystemError::Busy`]
    /// (a path too long), [`SystemError::Stopped`].
    pub async fn list(&self, path: &str) -> Result<Vec<DirEntry>, SystemError> {
        let what = format!("ls {path}");
        match self
            .op(&what, |c, now| c.list(now, path), |_, _| {}, None)
            .await?
        {
            FtpOutput::Listing(entries) => Ok(entries),
            _ => Err(protocol(what)),
        }
    }

    /// A file's contents, telling `progress` (bytes so far, size) as they come.
    ///
    /// # Errors
    /// As [`list`](Self::list).
    pub async fn read(
        &self,
        path: &str,
        progress: impl FnMut(u64, u64),
    ) -> Result<Vec<u8>, SystemError> {
        self.read_probing(path, progress, None).await
    }

    /// Like [`read`](Self::read); the first request (the open) is tried `first_retries`
    /// times more when given, rather than the usual retries (a caller with a fallback
    /// gives up sooner).
    pub(super) async fn read_probing(
        &self,
        path: &str,
        progress: impl FnMut(u64, u64),
        first_retries: Option<u8>,
    ) -> Result<Vec<u8>, SystemError> {
        let what = format!("get {path}");
        match self
            .op(&what, |c, now| c.read(now, path), progress, first_retries)
            .await?
        {
            FtpOutput::Data(bytes) => Ok(bytes),
            _ => Err(protocol(what)),
        }
    }

    /// Like [`read`](Self::read), then compared with the server's CRC32 of the file (not
    /// for a file made anew at each open: ArduPilot's `@SYS`, `@PARAM`... whose CRC32 asked
    /// afterwards is of other contents); returns the bytes and their CRC32.
    ///
    /// # Errors
    /// As [`list`](Self::list); [`SystemError::NotDone`] when the CRC32 of what arrived is not the server's.
    pub async fn read_checked(
        &self,
        path: &str,
        progress: impl FnMut(u64, u64),
    ) -> Result<(Vec<u8>, u32), SystemError> {
        let data = self.read(path, progress).await?;
        let ours = crc32(0, &data);
        if !generated_at_open(path) {
            let theirs = self.crc32(path).await?;
            if ours != theirs {
                return Err(SystemError::NotDone {
                    what: format!(
                        "ftp get {path}: CRC32 {ours:08x} of what arrived, the server's is {theirs:08x}"
                    ),
                    statustext: Vec::new(),
                });
            }
        }
        Ok((data, ours))
    }

    /// Writes `contents` as the file `path` (created; an existing file is refused by most
    /// servers), telling `progress` (bytes so far, size).
    ///
    /// # Errors
    /// As [`list`](Self::list).
    pub async fn write(
        &self,
        path: &str,
        contents: &[u8],
        progress: impl FnMut(u64, u64),
    ) -> Result<(), SystemError> {
        let what = format!("put {path}");
        self.op(&what, |c, now| c.write(now, path, contents), progress, None)
            .await
            .map(drop)
    }

    /// Removes a file (`rm`), makes or removes a directory (`mkdir`, `rmdir`).
    ///
    /// # Errors
    /// As [`list`](Self::list).
    pub async fn simple(&self, op: FtpPathOp, path: &str) -> Result<(), SystemError> {
        let what = format!("{} {path}", op.name());
        self.op(
            &what,
            |c, now| match op {
                FtpPathOp::Remove => c.remove(now, path),
                FtpPathOp::Mkdir => c.mkdir(now, path),
                FtpPathOp::Rmdir => c.rmdir(now, path),
            },
            |_, _| {},
            None,
        )
        .await
        .map(drop)
    }

    /// Renames `from` to `to`.
    ///
    /// # Errors
    /// As [`list`](Self::list).
    pub async fn rename(&self, from: &str, to: &str) -> Result<(), SystemError> {
        let what = format!("mv {from} {to}");
        self.op(&what, |c, now| c.rename(now, from, to), |_, _| {}, None)
            .await
            .map(drop)
    }

    /// A file's CRC32 as MAVFTP servers compute it (`mavstack_services::ftp::crc32`).
    ///
    /// # Errors
    /// As [`list`](Self::list).
    pub async fn crc32(&self, path: &str) -> Result<u32, SystemError> {
        let what = format!("crc {path}");
        match self
            .op(&what, |c, now| c.crc32(now, path), |_, _| {}, None)
            .await?
        {
            FtpOutput::Crc32(crc) => Ok(crc),
            _ => Err(protocol(what)),
        }
    }

    /// Runs one MAVFTP operation, started by `start`, to its end.
    async fn op(
        &self,
        what: &str,
        start: impl FnOnce(&mut FtpClient, mavstack_core::time::Instant) -> Result<(), StartError>,
        mut progress: impl FnMut(u64, u64),
        first_retries: Option<u8>,
    ) -> Result<FtpOutput, SystemError> {
        let inner = &self.system.inner;
        let _one = inner.locks.ftp.lock().await;
        let config = FtpConfig {
            attempts: self.system.retries().saturating_add(1),
            first_attempts: first_retries.map_or(0, |r| r.saturating_add(1)),
            ..FtpConfig::default()
        };
        let seq = *lock(&inner.ftp_seq);
        let mut client = FtpClient::new(inner.own, inner.target, config).starting_after(seq);
        let mut frames = self.system.frames().await;
        start(&mut client, clock::now())
            .map_err(|e| SystemError::Busy(format!("ftp {what}: {e}")))?;
        let result = run::drive(inner, &mut frames, &mut client, FTP_LIMIT, |c| {
            core::iter::from_fn(|| c.poll_event()).find_map(|e| match e {
                FtpEvent::Progress { done, total } => {
                    progress(done, total);
                    None
                }
                FtpEvent::Finished(result) => Some(result),
            })
        })
        .await;
        // The next operation's client starts past this one's numbers.
        *lock(&inner.ftp_seq) = client.last_seq().wrapping_add(1);
        result?.map_err(|source| SystemError::Ftp {
            what: what.to_owned(),
            source,
        })
    }
}

/// Whether a remote file is one a server makes when it is opened, whose CRC32 cannot be
/// compared with a download: ArduPilot's virtual directories (`@SYS`, `@PARAM`,
/// `@MISSION`...), but not `@ROMFS`, which holds files built into the firmware.
fn generated_at_open(path: &str) -> bool {
    let path = path.trim_start_matches('/');
    path.starts_with('@') && !path.starts_with("@ROMFS/")
}

fn protocol(what: String) -> SystemError {
    SystemError::Ftp {
        what,
        source: FtpError::Protocol,
    }
}
