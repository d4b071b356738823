//! A `mavstack vehicle` process for the CLI tests: on a free loopback UDP port, killed when
//! dropped.

use core::time::Duration;
use std::io::{BufRead as _, BufReader};
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;

/// How long a vehicle may take to open its link, on a machine as busy as CI's.
const START_LIMIT: Duration = Duration::from_secs(60);

/// A running `mavstack vehicle udpin:127.0.0.1:PORT ...`.
pub(crate) struct Vehicle {
    child: Child,
    /// The port it listens on.
    pub(crate) port: u16,
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

impl Vehicle {
    /// Starts a vehicle waiting on a free port, with `extra` options, and returns once it
    /// holds the port. A port picked free can be taken by another test's socket before the
    /// vehicle binds it (the vehicle then exits): it is tried again on another port.
    ///
    /// The vehicle runs with `--verbose`, whose first line it writes only after its link is
    /// open: that line, not the port looking busy, proves the port is this vehicle's (under
    /// load another test's process can hold the port while this one is still starting).
    pub(crate) fn start(extra: &[&str]) -> Self {
        for _ in 0..5 {
            let port = free_port();
            let mut child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
                .args(["vehicle", &format!("udpin:127.0.0.1:{port}"), "--verbose"])
                .args(extra)
                .stdout(Stdio::null())
                .stderr(Stdio::piped())
                .spawn()
                .expect("vehicle starts");
            let mut err = BufReader::new(child.stderr.take().expect("piped"));
            let (said, listening) = mpsc::channel();
            // Reads up to the first line, then on to the end and drops it, so the vehicle
            // never blocks on a full pipe. An end (the vehicle exited) before that line
            // drops `said`.
            std::thread::spawn(move || {
                let mut line = Vec::new();
                loop {
                    line.clear();
                    match err.read_until(b'\n', &mut line) {
                        Ok(0) | Err(_) => return,
                        Ok(_) if line.starts_with(b"vehicle: ") => break,
                        Ok(_) => {}
                    }
                }
                let _ = said.send(());
                let _ = std::io::copy(&mut err, &mut std::io::sink());
            });
            match listening.recv_timeout(START_LIMIT) {
                Ok(()) => return Self { child, port },
                Err(mpsc::RecvTimeoutError::Disconnected) => {}
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    let _ = child.kill();
                    panic!("mavstack vehicle did not say it listens within {START_LIMIT:?}");
                }
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        panic!("mavstack vehicle did not start on any of 5 free ports");
    }
}

impl Drop for Vehicle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
