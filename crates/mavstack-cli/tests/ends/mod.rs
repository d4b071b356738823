//! Running a command that must end by itself: the test waits for it with a bound far above
//! its own length (a hung command fails the test instead of hanging it), and asserts nothing
//! about how fast it was.

use core::time::Duration;
use std::io::Read as _;
use std::process::{Command, Output, Stdio};
use std::time::Instant;

/// How long a test waits before it calls a command hung: a bound on the wait, not a speed.
const HUNG: Duration = Duration::from_secs(120);

/// Runs `command` to its end and returns its output; fails the test (after killing it) if it
/// has not ended by itself within [`HUNG`].
pub(crate) fn output_ending_by_itself(command: &mut Command) -> Output {
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{command:?} does not start: {e}"));
    let mut stdout = child.stdout.take().expect("piped");
    let mut stderr = child.stderr.take().expect("piped");
    let out = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = stdout.read_to_end(&mut bytes);
        bytes
    });
    let err = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = stderr.read_to_end(&mut bytes);
        bytes
    });
    let deadline = Instant::now() + HUNG;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{command:?} did not end by itself; it printed:\n{}",
                String::from_utf8_lossy(&out.join().unwrap_or_default())
            );
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    Output {
        status,
        stdout: out.join().expect("stdout read"),
        stderr: err.join().expect("stderr read"),
    }
}
