//! `mavstack ftp ls|get|put|rm|mkdir|rmdir|mv|crc`: files on a system's MAVFTP server, over
//! `mavstack::system::System` (the `ftp_*` methods, which drive
//! `mavstack_services::ftp::FtpClient`).
//!
//! A download is checked against the server's CRC32 of the file after the transfer: a
//! mismatch fails the command (the local file is then not written).

use std::path::{Path, PathBuf};

use clap::Subcommand;
use mavstack::services::ftp::{EntryKind, crc32};
use mavstack::system::{FtpPathOp, System};
use serde_json::json;

use crate::gcs_cmd::{Remote, RemoteArgs, print_lines};
use crate::link_cmd::runtime;
use crate::progress::Progress;
use crate::{Failure, other};

#[derive(Debug, Subcommand)]
pub(crate) enum FtpAction {
    /// List a directory (with `--json`, one `{"name","type","size"}` object per entry).
    Ls {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The directory (default: the server's root).
        #[arg(default_value = "/")]
        path: String,
    },
    /// Download a file (checked against the server's CRC32).
    Get {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The file on the server.
        remote_path: String,
        /// Where to write it: a file, or a directory to put it in under its name (default:
        /// the current directory).
        local: Option<PathBuf>,
    },
    /// Upload a file.
    Put {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The file to send.
        local: PathBuf,
        /// Its path on the server.
        remote_path: String,
    },
    /// Remove a file.
    Rm {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The file.
        path: String,
    },
    /// Make a directory.
    Mkdir {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The directory.
        path: String,
    },
    /// Remove an empty directory.
    Rmdir {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The directory.
        path: String,
    },
    /// Rename a file or directory.
    Mv {
        #[command(flatten)]
        remote: RemoteArgs,
        /// Its path.
        from: String,
        /// Its new path.
        to: String,
    },
    /// The file's CRC32 as MAVFTP servers compute it.
    Crc {
        #[command(flatten)]
        remote: RemoteArgs,
        /// The file.
        path: String,
    },
}

impl FtpAction {
    const fn remote(&self) -> &RemoteArgs {
        match self {
            Self::Ls { remote, .. }
            | Self::Get { remote, .. }
            | Self::Put { remote, .. }
            | Self::Rm { remote, .. }
            | Self::Mkdir { remote, .. }
            | Self::Rmdir { remote, .. }
            | Self::Mv { remote, .. }
            | Self::Crc { remote, .. } => remote,
        }
    }
}

/// The local name of a downloaded file: the remote path's last part.
fn local_name(remote_path: &str) -> Result<PathBuf, Failure> {
    remote_path
        .rsplit('/')
        .find(|part| !part.is_empty())
        .map(PathBuf::from)
        .ok_or_else(|| Failure::Input(anyhow::anyhow!("ftp get: {remote_path:?} names no file")))
}

pub(crate) fn ftp(action: &FtpAction) -> Result<(), Failure> {
    let args = action.remote();
    // Read what is uploaded before connecting: a missing file is the user's mistake.
    let upload = match action {
        FtpAction::Put { local, .. } => Some(std::fs::read(local).map_err(|e| {
            Failure::Input(anyhow::anyhow!("cannot read {}: {e}", local.display()))
        })?),
        _ => None,
    };
    let download_to = match action {
        FtpAction::Get {
            remote_path, local, ..
        } => Some(match local {
            // Into a directory: under the remote file's name.
            Some(dir) if dir.is_dir() => dir.join(local_name(remote_path)?),
            Some(path) => path.clone(),
            None => local_name(remote_path)?,
        }),
        _ => None,
    };
    runtime()?.block_on(async {
        let mut remote = Remote::connect(args).await?;
        let began = remote.elapsed();
        let result = run(
            &mut remote,
            action,
            upload.as_deref(),
            download_to.as_deref(),
        )
        .await;
        let seconds = remote.since(began);
        remote.close().await?;
        let lines = result?;
        print_lines(&lines)?;
        if !args.json {
            eprintln!("ftp: done in {seconds:.2} s");
        }
        Ok(())
    })
}

/// One operation; the lines to print.
async fn run(
    remote: &mut Remote,
    action: &FtpAction,
    upload: Option<&[u8]>,
    download_to: Option<&Path>,
) -> Result<Vec<String>, Failure> {
    let json_out = action.remote().json;
    let system = &mut remote.system;
    Ok(match action {
        FtpAction::Ls { path, .. } => {
            let entries = system.ftp_list(path).await.map_err(other)?;
            entries
                .iter()
                .map(|e| {
                    let (kind, size) = match e.kind {
                        EntryKind::File { size } => ("file", Some(size)),
                        EntryKind::Directory => ("dir", None),
                        _ => ("skip", None),
                    };
                    if json_out {
                        json!({"name": e.name, "type": kind, "size": size}).to_string()
                    } else {
                        match size {
                            Some(size) => format!("{size:>12}  {}", e.name),
                            None if kind == "dir" => format!("{:>12}  {}/", "-", e.name),
                            None => format!("{:>12}  (skipped)", "?"),
                        }
                    }
                })
                .collect()
        }
        FtpAction::Get { remote_path, .. } => {
            // The size is known only once the file is open: the bar is drawn for a put.
            let (data, ours) = read_checked(system, remote_path, |_, _| {})
                .await
                .map_err(Failure::Other)?;
            let to = download_to.unwrap_or_else(|| Path::new("."));
            std::fs::write(to, &data)
                .map_err(|e| other(format!("cannot write {}: {e}", to.display())))?;
            vec![if json_out {
                json!({"get": remote_path, "to": to.display().to_string(), "bytes": data.len(), "crc32": format!("{ours:08x}")}).to_string()
            } else {
                format!(
                    "{remote_path} → {}: {} bytes, CRC32 {ours:08x}",
                    to.display(),
                    data.len()
                )
            }]
        }
        FtpAction::Put { remote_path, .. } => {
            let data = upload.unwrap_or_default();
            let mut bar = Progress::new("put", data.len() as u64);
            let sent = system
                .ftp_write(remote_path, data, |done, _| bar.set(done))
                .await;
            bar.finish();
            sent.map_err(other)?;
            vec![if json_out {
                json!({"put": remote_path, "bytes": data.len(), "crc32": format!("{:08x}", crc32(0, data))}).to_string()
            } else {
                format!("{remote_path}: {} bytes written", data.len())
            }]
        }
        FtpAction::Rm { path, .. }
        | FtpAction::Mkdir { path, .. }
        | FtpAction::Rmdir { path, .. } => {
            let op = match action {
                FtpAction::Rm { .. } => FtpPathOp::Remove,
                FtpAction::Mkdir { .. } => FtpPathOp::Mkdir,
                _ => FtpPathOp::Rmdir,
            };
            system.ftp_simple(op, path).await.map_err(other)?;
            vec![if json_out {
                json!({op.name(): path}).to_string()
            } else {
                format!("{} {path}: done", op.name())
            }]
        }
        FtpAction::Mv { from, to, .. } => {
            system.ftp_rename(from, to).await.map_err(other)?;
            vec![if json_out {
                json!({"mv": from, "to": to}).to_string()
            } else {
                format!("{from} → {to}")
            }]
        }
        FtpAction::Crc { path, .. } => {
            let crc = system.ftp_crc32(path).await.map_err(other)?;
            vec![if json_out {
                json!({"crc": path, "crc32": format!("{crc:08x}")}).to_string()
            } else {
                format!("{crc:08x}  {path}")
            }]
        }
    })
}

/// Downloads `path` and compares it with the server's CRC32 of the file (not for a file
/// [made at each open](generated_at_open)); returns the bytes and their CRC32.
///
/// # Errors
/// The download's, or a mismatch (`ftp get PATH: CRC32 ... of what arrived, the server's
/// is ...`).
pub(crate) async fn read_checked(
    system: &mut System,
    path: &str,
    progress: impl FnMut(u64, u64),
) -> Result<(Vec<u8>, u32), anyhow::Error> {
    let data = system.ftp_read(path, progress).await?;
    let ours = crc32(0, &data);
    // ArduPilot's `@` files (`@SYS/uarts.txt`, `@PARAM/param.pck`) are made anew at each
    // open, so a CRC32 asked afterwards is of other contents: not checked.
    if !generated_at_open(path) {
        let theirs = system.ftp_crc32(path).await?;
        if ours != theirs {
            anyhow::bail!(
                "ftp get {path}: CRC32 {ours:08x} of what arrived, the server's is {theirs:08x}"
            );
        }
    }
    Ok((data, ours))
}

/// Whether a remote file is one a server makes when it is opened, whose CRC32 cannot be
/// compared with a download: ArduPilot's virtual directories (`@SYS`, `@PARAM`,
/// `@MISSION`...), but not `@ROMFS`, which holds files built into the firmware.
fn generated_at_open(path: &str) -> bool {
    let path = path.trim_start_matches('/');
    path.starts_with('@') && !path.starts_with("@ROMFS/")
}
