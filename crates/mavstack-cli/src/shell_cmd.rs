//! `mavstack shell CONN`: a system's shell over MAVLink (`mavstack::system::Shell`), as
//! PX4's nsh over SERIAL_CONTROL. `--command LINE` prints the line's output and exits;
//! without it the terminal is joined to the shell: raw mode (keys go as they are typed,
//! Ctrl-C to the shell), Ctrl-D leaves. With stdin not a terminal, what it gives is sent,
//! and the command leaves once it has ended and the shell is quiet.

use core::time::Duration;
use std::io::{Read as _, Write as _};

use clap::Args;
use mavstack::system::ShellSession;
use serde_json::json;
use tokio::sync::mpsc;

use crate::link_cmd::{duration_arg, runtime, seconds};
use crate::remote::{RemoteArgs, close, connect, print_lines};
use crate::{Failure, fail};

/// The key that leaves an interactive session.
const CTRL_D: u8 = 0x04;

/// How long the shell must be quiet after piped input ends before the command leaves.
const SETTLE: Duration = Duration::from_secs(1);

#[derive(Debug, Args)]
pub(crate) struct ShellArgs {
    #[command(flatten)]
    remote: RemoteArgs,
    /// Run this one line, print its output and exit.
    #[arg(long)]
    command: Option<String>,
    /// Seconds a `--command` may take until the prompt comes back.
    #[arg(long, default_value_t = 30.0, value_parser = duration_arg)]
    wait: f64,
}

pub(crate) fn shell(args: &ShellArgs) -> Result<(), Failure> {
    let wait = seconds(args.wait, "--wait")?;
    runtime()?.block_on(async {
        let session = connect(&args.remote).await?;
        let shell = session.system().shell();
        let result = match &args.command {
            Some(line) => {
                let output = shell.run(line, wait).await.map_err(fail);
                output.and_then(|text| {
                    if args.remote.json {
                        print_lines(&[json!({"command": line, "output": text}).to_string()])
                    } else {
                        let mut out = std::io::stdout().lock();
                        out.write_all(text.as_bytes())
                            .and_then(|()| out.flush())
                            .map_err(fail)
                    }
                })
            }
            None => interactive(shell.open().await).await,
        };
        close(session).await?;
        result
    })
}

/// Joins stdin and stdout to the session until Ctrl-D (a terminal) or the end of stdin.
async fn interactive(mut session: ShellSession) -> Result<(), Failure> {
    let terminal = std::io::IsTerminal::is_terminal(&std::io::stdin());
    let _raw = if terminal {
        Some(raw::Raw::enter().map_err(fail)?)
    } else {
        None
    };
    let mut keys = stdin_reader();
    // The shell prints its prompt when it starts (NuttX) or after a line (SITL's pxh).
    session.write(b"\n").map_err(fail)?;
    let mut stdout = std::io::stdout();
    let mut ended = false;
    loop {
        let settle = tokio::time::sleep(SETTLE);
        tokio::select! {
            key = keys.recv(), if !ended => match key {
                Some(bytes) => {
                    if terminal && bytes.contains(&CTRL_D) {
                        let before = bytes.split(|&b| b == CTRL_D).next().unwrap_or(&[]);
                        session.write(&keys_to_shell(before, terminal)).map_err(fail)?;
                        break;
                    }
                    session.write(&keys_to_shell(&bytes, terminal)).map_err(fail)?;
                }
                None => ended = true,
            },
            printed = session.read() => match printed {
                Some(bytes) => {
                    stdout.write_all(&bytes).and_then(|()| stdout.flush()).map_err(fail)?;
                }
                None => break,
            },
            () = settle, if ended => break,
        }
    }
    if terminal {
        eprint!("\r\n");
    }
    session.close().await.map_err(fail)
}

/// A terminal's keys as the shell takes them: Enter (a carriage return in raw mode) as a
/// line feed; everything else, Ctrl-C included, as it is.
fn keys_to_shell(bytes: &[u8], terminal: bool) -> Vec<u8> {
    if terminal {
        bytes
            .iter()
            .map(|&b| if b == b'\r' { b'\n' } else { b })
            .collect()
    } else {
        bytes.to_vec()
    }
}

/// Stdin read on a thread of its own (blocking reads), its bytes as they come; the channel
/// ends with stdin.
fn stdin_reader() -> mpsc::UnboundedReceiver<Vec<u8>> {
    let (tx, rx) = mpsc::unbounded_channel();
    std::thread::spawn(move || {
        let mut stdin = std::io::stdin();
        let mut buf = [0u8; 256];
        loop {
            match stdin.read(&mut buf) {
                Ok(0) | Err(_) => return,
                Ok(n) => {
                    if tx.send(buf[..n].to_vec()).is_err() {
                        return;
                    }
                }
            }
        }
    });
    rx
}

/// The terminal in raw mode while a session runs.
#[cfg(unix)]
mod raw {
    use nix::sys::termios::{self, InputFlags, LocalFlags, SetArg, SpecialCharacterIndices};

    /// Raw input on stdin (no line editing, no echo, no signals from keys: Ctrl-C is a
    /// byte for the shell) with output processing kept (line feeds still return the
    /// carriage); the terminal as it was once dropped.
    pub(super) struct Raw {
        saved: termios::Termios,
    }

    impl Raw {
        pub(super) fn enter() -> std::io::Result<Self> {
            let stdin = std::io::stdin();
            let saved = termios::tcgetattr(&stdin)?;
            let mut raw = saved.clone();
            raw.local_flags.remove(
                LocalFlags::ICANON | LocalFlags::ECHO | LocalFlags::ISIG | LocalFlags::IEXTEN,
            );
            raw.input_flags
                .remove(InputFlags::ICRNL | InputFlags::IXON | InputFlags::INLCR);
            raw.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
            raw.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
            termios::tcsetattr(&stdin, SetArg::TCSANOW, &raw)?;
            Ok(Self { saved })
        }
    }

    impl Drop for Raw {
        fn drop(&mut self) {
            let _ = termios::tcsetattr(std::io::stdin(), SetArg::TCSANOW, &self.saved);
        }
    }
}

/// Elsewhere the terminal stays as it is (keys go line by line).
#[cfg(not(unix))]
mod raw {
    pub(super) struct Raw;

    impl Raw {
        pub(super) fn enter() -> std::io::Result<Self> {
            Ok(Self)
        }
    }
}
