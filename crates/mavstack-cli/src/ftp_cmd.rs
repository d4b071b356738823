//! `mavstack ftp ls|get|put|rm|mkdir|rmdir|mv|crc`: files on a system's MAVFTP server, over
//! `mavstack::system::System::ftp()`.
//!
//! A download is checked against the server's CRC32 of the file after the transfer: a
//! mismatch fails the command (the local file is then not written).

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use clap::Subcommand;
use mavstack::services::ftp::{EntryKind, crc32};
use mavstack::system::{Ftp, FtpPathOp, Session};
use serde_json::json;

use crate::link_cmd::runtime;
use crate::progress::Progress;
use crate::remote::{RemoteArgs, close, connect, print_lines, since};
use crate::{Failure, fail};

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
        FtpAction::Put { local, .. } => Some(
            std::fs::read(local)
                .with_context(|| format!("cannot read {}", local.display()))
                .map_err(Failure::Input)?,
        ),
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
        let session = connect(args).await?;
        let began = std::time::Instant::now();
        let result = run(&session, action, upload.as_deref(), download_to.as_deref()).await;
        let seconds = since(began);
        close(session).await?;
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
    session: &Session,
    action: &FtpAction,
    upload: Option<&[u8]>,
    download_to: Option<&Path>,
) -> Result<Vec<String>, Failure> {
    let json_out = action.remote().json;
    let ftp: Ftp = session.system().ftp();
    Ok(match action {
        FtpAction::Ls { path, .. } => {
            let entries = ftp.list(path).await.map_err(fail)?;
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
            let (data, ours) = ftp
                .read_checked(remote_path, |_, _| {})
                .await
                .map_err(fail)?;
            let to = download_to.unwrap_or_else(|| Path::new("."));
            std::fs::write(to, &data)
                .with_context(|| format!("cannot write {}", to.display()))
                .map_err(Failure::Other)?;
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
            let sent = ftp.write(remote_path, data, |done, _| bar.set(done)).await;
            bar.finish();
            sent.map_err(fail)?;
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
            ftp.simple(op, path).await.map_err(fail)?;
            vec![if json_out {
                json!({op.name(): path}).to_string()
            } else {
                format!("{} {path}: done", op.name())
            }]
        }
        FtpAction::Mv { from, to, .. } => {
            ftp.rename(from, to).await.map_err(fail)?;
            vec![if json_out {
                json!({"mv": from, "to": to}).to_string()
            } else {
                format!("{from} → {to}")
            }]
        }
        FtpAction::Crc { path, .. } => {
            let crc = ftp.crc32(path).await.map_err(fail)?;
            vec![if json_out {
                json!({"crc": path, "crc32": format!("{crc:08x}")}).to_string()
            } else {
                format!("{crc:08x}  {path}")
            }]
        }
    })
}
