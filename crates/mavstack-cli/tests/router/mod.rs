//! A `mavstack router` process for the CLI tests: started with its arguments, returned once it
//! says it is ready (what it printed on stderr before is kept), stopped with SIGTERM.

use core::time::Duration;
use std::ffi::OsStr;
use std::io::{BufRead, BufReader, Read};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::mpsc;
use std::time::Instant;

/// A running `mavstack router ...`.
pub(crate) struct Router {
    child: Child,
    /// Its stderr lines before `mavstack router: ready` (warnings about its options).
    pub(crate) before_ready: Vec<String>,
}

impl Router {
    /// Starts `mavstack router ARGS...` and waits until it is ready.
    pub(crate) fn start<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .arg("router")
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("mavstack router runs");
        let mut err = BufReader::new(child.stderr.take().expect("stderr piped"));
        let mut before_ready = Vec::new();
        loop {
            let mut line = String::new();
            let n = err.read_line(&mut line).expect("stderr readable");
            assert!(n > 0, "router exited before it was ready: {before_ready:?}");
            if line.contains("mavstack router: ready") {
                break;
            }
            before_ready.push(line.trim_end().to_owned());
        }
        std::thread::spawn(move || {
            let mut rest = String::new();
            let _ = err.read_to_string(&mut rest);
        });
        Self {
            child,
            before_ready,
        }
    }

    /// Its stdout, line by line, through a channel (a wait on it can be bounded).
    pub(crate) fn stdout_lines(&mut self) -> mpsc::Receiver<String> {
        let out: ChildStdout = self.child.stdout.take().expect("stdout not taken yet");
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        rx
    }

    /// SIGTERM; asserts it exits 0 within 10 s; returns what it printed on stdout (empty when
    /// [`stdout_lines`](Self::stdout_lines) took it).
    pub(crate) fn stop(mut self) -> String {
        let pid = self.child.id().to_string();
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill runs");
        let start = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("waitable") {
                assert!(status.success(), "router exit status {status}");
                let mut out = String::new();
                if let Some(mut stdout) = self.child.stdout.take() {
                    let _ = stdout.read_to_string(&mut out);
                }
                return out;
            }
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "router did not exit on SIGTERM within 10 s"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}
