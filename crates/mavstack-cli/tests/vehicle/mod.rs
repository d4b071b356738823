//! A `mavstack vehicle` process for the CLI tests: on a free loopback UDP port, killed when
//! dropped.

use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};

/// A running `mavstack vehicle udpin:127.0.0.1:PORT ...`.
pub(crate) struct Vehicle {
    child: Child,
    /// The port it listens on.
    pub(crate) port: u16,
}

impl Vehicle {
    /// Starts a vehicle waiting on a free port, with `extra` options.
    pub(crate) fn start(extra: &[&str]) -> Self {
        let port = UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .expect("a free port")
            .port();
        let child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
            .args(["vehicle", &format!("udpin:127.0.0.1:{port}")])
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("vehicle starts");
        Self { child, port }
    }
}

impl Drop for Vehicle {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
