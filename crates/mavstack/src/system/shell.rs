//! [`Shell`]: a system's shell over MAVLink (SERIAL_CONTROL to the SHELL device, as PX4's
//! nsh expects it): one command and its output ([`Shell::run`]), or a session for a terminal
//! ([`Shell::open`]). The protocol is `mavstack_services::shell`'s; one shell operation runs
//! at a time per system, since a system has one shell.

use core::time::Duration;

use mavstack_core::MessageSet as _;
use mavstack_dialects::common::MavMessage;
use mavstack_services::shell::{ShellClient, ShellCommand, ShellConfig};
use mavstack_services::{Address, Service as _};
use mavstack_transport::clock;
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::{System, SystemError, run};

/// A system's shell (from [`System::shell`]).
#[derive(Clone, Debug)]
pub struct Shell {
    system: System,
}

impl Shell {
    pub(super) const fn new(system: System) -> Self {
        Self { system }
    }

    /// Runs `command` (one line) on the shell and gives its output: what the shell printed
    /// between the echo of the line and the next prompt, made safe to print. The shell is
    /// closed afterwards.
    ///
    /// # Errors
    /// [`SystemError::Shell`] for a command with a line break, or when the shell never
    /// answers (ArduPilot has no SHELL device); [`SystemError::Timeout`] when the prompt does
    /// not come back within `limit`; [`SystemError::Stopped`].
    pub async fn run(&self, command: &str, limit: Duration) -> Result<String, SystemError> {
        let inner = &self.system.inner;
        let _one = inner.locks.shell.lock().await;
        let mut frames = self.system.frames().await;
        let mut shell =
            ShellCommand::start(clock::now(), inner.target, ShellConfig::default(), command)?;
        let result = run::drive(
            inner,
            &mut frames,
            &mut shell,
            limit,
            ShellCommand::poll_result,
        )
        .await;
        if result.is_err() {
            // Leave the shell as it would be after the command: closed.
            shell.cancel();
            run::flush(inner, &mut shell).await?;
        }
        Ok(result??)
    }

    /// Opens a session: what is written goes to the shell as it is (a terminal's keys), what
    /// the shell prints comes back as it is (with its escape sequences). It ends when the
    /// session is closed or dropped.
    pub async fn open(&self) -> ShellSession {
        let (input, keys) = mpsc::unbounded_channel::<Vec<u8>>();
        let (printed, output) = mpsc::unbounded_channel::<Vec<u8>>();
        let system = self.system.clone();
        let frames = system.frames().await;
        let task = tokio::spawn(async move { session(system, frames, keys, printed).await });
        ShellSession {
            input,
            output,
            task,
        }
    }
}

/// A session with a system's shell (from [`Shell::open`]).
#[derive(Debug)]
pub struct ShellSession {
    input: mpsc::UnboundedSender<Vec<u8>>,
    output: mpsc::UnboundedReceiver<Vec<u8>>,
    task: JoinHandle<Result<(), SystemError>>,
}

impl ShellSession {
    /// Sends `bytes` to the shell (in 70-byte SERIAL_CONTROL messages).
    ///
    /// # Errors
    /// [`SystemError::Stopped`] once the session has ended (the node stopped).
    pub fn write(&self, bytes: &[u8]) -> Result<(), SystemError> {
        self.input
            .send(bytes.to_vec())
            .map_err(|_| SystemError::Stopped)
    }

    /// The next bytes the shell printed; `None` once the session has ended.
    pub async fn read(&mut self) -> Option<Vec<u8>> {
        self.output.recv().await
    }

    /// Ends the session: the shell is told (PX4 then stops it).
    ///
    /// # Errors
    /// [`SystemError::Stopped`] when the node had stopped.
    pub async fn close(self) -> Result<(), SystemError> {
        let Self {
            input,
            output,
            task,
        } = self;
        drop(input);
        drop(output);
        task.await.map_err(|_| SystemError::Stopped)?
    }
}

/// The session's task: keys to the shell, its output back, polling on the timer; closes the
/// shell when the keys end.
async fn session(
    system: System,
    mut frames: crate::node::Subscription,
    mut keys: mpsc::UnboundedReceiver<Vec<u8>>,
    printed: mpsc::UnboundedSender<Vec<u8>>,
) -> Result<(), SystemError> {
    let inner = &system.inner;
    let _one = inner.locks.shell.lock().await;
    let mut client = ShellClient::new(inner.target, ShellConfig::default());
    client.open(clock::now());
    loop {
        run::flush(inner, &mut client).await?;
        while let Some(bytes) = client.poll_output() {
            // A reader that went away still lets the session end properly.
            let _ = printed.send(bytes);
        }
        let wake = client.poll_timeout().map_or_else(
            || tokio::time::Instant::now() + Duration::from_secs(1),
            clock::to_tokio,
        );
        tokio::select! {
            key = keys.recv() => match key {
                Some(bytes) => client.write(clock::now(), &bytes),
                None => {
                    client.close();
                    return run::flush(inner, &mut client).await;
                }
            },
            incoming = frames.recv() => {
                let incoming = incoming.ok_or(SystemError::Stopped)?;
                let f = incoming.frame.frame.view();
                if let Ok(msg @ MavMessage::SerialControl(_)) = MavMessage::decode(f.msg_id(), f.payload()) {
                    client.handle_message(clock::now(), Address::new(f.sysid(), f.compid()), &msg);
                }
            }
            () = tokio::time::sleep_until(wake) => client.handle_timeout(clock::now()),
        }
    }
}
