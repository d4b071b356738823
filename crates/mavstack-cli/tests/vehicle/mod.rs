//! A `mavstack vehicle` process for the CLI tests: on a free loopback UDP port, killed when
//! dropped.

use core::time::Duration;
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::time::Instant;

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
    pub(crate) fn start(extra: &[&str]) -> Self {
        for _ in 0..5 {
            let port = free_port();
            let mut child = Command::new(env!("CARGO_BIN_EXE_mavstack"))
                .args(["vehicle", &format!("udpin:127.0.0.1:{port}")])
                .args(extra)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("vehicle starts");
            let deadline = Instant::now() + Duration::from_secs(10);
            let mut bound_since = None;
            while Instant::now() < deadline {
                if child.try_wait().ok().flatten().is_some() {
                    break;
                }
                let taken = UdpSocket::bind(("127.0.0.1", port)).is_err();
                match (taken, bound_since) {
                    (true, None) => bound_since = Some(Instant::now()),
                    // Still running a while after the port was taken: it is the vehicle's.
                    (true, Some(t)) if t.elapsed() > Duration::from_millis(100) => {
                        return Self { child, port };
                    }
                    (false, _) => bound_since = None,
                    _ => {}
                }
                std::thread::sleep(Duration::from_millis(10));
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
